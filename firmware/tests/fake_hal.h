/* fake_hal.h - deterministic in-memory HAL for unit tests and the fuzzer: simulated clock,
 * synthetic pixels, captured UART output, injectable sensor faults. */
#ifndef FAKE_HAL_H
#define FAKE_HAL_H

#include <stddef.h>
#include <stdint.h>

#include "gs_hal.h"

#define FAKE_OUT_CAP 65536u

typedef struct {
    uint64_t now;             /* us; advanced by sleep_until and by 1 us per time read */
    gs_sensor_geometry geom;
    uint32_t frame;
    int busy_begins;          /* sensor_begin reports BUSY this many times */
    int frame_changes;        /* sensor_end reports a changed frame this many times */
    int io_fail;              /* sensor_read fails */
    int16_t temp_cdeg;
    uint32_t cfg_exposure_us;
    uint16_t cfg_gain_x16;
    int configures, kicks;
    int exposes;              /* sensor_expose calls, with the last one's arguments */
    uint64_t expose_t_us;
    uint32_t expose_us;
    size_t tx_backlog;        /* what uart_tx_backlog reports */
    const uint16_t *image;    /* when set: the light plane, row-major (else fake_pixel) */
    uint8_t out[FAKE_OUT_CAP];
    size_t out_len;
} fake_hal;

/* Synthetic pixel of plane at row-major index (light values exceed 1023 in places). */
uint16_t fake_pixel(const fake_hal *f, uint8_t plane, uint32_t index);
void fake_hal_init(fake_hal *f, gs_hal *hal, uint16_t width, uint16_t height, uint8_t planes);

#endif
