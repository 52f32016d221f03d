/* gs_hal.h - hardware abstraction of the camera head: sensor, UART, clock, watchdog.
 *
 * The portable core (core/) only talks to the hardware through this table of functions,
 * so the same core runs on the POSIX host build, on the mps2 Cortex-M image and against
 * the fake HAL of the unit tests and the fuzzer. Every function gets `ctx` back.
 */
#ifndef GS_HAL_H
#define GS_HAL_H

#include <stddef.h>
#include <stdint.h>

typedef enum {
    GS_SENSOR_OK = 0,
    GS_SENSOR_BUSY = 1, /* a new frame is being written: try again */
    GS_SENSOR_IO = 2    /* the pixel array cannot be read */
} gs_sensor_status;

typedef struct {
    uint16_t width;  /* columns */
    uint16_t height; /* rows */
    uint8_t planes;  /* 1 = light only, 2 = light + dark */
} gs_sensor_geometry;

typedef struct {
    void *ctx;
    uint8_t port_id; /* reported by GET_INFO: 0 test, 1 posix host, 2 mps2 */

    /* Clock: microseconds since an arbitrary epoch, monotonic. */
    uint64_t (*time_us)(void *ctx);
    /* Block (or sleep) until time_us() >= t_us. */
    void (*sleep_until_us)(void *ctx, uint64_t t_us);

    /* UART: send all n bytes (the port may drop them if the link is stalled and count it). */
    void (*uart_write)(void *ctx, const uint8_t *data, size_t n);
    /* Bytes written but not yet on the wire (the transmitter's queue); a stream drops a
     * frame rather than queue it behind more than stream_tx_backlog_max. May be NULL (0). */
    size_t (*uart_tx_backlog)(void *ctx);

    /* Sensor. A readout is bracketed by begin/end (a sequence lock): begin returns the
     * frame counter of a complete frame; end returns GS_SENSOR_OK if that frame was not
     * replaced meanwhile, GS_SENSOR_BUSY if it was (the caller reads again). */
    void (*sensor_geometry)(void *ctx, gs_sensor_geometry *g);
    gs_sensor_status (*sensor_begin)(void *ctx, uint32_t *frame);
    /* Read `count` pixels from row-major index `index` of `plane` into out (raw values). */
    gs_sensor_status (*sensor_read)(void *ctx, uint8_t plane, uint32_t index, uint16_t count, uint16_t *out);
    gs_sensor_status (*sensor_end)(void *ctx, uint32_t frame);
    /* Program exposure (us) and gain (1/16 steps) into the sensor; may be NULL. */
    void (*sensor_configure)(void *ctx, uint32_t exposure_us, uint16_t gain_x16);
    /* The exposure starts now (t_start_us, as CAPTURE reports it) and lasts exposure_us: a
     * sensor triggered from outside (a simulator behind the POSIX port) starts integrating
     * here, and sensor_begin then serves that exposure's frame. May be NULL. */
    void (*sensor_expose)(void *ctx, uint64_t t_start_us, uint32_t exposure_us);
    /* Sensor die temperature in 0.01 degC. */
    int16_t (*temperature_cdeg)(void *ctx);

    /* Watchdog kick; may be NULL. */
    void (*watchdog_kick)(void *ctx);
} gs_hal;

#endif
