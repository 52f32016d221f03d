/* test_spots.c - FIND_SPOTS on a hand-built image: background statistics, local maxima,
 * tie rules, neighbour scores, suppression, the bounded list, clipped windows, rejections. Every expected
 * value below is worked out by hand from the image. */
#include <string.h>

#include "gs_bytes.h"
#include "test_util.h"

#define W 64
#define H 48

static uint16_t img[W * H];
static uint8_t q[16];

/* Background 100 DN everywhere except a checker of 101 on odd columns of odd rows (never
 * on the 7-grid's odd positions only: the grid sees rows/cols 0,7,14,..: values 100 at
 * even (r,c), 101 where both are odd). */
static void put(uint16_t row, uint16_t col, uint16_t v) { img[row * W + col] = v; }

static void blob(uint16_t row, uint16_t col, uint16_t peak, uint16_t ring)
{
    for (int dr = -1; dr <= 1; dr++)
        for (int dc = -1; dc <= 1; dc++)
            put((uint16_t)(row + dr), (uint16_t)(col + dc), (uint16_t)(dr || dc ? ring : peak));
}

static void scene(void)
{
    for (uint16_t r = 0; r < H; r++)
        for (uint16_t c = 0; c < W; c++)
            img[r * W + c] = (uint16_t)((r & 1u) && (c & 1u) ? 101 : 100);
    blob(10, 10, 900, 300); /* best */
    blob(12, 14, 500, 250); /* 2 rows, 4 cols from it: inside box 7 -> suppressed */
    blob(30, 40, 600, 200);
    blob(40, 5, 700, 280);
    blob(1, 60, 650, 260);  /* next to the top edge: its window is clipped to rows 0..4 */
    put(20, 20, 2000);   /* above 10 bits: saturates to 1023, a single hot pixel */
    put(25, 30, 400);    /* two equal pixels side by side: the earlier one is the maximum */
    put(25, 31, 400);
}

static size_t req(uint16_t n_sigma_x16, uint16_t max_spots, uint8_t box)
{
    memset(q, 0, sizeof q);
    gs_put_u16(q, n_sigma_x16);
    gs_put_u16(q + 2, max_spots);
    q[4] = box;
    return GS_FIND_SPOTS_REQ_SIZE;
}

static rig *boot(void)
{
    rig *r = rig_boot(W, H, 1);
    scene();
    r->f.image = img;
    return r;
}

static void spot_list_brightest_first_with_suppression(void **state)
{
    (void)state;
    rig *r = boot();
    const gs_frame *f = rig_call(r, GS_MSG_FIND_SPOTS, 9, q, req(6 * 16, 8, 7));
    assert_int_equal(f->type, GS_MSG_FIND_SPOTS | GS_PROTO_REPLY_FLAG);
    const uint8_t *p = f->payload;
    /* grid: 10 rows (0..63 step 7) x 7 ... all grid points have an even row or column
     * except where both are odd: rows 7,21,35 and cols 7,21,35,49,63 -> 101 there. */
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_BACKGROUND_X16), 1600);
    /* MAD = 0 -> sigma floored at 0.5 DN = 8 (x16); threshold = 1600 + 6*16*8/16 = 1648 */
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_SIGMA_X16), 8);
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_THRESHOLD_X16), 1648);
    /* candidates: 5 blob peaks + the hot pixel + the earlier of the equal pair = 7 */
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_CANDIDATES), 7);
    uint16_t n = gs_get_u16(p + GS_FIND_SPOTS_REP_N_WINDOWS);
    assert_int_equal(n, 6);
    /* score = the 8 neighbours' excess over 100 DN: blob 8 x (ring - 100); the hot pixel only
     * its four 101 neighbours (4); of the equal pair, the other one (300) and one 101 */
    static const uint16_t want[6][3] = {{10, 10, 1600}, {40, 5, 1440}, {1, 60, 1280},
                                        {30, 40, 800},  {25, 30, 301}, {20, 20, 4}};
    assert_int_equal(f->payload_len, GS_FIND_SPOTS_REP_SIZE + 6u * n);
    for (uint16_t i = 0; i < n; i++) {
        const uint8_t *s = p + GS_FIND_SPOTS_REP_SIZE + 6u * i;
        assert_int_equal(gs_get_u16(s), want[i][0]);
        assert_int_equal(gs_get_u16(s + 2), want[i][1]);
        assert_int_equal(gs_get_u16(s + 4), want[i][2]);
    }
    /* windows: 7x7 except the edge one (rows 0..4, cols 57..63 -> 5 x 7 = 35 px) */
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_N_PIXELS), 5u * 49u + 35u);
    assert_int_equal(r->f.exposes, 1);
    /* the pixels come back through WINDOW_DATA; window 1 is the 900 blob, centre at (3,3) */
    uint8_t wd[4] = {0, 0, GS_PIXFMT_U16, 0};
    f = rig_call(r, GS_MSG_WINDOW_DATA, 10, wd, 4);
    const uint8_t *t = f->payload + GS_WINDOW_DATA_REP_SIZE;
    assert_int_equal(gs_get_u16(f->payload + GS_WINDOW_DATA_REP_TOTAL), 6);
    assert_int_equal(gs_get_u16(t), 1);
    assert_int_equal(gs_get_u16(t + 2), 49);
    assert_int_equal(gs_get_u16(t + 8 + 2 * (3 * 7 + 3)), 900);
    assert_int_equal(gs_get_u16(t + 8 + 2 * (2 * 7 + 2)), 300);
}

static void bounded_list_keeps_the_brightest(void **state)
{
    (void)state;
    rig *r = boot();
    const gs_frame *f = rig_call(r, GS_MSG_FIND_SPOTS, 11, q, req(6 * 16, 3, 7));
    const uint8_t *p = f->payload;
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_CANDIDATES), 7);
    assert_int_equal(gs_get_u16(p + GS_FIND_SPOTS_REP_N_WINDOWS), 3);
    const uint8_t *s = p + GS_FIND_SPOTS_REP_SIZE;
    assert_int_equal(gs_get_u16(s + 4), 1600);
    assert_int_equal(gs_get_u16(s + 6 + 4), 1440);
    assert_int_equal(gs_get_u16(s + 12 + 4), 1280);
    /* a higher threshold (600 DN: 100 + n_sigma * 0.5) leaves 1023, 900, 700, 650 */
    f = rig_call(r, GS_MSG_FIND_SPOTS, 12, q, req(1000 * 16, 8, 3));
    p = f->payload;
    assert_int_equal(gs_get_u32(p + GS_FIND_SPOTS_REP_THRESHOLD_X16), 1600 + 8000);
    assert_int_equal(gs_get_u16(p + GS_FIND_SPOTS_REP_N_WINDOWS), 4);
    /* box 3: the 500 blob (2 rows, 4 cols away) is no longer covered by the 900 one */
    f = rig_call(r, GS_MSG_FIND_SPOTS, 13, q, req(6 * 16, 16, 3));
    assert_int_equal(gs_get_u16(f->payload + GS_FIND_SPOTS_REP_N_WINDOWS), 7);
    assert_int_equal(gs_get_u32(f->payload + GS_FIND_SPOTS_REP_N_PIXELS), 7u * 9u); /* (1,60): rows 0..2, whole */
}

static void settings_rejections_change_nothing(void **state)
{
    (void)state;
    rig *r = boot();
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(0, 8, 7), &d), GS_ERR_SPOT_SETTINGS);
    assert_int_equal(d, 1);
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, 0, 7), &d), GS_ERR_SPOT_SETTINGS);
    assert_int_equal(d, 2);
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, GS_LIM_MAX_WINDOWS + 1, 7), &d),
                     GS_ERR_SPOT_SETTINGS);
    assert_int_equal(d, 2);
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, 8, 6), &d), GS_ERR_SPOT_SETTINGS);
    assert_int_equal(d, 3);
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, 8, GS_LIM_SPOT_BOX_MAX + 2), &d),
                     GS_ERR_SPOT_SETTINGS);
    assert_int_equal(d, 3);
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, 64, 9), &d), GS_ERR_SPOT_SETTINGS);
    assert_int_equal(d, 4); /* 64 x 9 spans > 512 */
    /* (detail 5, pixels, cannot happen with today's limits: max_spans x spot_box_max < pixel_budget) */
    size_t n = req(96, 8, 7);
    q[5] = 1;
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, n, &d), GS_ERR_RESERVED_NONZERO);
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, n - 1, &d), GS_ERR_PAYLOAD_LENGTH);
    assert_int_equal(r->f.exposes, 0); /* nothing was exposed */
    assert_int_equal(r->head.cnt.captures, 0);
}

static void too_wide_sensor_and_sensor_faults(void **state)
{
    (void)state;
    rig *r = rig_boot(GS_LIM_SPOT_WIDTH_MAX + 1, 4, 1);
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, 8, 7), &d), GS_ERR_SENSOR_TOO_WIDE);
    assert_int_equal(d, GS_LIM_SPOT_WIDTH_MAX + 1);
    r = boot();
    r->f.io_fail = 1;
    assert_int_equal(rig_reject(r, GS_MSG_FIND_SPOTS, q, req(96, 8, 7), &d), GS_ERR_SENSOR_IO);
    uint8_t wd[4] = {0, 0, GS_PIXFMT_U16, 0};
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wd, 4, &d), GS_ERR_NO_CAPTURE);
    r->f.io_fail = 0;
    r->f.frame_changes = 1; /* the frame changed during the scan: scanned again, same list */
    const gs_frame *f = rig_call(r, GS_MSG_FIND_SPOTS, 14, q, req(96, 8, 7));
    assert_int_equal(gs_get_u16(f->payload + GS_FIND_SPOTS_REP_N_WINDOWS), 6);
    assert_int_equal(gs_get_u32(f->payload + GS_FIND_SPOTS_REP_SENSOR_FRAME), 8);
}

int run_spots_tests(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(spot_list_brightest_first_with_suppression),
        cmocka_unit_test(bounded_list_keeps_the_brightest),
        cmocka_unit_test(settings_rejections_change_nothing),
        cmocka_unit_test(too_wide_sensor_and_sensor_faults),
    };
    return cmocka_run_group_tests_name("spots", tests, NULL, NULL);
}
