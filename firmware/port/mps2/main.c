/* main.c - mps2 entry: find the sensor file on the semihosting command line
 * ("... --sensor PATH"), boot the head, then serve the UART and the stream's timer (TIMER1
 * wakes the core at each exposure end) and sleep on wfi when idle. */
#include <string.h>

#include "gs_head.h"
#include "hal_mps2.h"
#include "semihost.h"

static gs_head g_head;
static gs_hal g_hal;
static mps2_sensor g_sensor;
static char g_cmdline[256];
__attribute__((section(".linebuf"))) static uint16_t g_line[GS_LIM_FRAME_CHUNK_MAX];

static const char *sensor_path(void)
{
    static const char fallback[] = "gyrostar-sensor.raw";
    if (sh_cmdline(g_cmdline, sizeof g_cmdline) != 0)
        return fallback;
    char *p = strstr(g_cmdline, "--sensor ");
    if (!p)
        return fallback;
    p += 9;
    char *end = strchr(p, ' ');
    if (end)
        *end = 0;
    return *p ? p : fallback;
}

int main(void)
{
    mps2_hal_init(&g_hal, &g_sensor, sensor_path());
    gs_head_init(&g_head, &g_hal, g_line);
    mps2_watchdog_start(2000);
    uint8_t buf[64];
    uint32_t overruns = 0;
    for (;;) {
        g_hal.watchdog_kick(g_hal.ctx);
        mps2_alarm_at(gs_head_poll(&g_head)); /* stream: read out due frames, wake at the next */
        uint32_t n = mps2_uart_take(buf, sizeof buf);
        if (n)
            gs_head_rx(&g_head, buf, n);
        while (overruns != mps2_uart_overruns()) {
            overruns++;
            gs_head_note_overrun(&g_head);
        }
        if (!n)
            mps2_idle();
    }
}
