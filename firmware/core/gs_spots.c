/* gs_spots.c - FIND_SPOTS: background, local maxima, bounded brightest-first list. */
#include "gs_spots.h"

#include <string.h>

#include "gs_bytes.h"

uint32_t gs_spots_check(uint16_t n_sigma_x16, uint16_t max_spots, uint8_t box)
{
    if (n_sigma_x16 == 0u)
        return 1u;
    if (max_spots == 0u || max_spots > GS_LIM_MAX_WINDOWS)
        return 2u;
    if (box < 3u || box > GS_LIM_SPOT_BOX_MAX || (box & 1u) == 0u)
        return 3u;
    if ((uint32_t)max_spots * box > GS_LIM_MAX_SPANS)
        return 4u;
    if ((uint32_t)max_spots * box * box > GS_LIM_PIXEL_BUDGET)
        return 5u;
    return 0u;
}

static void clip10(uint16_t *v, uint16_t n)
{
    for (uint16_t i = 0; i < n; i++)
        if (v[i] > 0x3FFu)
            v[i] = 0x3FFu; /* a 10-bit ADC saturates */
}

/* Read row r of `plane` into buf (width <= 2 x frame_chunk_max: two reads at most). */
static gs_sensor_status read_row(const gs_hal *hal, uint8_t plane, uint16_t width, uint16_t r, uint16_t *buf)
{
    uint16_t done = 0;
    while (done < width) {
        uint16_t n = (uint16_t)(width - done);
        if (n > GS_LIM_FRAME_CHUNK_MAX)
            n = GS_LIM_FRAME_CHUNK_MAX;
        gs_sensor_status st = hal->sensor_read(hal->ctx, plane, (uint32_t)r * width + done, n, buf + done);
        if (st != GS_SENSOR_OK)
            return st;
        clip10(buf + done, n);
        done = (uint16_t)(done + n);
    }
    return GS_SENSOR_OK;
}

/* The value below which more than k of the histogram's n entries lie: sorted[k]. */
static uint16_t hist_rank(const uint32_t *hist, uint32_t k)
{
    uint32_t cum = 0;
    for (uint16_t v = 0; v < GS_SPOT_LEVELS; v++) {
        cum += hist[v];
        if (cum > k)
            return v;
    }
    return (uint16_t)(GS_SPOT_LEVELS - 1u);
}

static gs_sensor_status background(const gs_hal *hal, uint8_t plane, uint16_t width, uint16_t height,
                                   gs_spot_scratch *s, gs_spot_list *out)
{
    memset(s->hist, 0, sizeof s->hist);
    uint32_t k = 0;
    for (uint32_t r = 0; r < height; r += GS_LIM_SPOT_GRID) {
        gs_sensor_status st = read_row(hal, plane, width, (uint16_t)r, s->rows[0]);
        if (st != GS_SENSOR_OK)
            return st;
        for (uint32_t c = 0; c < width; c += GS_LIM_SPOT_GRID) {
            s->hist[s->rows[0][c]]++;
            k++;
        }
    }
    uint16_t med = hist_rank(s->hist, k / 2u);
    /* MAD: the rank k/2 of |v - med|, counted outwards from the median (no second histogram) */
    uint32_t mad = GS_SPOT_LEVELS - 1u, cum = 0;
    for (uint32_t d = 0; d < GS_SPOT_LEVELS; d++) {
        cum += (med + d < GS_SPOT_LEVELS ? s->hist[med + d] : 0u) + (d && d <= med ? s->hist[med - d] : 0u);
        if (cum > k / 2u) {
            mad = d;
            break;
        }
    }
    /* sigma = max(1.4826 MAD, 0.5) in 1/16 DN: 1.4826 * 16 = 23.7216 */
    uint32_t sig = (mad * 237216u + 5000u) / 10000u;
    if (sig < 8u)
        sig = 8u;
    out->background_x16 = 16u * med;
    out->sigma_x16 = sig;
    return GS_SENSOR_OK;
}

static int within(const gs_spot *a, uint16_t row, uint16_t col, uint8_t box)
{
    uint16_t dr = a->row > row ? (uint16_t)(a->row - row) : (uint16_t)(row - a->row);
    uint16_t dc = a->col > col ? (uint16_t)(a->col - col) : (uint16_t)(col - a->col);
    return dr < box && dc < box;
}

static void offer(gs_spot_list *out, uint16_t max_spots, uint8_t box, uint16_t row, uint16_t col, uint32_t score)
{
    out->candidates++;
    for (uint16_t i = 0; i < out->n; i++)
        if (out->spots[i].score >= score && within(&out->spots[i], row, col, box))
            return; /* a brighter (or equal, earlier) spot covers it */
    uint16_t m = 0; /* drop the fainter spots it covers */
    for (uint16_t i = 0; i < out->n; i++)
        if (!within(&out->spots[i], row, col, box))
            out->spots[m++] = out->spots[i];
    out->n = m;
    uint16_t at = out->n; /* after every spot of equal or higher peak */
    while (at > 0u && out->spots[at - 1u].score < score)
        at--;
    if (at >= max_spots)
        return; /* fainter than a full list */
    uint16_t last = out->n < max_spots ? out->n : (uint16_t)(max_spots - 1u);
    for (uint16_t i = last; i > at; i--)
        out->spots[i] = out->spots[i - 1u];
    out->spots[at].row = row;
    out->spots[at].col = col;
    out->spots[at].score = score;
    if (out->n < max_spots)
        out->n++;
}

gs_sensor_status gs_spots_find(const gs_hal *hal, uint8_t plane, uint16_t width, uint16_t height,
                               uint16_t n_sigma_x16, uint16_t max_spots, uint8_t box, gs_spot_scratch *s,
                               gs_spot_list *out)
{
    memset(out, 0, sizeof *out);
    if (width > GS_LIM_SPOT_WIDTH_MAX || max_spots > GS_LIM_MAX_WINDOWS)
        return GS_SENSOR_IO;
    gs_sensor_status st = background(hal, plane, width, height, s, out);
    if (st != GS_SENSOR_OK)
        return st;
    out->threshold_x16 = out->background_x16 + ((uint32_t)n_sigma_x16 * out->sigma_x16 + 8u) / 16u;
    if (height < 3u || width < 3u)
        return GS_SENSOR_OK;
    uint16_t *prev = s->rows[0], *cur = s->rows[1], *next = s->rows[2];
    if ((st = read_row(hal, plane, width, 0, prev)) != GS_SENSOR_OK ||
        (st = read_row(hal, plane, width, 1, cur)) != GS_SENSOR_OK)
        return st;
    for (uint16_t r = 1; r + 1u < height; r++) {
        if ((st = read_row(hal, plane, width, (uint16_t)(r + 1u), next)) != GS_SENSOR_OK)
            return st;
        for (uint16_t c = 1; c + 1u < width; c++) {
            uint16_t v = cur[c];
            if (16u * (uint32_t)v <= out->threshold_x16)
                continue;
            /* earlier neighbours (row above, left) disqualify on >=, later ones on > */
            if (prev[c - 1u] >= v || prev[c] >= v || prev[c + 1u] >= v || cur[c - 1u] >= v)
                continue;
            if (cur[c + 1u] > v || next[c - 1u] > v || next[c] > v || next[c + 1u] > v)
                continue;
            /* score: the 8 neighbours' excess over the background (a star's PSF spreads
             * there, a hot pixel or a cosmic-ray hit on one pixel does not) */
            int32_t ring = 0;
            for (int d = -1; d <= 1; d++) {
                ring += (int32_t)(16u * prev[c + d]) + (int32_t)(16u * next[c + d]) - 2 * (int32_t)out->background_x16;
                if (d)
                    ring += (int32_t)(16u * cur[c + d]) - (int32_t)out->background_x16;
            }
            uint32_t score = ring > 0 ? (uint32_t)ring : 0u;
            offer(out, max_spots, box, r, c, score);
        }
        uint16_t *t = prev;
        prev = cur;
        cur = next;
        next = t;
    }
    return GS_SENSOR_OK;
}

uint16_t gs_spots_spans(const gs_spot_list *list, uint8_t box, uint16_t width, uint16_t height, uint8_t *out,
                        size_t cap)
{
    uint16_t n = 0, half = (uint16_t)(box / 2u);
    for (uint16_t i = 0; i < list->n; i++) {
        const gs_spot *sp = &list->spots[i];
        uint16_t r0 = sp->row > half ? (uint16_t)(sp->row - half) : 0u;
        uint16_t r1 = (uint32_t)sp->row + half + 1u < height ? (uint16_t)(sp->row + half + 1u) : height;
        uint16_t c0 = sp->col > half ? (uint16_t)(sp->col - half) : 0u;
        uint16_t c1 = (uint32_t)sp->col + half + 1u < width ? (uint16_t)(sp->col + half + 1u) : width;
        for (uint16_t r = r0; r < r1 && 8u * ((size_t)n + 1u) <= cap; r++) {
            uint8_t *p = out + 8u * n++;
            gs_put_u16(p, (uint16_t)(i + 1u));
            gs_put_u16(p + 2, r);
            gs_put_u16(p + 4, c0);
            gs_put_u16(p + 6, c1);
        }
    }
    return n;
}
