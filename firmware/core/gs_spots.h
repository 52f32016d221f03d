/* gs_spots.h - lost-in-space spot finding on the head (FIND_SPOTS).
 *
 * One pass over a sensor frame, three rows at a time: background and noise from a sparse
 * grid (a 10-bit histogram: median and MAD, no sort), 3x3 local maxima above
 * background + n_sigma * sigma scored by their 8 neighbours' excess (a star's PSF spreads
 * there; a hot pixel or a cosmic-ray hit does not), and a bounded list of the best ones with
 * non-maximum suppression. The exact rules are the FIND_SPOTS doc of firmware/proto/protocol.toml; the
 * Python head emulator follows them to the pixel. No malloc: every buffer is in the
 * caller's gs_spot_scratch.
 */
#ifndef GS_SPOTS_H
#define GS_SPOTS_H

#include <stddef.h>
#include <stdint.h>

#include "gs_hal.h"
#include "gs_proto_defs.h"

#define GS_SPOT_LEVELS 1024u /* 10-bit values */

typedef struct {
    uint16_t row, col;
    uint32_t score; /* DN x 16: excess over the background of the 8 neighbours (>= 0) */
} gs_spot;

typedef struct {
    uint32_t background_x16, sigma_x16, threshold_x16; /* DN x 16 */
    uint32_t candidates;                               /* local maxima above the threshold */
    uint16_t n;
    gs_spot spots[GS_LIM_MAX_WINDOWS]; /* highest score first */
} gs_spot_list;

typedef struct {
    uint16_t rows[3][GS_LIM_SPOT_WIDTH_MAX];
    uint32_t hist[GS_SPOT_LEVELS]; /* grid values */
} gs_spot_scratch;

/* Settings check: 0 if usable, else the SPOT_SETTINGS detail (1 n_sigma .. 5 pixels). */
uint32_t gs_spots_check(uint16_t n_sigma_x16, uint16_t max_spots, uint8_t box);

/* Scan `plane` of the current sensor frame (the caller holds the sequence lock) of a
 * width x height sensor (width <= GS_LIM_SPOT_WIDTH_MAX). Returns the first non-OK sensor
 * status; on OK *out holds the spot list. */
gs_sensor_status gs_spots_find(const gs_hal *hal, uint8_t plane, uint16_t width, uint16_t height,
                               uint16_t n_sigma_x16, uint16_t max_spots, uint8_t box, gs_spot_scratch *s,
                               gs_spot_list *out);

/* The box x box windows (clipped to the sensor) around the spots as SET_WINDOWS wire
 * bytes (8 per span) in out (cap bytes); returns the number of spans written. */
uint16_t gs_spots_spans(const gs_spot_list *list, uint8_t box, uint16_t width, uint16_t height, uint8_t *out,
                        size_t cap);

#endif
