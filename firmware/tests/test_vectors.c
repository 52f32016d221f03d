/* test_vectors.c - the golden vectors of firmware/proto/vectors.json (shared with the
 * Python tests): CRC, COBS, framed messages, corrupt frames, a mixed stream, and exact
 * request -> reply exchanges against a freshly booted head. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gs_crc32c.h"
#include "mini_json.h"
#include "test_util.h"

#define MAX_TOK 40000
static char *js;
static size_t js_len;
static mj_tok tok[MAX_TOK];
static int ntok;
static uint8_t a[GS_FRAME_MAX_ENCODED + 64], b[GS_FRAME_MAX_ENCODED + 64], raw[GS_FRAME_MAX_RAW];

static int section(const char *name)
{
    int i = mj_get(js, tok, 0, name);
    assert_true(i > 0);
    return i;
}

static void vec_crc(void **state)
{
    (void)state;
    int arr = section("crc");
    assert_true(tok[arr].size >= 1);
    for (int k = 0; k < tok[arr].size; k++) {
        int o = mj_item(tok, arr, k);
        long n = mj_hex(js, tok, mj_get(js, tok, o, "data"), a, sizeof a);
        assert_true(n >= 0);
        assert_int_equal(gs_crc32c(a, (size_t)n), mj_u64(js, tok, mj_get(js, tok, o, "crc")));
    }
}

static void vec_cobs(void **state)
{
    (void)state;
    int arr = section("cobs");
    for (int k = 0; k < tok[arr].size; k++) {
        int o = mj_item(tok, arr, k);
        long n = mj_hex(js, tok, mj_get(js, tok, o, "raw"), a, sizeof a);
        long m = mj_hex(js, tok, mj_get(js, tok, o, "encoded"), b, sizeof b);
        uint8_t out[600];
        size_t e = gs_cobs_encode(a, (size_t)n, out, sizeof out);
        assert_int_equal(e, m);
        assert_memory_equal(out, b, (size_t)m);
        size_t d = 0;
        assert_int_equal(gs_cobs_decode(b, (size_t)m, out, sizeof out, &d), 0);
        assert_int_equal(d, n);
        assert_memory_equal(out, a, (size_t)n);
    }
}

static void vec_frames(void **state)
{
    (void)state;
    int arr = section("frames");
    for (int k = 0; k < tok[arr].size; k++) {
        int o = mj_item(tok, arr, k);
        uint8_t type = (uint8_t)mj_u64(js, tok, mj_get(js, tok, o, "type"));
        uint16_t seq = (uint16_t)mj_u64(js, tok, mj_get(js, tok, o, "seq"));
        long pn = mj_hex(js, tok, mj_get(js, tok, o, "payload"), a, sizeof a);
        long fn = mj_hex(js, tok, mj_get(js, tok, o, "frame"), b, sizeof b);
        static uint8_t out[GS_FRAME_MAX_ENCODED + 1];
        size_t n = gs_frame_encode(type, seq, a, (size_t)pn, raw, sizeof raw, out, sizeof out);
        assert_int_equal(n, fn);
        assert_memory_equal(out, b, n);
        gs_frame f;
        assert_int_equal(gs_frame_decode(b, (size_t)fn - 1, raw, sizeof raw, &f), GS_FRAME_OK);
        assert_int_equal(f.type, type);
        assert_int_equal(f.seq, seq);
        assert_int_equal(f.payload_len, pn);
        assert_memory_equal(f.payload, a, (size_t)pn);
    }
}

static void vec_corrupt(void **state)
{
    (void)state;
    int arr = section("corrupt");
    for (int k = 0; k < tok[arr].size; k++) {
        int o = mj_item(tok, arr, k);
        long n = mj_hex(js, tok, mj_get(js, tok, o, "frame"), b, sizeof b);
        int reason = mj_get(js, tok, o, "reason");
        size_t body = (size_t)n;
        if (body && b[body - 1] == 0)
            body--;
        gs_frame f;
        gs_frame_status st = gs_frame_decode(b, body, raw, sizeof raw, &f);
        if (mj_eq(js, tok, reason, "crc"))
            assert_int_equal(st, GS_FRAME_ERR_CRC);
        else if (mj_eq(js, tok, reason, "cobs"))
            assert_int_equal(st, GS_FRAME_ERR_COBS);
        else if (mj_eq(js, tok, reason, "short"))
            assert_int_equal(st, GS_FRAME_ERR_SHORT);
        else if (mj_eq(js, tok, reason, "length"))
            assert_int_equal(st, GS_FRAME_ERR_LENGTH);
        else if (mj_eq(js, tok, reason, "version")) {
            assert_int_equal(st, GS_FRAME_OK);
            assert_int_not_equal(f.version, GS_PROTO_VERSION);
        } else
            fail_msg("unknown reason in vector %d", k);
    }
}

static void vec_stream(void **state)
{
    (void)state;
    int s = section("stream");
    static uint8_t bytes[4096];
    long n = mj_hex(js, tok, mj_get(js, tok, s, "bytes"), bytes, sizeof bytes);
    int frames = mj_get(js, tok, s, "frames");
    static gs_rx_stream rx;
    gs_rx_reset(&rx);
    int good = 0, bad = 0;
    for (long i = 0; i < n; i++) {
        if (gs_rx_push(&rx, bytes[i]) != GS_RX_FRAME)
            continue;
        gs_frame f;
        if (gs_frame_decode(rx.buf, rx.len, raw, sizeof raw, &f) == GS_FRAME_OK) {
            int o = mj_item(tok, frames, good++);
            assert_int_equal(f.type, mj_u64(js, tok, mj_get(js, tok, o, "type")));
            assert_int_equal(f.seq, mj_u64(js, tok, mj_get(js, tok, o, "seq")));
            long pn = mj_hex(js, tok, mj_get(js, tok, o, "payload"), a, sizeof a);
            assert_int_equal(f.payload_len, pn);
            assert_memory_equal(f.payload, a, (size_t)pn);
        } else {
            bad++;
        }
        gs_rx_reset(&rx);
    }
    assert_int_equal(good, tok[frames].size);
    assert_int_equal(bad, mj_u64(js, tok, mj_get(js, tok, s, "corrupt")));
}

static void vec_exchanges(void **state)
{
    (void)state;
    int arr = section("exchanges");
    assert_true(tok[arr].size > 30);
    for (int k = 0; k < tok[arr].size; k++) {
        int o = mj_item(tok, arr, k);
        rig *r = rig_boot(GS_SENSOR_DEFAULT_WIDTH, GS_SENSOR_DEFAULT_HEIGHT, 2);
        long qn = mj_hex(js, tok, mj_get(js, tok, o, "request"), a, sizeof a);
        long rn = mj_hex(js, tok, mj_get(js, tok, o, "reply"), b, sizeof b);
        assert_true(qn > 0 && rn > 0);
        assert_int_equal(rig_feed(r, a, (size_t)qn), 1);
        int name = mj_get(js, tok, o, "name");
        if (r->f.out_len != (size_t)rn || memcmp(r->f.out, b, (size_t)rn) != 0)
            fail_msg("exchange '%.*s': reply differs from the golden vector", tok[name].end - tok[name].start,
                     js + tok[name].start);
    }
}

static const char *g_path;

static int load(void **state)
{
    (void)state;
    const char *path = g_path;
    FILE *fp = fopen(path, "rb");
    if (!fp) {
        fprintf(stderr, "cannot open vectors %s\n", path);
        return -1;
    }
    fseek(fp, 0, SEEK_END);
    long n = ftell(fp);
    fseek(fp, 0, SEEK_SET);
    js = malloc((size_t)n + 1); /* test harness only; the firmware never allocates */
    if (!js || fread(js, 1, (size_t)n, fp) != (size_t)n) {
        fclose(fp);
        return -1;
    }
    fclose(fp);
    js_len = (size_t)n;
    ntok = mj_parse(js, js_len, tok, MAX_TOK);
    if (ntok <= 0 || tok[0].type != MJ_OBJ) {
        fprintf(stderr, "cannot parse %s\n", path);
        return -1;
    }
    int v = mj_get(js, tok, 0, "protocol_version");
    return (v > 0 && mj_u64(js, tok, v) == GS_PROTO_VERSION) ? 0 : -1;
}

static int unload(void **state)
{
    (void)state;
    free(js);
    return 0;
}

int run_vector_tests(const char *path)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(vec_crc),     cmocka_unit_test(vec_cobs),   cmocka_unit_test(vec_frames),
        cmocka_unit_test(vec_corrupt), cmocka_unit_test(vec_stream), cmocka_unit_test(vec_exchanges),
    };
    g_path = path;
    return cmocka_run_group_tests_name("golden vectors", tests, load, unload);
}
