/* gs_head.h - the camera head application: link receive, command dispatch, exposure
 * control, capture into the window store, telemetry. No malloc; all buffers are in
 * gs_head (one static instance per port) plus the caller's pixel line buffer. */
#ifndef GS_HEAD_H
#define GS_HEAD_H

#include <stddef.h>
#include <stdint.h>

#include "gs_frame.h"
#include "gs_hal.h"
#include "gs_windows.h"

#define GS_FW_MAJOR 1u
#define GS_FW_MINOR 0u
#define GS_FW_PATCH 0u
#define GS_SENSOR_RETRIES 20u       /* readout attempts while frames keep changing */
#define GS_SENSOR_RETRY_US 500u     /* wait between attempts */

typedef struct {
    uint32_t captures, rx_frames, crc_errors, framing_errors, overruns, rejected;
    uint16_t last_error;
} gs_counters;

typedef struct {
    const gs_hal *hal;
    uint16_t *line;                 /* pixel line buffer, GS_LIM_FRAME_CHUNK_MAX entries */
    gs_sensor_geometry geom;
    uint64_t boot_us;
    uint32_t exposure_us;
    uint16_t gain_x16;
    uint8_t has_capture;
    uint8_t capture_plane;
    uint32_t capture_no;
    gs_counters cnt;
    gs_rx_stream rx;
    gs_window_set ws;
    uint32_t sums[GS_LIM_MAX_WINDOWS];
    uint16_t store[GS_LIM_PIXEL_BUDGET];
    uint8_t raw[GS_FRAME_MAX_RAW];    /* decoded request */
    uint8_t tx_raw[GS_FRAME_MAX_RAW]; /* reply header + payload + CRC */
    uint8_t tx[GS_FRAME_MAX_ENCODED + 1u];
} gs_head;

/* Boot: bind the HAL, read the sensor geometry, defaults, zero counters. */
void gs_head_init(gs_head *h, const gs_hal *hal, uint16_t *line_buf);
/* Feed received bytes; complete frames are dispatched and replied to at once. */
void gs_head_rx(gs_head *h, const uint8_t *data, size_t n);
/* Handle one encoded frame (no delimiter) completed at MCU time rx_us. */
void gs_head_frame(gs_head *h, const uint8_t *enc, size_t n, uint64_t rx_us);
/* The port saw bytes lost (UART hardware overrun, stalled transmitter). */
void gs_head_note_overrun(gs_head *h);

#endif
