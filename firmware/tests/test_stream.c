/* test_stream.c - streaming on the fake HAL: frame sequencing and timing, window sets for
 * named frames (early, exact, late), back-pressure drops, multi-part frames, rejections. */
#include <string.h>

#include "gs_bytes.h"
#include "test_util.h"

#define PERIOD 10000u
#define EXPO 10000u

static uint8_t q[GS_PROTO_MAX_PAYLOAD + 16];

typedef struct {
    uint32_t frame, set_frame, late, dropped, backpressure, n_pixels;
    uint64_t t0, t1;
    uint16_t start, count, total, first_id;
    uint16_t seq;
} pushed;

/* Decode every FRAME message in the fake UART output (asserts they are all FRAMEs). */
static int frames_out(rig *r, pushed *out, int cap)
{
    int n = 0;
    size_t s = 0;
    for (size_t i = 0; i < r->f.out_len; i++) {
        if (r->f.out[i] != 0)
            continue;
        gs_frame f;
        assert_int_equal(gs_frame_decode(r->f.out + s, i - s, r->raw, sizeof r->raw, &f), GS_FRAME_OK);
        size_t at = s;
        s = i + 1;
        if (at == 0 && f.type != (GS_MSG_FRAME | GS_PROTO_REPLY_FLAG))
            continue; /* the reply to the last request, still in the buffer */
        assert_int_equal(f.type, GS_MSG_FRAME | GS_PROTO_REPLY_FLAG);
        assert_true(n < cap);
        const uint8_t *p = f.payload;
        pushed *o = &out[n++];
        o->seq = f.seq;
        o->frame = gs_get_u32(p + GS_FRAME_REP_FRAME);
        o->set_frame = gs_get_u32(p + GS_FRAME_REP_SET_FRAME);
        o->t0 = gs_get_u64(p + GS_FRAME_REP_T_START_US);
        o->t1 = gs_get_u64(p + GS_FRAME_REP_T_END_US);
        o->late = gs_get_u32(p + GS_FRAME_REP_LATE_SETS);
        o->dropped = gs_get_u32(p + GS_FRAME_REP_DROPPED);
        o->backpressure = gs_get_u32(p + GS_FRAME_REP_BACKPRESSURE);
        o->n_pixels = gs_get_u32(p + GS_FRAME_REP_N_PIXELS);
        o->start = gs_get_u16(p + GS_FRAME_REP_START);
        o->count = gs_get_u16(p + GS_FRAME_REP_COUNT);
        o->total = gs_get_u16(p + GS_FRAME_REP_TOTAL);
        o->first_id = o->count ? gs_get_u16(p + GS_FRAME_REP_SIZE) : 0xFFFFu;
    }
    r->f.out_len = 0;
    return n;
}

static uint32_t start_stream(rig *r, uint16_t seq, uint32_t period, uint32_t expo, uint8_t fmt, uint64_t *t_first)
{
    memset(q, 0, GS_START_STREAM_REQ_SIZE);
    gs_put_u32(q + GS_START_STREAM_REQ_PERIOD_US, period);
    gs_put_u32(q + GS_START_STREAM_REQ_EXPOSURE_US, expo);
    q[GS_START_STREAM_REQ_PIXEL_FORMAT] = fmt;
    const gs_frame *f = rig_call(r, GS_MSG_START_STREAM, seq, q, GS_START_STREAM_REQ_SIZE);
    assert_int_equal(f->type, GS_MSG_START_STREAM | GS_PROTO_REPLY_FLAG);
    assert_int_equal(gs_get_u32(f->payload + GS_START_STREAM_REP_PERIOD_US), period);
    *t_first = gs_get_u64(f->payload + GS_START_STREAM_REP_T_FIRST_US);
    return gs_get_u32(f->payload + GS_START_STREAM_REP_FIRST_FRAME);
}

/* Advance the fake clock to t and run the stream's due work. */
static void run_to(rig *r, uint64_t t)
{
    for (;;) {
        uint64_t due = gs_head_poll(&r->head);
        if (due > t)
            break;
        if (r->f.now < due)
            r->f.now = due;
    }
    if (r->f.now < t)
        r->f.now = t;
}

static uint32_t set_at(rig *r, uint16_t id, uint16_t row, uint32_t frame)
{
    uint16_t span[1][4] = {{id, row, 4, 10}};
    size_t len = spans_payload_frame(q, (const uint16_t (*)[4])span, 1, frame);
    const gs_frame *f = rig_call(r, GS_MSG_SET_WINDOWS, 40, q, len);
    assert_int_equal(f->type, GS_MSG_SET_WINDOWS | GS_PROTO_REPLY_FLAG);
    assert_int_equal(gs_get_u32(f->payload + GS_SET_WINDOWS_REP_N_PIXELS), 6);
    return gs_get_u32(f->payload + GS_SET_WINDOWS_REP_FRAME);
}

static void frames_in_sequence_on_the_timer(void **state)
{
    (void)state;
    rig *r = rig_boot(64, 48, 1);
    assert_int_equal(gs_head_poll(&r->head), UINT64_MAX);
    set_at(r, 1, 5, 0);
    uint64_t t0;
    uint32_t first = start_stream(r, 0x4242, PERIOD, EXPO, GS_PIXFMT_PACKED10, &t0);
    assert_true(first >= 1);
    assert_int_equal(r->f.expose_t_us, t0);           /* the sensor starts integrating at once */
    assert_int_equal(r->f.cfg_exposure_us, EXPO);
    r->f.out_len = 0;
    run_to(r, t0 + EXPO - 1);
    pushed got[64];
    assert_int_equal(frames_out(r, got, 64), 0);      /* nothing before the first exposure ends */
    run_to(r, t0 + 20 * PERIOD + EXPO - 1);
    int n = frames_out(r, got, 64);
    assert_int_equal(n, 20);
    for (int i = 0; i < n; i++) {
        assert_int_equal(got[i].seq, 0x4242);
        assert_int_equal(got[i].frame, first + (uint32_t)i);
        assert_int_equal(got[i].t0, t0 + (uint64_t)i * PERIOD);   /* exposures back to back */
        assert_int_equal(got[i].t1, got[i].t0 + EXPO);
        assert_int_equal(got[i].dropped, 0);
        assert_int_equal(got[i].n_pixels, 6);
        assert_int_equal(got[i].first_id, 1);
    }
    /* frame k+1 was already integrating when k was read: its exposure was announced at k's end */
    assert_int_equal(r->f.expose_t_us, t0 + 20 * PERIOD);
    /* request/response captures are refused while streaming */
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_CAPTURE, q, 0, &d), GS_ERR_STREAMING);
    assert_int_equal(rig_reject(r, GS_MSG_DARK, q, 0, &d), GS_ERR_STREAMING);
    memset(q, 0, 8);
    q[5] = 1;
    assert_int_equal(rig_reject(r, GS_MSG_FULL_FRAME, q, GS_FULL_FRAME_REQ_SIZE, &d), GS_ERR_STREAMING);
    gs_put_u32(q, 5000);
    assert_int_equal(rig_reject(r, GS_MSG_SET_EXPOSURE, q, 4, &d), GS_ERR_STREAMING);
    const gs_frame *f = rig_call(r, GS_MSG_STOP_STREAM, 9, NULL, 0);
    assert_int_equal(gs_get_u32(f->payload + GS_STOP_STREAM_REP_FRAMES), 20);
    assert_int_equal(gs_get_u32(f->payload + GS_STOP_STREAM_REP_LAST_FRAME), first + 19);
    run_to(r, r->f.now + 10 * PERIOD);
    assert_int_equal(frames_out(r, got, 64), 0);      /* nothing after STOP_STREAM */
    assert_int_equal(gs_head_poll(&r->head), UINT64_MAX);
    /* a new stream continues the frame numbers */
    uint64_t t1;
    assert_int_equal(start_stream(r, 0x4243, PERIOD, EXPO, GS_PIXFMT_U16, &t1), first + 21);
}

static void window_sets_for_named_frames_and_late_ones(void **state)
{
    (void)state;
    rig *r = rig_boot(64, 48, 1);
    set_at(r, 1, 5, 0);
    uint64_t t0;
    uint32_t k = start_stream(r, 7, PERIOD, EXPO, GS_PIXFMT_U16, &t0);
    /* two sets queued ahead (frames k+2 and k+3), as the loop does one frame ahead */
    assert_int_equal(set_at(r, 2, 6, k + 2), k + 2);
    assert_int_equal(set_at(r, 3, 7, k + 3), k + 3);
    run_to(r, t0 + 4 * PERIOD + EXPO - 1);             /* frames k .. k+3 read */
    pushed got[16];
    assert_int_equal(frames_out(r, got, 16), 4);
    assert_int_equal(got[0].first_id, 1);
    assert_int_equal(got[1].first_id, 1);
    assert_int_equal(got[2].first_id, 2);
    assert_int_equal(got[2].set_frame, k + 2);
    assert_int_equal(got[3].first_id, 3);
    assert_int_equal(got[3].set_frame, k + 3);
    assert_int_equal(got[3].late, 0);
    /* frame k+4 integrates now; a set naming k+3 (already read) is late: it applies to k+4 */
    assert_int_equal(set_at(r, 4, 8, k + 3), k + 4);
    run_to(r, t0 + 5 * PERIOD + EXPO - 1);
    assert_int_equal(frames_out(r, got, 16), 1);
    assert_int_equal(got[0].frame, k + 4);
    assert_int_equal(got[0].first_id, 4);
    assert_int_equal(got[0].set_frame, k + 3);         /* the set the host meant for k+3 */
    assert_int_equal(got[0].late, 1);
    /* a set for a later frame replaces one waiting for an equal or later frame */
    set_at(r, 5, 9, k + 8);
    set_at(r, 6, 10, k + 7);
    run_to(r, t0 + 9 * PERIOD + EXPO - 1);             /* frames k+5 .. k+8 */
    assert_int_equal(frames_out(r, got, 16), 4);
    assert_int_equal(got[1].first_id, 4);
    assert_int_equal(got[2].first_id, 6);
    assert_int_equal(got[3].first_id, 6);
    /* a rejected set changes nothing (queue and active set) */
    uint16_t bad[1][4] = {{9, 100, 0, 4}};              /* row 100 is off the 48-row sensor */
    size_t len = spans_payload_frame(q, (const uint16_t (*)[4])bad, 1, k + 10);
    uint32_t d;
    assert_int_equal(rig_reject(r, GS_MSG_SET_WINDOWS, q, len, &d), GS_ERR_SPAN_OUTSIDE);
    run_to(r, t0 + 11 * PERIOD + EXPO - 1);
    assert_int_equal(frames_out(r, got, 16), 2);
    assert_int_equal(got[1].first_id, 6);
    assert_int_equal(got[1].late, 1);
}

static void back_pressure_drops_frames_never_queues_them(void **state)
{
    (void)state;
    rig *r = rig_boot(64, 48, 1);
    set_at(r, 1, 5, 0);
    uint64_t t0;
    uint32_t k = start_stream(r, 7, PERIOD, EXPO, GS_PIXFMT_PACKED10, &t0);
    run_to(r, t0 + 2 * PERIOD + EXPO - 1);
    pushed got[16];
    assert_int_equal(frames_out(r, got, 16), 2);
    r->f.tx_backlog = GS_LIM_STREAM_TX_BACKLOG_MAX + 1; /* the link has not carried the last frames */
    run_to(r, t0 + 5 * PERIOD + EXPO - 1);
    assert_int_equal(frames_out(r, got, 16), 0);
    r->f.tx_backlog = GS_LIM_STREAM_TX_BACKLOG_MAX;     /* at the limit a frame is sent */
    run_to(r, t0 + 6 * PERIOD + EXPO - 1);
    assert_int_equal(frames_out(r, got, 16), 1);
    assert_int_equal(got[0].frame, k + 5);
    assert_int_equal(got[0].dropped, 3);
    assert_int_equal(got[0].backpressure, 3);
    /* the MCU held up for 3.5 periods: the overdue frames are dropped, not read late */
    r->f.now = t0 + 9 * PERIOD + EXPO + PERIOD / 2;
    gs_head_poll(&r->head);
    assert_int_equal(frames_out(r, got, 16), 1);        /* k+6, read late once */
    assert_int_equal(got[0].frame, k + 6);
    run_to(r, t0 + 10 * PERIOD + EXPO - 1);             /* k+9 was less than a period overdue */
    assert_int_equal(frames_out(r, got, 16), 1);
    assert_int_equal(got[0].frame, k + 9);
    assert_int_equal(got[0].dropped, 3 + 2);            /* k+7, k+8 */
    assert_int_equal(got[0].backpressure, 3);
    run_to(r, t0 + 10 * PERIOD + EXPO);
    assert_int_equal(frames_out(r, got, 16), 1);
    assert_int_equal(got[0].frame, k + 10);
    assert_int_equal(got[0].t0, t0 + 10 * PERIOD);      /* the timer grid is kept */
}

static void big_frames_come_in_parts(void **state)
{
    (void)state;
    rig *r = rig_boot(1024, 1024, 1);
    static uint16_t spans[8][4];
    for (int i = 0; i < 8; i++) {   /* four windows of 2000 px: 4 kB each in U16 */
        spans[i][0] = (uint16_t)(i / 2);
        spans[i][1] = (uint16_t)(100 + i % 2);
        spans[i][3] = 1000;
    }
    size_t len = spans_payload(q, (const uint16_t (*)[4])spans, 8);
    rig_call(r, GS_MSG_SET_WINDOWS, 1, q, len);
    uint64_t t0;
    uint32_t k = start_stream(r, 7, PERIOD, EXPO, GS_PIXFMT_U16, &t0);
    run_to(r, t0 + EXPO);
    pushed got[16];
    int n = frames_out(r, got, 16);
    assert_int_equal(n, 4);
    for (int i = 0; i < n; i++) {
        assert_int_equal(got[i].frame, k);
        assert_int_equal(got[i].start, i);
        assert_int_equal(got[i].count, 1);
        assert_int_equal(got[i].total, 4);
    }
}

static void stream_rejections(void **state)
{
    (void)state;
    rig *r = rig_boot(64, 48, 1);
    uint32_t d;
    memset(q, 0, 16);
    gs_put_u32(q, 999);
    gs_put_u32(q + 4, 500);
    assert_int_equal(rig_reject(r, GS_MSG_START_STREAM, q, GS_START_STREAM_REQ_SIZE, &d), GS_ERR_STREAM_PERIOD);
    gs_put_u32(q, 9000);
    gs_put_u32(q + 4, 9001);
    assert_int_equal(rig_reject(r, GS_MSG_START_STREAM, q, GS_START_STREAM_REQ_SIZE, &d), GS_ERR_STREAM_PERIOD);
    assert_int_equal(d, 9000);
    assert_int_equal(r->head.stream.on, 0);
}

int run_stream_tests(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(frames_in_sequence_on_the_timer),
        cmocka_unit_test(window_sets_for_named_frames_and_late_ones),
        cmocka_unit_test(back_pressure_drops_frames_never_queues_them),
        cmocka_unit_test(big_frames_come_in_parts),
        cmocka_unit_test(stream_rejections),
    };
    return cmocka_run_group_tests_name("stream", tests, NULL, NULL);
}
