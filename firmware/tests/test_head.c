/* test_head.c - every command and every rejection path of the dispatcher, on the fake HAL. */
#include <string.h>

#include "gs_bytes.h"
#include "gs_crc32c.h"
#include "test_util.h"

#define W 64
#define H 48

static uint8_t q[GS_PROTO_MAX_PAYLOAD + 16];

static void set_windows_ok(rig *r, const uint16_t (*spans)[4], uint16_t n)
{
    size_t len = spans_payload(q, spans, n);
    const gs_frame *f = rig_call(r, GS_MSG_SET_WINDOWS, 1, q, len);
    assert_int_equal(f->type, GS_MSG_SET_WINDOWS | GS_PROTO_REPLY_FLAG);
    assert_int_equal(gs_get_u16(f->payload + GS_SET_WINDOWS_REP_N_SPANS), n);
}

static uint16_t set_windows_reject(rig *r, const uint16_t (*spans)[4], uint16_t n, uint32_t *detail)
{
    size_t len = spans_payload(q, spans, n);
    return rig_reject(r, GS_MSG_SET_WINDOWS, q, len, detail);
}

static void ping_echo_and_limit(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    const gs_frame *f = rig_call(r, GS_MSG_PING, 77, (const uint8_t *)"\x00xyz\x00", 5);
    assert_int_equal(f->type, GS_MSG_PING | GS_PROTO_REPLY_FLAG);
    assert_int_equal(f->payload_len, 5);
    assert_memory_equal(f->payload, "\x00xyz\x00", 5);
    memset(q, 0xA5, GS_PROTO_PING_MAX + 1);
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_PING, q, GS_PROTO_PING_MAX + 1, &d), GS_ERR_PAYLOAD_LENGTH);
    assert_int_equal(d, GS_PROTO_PING_MAX + 1);
    assert_true(r->f.kicks >= 1);
}

static void get_info_reports_geometry_and_limits(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 1);
    const gs_frame *f = rig_call(r, GS_MSG_GET_INFO, 2, NULL, 0);
    assert_int_equal(f->payload_len, GS_GET_INFO_REP_SIZE);
    const uint8_t *p = f->payload;
    assert_int_equal(p[GS_GET_INFO_REP_PROTO_VERSION], GS_PROTO_VERSION);
    assert_int_equal(gs_get_u16(p + GS_GET_INFO_REP_WIDTH), W);
    assert_int_equal(gs_get_u16(p + GS_GET_INFO_REP_HEIGHT), H);
    assert_int_equal(p[GS_GET_INFO_REP_BITS], 10);
    assert_int_equal(p[GS_GET_INFO_REP_PLANES], 1);
    assert_int_equal(gs_get_u32(p + GS_GET_INFO_REP_PIXEL_BUDGET), GS_LIM_PIXEL_BUDGET);
    assert_int_equal(gs_get_u16(p + GS_GET_INFO_REP_MAX_SPANS), GS_LIM_MAX_SPANS);
    assert_int_equal(rig_reject(r, GS_MSG_GET_INFO, q, 1, NULL), GS_ERR_PAYLOAD_LENGTH);
}

static void exposure_and_gain(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    assert_int_equal(r->f.cfg_exposure_us, GS_LIM_EXPOSURE_DEFAULT_US);
    uint8_t b[4];
    gs_put_u32(b, 2500);
    const gs_frame *f = rig_call(r, GS_MSG_SET_EXPOSURE, 3, b, 4);
    assert_int_equal(gs_get_u32(f->payload), 2500);
    assert_int_equal(r->f.cfg_exposure_us, 2500);
    uint32_t d;
    gs_put_u32(b, GS_LIM_EXPOSURE_MIN_US - 1);
    assert_int_equal(rig_reject(r, GS_MSG_SET_EXPOSURE, b, 4, &d), GS_ERR_EXPOSURE_RANGE);
    gs_put_u32(b, GS_LIM_EXPOSURE_MAX_US + 1);
    assert_int_equal(rig_reject(r, GS_MSG_SET_EXPOSURE, b, 4, &d), GS_ERR_EXPOSURE_RANGE);
    assert_int_equal(d, GS_LIM_EXPOSURE_MAX_US + 1);
    assert_int_equal(rig_reject(r, GS_MSG_SET_EXPOSURE, b, 3, &d), GS_ERR_PAYLOAD_LENGTH);
    assert_int_equal(r->head.exposure_us, 2500); /* rejections changed nothing */
    gs_put_u16(b, 64);
    f = rig_call(r, GS_MSG_SET_GAIN, 4, b, 2);
    assert_int_equal(gs_get_u16(f->payload), 64);
    assert_int_equal(r->f.cfg_gain_x16, 64);
    gs_put_u16(b, GS_LIM_GAIN_MIN_X16 - 1);
    assert_int_equal(rig_reject(r, GS_MSG_SET_GAIN, b, 2, &d), GS_ERR_GAIN_RANGE);
    gs_put_u16(b, GS_LIM_GAIN_MAX_X16 + 1);
    assert_int_equal(rig_reject(r, GS_MSG_SET_GAIN, b, 2, &d), GS_ERR_GAIN_RANGE);
    assert_int_equal(rig_reject(r, GS_MSG_SET_GAIN, b, 4, &d), GS_ERR_PAYLOAD_LENGTH);
    assert_int_equal(r->head.gain_x16, 64);
}

static const uint16_t two_windows[5][4] = {
    {2, 10, 5, 11}, {2, 11, 5, 12}, {2, 12, 6, 12}, {9, 0, 60, 64}, {9, 33, 0, 3},
};

static void capture_reads_windows_with_timestamps(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    set_windows_ok(r, two_windows, 5);
    uint8_t b[4];
    gs_put_u32(b, 3000);
    rig_call(r, GS_MSG_SET_EXPOSURE, 3, b, 4);
    const gs_frame *f = rig_call(r, GS_MSG_CAPTURE, 5, NULL, 0);
    const uint8_t *p = f->payload;
    assert_int_equal(f->payload_len, GS_CAPTURE_REP_SIZE);
    uint64_t t0 = gs_get_u64(p + GS_CAPTURE_REP_T_START_US), t1 = gs_get_u64(p + GS_CAPTURE_REP_T_END_US);
    assert_true(t1 >= t0 + 3000 && t1 <= t0 + 3002);
    /* the sensor was triggered once, at the reported start, for the set exposure */
    assert_int_equal(r->f.exposes, 1);
    assert_int_equal(r->f.expose_t_us, t0);
    assert_int_equal(r->f.expose_us, 3000);
    assert_int_equal(gs_get_u32(p + GS_CAPTURE_REP_CAPTURE_NO), 1);
    assert_int_equal(gs_get_u32(p + GS_CAPTURE_REP_SENSOR_FRAME), 7);
    assert_int_equal(gs_get_u16(p + GS_CAPTURE_REP_N_WINDOWS), 2);
    assert_int_equal(gs_get_u32(p + GS_CAPTURE_REP_N_PIXELS), 6 + 7 + 6 + 4 + 3);
    assert_int_equal(p[GS_CAPTURE_REP_PLANE], GS_PLANE_LIGHT);
    /* window data, 16-bit: compare with the fake sensor (clipped at 1023) */
    uint8_t wq[4] = {0, 0, GS_PIXFMT_U16, 0};
    f = rig_call(r, GS_MSG_WINDOW_DATA, 6, wq, 4);
    p = f->payload;
    assert_int_equal(gs_get_u16(p + GS_WINDOW_DATA_REP_COUNT), 2);
    assert_int_equal(gs_get_u16(p + GS_WINDOW_DATA_REP_TOTAL), 2);
    size_t off = GS_WINDOW_DATA_REP_SIZE;
    int span = 0, clipped = 0;
    for (int w = 0; w < 2; w++) {
        uint16_t id = gs_get_u16(p + off), n = gs_get_u16(p + off + 2);
        uint32_t sum = gs_get_u32(p + off + 4), want_sum = 0;
        assert_int_equal(id, w ? 9 : 2);
        off += 8;
        for (int done = 0; done < n; span++) {
            for (uint16_t c = two_windows[span][2]; c < two_windows[span][3]; c++, done++) {
                uint16_t v = fake_pixel(&r->f, 0, (uint32_t)two_windows[span][1] * W + c);
                clipped += v > 1023;
                v = v > 1023 ? 1023 : v;
                assert_int_equal(gs_get_u16(p + off + 2u * done), v);
                want_sum += v;
            }
        }
        assert_int_equal(sum, want_sum);
        off += 2u * n;
    }
    assert_int_equal(off, f->payload_len);
    assert_true(clipped > 0); /* the synthetic image exercises saturation */
    /* packed 10-bit: 26 pixels in 2 windows -> 8 + 8 + ceil(19*10/8) + ceil(7*10/8) */
    wq[2] = GS_PIXFMT_PACKED10;
    f = rig_call(r, GS_MSG_WINDOW_DATA, 7, wq, 4);
    assert_int_equal(f->payload_len, GS_WINDOW_DATA_REP_SIZE + 8 + 24 + 8 + 9);
    /* second capture increments the number; telemetry counts it */
    f = rig_call(r, GS_MSG_CAPTURE, 8, NULL, 0);
    assert_int_equal(gs_get_u32(f->payload + GS_CAPTURE_REP_CAPTURE_NO), 2);
    assert_int_equal(r->head.cnt.captures, 2);
}

static void window_data_paging_and_rejections(void **state)
{
    (void)state;
    rig *r = rig_boot(1024, 1024, 2);
    uint32_t d;
    uint8_t wq[4] = {0, 0, GS_PIXFMT_U16, 0};
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 4, &d), GS_ERR_NO_CAPTURE);
    /* four windows of 2 x 1000 pixels: 4 kB each in 16-bit, so one window per reply */
    static uint16_t spans[8][4];
    for (int i = 0; i < 8; i++) {
        spans[i][0] = (uint16_t)(i / 2);
        spans[i][1] = (uint16_t)(100 + i % 2);
        spans[i][2] = 0;
        spans[i][3] = 1000;
    }
    set_windows_ok(r, (const uint16_t (*)[4])spans, 8);
    rig_call(r, GS_MSG_CAPTURE, 2, NULL, 0);
    uint16_t start = 0, pages = 0;
    while (start < 4) {
        gs_put_u16(wq, start);
        const gs_frame *f = rig_call(r, GS_MSG_WINDOW_DATA, 3, wq, 4);
        uint16_t count = gs_get_u16(f->payload + GS_WINDOW_DATA_REP_COUNT);
        assert_int_equal(gs_get_u16(f->payload + GS_WINDOW_DATA_REP_START), start);
        assert_true(count >= 1 && f->payload_len <= GS_PROTO_MAX_PAYLOAD);
        start = (uint16_t)(start + count);
        pages++;
    }
    assert_int_equal(pages, 4);
    /* packed: two windows (2 x 2500 B) do not fit 4160 B either; one per page */
    gs_put_u16(wq, 0);
    wq[2] = GS_PIXFMT_PACKED10;
    const gs_frame *f = rig_call(r, GS_MSG_WINDOW_DATA, 4, wq, 4);
    assert_int_equal(gs_get_u16(f->payload + GS_WINDOW_DATA_REP_COUNT), 1);
    gs_put_u16(wq, 4);
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 4, &d), GS_ERR_WINDOW_INDEX);
    assert_int_equal(d, 4);
    gs_put_u16(wq, 0);
    wq[2] = 2;
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 4, &d), GS_ERR_PIXEL_FORMAT);
    wq[2] = 0;
    wq[3] = 1;
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 4, &d), GS_ERR_RESERVED_NONZERO);
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 3, &d), GS_ERR_PAYLOAD_LENGTH);
    /* new windows invalidate the capture */
    set_windows_ok(r, two_windows, 5);
    wq[3] = 0;
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 4, &d), GS_ERR_NO_CAPTURE);
}

static void set_windows_rejections_change_nothing(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    set_windows_ok(r, two_windows, 5);
    uint32_t d;
    static const uint16_t row_out[2][4] = {{1, 5, 0, 4}, {1, H, 0, 4}};
    assert_int_equal(set_windows_reject(r, row_out, 2, &d), GS_ERR_SPAN_OUTSIDE);
    assert_int_equal(d, 1);
    static const uint16_t col_out[1][4] = {{1, 5, W - 2, W + 1}};
    assert_int_equal(set_windows_reject(r, col_out, 1, &d), GS_ERR_SPAN_OUTSIDE);
    static const uint16_t empty[1][4] = {{1, 5, 3, 3}};
    assert_int_equal(set_windows_reject(r, empty, 1, &d), GS_ERR_SPAN_EMPTY);
    static const uint16_t order[2][4] = {{1, 5, 0, 4}, {1, 5, 0, 4}};
    assert_int_equal(set_windows_reject(r, order, 2, &d), GS_ERR_SPAN_ORDER);
    static const uint16_t order_id[2][4] = {{3, 5, 0, 4}, {1, 9, 0, 4}};
    assert_int_equal(set_windows_reject(r, order_id, 2, &d), GS_ERR_SPAN_ORDER);
    static uint16_t many[GS_LIM_MAX_WINDOWS + 1][4];
    for (int i = 0; i <= (int)GS_LIM_MAX_WINDOWS; i++) {
        many[i][0] = (uint16_t)i;
        many[i][3] = 1;
    }
    assert_int_equal(set_windows_reject(r, (const uint16_t (*)[4])many, GS_LIM_MAX_WINDOWS + 1, &d),
                     GS_ERR_WINDOW_COUNT);
    assert_int_equal(d, GS_LIM_MAX_WINDOWS);
    /* exactly max_windows is accepted on a big sensor */
    /* spans: count over the table, length mismatch, reserved */
    static uint16_t big[GS_LIM_MAX_SPANS][4];
    for (int i = 0; i < (int)GS_LIM_MAX_SPANS; i++) {
        big[i][0] = (uint16_t)(i / 40);
        big[i][1] = (uint16_t)(i % 40);
        big[i][3] = 1;
    }
    uint8_t hdr[8] = {(uint8_t)(GS_LIM_MAX_SPANS + 1), (uint8_t)((GS_LIM_MAX_SPANS + 1) >> 8), 0, 0, 0, 0, 0, 0};
    assert_int_equal(rig_reject(r, GS_MSG_SET_WINDOWS, hdr, 8, &d), GS_ERR_SPAN_COUNT);
    size_t len = spans_payload(q, two_windows, 5);
    assert_int_equal(rig_reject(r, GS_MSG_SET_WINDOWS, q, len - 1, &d), GS_ERR_SPANS_LENGTH);
    assert_int_equal(rig_reject(r, GS_MSG_SET_WINDOWS, q, 3, &d), GS_ERR_PAYLOAD_LENGTH);
    q[2] = 1;
    assert_int_equal(rig_reject(r, GS_MSG_SET_WINDOWS, q, len, &d), GS_ERR_RESERVED_NONZERO);
    /* after all rejections the original 2 windows are still there */
    assert_int_equal(r->head.ws.n_windows, 2);
    assert_int_equal(r->head.ws.n_spans, 5);
    const gs_frame *f = rig_call(r, GS_MSG_CAPTURE, 9, NULL, 0);
    assert_int_equal(gs_get_u32(f->payload + GS_CAPTURE_REP_N_PIXELS), 26);
    /* a full table is accepted (512 spans over 13 windows) */
    set_windows_ok(r, (const uint16_t (*)[4])big, GS_LIM_MAX_SPANS);
    assert_int_equal(r->head.ws.n_windows, 13);
}

static void pixel_limits(void **state)
{
    (void)state;
    rig *r = rig_boot(1024, 1024, 2);
    uint32_t d;
    static const uint16_t large[3][4] = {{1, 0, 0, 1000}, {1, 1, 0, 1000}, {1, 2, 0, 49}};
    assert_int_equal(set_windows_reject(r, large, 3, &d), GS_ERR_WINDOW_TOO_LARGE);
    assert_int_equal(d, 2);
    static const uint16_t edge[3][4] = {{1, 0, 0, 1000}, {1, 1, 0, 1000}, {1, 2, 0, 48}};
    set_windows_ok(r, edge, 3); /* exactly max_window_pixels */
    static uint16_t budget[10][4];
    for (int i = 0; i < 10; i++) {
        budget[i][0] = (uint16_t)(i / 2);
        budget[i][1] = (uint16_t)(i % 2);
        budget[i][3] = 1000;
    }
    assert_int_equal(set_windows_reject(r, (const uint16_t (*)[4])budget, 10, &d), GS_ERR_PIXEL_BUDGET);
    assert_int_equal(d, 8);
    budget[8][3] = 192; /* 8192 exactly */
    set_windows_ok(r, (const uint16_t (*)[4])budget, 9);
    assert_int_equal(r->head.ws.n_pixels, GS_LIM_PIXEL_BUDGET);
}

static void capture_and_dark_rejections(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 1);
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, NULL, 0, &d), GS_ERR_NO_WINDOWS);
    assert_int_equal(rig_reject(r, GS_MSG_DARK, NULL, 0, &d), GS_ERR_NO_WINDOWS);
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, q, 1, &d), GS_ERR_PAYLOAD_LENGTH);
    set_windows_ok(r, two_windows, 5);
    assert_int_equal(rig_reject(r, GS_MSG_DARK, NULL, 0, &d), GS_ERR_DARK_UNAVAILABLE);
    r->f.io_fail = 1;
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, NULL, 0, &d), GS_ERR_SENSOR_IO);
    r->f.io_fail = 0;
    r->f.busy_begins = 1000;
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, NULL, 0, &d), GS_ERR_SENSOR_BUSY);
    r->f.busy_begins = 0;
    r->f.frame_changes = 1000;
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, NULL, 0, &d), GS_ERR_SENSOR_BUSY);
    r->f.frame_changes = 0;
    uint8_t wq[4] = {0, 0, 0, 0};
    assert_int_equal(rig_reject(r, GS_MSG_WINDOW_DATA, wq, 4, &d), GS_ERR_NO_CAPTURE);
    assert_int_equal(r->head.cnt.captures, 0);
}

static void sensor_retries_until_stable(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    set_windows_ok(r, two_windows, 5);
    r->f.busy_begins = 3;
    r->f.frame_changes = 2; /* the writer replaced the frame twice during readout */
    const gs_frame *f = rig_call(r, GS_MSG_CAPTURE, 1, NULL, 0);
    assert_int_equal(f->type, GS_MSG_CAPTURE | GS_PROTO_REPLY_FLAG);
    assert_int_equal(gs_get_u32(f->payload + GS_CAPTURE_REP_SENSOR_FRAME), 9);
    /* the stored pixels are those of frame 9, not a mix */
    uint8_t wq[4] = {0, 0, 0, 0};
    f = rig_call(r, GS_MSG_WINDOW_DATA, 2, wq, 4);
    assert_int_equal(gs_get_u16(f->payload + GS_WINDOW_DATA_REP_SIZE + 8),
                     fake_pixel(&r->f, 0, 10 * W + 5) > 1023 ? 1023 : fake_pixel(&r->f, 0, 10 * W + 5));
}

static void dark_capture(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    set_windows_ok(r, two_windows, 5);
    const gs_frame *f = rig_call(r, GS_MSG_DARK, 1, NULL, 0);
    assert_int_equal(f->type, GS_MSG_DARK | GS_PROTO_REPLY_FLAG);
    assert_int_equal(f->payload[GS_CAPTURE_REP_PLANE], GS_PLANE_DARK);
    uint8_t wq[4] = {0, 0, 0, 0};
    f = rig_call(r, GS_MSG_WINDOW_DATA, 2, wq, 4);
    assert_int_equal(gs_get_u16(f->payload + GS_WINDOW_DATA_REP_SIZE + 8), fake_pixel(&r->f, 1, 10 * W + 5));
}

static void full_frame_chunks(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    uint8_t b[8];
    uint32_t d;
    for (uint8_t plane = 0; plane < 2; plane++) {
        gs_put_u32(b, 100);
        gs_put_u16(b + 4, 300);
        b[6] = GS_PIXFMT_U16;
        b[7] = plane;
        const gs_frame *f = rig_call(r, GS_MSG_FULL_FRAME, 1, b, 8);
        assert_int_equal(f->payload_len, GS_FULL_FRAME_REP_SIZE + 600);
        assert_int_equal(gs_get_u32(f->payload + GS_FULL_FRAME_REP_SENSOR_FRAME), 7);
        for (int i = 0; i < 300; i++) {
            uint16_t v = fake_pixel(&r->f, plane, 100u + (uint32_t)i);
            assert_int_equal(gs_get_u16(f->payload + GS_FULL_FRAME_REP_SIZE + 2 * i), v > 1023 ? 1023 : v);
        }
    }
    gs_put_u32(b, W * H - GS_LIM_FRAME_CHUNK_MAX); /* last chunk, packed */
    gs_put_u16(b + 4, GS_LIM_FRAME_CHUNK_MAX);
    b[6] = GS_PIXFMT_PACKED10;
    b[7] = 0;
    const gs_frame *f = rig_call(r, GS_MSG_FULL_FRAME, 2, b, 8);
    assert_int_equal(f->payload_len, GS_FULL_FRAME_REP_SIZE + GS_LIM_FRAME_CHUNK_MAX * 10 / 8);
    gs_put_u32(b, W * H - GS_LIM_FRAME_CHUNK_MAX + 1);
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_FRAME_RANGE);
    gs_put_u32(b, 0xFFFFFFF0u); /* offset + count wraps in 32 bits */
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_FRAME_RANGE);
    gs_put_u32(b, 0);
    gs_put_u16(b + 4, 0);
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_CHUNK_SIZE);
    gs_put_u16(b + 4, GS_LIM_FRAME_CHUNK_MAX + 1);
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_CHUNK_SIZE);
    gs_put_u16(b + 4, 10);
    b[6] = 5;
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_PIXEL_FORMAT);
    b[6] = 0;
    b[7] = 2;
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_BAD_PLANE);
    b[7] = 0;
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 7, &d), GS_ERR_PAYLOAD_LENGTH);
    r->f.io_fail = 1;
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_SENSOR_IO);
    r->f.io_fail = 0;
    r->f.busy_begins = 1000;
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_SENSOR_BUSY);
    rig *r1 = rig_boot(W, H, 1);
    b[7] = 1;
    r1->f.busy_begins = 0;
    assert_int_equal(rig_reject(r1, GS_MSG_FULL_FRAME, b, 8, &d), GS_ERR_DARK_UNAVAILABLE);
}

static void time_sync_and_telemetry(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    uint8_t b[8];
    gs_put_u64(b, 0x0102030405060708ull);
    const gs_frame *f = rig_call(r, GS_MSG_TIME_SYNC, 1, b, 8);
    assert_int_equal(gs_get_u64(f->payload + GS_TIME_SYNC_REP_HOST_US), 0x0102030405060708ull);
    uint64_t rx = gs_get_u64(f->payload + GS_TIME_SYNC_REP_MCU_RX_US);
    uint64_t tx = gs_get_u64(f->payload + GS_TIME_SYNC_REP_MCU_TX_US);
    assert_true(rx >= 1000000u && tx > rx && tx < rx + 10);
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_TIME_SYNC, b, 7, &d), GS_ERR_PAYLOAD_LENGTH);
    /* corrupt traffic: one CRC error, two framing errors, one overrun */
    static uint8_t enc[GS_FRAME_MAX_ENCODED + 200], scratch[GS_FRAME_MAX_RAW];
    size_t n = gs_frame_encode(GS_MSG_PING, 1, (const uint8_t *)"abc", 3, scratch, sizeof scratch, enc, sizeof enc);
    enc[7] ^= 0x40;
    assert_int_equal(rig_feed(r, enc, n), 0);
    const uint8_t junk[] = {0x09, 0x01, 0x00, 0x02, 0x05, 0x00};
    assert_int_equal(rig_feed(r, junk, sizeof junk), 0);
    memset(enc, 0x33, sizeof enc);
    assert_int_equal(rig_feed(r, enc, sizeof enc), 0);
    assert_int_equal(rig_feed(r, (const uint8_t *)"\x00", 1), 0);
    r->f.temp_cdeg = -1234;
    f = rig_call(r, GS_MSG_TELEMETRY, 2, NULL, 0);
    const uint8_t *p = f->payload;
    assert_int_equal(f->payload_len, GS_TELEMETRY_REP_SIZE);
    assert_int_equal((int16_t)gs_get_u16(p + GS_TELEMETRY_REP_TEMPERATURE_CDEG), -1234);
    assert_int_equal(gs_get_u32(p + GS_TELEMETRY_REP_CRC_ERRORS), 1);
    assert_int_equal(gs_get_u32(p + GS_TELEMETRY_REP_FRAMING_ERRORS), 2);
    assert_int_equal(gs_get_u32(p + GS_TELEMETRY_REP_OVERRUNS), 1);
    assert_int_equal(gs_get_u32(p + GS_TELEMETRY_REP_REJECTED), 1);
    assert_int_equal(gs_get_u16(p + GS_TELEMETRY_REP_LAST_ERROR), GS_ERR_PAYLOAD_LENGTH);
    assert_int_equal(gs_get_u32(p + GS_TELEMETRY_REP_RX_FRAMES), 3);
    assert_true(gs_get_u64(p + GS_TELEMETRY_REP_UPTIME_US) > 0);
    gs_head_note_overrun(&r->head);
    assert_int_equal(r->head.cnt.overruns, 2);
    assert_int_equal(rig_reject(r, GS_MSG_TELEMETRY, b, 1, &d), GS_ERR_PAYLOAD_LENGTH);
}

static void reset_restores_defaults(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    set_windows_ok(r, two_windows, 5);
    uint8_t b[4];
    gs_put_u32(b, 777);
    rig_call(r, GS_MSG_SET_EXPOSURE, 1, b, 4);
    rig_call(r, GS_MSG_CAPTURE, 2, NULL, 0);
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_RESET, b, 1, &d), GS_ERR_PAYLOAD_LENGTH);
    const gs_frame *f = rig_call(r, GS_MSG_RESET, 3, NULL, 0);
    assert_int_equal(f->type, GS_MSG_RESET | GS_PROTO_REPLY_FLAG);
    assert_int_equal(f->payload_len, 0);
    assert_int_equal(r->head.exposure_us, GS_LIM_EXPOSURE_DEFAULT_US);
    assert_int_equal(r->f.cfg_exposure_us, GS_LIM_EXPOSURE_DEFAULT_US);
    assert_int_equal(r->head.cnt.captures, 0);
    assert_int_equal(r->head.cnt.rejected, 0);
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, NULL, 0, &d), GS_ERR_NO_WINDOWS);
}

static void header_rejections(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    uint32_t d;
    assert_int_equal(rig_reject(r, 0x42, NULL, 0, &d), GS_ERR_UNKNOWN_TYPE);
    assert_int_equal(rig_reject(r, GS_MSG_PING | GS_PROTO_REPLY_FLAG, NULL, 0, &d), GS_ERR_UNKNOWN_TYPE);
    assert_int_equal(rig_reject(r, GS_MSG_ERROR, NULL, 0, &d), GS_ERR_UNKNOWN_TYPE);
    /* wrong version and a lying length field: build raw frames by hand */
    uint8_t raw[16] = {GS_PROTO_VERSION + 1, GS_MSG_PING, 5, 0, 0, 0};
    uint32_t c = gs_crc32c(raw, 6);
    gs_put_u32(raw + 6, c);
    uint8_t enc[32];
    size_t n = gs_cobs_encode(raw, 10, enc, sizeof enc);
    enc[n++] = 0;
    r->f.out_len = 0;
    assert_int_equal(rig_feed(r, enc, n), 1);
    gs_frame f;
    assert_int_equal(gs_frame_decode(r->f.out, r->f.out_len - 1, r->raw, sizeof r->raw, &f), GS_FRAME_OK);
    assert_int_equal(f.type, GS_MSG_ERROR);
    assert_int_equal(gs_get_u16(f.payload), GS_ERR_BAD_VERSION);
    g_codes_seen[GS_ERR_BAD_VERSION]++;
    assert_int_equal(gs_get_u32(f.payload + GS_ERROR_REP_DETAIL), GS_PROTO_VERSION + 1);
    uint8_t lie[16] = {GS_PROTO_VERSION, GS_MSG_PING, 6, 0, 4, 0, 'a', 'b'};
    gs_put_u32(lie + 8, gs_crc32c(lie, 8));
    n = gs_cobs_encode(lie, 12, enc, sizeof enc);
    enc[n++] = 0;
    assert_int_equal(rig_feed(r, enc, n), 1);
    assert_int_equal(gs_frame_decode(r->f.out, r->f.out_len - 1, r->raw, sizeof r->raw, &f), GS_FRAME_OK);
    assert_int_equal(gs_get_u16(f.payload), GS_ERR_FRAME_LENGTH);
    g_codes_seen[GS_ERR_FRAME_LENGTH]++;
    assert_int_equal(f.seq, 6);
}

static void back_to_back_frames_in_one_read(void **state)
{
    (void)state;
    rig *r = rig_boot(W, H, 2);
    static uint8_t enc[3 * 64], scratch[GS_FRAME_MAX_RAW];
    size_t n = 0;
    for (uint16_t s = 1; s <= 3; s++)
        n += gs_frame_encode(GS_MSG_PING, s, NULL, 0, scratch, sizeof scratch, enc + n, sizeof enc - n);
    assert_int_equal(rig_feed(r, enc, n), 3);
}

/* Runs last in this group: every error code of protocol.toml was provoked above. */
static void every_error_code_was_exercised(void **state)
{
    (void)state;
    for (unsigned code = 1; code <= GS_ERR_COUNT; code++)
        if (!g_codes_seen[code])
            fail_msg("error code %u was never provoked by a test", code);
}

int run_head_tests(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(ping_echo_and_limit),
        cmocka_unit_test(get_info_reports_geometry_and_limits),
        cmocka_unit_test(exposure_and_gain),
        cmocka_unit_test(capture_reads_windows_with_timestamps),
        cmocka_unit_test(window_data_paging_and_rejections),
        cmocka_unit_test(set_windows_rejections_change_nothing),
        cmocka_unit_test(pixel_limits),
        cmocka_unit_test(capture_and_dark_rejections),
        cmocka_unit_test(sensor_retries_until_stable),
        cmocka_unit_test(dark_capture),
        cmocka_unit_test(full_frame_chunks),
        cmocka_unit_test(time_sync_and_telemetry),
        cmocka_unit_test(reset_restores_defaults),
        cmocka_unit_test(header_rejections),
        cmocka_unit_test(back_to_back_frames_in_one_read),
        cmocka_unit_test(every_error_code_was_exercised),
    };
    return cmocka_run_group_tests_name("head", tests, NULL, NULL);
}
