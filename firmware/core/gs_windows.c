/* gs_windows.c - span table validation and window readout. */
#include "gs_windows.h"

#include "gs_bytes.h"

void gs_windows_clear(gs_window_set *ws)
{
    ws->n_spans = 0;
    ws->n_windows = 0;
    ws->n_pixels = 0;
}

static gs_span span_at(const uint8_t *wire, uint16_t i)
{
    const uint8_t *p = wire + 8u * i;
    gs_span s = {gs_get_u16(p), gs_get_u16(p + 2), gs_get_u16(p + 4), gs_get_u16(p + 6)};
    return s;
}

uint16_t gs_windows_set(gs_window_set *ws, const uint8_t *wire, uint16_t n, uint16_t width,
                        uint16_t height, uint32_t *detail)
{
    if (n > GS_LIM_MAX_SPANS) {
        *detail = n;
        return GS_ERR_SPAN_COUNT;
    }
    /* pass 1: validate without touching *ws */
    uint32_t total = 0, in_window = 0;
    uint16_t windows = 0;
    for (uint16_t i = 0; i < n; i++) {
        gs_span s = span_at(wire, i);
        *detail = i;
        if (s.row >= height || s.col_stop > width)
            return GS_ERR_SPAN_OUTSIDE;
        if (s.col_start >= s.col_stop)
            return GS_ERR_SPAN_EMPTY;
        if (i > 0) {
            gs_span p = span_at(wire, (uint16_t)(i - 1u));
            if (s.id < p.id || (s.id == p.id && s.row <= p.row))
                return GS_ERR_SPAN_ORDER;
        }
        if (i == 0 || s.id != span_at(wire, (uint16_t)(i - 1u)).id) {
            if (++windows > GS_LIM_MAX_WINDOWS)
                return GS_ERR_WINDOW_COUNT;
            in_window = 0;
        }
        uint32_t w = (uint32_t)(s.col_stop - s.col_start);
        in_window += w;
        total += w;
        if (in_window > GS_LIM_MAX_WINDOW_PIXELS)
            return GS_ERR_WINDOW_TOO_LARGE;
        if (total > GS_LIM_PIXEL_BUDGET)
            return GS_ERR_PIXEL_BUDGET;
    }
    *detail = 0;
    /* pass 2: commit */
    gs_windows_clear(ws);
    for (uint16_t i = 0; i < n; i++) {
        gs_span s = span_at(wire, i);
        ws->spans[i] = s;
        if (i == 0 || s.id != ws->spans[i - 1u].id) {
            gs_window *w = &ws->windows[ws->n_windows++];
            w->id = s.id;
            w->first_span = i;
            w->n_spans = 0;
            w->n_pixels = 0;
            w->px_offset = (uint16_t)ws->n_pixels;
        }
        gs_window *w = &ws->windows[ws->n_windows - 1u];
        w->n_spans++;
        w->n_pixels = (uint16_t)(w->n_pixels + (s.col_stop - s.col_start));
        ws->n_pixels += (uint32_t)(s.col_stop - s.col_start);
    }
    ws->n_spans = n;
    return 0;
}

gs_sensor_status gs_windows_read(const gs_window_set *ws, const gs_hal *hal, uint8_t plane, uint16_t width,
                                 uint16_t *store, uint32_t *sums)
{
    uint32_t off = 0;
    for (uint16_t wi = 0; wi < ws->n_windows; wi++) {
        const gs_window *w = &ws->windows[wi];
        uint32_t sum = 0;
        for (uint16_t k = 0; k < w->n_spans; k++) {
            const gs_span *s = &ws->spans[w->first_span + k];
            uint16_t count = (uint16_t)(s->col_stop - s->col_start);
            uint32_t index = (uint32_t)s->row * width + s->col_start;
            gs_sensor_status st = hal->sensor_read(hal->ctx, plane, index, count, store + off);
            if (st != GS_SENSOR_OK)
                return st;
            for (uint16_t c = 0; c < count; c++) {
                if (store[off + c] > 0x3FFu)
                    store[off + c] = 0x3FFu; /* a 10-bit ADC saturates */
                sum += store[off + c];
            }
            off += count;
        }
        sums[wi] = sum;
    }
    return GS_SENSOR_OK;
}
