/* hal_mps2.h - HAL for QEMU mps2-an385/an386: CMSDK APB UART0 (RX interrupt), TIMER1 alarm
 * pacing a stream's exposures, SysTick
 * 1 ms wake-up tick, TIMER0 free-running microsecond clock (25 MHz), CMSDK APB watchdog, sensor array read from a
 * host pixel file (firmware/README.md layout) through semihosting. */
#ifndef HAL_MPS2_H
#define HAL_MPS2_H

#include <stdint.h>

#include "gs_hal.h"

#define MPS2_SYSCLK_HZ 25000000u
#define MPS2_BAUD 115200u
#define MPS2_RX_RING 4096u /* power of two */

typedef struct {
    int handle;                 /* semihosting file handle, -1 if not open */
    const char *path;
    gs_sensor_geometry geom;
    uint32_t lock_seq;
    int16_t temp_cdeg;
} mps2_sensor;

void mps2_hal_init(gs_hal *hal, mps2_sensor *s, const char *sensor_path);
/* Pop received bytes into buf (up to cap); returns the count. */
uint32_t mps2_uart_take(uint8_t *buf, uint32_t cap);
/* Bytes lost since boot (ring full or UART hardware overrun). */
uint32_t mps2_uart_overruns(void);
/* Sleep until an interrupt if nothing was received. */
void mps2_idle(void);
void mps2_watchdog_start(uint32_t timeout_ms);
/* Wake the core (TIMER1 interrupt) at MCU time t_us; UINT64_MAX: no alarm. */
void mps2_alarm_at(uint64_t t_us);

#endif
