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
#include "gs_spots.h"

#define GS_FW_MAJOR 1u
#define GS_FW_MINOR 0u
#define GS_FW_PATCH 0u
#define GS_SENSOR_RETRIES 20u       /* readout attempts while frames keep changing */
#define GS_SENSOR_RETRY_US 500u     /* wait between attempts */

typedef struct {
    uint32_t captures, rx_frames, crc_errors, framing_errors, overruns, rejected;
    uint16_t last_error;
} gs_counters;

/* Streaming state (START_STREAM .. STOP_STREAM), see gs_stream.h. */
typedef struct {
    uint8_t on;
    uint8_t fmt;                    /* pixel format of FRAME messages */
    uint16_t seq;                   /* the START_STREAM's seq, carried by every FRAME */
    uint32_t period_us, exposure_us;
    uint32_t frame;                 /* the frame integrating now: the next readout */
    uint64_t t_start_us;            /* its exposure start (MCU us) */
    uint32_t frames, late_sets, dropped, backpressure; /* this stream's counters */
    uint32_t last_frame;            /* last frame sent */
    uint32_t set_frame;             /* frame named by the set in use (0: none named) */
    uint8_t n_pending;
    uint32_t pending_frame[GS_LIM_STREAM_PENDING_SETS]; /* first frame each waiting set is for */
    uint32_t pending_named[GS_LIM_STREAM_PENDING_SETS]; /* the frame its SET_WINDOWS named */
    gs_window_set pending[GS_LIM_STREAM_PENDING_SETS];
} gs_stream;

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
    gs_stream stream;
    uint32_t frame_no;              /* last stream frame number handed out (never reused) */
    uint32_t sums[GS_LIM_MAX_WINDOWS];
    uint16_t store[GS_LIM_PIXEL_BUDGET];
    gs_spot_scratch spot_scratch;   /* FIND_SPOTS: row buffers, histograms, spans */
    gs_spot_list spots;
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
/* Run the stream's timer work due at time_us() (read out frames whose exposure ended,
 * push them, start the next exposure). Returns the MCU time (us) at which it must be
 * called again, or UINT64_MAX when not streaming. Ports call it from their main loop or
 * timer interrupt; calling it early or often is harmless. */
uint64_t gs_head_poll(gs_head *h);

/* For the stream engine (gs_stream.c): frame and send a message from the tx payload area,
 * and read every window of ws into the window store inside the sensor's sequence lock. */
uint8_t *gs_head_payload(gs_head *h);
void gs_head_send(gs_head *h, uint8_t type, uint16_t seq, size_t len);
gs_sensor_status gs_head_read_windows(gs_head *h, uint8_t plane, uint32_t *frame_out);

#endif
