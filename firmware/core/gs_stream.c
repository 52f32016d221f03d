/* gs_stream.c - the streaming engine (see gs_stream.h). */
#include "gs_stream.h"

#include <string.h>

#include "gs_bytes.h"
#include "gs_pixels.h"

#define WIN_HEADER_SIZE 8u

uint16_t gs_stream_start(gs_head *h, const uint8_t *q, size_t n, uint16_t seq, uint64_t now, size_t *len,
                         uint32_t *detail)
{
    if (n != GS_START_STREAM_REQ_SIZE) {
        *detail = (uint32_t)n;
        return GS_ERR_PAYLOAD_LENGTH;
    }
    uint32_t period = gs_get_u32(q + GS_START_STREAM_REQ_PERIOD_US);
    uint32_t exposure = gs_get_u32(q + GS_START_STREAM_REQ_EXPOSURE_US);
    uint8_t fmt = q[GS_START_STREAM_REQ_PIXEL_FORMAT];
    uint16_t reserved = (uint16_t)(q[GS_START_STREAM_REQ_RESERVED] | gs_get_u16(q + GS_START_STREAM_REQ_RESERVED2));
    if (reserved) {
        *detail = reserved;
        return GS_ERR_RESERVED_NONZERO;
    }
    if (exposure < GS_LIM_EXPOSURE_MIN_US || exposure > GS_LIM_EXPOSURE_MAX_US) {
        *detail = exposure;
        return GS_ERR_EXPOSURE_RANGE;
    }
    if (period < GS_LIM_STREAM_PERIOD_MIN_US || period > GS_LIM_STREAM_PERIOD_MAX_US || period < exposure) {
        *detail = period;
        return GS_ERR_STREAM_PERIOD;
    }
    if (fmt > GS_PIXFMT_PACKED10) {
        *detail = fmt;
        return GS_ERR_PIXEL_FORMAT;
    }
    gs_stream *s = &h->stream;
    s->on = 1;
    s->fmt = fmt;
    s->seq = seq;
    s->period_us = period;
    s->exposure_us = exposure;
    s->frames = s->late_sets = s->dropped = s->backpressure = 0;
    s->last_frame = 0;
    s->set_frame = 0;
    s->n_pending = 0;
    h->exposure_us = exposure;
    if (h->hal->sensor_configure)
        h->hal->sensor_configure(h->hal->ctx, exposure, h->gain_x16);
    h->frame_no = h->frame_no == UINT32_MAX ? 1u : h->frame_no + 1u;
    s->frame = h->frame_no;
    s->t_start_us = now;
    if (h->hal->sensor_expose)
        h->hal->sensor_expose(h->hal->ctx, now, exposure);
    uint8_t *p = gs_head_payload(h);
    gs_put_u32(p + GS_START_STREAM_REP_FIRST_FRAME, s->frame);
    gs_put_u64(p + GS_START_STREAM_REP_T_FIRST_US, now);
    gs_put_u32(p + GS_START_STREAM_REP_PERIOD_US, period);
    gs_put_u32(p + GS_START_STREAM_REP_EXPOSURE_US, exposure);
    *len = GS_START_STREAM_REP_SIZE;
    return 0;
}

size_t gs_stream_stop(gs_head *h)
{
    gs_stream *s = &h->stream;
    s->on = 0;
    s->n_pending = 0;
    uint8_t *p = gs_head_payload(h);
    gs_put_u32(p + GS_STOP_STREAM_REP_FRAMES, s->frames);
    gs_put_u32(p + GS_STOP_STREAM_REP_LAST_FRAME, s->last_frame);
    gs_put_u32(p + GS_STOP_STREAM_REP_DROPPED, s->dropped);
    gs_put_u32(p + GS_STOP_STREAM_REP_LATE_SETS, s->late_sets);
    gs_put_u32(p + GS_STOP_STREAM_REP_BACKPRESSURE, s->backpressure);
    return GS_STOP_STREAM_REP_SIZE;
}

uint16_t gs_stream_set_windows(gs_head *h, const uint8_t *wire, uint16_t n, uint32_t named, uint32_t *applies,
                               uint32_t *detail)
{
    gs_stream *s = &h->stream;
    uint8_t late = named != 0u && named < s->frame;
    uint32_t first = (named == 0u || late) ? s->frame : named;
    uint8_t keep = 0; /* waiting sets for earlier frames stay; later ones are replaced */
    while (keep < s->n_pending && s->pending_frame[keep] < first)
        keep++;
    uint8_t slot = keep < GS_LIM_STREAM_PENDING_SETS ? keep : (uint8_t)(GS_LIM_STREAM_PENDING_SETS - 1u);
    uint16_t code = gs_windows_set(&s->pending[slot], wire, n, h->geom.width, h->geom.height, detail);
    if (code)
        return code;
    s->pending_frame[slot] = first;
    s->pending_named[slot] = named ? named : first;
    s->n_pending = (uint8_t)(slot + 1u);
    if (late)
        s->late_sets++;
    *applies = first;
    return 0;
}

/* FRAME messages of the window store: as many whole windows per part as fit a payload. */
static void push(gs_head *h, uint64_t t_end)
{
    const gs_stream *s = &h->stream;
    const gs_window_set *ws = &h->ws;
    uint16_t start = 0;
    do {
        uint8_t *p = gs_head_payload(h);
        size_t len = GS_FRAME_REP_SIZE;
        uint16_t count = 0;
        for (uint16_t wi = start; wi < ws->n_windows; wi++) {
            const gs_window *w = &ws->windows[wi];
            size_t need = WIN_HEADER_SIZE + gs_pixels_bytes(w->n_pixels, s->fmt);
            if (len + need > GS_PROTO_MAX_PAYLOAD)
                break; /* max_window_pixels guarantees one window always fits */
            gs_put_u16(p + len, w->id);
            gs_put_u16(p + len + 2u, w->n_pixels);
            gs_put_u32(p + len + 4u, h->sums[wi]);
            len += WIN_HEADER_SIZE;
            len += gs_pixels_encode(h->store + w->px_offset, w->n_pixels, s->fmt, p + len, GS_PROTO_MAX_PAYLOAD - len);
            count++;
        }
        memset(p, 0, GS_FRAME_REP_SIZE);
        gs_put_u32(p + GS_FRAME_REP_FRAME, s->frame);
        gs_put_u32(p + GS_FRAME_REP_SET_FRAME, s->set_frame);
        gs_put_u64(p + GS_FRAME_REP_T_START_US, s->t_start_us);
        gs_put_u64(p + GS_FRAME_REP_T_END_US, t_end);
        gs_put_u32(p + GS_FRAME_REP_EXPOSURE_US, s->exposure_us);
        gs_put_u32(p + GS_FRAME_REP_LATE_SETS, s->late_sets);
        gs_put_u32(p + GS_FRAME_REP_DROPPED, s->dropped);
        gs_put_u32(p + GS_FRAME_REP_BACKPRESSURE, s->backpressure);
        gs_put_u32(p + GS_FRAME_REP_N_PIXELS, ws->n_pixels);
        gs_put_u16(p + GS_FRAME_REP_START, start);
        gs_put_u16(p + GS_FRAME_REP_COUNT, count);
        gs_put_u16(p + GS_FRAME_REP_TOTAL, ws->n_windows);
        p[GS_FRAME_REP_PIXEL_FORMAT] = s->fmt;
        gs_head_send(h, (uint8_t)(GS_MSG_FRAME | GS_PROTO_REPLY_FLAG), s->seq, len);
        start = (uint16_t)(start + count);
    } while (start < ws->n_windows);
}

/* Readout of the frame whose exposure just ended: install its window set, read, push. */
static void read_frame(gs_head *h, uint64_t t_end)
{
    gs_stream *s = &h->stream;
    while (s->n_pending && s->pending_frame[0] <= s->frame) {
        memcpy(&h->ws, &s->pending[0], sizeof h->ws);
        s->set_frame = s->pending_named[0];
        s->n_pending--;
        for (uint8_t i = 0; i < s->n_pending; i++) {
            memcpy(&s->pending[i], &s->pending[i + 1u], sizeof s->pending[i]);
            s->pending_frame[i] = s->pending_frame[i + 1u];
            s->pending_named[i] = s->pending_named[i + 1u];
        }
    }
    size_t backlog = h->hal->uart_tx_backlog ? h->hal->uart_tx_backlog(h->hal->ctx) : 0u;
    if (backlog > GS_LIM_STREAM_TX_BACKLOG_MAX) {
        s->dropped++;
        s->backpressure++;
        return;
    }
    h->has_capture = 0; /* the store now holds stream pixels, not the last CAPTURE's */
    if (h->ws.n_windows) {
        uint32_t sensor_frame = 0;
        if (gs_head_read_windows(h, GS_PLANE_LIGHT, &sensor_frame) != GS_SENSOR_OK) {
            s->dropped++;
            return;
        }
    }
    push(h, t_end);
    s->frames++;
    s->last_frame = s->frame;
}

static void next_frame(gs_head *h)
{
    gs_stream *s = &h->stream;
    h->frame_no = h->frame_no == UINT32_MAX ? 1u : h->frame_no + 1u;
    s->frame = h->frame_no;
    s->t_start_us += s->period_us;
}

uint64_t gs_stream_poll(gs_head *h)
{
    gs_stream *s = &h->stream;
    if (!s->on)
        return UINT64_MAX;
    const gs_hal *hal = h->hal;
    uint64_t t_end = s->t_start_us + s->exposure_us;
    if (hal->time_us(hal->ctx) < t_end)
        return t_end;
    read_frame(h, t_end);
    next_frame(h);
    /* a frame more than a period overdue (the MCU was held up) is never read: dropped */
    uint64_t now = hal->time_us(hal->ctx);
    while (s->t_start_us + s->exposure_us + s->period_us <= now) {
        s->dropped++;
        next_frame(h);
    }
    if (hal->sensor_expose)
        hal->sensor_expose(hal->ctx, s->t_start_us, s->exposure_us);
    return s->t_start_us + s->exposure_us;
}
