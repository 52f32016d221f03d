/* hal_mps2.c - see hal_mps2.h. */
#include "hal_mps2.h"

#include <string.h>

#include "gs_bytes.h"
#include "gs_proto_defs.h"
#include "semihost.h"

#define REG(addr) (*(volatile uint32_t *)(addr))
/* CMSDK APB UART0 */
#define UART0_DATA REG(0x40004000u)
#define UART0_STATE REG(0x40004004u)
#define UART0_CTRL REG(0x40004008u)
#define UART0_INTCLR REG(0x4000400Cu)
#define UART0_BAUDDIV REG(0x40004010u)
#define UART_STATE_TXFULL 0x1u
#define UART_STATE_RXFULL 0x2u
#define UART_STATE_RXOVR 0x8u
#define UART_CTRL_TXEN 0x1u
#define UART_CTRL_RXEN 0x2u
#define UART_CTRL_RXIE 0x8u
/* Cortex-M system */
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define NVIC_ISER0 REG(0xE000E100u)
/* CMSDK APB timer 0: free-running 32-bit down counter on the 25 MHz peripheral clock */
#define TIMER0_CTRL REG(0x40000000u)
#define TIMER0_VALUE REG(0x40000004u)
#define TIMER0_RELOAD REG(0x40000008u)
/* CMSDK APB timer 1: one-shot alarm for the stream's exposure ends (IRQ 9 on AN385) */
#define TIMER1_CTRL REG(0x40001000u)
#define TIMER1_VALUE REG(0x40001004u)
#define TIMER1_RELOAD REG(0x40001008u)
#define TIMER1_INTCLR REG(0x4000100Cu)
#define TIMER1_IRQ 9u
/* CMSDK APB watchdog */
#define WDOG_LOAD REG(0x40008000u)
#define WDOG_CTRL REG(0x40008008u)
#define WDOG_INTCLR REG(0x4000800Cu)
#define WDOG_LOCK REG(0x40008C00u)

#define TICK_FAST (MPS2_SYSCLK_HZ / 1000u) /* SysTick 1 ms while waiting out an exposure */
#define TICK_IDLE (MPS2_SYSCLK_HZ / 2u)    /* SysTick 0.5 s otherwise (watchdog kick, clock upkeep) */
#define CYCLES_PER_US (MPS2_SYSCLK_HZ / 1000000u)
#define PIXFILE_HEADER 64u

static volatile uint64_t g_ticks;   /* 25 MHz ticks since boot */
static volatile uint32_t g_last_raw; /* TIMER0 value at the last update */
static volatile uint8_t g_ring[MPS2_RX_RING];
static volatile uint32_t g_head, g_tail, g_overruns;

static inline uint32_t irq_save(void)
{
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
    return primask;
}
static inline void irq_restore(uint32_t primask) { __asm__ volatile("msr primask, %0" ::"r"(primask) : "memory"); }

static uint64_t time_us(void *ctx);

/* SysTick only wakes the core (1 ms during exposure waits, 0.5 s when idle) and keeps the
 * TIMER0 accumulation current; time itself comes from TIMER0, so ticks lost while the host
 * (or QEMU) is late do not slow the clock. */
void SysTick_Handler(void) { (void)time_us(NULL); }

/* The stream's alarm: the exposure ending now is read out by the main loop (gs_head_poll);
 * the interrupt only wakes the core from wfi. One-shot: stopped until set again. */
void TIMER1_Handler(void)
{
    TIMER1_INTCLR = 1u;
    TIMER1_CTRL = 0u;
}

void mps2_alarm_at(uint64_t t_us)
{
    TIMER1_CTRL = 0u;
    if (t_us == UINT64_MAX)
        return;
    uint64_t now = time_us(NULL);
    uint64_t us = t_us > now ? t_us - now : 1u;
    if (us > 100000000u)
        us = 100000000u; /* 100 s: the counter holds 171 s of 25 MHz ticks */
    TIMER1_RELOAD = (uint32_t)(us * CYCLES_PER_US);
    TIMER1_VALUE = (uint32_t)(us * CYCLES_PER_US);
    TIMER1_INTCLR = 1u;
    TIMER1_CTRL = 0x9u; /* enable, interrupt enable */
}

void UART0_RX_Handler(void)
{
    /* Clear the RX interrupt before draining, never after: a byte that lands between the
     * last RXFULL check and a late clear would lose its interrupt, and with the byte left in
     * the 1-byte buffer QEMU delivers nothing more - the link went silent for good (seen in
     * 1 of 3 boots when a request raced the start-up). Cleared first, such a byte re-raises it. */
    UART0_INTCLR = 0x2u;
    while (UART0_STATE & UART_STATE_RXFULL) {
        uint8_t b = (uint8_t)UART0_DATA;
        uint32_t next = (g_head + 1u) & (MPS2_RX_RING - 1u);
        if (next == g_tail) {
            g_overruns++;
        } else {
            g_ring[g_head] = b;
            g_head = next;
        }
    }
    if (UART0_STATE & UART_STATE_RXOVR) {
        UART0_STATE = UART_STATE_RXOVR; /* write 1 to clear */
        g_overruns++;
    }
}

uint32_t mps2_uart_take(uint8_t *buf, uint32_t cap)
{
    uint32_t n = 0;
    while (n < cap && g_tail != g_head) {
        buf[n++] = g_ring[g_tail];
        g_tail = (g_tail + 1u) & (MPS2_RX_RING - 1u);
    }
    return n;
}

uint32_t mps2_uart_overruns(void) { return g_overruns; }

void mps2_idle(void)
{
    uint32_t pm = irq_save();
    if (g_head == g_tail)
        __asm__ volatile("wfi"); /* a pending interrupt wakes us even with PRIMASK set */
    irq_restore(pm);
}

static uint64_t time_us(void *ctx)
{
    (void)ctx;
    uint32_t pm = irq_save();
    uint32_t raw = TIMER0_VALUE;
    g_ticks += (uint32_t)(g_last_raw - raw); /* down counter: elapsed ticks mod 2^32 (wraps every 171 s) */
    g_last_raw = raw;
    uint64_t t = g_ticks / CYCLES_PER_US;
    irq_restore(pm);
    return t;
}

static void tick_period(uint32_t cycles)
{
    SYST_RVR = cycles - 1u;
    SYST_CVR = 0; /* restart the count with the new period */
}

static void sleep_until_us(void *ctx, uint64_t t)
{
    tick_period(TICK_FAST);
    for (;;) {
        uint64_t now = time_us(ctx);
        if (now >= t)
            break;
        if (t - now > 1000u)
            __asm__ volatile("wfi"); /* the 1 ms tick wakes us */
    }
    tick_period(TICK_IDLE);
}

static void uart_write(void *ctx, const uint8_t *d, size_t n)
{
    (void)ctx;
    for (size_t i = 0; i < n; i++) {
        while (UART0_STATE & UART_STATE_TXFULL) {
        }
        UART0_DATA = d[i];
    }
}

/* ---- sensor through semihosting ---- */
static int sensor_open(mps2_sensor *s)
{
    if (s->handle >= 0)
        return 0;
    s->handle = sh_open(s->path, 1);
    return s->handle >= 0 ? 0 : -1;
}

static int read_header(mps2_sensor *s, uint8_t *hdr)
{
    if (sensor_open(s) || sh_seek(s->handle, 0) != 0 || sh_read(s->handle, hdr, 36) != 0)
        return -1;
    return memcmp(hdr, "GSPX", 4) == 0 ? 0 : -1;
}

static void geometry(void *ctx, gs_sensor_geometry *g) { *g = ((mps2_sensor *)ctx)->geom; }

static gs_sensor_status sensor_begin(void *ctx, uint32_t *frame)
{
    mps2_sensor *s = ctx;
    uint8_t hdr[36];
    if (read_header(s, hdr))
        return GS_SENSOR_IO;
    if (gs_get_u16(hdr + 8) != s->geom.width || gs_get_u16(hdr + 10) != s->geom.height)
        return GS_SENSOR_IO;
    s->lock_seq = gs_get_u32(hdr + 16);
    s->temp_cdeg = (int16_t)gs_get_u16(hdr + 32);
    if (s->lock_seq & 1u)
        return GS_SENSOR_BUSY;
    *frame = gs_get_u32(hdr + 20);
    return GS_SENSOR_OK;
}

static gs_sensor_status sensor_read(void *ctx, uint8_t plane, uint32_t index, uint16_t count, uint16_t *out)
{
    mps2_sensor *s = ctx;
    uint32_t plane_px = (uint32_t)s->geom.width * s->geom.height;
    if (plane >= s->geom.planes || (uint64_t)index + count > plane_px)
        return GS_SENSOR_IO;
    uint32_t pos = PIXFILE_HEADER + 2u * (plane * plane_px + index);
    if (sensor_open(s) || sh_seek(s->handle, pos) != 0 || sh_read(s->handle, out, 2u * count) != 0)
        return GS_SENSOR_IO;
    return GS_SENSOR_OK; /* Cortex-M is little-endian like the file */
}

static gs_sensor_status sensor_end(void *ctx, uint32_t frame)
{
    mps2_sensor *s = ctx;
    uint8_t hdr[36];
    if (read_header(s, hdr))
        return GS_SENSOR_IO;
    return (gs_get_u32(hdr + 16) == s->lock_seq && gs_get_u32(hdr + 20) == frame) ? GS_SENSOR_OK
                                                                                    : GS_SENSOR_BUSY;
}

static int16_t temperature(void *ctx) { return ((mps2_sensor *)ctx)->temp_cdeg; }

static void watchdog_kick(void *ctx)
{
    (void)ctx;
    WDOG_LOCK = 0x1ACCE551u;
    WDOG_INTCLR = 1u; /* reloads the counter */
    WDOG_LOCK = 0;
}

void mps2_watchdog_start(uint32_t timeout_ms)
{
    WDOG_LOCK = 0x1ACCE551u;
    WDOG_LOAD = timeout_ms * (MPS2_SYSCLK_HZ / 1000u);
    WDOG_CTRL = 0x3u; /* interrupt (NMI) on the first expiry, reset on the second */
    WDOG_LOCK = 0;
}

void mps2_hal_init(gs_hal *hal, mps2_sensor *s, const char *sensor_path)
{
    /* clock: TIMER0 free-running from 0xFFFFFFFF, no interrupt */
    TIMER0_CTRL = 0;
    TIMER0_RELOAD = 0xFFFFFFFFu;
    TIMER0_VALUE = 0xFFFFFFFFu;
    TIMER0_CTRL = 0x1u;
    g_last_raw = TIMER0_VALUE;
    g_ticks = 0;
    /* wake-up tick on the core clock */
    tick_period(TICK_IDLE);
    SYST_CSR = 0x7u; /* enable, interrupt, processor clock */
    /* UART0: 115200 8N1 nominal (QEMU ignores the rate), RX interrupt */
    UART0_BAUDDIV = MPS2_SYSCLK_HZ / MPS2_BAUD;
    UART0_CTRL = UART_CTRL_TXEN | UART_CTRL_RXEN | UART_CTRL_RXIE;
    (void)UART0_DATA; /* dummy read: QEMU re-polls the chardev once RX is enabled */
    NVIC_ISER0 = (1u << 0) | (1u << TIMER1_IRQ);
    TIMER1_CTRL = 0u;

    memset(s, 0, sizeof *s);
    s->handle = -1;
    s->path = sensor_path;
    s->geom.width = GS_SENSOR_DEFAULT_WIDTH;
    s->geom.height = GS_SENSOR_DEFAULT_HEIGHT;
    s->geom.planes = 1;
    uint8_t hdr[36];
    if (read_header(s, hdr) == 0) {
        s->geom.width = gs_get_u16(hdr + 8);
        s->geom.height = gs_get_u16(hdr + 10);
        s->geom.planes = (uint8_t)(gs_get_u16(hdr + 12) >= 2u ? 2u : 1u);
        s->temp_cdeg = (int16_t)gs_get_u16(hdr + 32);
    }

    memset(hal, 0, sizeof *hal);
    hal->ctx = s;
    hal->port_id = 2;
    hal->time_us = time_us;
    hal->sleep_until_us = sleep_until_us;
    hal->uart_write = uart_write;
    hal->sensor_geometry = geometry;
    hal->sensor_begin = sensor_begin;
    hal->sensor_read = sensor_read;
    hal->sensor_end = sensor_end;
    hal->temperature_cdeg = temperature;
    hal->watchdog_kick = watchdog_kick;
}
