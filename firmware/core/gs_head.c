/* gs_head.c - command dispatch. Every request gets exactly one reply: its type | 0x80,
 * or an ERROR frame with a distinct code (GS_ERR_*); a rejected request changes nothing.
 * Corrupt frames (COBS, short, CRC) get no reply: they are dropped and counted. */
#include "gs_head.h"

#include <string.h>

#include "gs_bytes.h"
#include "gs_pixels.h"
#include "gs_stream.h"

#define PAYLOAD(h) ((h)->tx_raw + GS_PROTO_HEADER_SIZE)
#define WIN_HEADER_SIZE 8u

_Static_assert(sizeof(uint16_t) * GS_LIM_FRAME_CHUNK_MAX >= 8u * GS_LIM_MAX_SPANS,
               "FIND_SPOTS builds its span table in the line buffer");

static void reset_state(gs_head *h)
{
    h->exposure_us = GS_LIM_EXPOSURE_DEFAULT_US;
    h->gain_x16 = GS_LIM_GAIN_DEFAULT_X16;
    h->has_capture = 0;
    h->capture_plane = 0;
    h->capture_no = 0;
    memset(&h->cnt, 0, sizeof h->cnt);
    gs_windows_clear(&h->ws);
    memset(&h->stream, 0, sizeof h->stream); /* frame_no goes on: frame numbers are never reused */
    gs_rx_reset(&h->rx);
    h->boot_us = h->hal->time_us(h->hal->ctx);
    if (h->hal->sensor_configure)
        h->hal->sensor_configure(h->hal->ctx, h->exposure_us, h->gain_x16);
}

void gs_head_init(gs_head *h, const gs_hal *hal, uint16_t *line_buf)
{
    h->hal = hal;
    h->frame_no = 0;
    h->line = line_buf;
    hal->sensor_geometry(hal->ctx, &h->geom);
    if (h->geom.planes < 1u)
        h->geom.planes = 1u;
    reset_state(h);
}

void gs_head_note_overrun(gs_head *h) { h->cnt.overruns++; }

static void send(gs_head *h, uint8_t type, uint16_t seq, size_t len)
{
    size_t n = gs_frame_encode(type, seq, PAYLOAD(h), len, h->tx_raw, sizeof h->tx_raw, h->tx, sizeof h->tx);
    if (n)
        h->hal->uart_write(h->hal->ctx, h->tx, n);
}

uint8_t *gs_head_payload(gs_head *h) { return PAYLOAD(h); }

void gs_head_send(gs_head *h, uint8_t type, uint16_t seq, size_t len) { send(h, type, seq, len); }

uint64_t gs_head_poll(gs_head *h) { return gs_stream_poll(h); }

static void reject(gs_head *h, uint8_t req_type, uint16_t seq, uint16_t code, uint32_t detail)
{
    uint8_t *p = PAYLOAD(h);
    memset(p, 0, GS_ERROR_REP_SIZE);
    gs_put_u16(p + GS_ERROR_REP_CODE, code);
    p[GS_ERROR_REP_REQUEST_TYPE] = req_type;
    gs_put_u32(p + GS_ERROR_REP_DETAIL, detail);
    h->cnt.rejected++;
    h->cnt.last_error = code;
    send(h, (uint8_t)GS_MSG_ERROR, seq, GS_ERROR_REP_SIZE);
}

/* Reply helpers return the payload length, or 0x10000 | code on rejection with h->detail. */
typedef struct {
    uint16_t code;
    uint32_t detail;
} gs_fail;

#define OK(len) ((int32_t)(len))
#define FAIL(f, c, d) ((f)->code = (uint16_t)(c), (f)->detail = (uint32_t)(d), -1)

static int32_t cmd_get_info(gs_head *h, gs_fail *f, size_t n)
{
    if (n != GS_GET_INFO_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    uint8_t *p = PAYLOAD(h);
    memset(p, 0, GS_GET_INFO_REP_SIZE);
    p[GS_GET_INFO_REP_PROTO_VERSION] = GS_PROTO_VERSION;
    p[GS_GET_INFO_REP_FW_MAJOR] = GS_FW_MAJOR;
    p[GS_GET_INFO_REP_FW_MINOR] = GS_FW_MINOR;
    p[GS_GET_INFO_REP_FW_PATCH] = GS_FW_PATCH;
    gs_put_u16(p + GS_GET_INFO_REP_WIDTH, h->geom.width);
    gs_put_u16(p + GS_GET_INFO_REP_HEIGHT, h->geom.height);
    p[GS_GET_INFO_REP_BITS] = GS_SENSOR_DEFAULT_BITS;
    p[GS_GET_INFO_REP_PORT] = h->hal->port_id;
    gs_put_u16(p + GS_GET_INFO_REP_MAX_WINDOWS, GS_LIM_MAX_WINDOWS);
    gs_put_u16(p + GS_GET_INFO_REP_MAX_SPANS, GS_LIM_MAX_SPANS);
    gs_put_u16(p + GS_GET_INFO_REP_MAX_WINDOW_PIXELS, GS_LIM_MAX_WINDOW_PIXELS);
    gs_put_u32(p + GS_GET_INFO_REP_PIXEL_BUDGET, GS_LIM_PIXEL_BUDGET);
    gs_put_u16(p + GS_GET_INFO_REP_MAX_PAYLOAD, GS_PROTO_MAX_PAYLOAD);
    gs_put_u16(p + GS_GET_INFO_REP_FRAME_CHUNK_MAX, GS_LIM_FRAME_CHUNK_MAX);
    gs_put_u32(p + GS_GET_INFO_REP_EXPOSURE_MIN_US, GS_LIM_EXPOSURE_MIN_US);
    gs_put_u32(p + GS_GET_INFO_REP_EXPOSURE_MAX_US, GS_LIM_EXPOSURE_MAX_US);
    gs_put_u16(p + GS_GET_INFO_REP_GAIN_MIN_X16, GS_LIM_GAIN_MIN_X16);
    gs_put_u16(p + GS_GET_INFO_REP_GAIN_MAX_X16, GS_LIM_GAIN_MAX_X16);
    p[GS_GET_INFO_REP_PLANES] = h->geom.planes;
    return OK(GS_GET_INFO_REP_SIZE);
}

static int32_t cmd_set_exposure(gs_head *h, gs_fail *f, const uint8_t *q, size_t n)
{
    if (n != GS_SET_EXPOSURE_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    if (h->stream.on)
        return FAIL(f, GS_ERR_STREAMING, 0);
    uint32_t us = gs_get_u32(q + GS_SET_EXPOSURE_REQ_EXPOSURE_US);
    if (us < GS_LIM_EXPOSURE_MIN_US || us > GS_LIM_EXPOSURE_MAX_US)
        return FAIL(f, GS_ERR_EXPOSURE_RANGE, us);
    h->exposure_us = us;
    if (h->hal->sensor_configure)
        h->hal->sensor_configure(h->hal->ctx, h->exposure_us, h->gain_x16);
    gs_put_u32(PAYLOAD(h) + GS_SET_EXPOSURE_REP_EXPOSURE_US, us);
    return OK(GS_SET_EXPOSURE_REP_SIZE);
}

static int32_t cmd_set_gain(gs_head *h, gs_fail *f, const uint8_t *q, size_t n)
{
    if (n != GS_SET_GAIN_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    uint16_t g = gs_get_u16(q + GS_SET_GAIN_REQ_GAIN_X16);
    if (g < GS_LIM_GAIN_MIN_X16 || g > GS_LIM_GAIN_MAX_X16)
        return FAIL(f, GS_ERR_GAIN_RANGE, g);
    h->gain_x16 = g;
    if (h->hal->sensor_configure)
        h->hal->sensor_configure(h->hal->ctx, h->exposure_us, h->gain_x16);
    gs_put_u16(PAYLOAD(h) + GS_SET_GAIN_REP_GAIN_X16, g);
    return OK(GS_SET_GAIN_REP_SIZE);
}

static int32_t cmd_set_windows(gs_head *h, gs_fail *f, const uint8_t *q, size_t n)
{
    if (n < GS_SET_WINDOWS_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    uint16_t count = gs_get_u16(q + GS_SET_WINDOWS_REQ_N_SPANS);
    uint16_t reserved = gs_get_u16(q + GS_SET_WINDOWS_REQ_RESERVED);
    if (reserved)
        return FAIL(f, GS_ERR_RESERVED_NONZERO, reserved);
    if (count > GS_LIM_MAX_SPANS)
        return FAIL(f, GS_ERR_SPAN_COUNT, count);
    if (n != GS_SET_WINDOWS_REQ_SIZE + 8u * (size_t)count)
        return FAIL(f, GS_ERR_SPANS_LENGTH, count);
    uint32_t detail = 0, applies = 0;
    const gs_window_set *set = &h->ws;
    uint16_t code;
    if (h->stream.on) {
        code = gs_stream_set_windows(h, q + GS_SET_WINDOWS_REQ_SIZE, count,
                                     gs_get_u32(q + GS_SET_WINDOWS_REQ_FRAME), &applies, &detail);
        set = &h->stream.pending[h->stream.n_pending ? h->stream.n_pending - 1u : 0u];
    } else {
        code = gs_windows_set(&h->ws, q + GS_SET_WINDOWS_REQ_SIZE, count, h->geom.width, h->geom.height, &detail);
        if (!code)
            h->has_capture = 0; /* the store's layout belonged to the old windows */
    }
    if (code)
        return FAIL(f, code, detail);
    uint8_t *p = PAYLOAD(h);
    gs_put_u16(p + GS_SET_WINDOWS_REP_N_WINDOWS, set->n_windows);
    gs_put_u16(p + GS_SET_WINDOWS_REP_N_SPANS, set->n_spans);
    gs_put_u32(p + GS_SET_WINDOWS_REP_N_PIXELS, set->n_pixels);
    gs_put_u32(p + GS_SET_WINDOWS_REP_FRAME, applies);
    return OK(GS_SET_WINDOWS_REP_SIZE);
}

/* Run fn inside the sensor's sequence lock, retrying while frames change. */
static gs_sensor_status locked_read(gs_head *h, uint8_t plane, uint32_t offset, uint16_t count,
                                    uint32_t *frame_out)
{
    const gs_hal *hal = h->hal;
    gs_sensor_status st = GS_SENSOR_BUSY;
    for (unsigned attempt = 0; attempt < GS_SENSOR_RETRIES; attempt++) {
        if (attempt)
            hal->sleep_until_us(hal->ctx, hal->time_us(hal->ctx) + GS_SENSOR_RETRY_US);
        uint32_t frame = 0;
        st = hal->sensor_begin(hal->ctx, &frame);
        if (st == GS_SENSOR_BUSY)
            continue;
        if (st != GS_SENSOR_OK)
            return st;
        if (count)
            st = hal->sensor_read(hal->ctx, plane, offset, count, h->line);
        else
            st = gs_windows_read(&h->ws, hal, plane, h->geom.width, h->store, h->sums);
        if (st == GS_SENSOR_IO)
            return st;
        if (st == GS_SENSOR_OK)
            st = hal->sensor_end(hal->ctx, frame);
        if (st == GS_SENSOR_OK) {
            *frame_out = frame;
            return st;
        }
        if (st != GS_SENSOR_BUSY)
            return st;
    }
    return st;
}

gs_sensor_status gs_head_read_windows(gs_head *h, uint8_t plane, uint32_t *frame_out)
{
    return locked_read(h, plane, 0, 0, frame_out);
}

static int32_t sensor_fail(gs_fail *f, gs_sensor_status st)
{
    return st == GS_SENSOR_BUSY ? FAIL(f, GS_ERR_SENSOR_BUSY, 0) : FAIL(f, GS_ERR_SENSOR_IO, st);
}

static int32_t cmd_capture(gs_head *h, gs_fail *f, size_t n, uint8_t plane)
{
    if (n != GS_CAPTURE_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    if (h->stream.on)
        return FAIL(f, GS_ERR_STREAMING, 0);
    if (h->ws.n_windows == 0)
        return FAIL(f, GS_ERR_NO_WINDOWS, 0);
    if (plane == GS_PLANE_DARK && h->geom.planes < 2u)
        return FAIL(f, GS_ERR_DARK_UNAVAILABLE, 0);
    const gs_hal *hal = h->hal;
    uint64_t t0 = hal->time_us(hal->ctx);
    if (hal->sensor_expose)
        hal->sensor_expose(hal->ctx, t0, h->exposure_us);
    hal->sleep_until_us(hal->ctx, t0 + h->exposure_us);
    uint64_t t1 = hal->time_us(hal->ctx);
    uint32_t frame = 0;
    h->has_capture = 0;
    gs_sensor_status st = locked_read(h, plane, 0, 0, &frame);
    if (st != GS_SENSOR_OK)
        return sensor_fail(f, st);
    h->has_capture = 1;
    h->capture_plane = plane;
    h->capture_no = ++h->cnt.captures;
    uint8_t *p = PAYLOAD(h);
    memset(p, 0, GS_CAPTURE_REP_SIZE);
    gs_put_u32(p + GS_CAPTURE_REP_CAPTURE_NO, h->capture_no);
    gs_put_u32(p + GS_CAPTURE_REP_SENSOR_FRAME, frame);
    gs_put_u64(p + GS_CAPTURE_REP_T_START_US, t0);
    gs_put_u64(p + GS_CAPTURE_REP_T_END_US, t1);
    gs_put_u32(p + GS_CAPTURE_REP_EXPOSURE_US, h->exposure_us);
    gs_put_u16(p + GS_CAPTURE_REP_GAIN_X16, h->gain_x16);
    gs_put_u16(p + GS_CAPTURE_REP_N_WINDOWS, h->ws.n_windows);
    gs_put_u32(p + GS_CAPTURE_REP_N_PIXELS, h->ws.n_pixels);
    p[GS_CAPTURE_REP_PLANE] = plane;
    return OK(GS_CAPTURE_REP_SIZE);
}

static int32_t cmd_window_data(gs_head *h, gs_fail *f, const uint8_t *q, size_t n)
{
    if (n != GS_WINDOW_DATA_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    uint16_t start = gs_get_u16(q + GS_WINDOW_DATA_REQ_START);
    uint8_t fmt = q[GS_WINDOW_DATA_REQ_PIXEL_FORMAT];
    if (q[GS_WINDOW_DATA_REQ_RESERVED])
        return FAIL(f, GS_ERR_RESERVED_NONZERO, q[GS_WINDOW_DATA_REQ_RESERVED]);
    if (fmt > GS_PIXFMT_PACKED10)
        return FAIL(f, GS_ERR_PIXEL_FORMAT, fmt);
    if (!h->has_capture)
        return FAIL(f, GS_ERR_NO_CAPTURE, 0);
    if (start >= h->ws.n_windows)
        return FAIL(f, GS_ERR_WINDOW_INDEX, start);
    uint8_t *p = PAYLOAD(h);
    size_t len = GS_WINDOW_DATA_REP_SIZE;
    uint16_t count = 0;
    for (uint16_t wi = start; wi < h->ws.n_windows; wi++) {
        const gs_window *w = &h->ws.windows[wi];
        size_t need = WIN_HEADER_SIZE + gs_pixels_bytes(w->n_pixels, fmt);
        if (len + need > GS_PROTO_MAX_PAYLOAD)
            break; /* max_window_pixels guarantees one window always fits */
        gs_put_u16(p + len, w->id);
        gs_put_u16(p + len + 2u, w->n_pixels);
        gs_put_u32(p + len + 4u, h->sums[wi]);
        len += WIN_HEADER_SIZE;
        len += gs_pixels_encode(h->store + w->px_offset, w->n_pixels, fmt, p + len, GS_PROTO_MAX_PAYLOAD - len);
        count++;
    }
    memset(p, 0, GS_WINDOW_DATA_REP_SIZE);
    gs_put_u32(p + GS_WINDOW_DATA_REP_CAPTURE_NO, h->capture_no);
    gs_put_u16(p + GS_WINDOW_DATA_REP_START, start);
    gs_put_u16(p + GS_WINDOW_DATA_REP_COUNT, count);
    gs_put_u16(p + GS_WINDOW_DATA_REP_TOTAL, h->ws.n_windows);
    p[GS_WINDOW_DATA_REP_PIXEL_FORMAT] = fmt;
    return OK(len);
}

static int32_t cmd_full_frame(gs_head *h, gs_fail *f, const uint8_t *q, size_t n)
{
    if (n != GS_FULL_FRAME_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    if (h->stream.on)
        return FAIL(f, GS_ERR_STREAMING, 0);
    uint32_t offset = gs_get_u32(q + GS_FULL_FRAME_REQ_OFFSET);
    uint16_t count = gs_get_u16(q + GS_FULL_FRAME_REQ_COUNT);
    uint8_t fmt = q[GS_FULL_FRAME_REQ_PIXEL_FORMAT];
    uint8_t plane = q[GS_FULL_FRAME_REQ_PLANE];
    if (fmt > GS_PIXFMT_PACKED10)
        return FAIL(f, GS_ERR_PIXEL_FORMAT, fmt);
    if (plane > GS_PLANE_DARK)
        return FAIL(f, GS_ERR_BAD_PLANE, plane);
    if (plane == GS_PLANE_DARK && h->geom.planes < 2u)
        return FAIL(f, GS_ERR_DARK_UNAVAILABLE, 0);
    if (count == 0 || count > GS_LIM_FRAME_CHUNK_MAX)
        return FAIL(f, GS_ERR_CHUNK_SIZE, count);
    if ((uint64_t)offset + count > (uint64_t)h->geom.width * h->geom.height)
        return FAIL(f, GS_ERR_FRAME_RANGE, offset);
    uint32_t frame = 0;
    gs_sensor_status st = locked_read(h, plane, offset, count, &frame);
    if (st != GS_SENSOR_OK)
        return sensor_fail(f, st);
    for (uint16_t i = 0; i < count; i++)
        if (h->line[i] > 0x3FFu)
            h->line[i] = 0x3FFu;
    uint8_t *p = PAYLOAD(h);
    gs_put_u32(p + GS_FULL_FRAME_REP_SENSOR_FRAME, frame);
    gs_put_u32(p + GS_FULL_FRAME_REP_OFFSET, offset);
    gs_put_u16(p + GS_FULL_FRAME_REP_COUNT, count);
    p[GS_FULL_FRAME_REP_PIXEL_FORMAT] = fmt;
    p[GS_FULL_FRAME_REP_PLANE] = plane;
    size_t len = GS_FULL_FRAME_REP_SIZE;
    len += gs_pixels_encode(h->line, count, fmt, p + len, GS_PROTO_MAX_PAYLOAD - len);
    return OK(len);
}

/* FIND_SPOTS: expose, scan the frame for spots and read a window around each, all inside
 * one sequence lock so the list and the pixels come from the same sensor frame. */
static gs_sensor_status locked_spots(gs_head *h, uint16_t n_sigma_x16, uint16_t max_spots, uint8_t box,
                                     uint32_t *frame_out, uint16_t *code)
{
    const gs_hal *hal = h->hal;
    gs_sensor_status st = GS_SENSOR_BUSY;
    for (unsigned attempt = 0; attempt < GS_SENSOR_RETRIES; attempt++) {
        if (attempt)
            hal->sleep_until_us(hal->ctx, hal->time_us(hal->ctx) + GS_SENSOR_RETRY_US);
        uint32_t frame = 0;
        st = hal->sensor_begin(hal->ctx, &frame);
        if (st == GS_SENSOR_BUSY)
            continue;
        if (st != GS_SENSOR_OK)
            return st;
        st = gs_spots_find(hal, GS_PLANE_LIGHT, h->geom.width, h->geom.height, n_sigma_x16, max_spots, box,
                           &h->spot_scratch, &h->spots);
        if (st == GS_SENSOR_OK) {
            /* the spans are built in the line buffer (free here: 512 spans x 8 bytes fit it) */
            uint8_t *wire = (uint8_t *)h->line;
            uint16_t n = gs_spots_spans(&h->spots, box, h->geom.width, h->geom.height, wire,
                                        sizeof(uint16_t) * GS_LIM_FRAME_CHUNK_MAX);
            uint32_t detail = 0;
            *code = gs_windows_set(&h->ws, wire, n, h->geom.width, h->geom.height, &detail);
            if (*code)
                return GS_SENSOR_IO; /* cannot happen: the settings check bounds the set */
            st = gs_windows_read(&h->ws, hal, GS_PLANE_LIGHT, h->geom.width, h->store, h->sums);
        }
        if (st == GS_SENSOR_IO)
            return st;
        if (st == GS_SENSOR_OK)
            st = hal->sensor_end(hal->ctx, frame);
        if (st == GS_SENSOR_OK) {
            *frame_out = frame;
            return st;
        }
        if (st != GS_SENSOR_BUSY)
            return st;
    }
    return st;
}

static int32_t cmd_find_spots(gs_head *h, gs_fail *f, const uint8_t *q, size_t n)
{
    if (n != GS_FIND_SPOTS_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    if (h->stream.on)
        return FAIL(f, GS_ERR_STREAMING, 0);
    uint16_t n_sigma = gs_get_u16(q + GS_FIND_SPOTS_REQ_N_SIGMA_X16);
    uint16_t max_spots = gs_get_u16(q + GS_FIND_SPOTS_REQ_MAX_SPOTS);
    uint8_t box = q[GS_FIND_SPOTS_REQ_BOX];
    if (q[GS_FIND_SPOTS_REQ_RESERVED] || gs_get_u16(q + GS_FIND_SPOTS_REQ_RESERVED2))
        return FAIL(f, GS_ERR_RESERVED_NONZERO, q[GS_FIND_SPOTS_REQ_RESERVED]);
    uint32_t bad = gs_spots_check(n_sigma, max_spots, box);
    if (bad)
        return FAIL(f, GS_ERR_SPOT_SETTINGS, bad);
    if (h->geom.width > GS_LIM_SPOT_WIDTH_MAX)
        return FAIL(f, GS_ERR_SENSOR_TOO_WIDE, h->geom.width);
    const gs_hal *hal = h->hal;
    uint64_t t0 = hal->time_us(hal->ctx);
    if (hal->sensor_expose)
        hal->sensor_expose(hal->ctx, t0, h->exposure_us);
    hal->sleep_until_us(hal->ctx, t0 + h->exposure_us);
    uint64_t t1 = hal->time_us(hal->ctx);
    uint32_t frame = 0;
    uint16_t code = 0;
    h->has_capture = 0;
    gs_windows_clear(&h->ws); /* the old set's store layout is gone either way */
    gs_sensor_status st = locked_spots(h, n_sigma, max_spots, box, &frame, &code);
    if (st != GS_SENSOR_OK) {
        gs_windows_clear(&h->ws);
        return sensor_fail(f, st);
    }
    h->has_capture = 1;
    h->capture_plane = GS_PLANE_LIGHT;
    h->capture_no = ++h->cnt.captures;
    const gs_spot_list *sl = &h->spots;
    uint8_t *p = PAYLOAD(h);
    memset(p, 0, GS_FIND_SPOTS_REP_SIZE);
    gs_put_u32(p + GS_FIND_SPOTS_REP_CAPTURE_NO, h->capture_no);
    gs_put_u32(p + GS_FIND_SPOTS_REP_SENSOR_FRAME, frame);
    gs_put_u64(p + GS_FIND_SPOTS_REP_T_START_US, t0);
    gs_put_u64(p + GS_FIND_SPOTS_REP_T_END_US, t1);
    gs_put_u32(p + GS_FIND_SPOTS_REP_EXPOSURE_US, h->exposure_us);
    gs_put_u16(p + GS_FIND_SPOTS_REP_GAIN_X16, h->gain_x16);
    gs_put_u16(p + GS_FIND_SPOTS_REP_N_WINDOWS, h->ws.n_windows);
    gs_put_u32(p + GS_FIND_SPOTS_REP_N_PIXELS, h->ws.n_pixels);
    gs_put_u32(p + GS_FIND_SPOTS_REP_CANDIDATES, sl->candidates);
    gs_put_u32(p + GS_FIND_SPOTS_REP_BACKGROUND_X16, sl->background_x16);
    gs_put_u32(p + GS_FIND_SPOTS_REP_SIGMA_X16, sl->sigma_x16);
    gs_put_u32(p + GS_FIND_SPOTS_REP_THRESHOLD_X16, sl->threshold_x16);
    size_t len = GS_FIND_SPOTS_REP_SIZE;
    for (uint16_t i = 0; i < sl->n && len + 6u <= GS_PROTO_MAX_PAYLOAD; i++) {
        gs_put_u16(p + len, sl->spots[i].row);
        gs_put_u16(p + len + 2u, sl->spots[i].col);
        uint32_t flux = sl->spots[i].score / 16u;
        gs_put_u16(p + len + 4u, (uint16_t)(flux > 0xFFFFu ? 0xFFFFu : flux));
        len += 6u;
    }
    return OK(len);
}

static int32_t cmd_time_sync(gs_head *h, gs_fail *f, const uint8_t *q, size_t n, uint64_t rx_us)
{
    if (n != GS_TIME_SYNC_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    uint8_t *p = PAYLOAD(h);
    gs_put_u64(p + GS_TIME_SYNC_REP_HOST_US, gs_get_u64(q + GS_TIME_SYNC_REQ_HOST_US));
    gs_put_u64(p + GS_TIME_SYNC_REP_MCU_RX_US, rx_us);
    gs_put_u64(p + GS_TIME_SYNC_REP_MCU_TX_US, h->hal->time_us(h->hal->ctx));
    return OK(GS_TIME_SYNC_REP_SIZE);
}

static int32_t cmd_telemetry(gs_head *h, gs_fail *f, size_t n)
{
    if (n != GS_TELEMETRY_REQ_SIZE)
        return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    uint8_t *p = PAYLOAD(h);
    const gs_counters *c = &h->cnt;
    gs_put_u64(p + GS_TELEMETRY_REP_UPTIME_US, h->hal->time_us(h->hal->ctx) - h->boot_us);
    gs_put_u16(p + GS_TELEMETRY_REP_TEMPERATURE_CDEG, (uint16_t)h->hal->temperature_cdeg(h->hal->ctx));
    gs_put_u16(p + GS_TELEMETRY_REP_LAST_ERROR, c->last_error);
    gs_put_u32(p + GS_TELEMETRY_REP_CAPTURES, c->captures);
    gs_put_u32(p + GS_TELEMETRY_REP_RX_FRAMES, c->rx_frames);
    gs_put_u32(p + GS_TELEMETRY_REP_CRC_ERRORS, c->crc_errors);
    gs_put_u32(p + GS_TELEMETRY_REP_FRAMING_ERRORS, c->framing_errors);
    gs_put_u32(p + GS_TELEMETRY_REP_OVERRUNS, c->overruns);
    gs_put_u32(p + GS_TELEMETRY_REP_REJECTED, c->rejected);
    return OK(GS_TELEMETRY_REP_SIZE);
}

static int32_t dispatch(gs_head *h, gs_fail *f, uint8_t type, uint16_t seq, const uint8_t *q, size_t n,
                        uint64_t rx_us)
{
    switch (type) {
    case GS_MSG_PING:
        if (n > GS_PROTO_PING_MAX)
            return FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
        memcpy(PAYLOAD(h), q, n);
        return OK(n);
    case GS_MSG_GET_INFO:
        return cmd_get_info(h, f, n);
    case GS_MSG_SET_EXPOSURE:
        return cmd_set_exposure(h, f, q, n);
    case GS_MSG_SET_GAIN:
        return cmd_set_gain(h, f, q, n);
    case GS_MSG_SET_WINDOWS:
        return cmd_set_windows(h, f, q, n);
    case GS_MSG_CAPTURE:
        return cmd_capture(h, f, n, GS_PLANE_LIGHT);
    case GS_MSG_DARK:
        return cmd_capture(h, f, n, GS_PLANE_DARK);
    case GS_MSG_WINDOW_DATA:
        return cmd_window_data(h, f, q, n);
    case GS_MSG_FULL_FRAME:
        return cmd_full_frame(h, f, q, n);
    case GS_MSG_FIND_SPOTS:
        return cmd_find_spots(h, f, q, n);
    case GS_MSG_TIME_SYNC:
        return cmd_time_sync(h, f, q, n, rx_us);
    case GS_MSG_TELEMETRY:
        return cmd_telemetry(h, f, n);
    case GS_MSG_RESET:
        return n == GS_RESET_REQ_SIZE ? OK(0) : FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    case GS_MSG_START_STREAM: {
        size_t len = 0;
        uint16_t code = gs_stream_start(h, q, n, seq, rx_us, &len, &f->detail);
        return code ? FAIL(f, code, f->detail) : OK(len);
    }
    case GS_MSG_STOP_STREAM:
        return n == GS_STOP_STREAM_REQ_SIZE ? OK(gs_stream_stop(h)) : FAIL(f, GS_ERR_PAYLOAD_LENGTH, n);
    default:
        return FAIL(f, GS_ERR_UNKNOWN_TYPE, 0);
    }
}

void gs_head_frame(gs_head *h, const uint8_t *enc, size_t n, uint64_t rx_us)
{
    gs_frame fr;
    gs_frame_status st = gs_frame_decode(enc, n, h->raw, sizeof h->raw, &fr);
    switch (st) {
    case GS_FRAME_OK:
        break;
    case GS_FRAME_ERR_CRC:
        h->cnt.crc_errors++;
        return;
    case GS_FRAME_ERR_LENGTH:
        h->cnt.rx_frames++;
        reject(h, fr.type, fr.seq, GS_ERR_FRAME_LENGTH, fr.length);
        return;
    default:
        h->cnt.framing_errors++;
        return;
    }
    h->cnt.rx_frames++;
    if (fr.version != GS_PROTO_VERSION) {
        reject(h, fr.type, fr.seq, GS_ERR_BAD_VERSION, fr.version);
        return;
    }
    gs_fail f = {0, 0};
    int32_t len = dispatch(h, &f, fr.type, fr.seq, fr.payload, fr.payload_len, rx_us);
    if (len < 0) {
        reject(h, fr.type, fr.seq, f.code, f.detail);
        return;
    }
    send(h, (uint8_t)(fr.type | GS_PROTO_REPLY_FLAG), fr.seq, (size_t)len);
    if (fr.type == GS_MSG_RESET)
        reset_state(h);
    if (h->hal->watchdog_kick)
        h->hal->watchdog_kick(h->hal->ctx);
}

void gs_head_rx(gs_head *h, const uint8_t *data, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        gs_rx_event ev = gs_rx_push(&h->rx, data[i]);
        if (ev == GS_RX_OVERRUN) {
            h->cnt.overruns++;
        } else if (ev == GS_RX_FRAME) {
            uint64_t t = h->hal->time_us(h->hal->ctx);
            gs_head_frame(h, h->rx.buf, h->rx.len, t);
            gs_rx_reset(&h->rx);
        }
    }
}
