/* gs_windows.h - the window engine: validated span table, per-window index, readout.
 *
 * A window is a set of row spans [col_start, col_stop) (one per row) sharing a window id;
 * spans are sorted by (window_id, row). This is how the union of k x k squares along a
 * star's predicted trajectory is expressed.
 */
#ifndef GS_WINDOWS_H
#define GS_WINDOWS_H

#include <stdint.h>

#include "gs_hal.h"
#include "gs_proto_defs.h"

typedef struct {
    uint16_t id, row, col_start, col_stop;
} gs_span;

typedef struct {
    uint16_t id;
    uint16_t first_span;
    uint16_t n_spans;
    uint16_t n_pixels;
    uint16_t px_offset; /* first pixel in the window store */
} gs_window;

typedef struct {
    gs_span spans[GS_LIM_MAX_SPANS];
    gs_window windows[GS_LIM_MAX_WINDOWS];
    uint16_t n_spans;
    uint16_t n_windows;
    uint32_t n_pixels;
} gs_window_set;

void gs_windows_clear(gs_window_set *ws);

/* Validate n spans given as wire bytes (8 bytes each, LE u16 id,row,c0,c1) against a
 * width x height sensor and the limits; on success replace *ws and return 0. On failure
 * return the GS_ERR_* code, set *detail to the offending span index, leave *ws unchanged. */
uint16_t gs_windows_set(gs_window_set *ws, const uint8_t *wire, uint16_t n, uint16_t width,
                        uint16_t height, uint32_t *detail);

/* Read every window's pixels of `plane` into store (span order, clipped to 10 bits) and
 * their sums into sums[]. Returns the first non-OK sensor status. */
gs_sensor_status gs_windows_read(const gs_window_set *ws, const gs_hal *hal, uint8_t plane, uint16_t width,
                                 uint16_t *store, uint32_t *sums);

#endif
