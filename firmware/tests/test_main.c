/* test_main.c - runs every cmocka group; argv[1] is the golden vector file. */
#include <stdio.h>
#include <string.h>

#include "test_util.h"

rig g_rig;
unsigned g_codes_seen[GS_ERR_COUNT + 1];

rig *rig_boot(uint16_t width, uint16_t height, uint8_t planes)
{
    rig *r = &g_rig;
    memset(r, 0, sizeof *r);
    fake_hal_init(&r->f, &r->hal, width, height, planes);
    gs_head_init(&r->head, &r->hal, r->line);
    return r;
}

int rig_feed(rig *r, const uint8_t *bytes, size_t n)
{
    r->f.out_len = 0;
    gs_head_rx(&r->head, bytes, n);
    int frames = 0;
    for (size_t i = 0; i < r->f.out_len; i++)
        frames += r->f.out[i] == 0;
    return frames;
}

const gs_frame *rig_call(rig *r, uint8_t type, uint16_t seq, const uint8_t *payload, size_t n)
{
    static uint8_t enc[GS_FRAME_MAX_ENCODED + 1], scratch[GS_FRAME_MAX_RAW];
    size_t len = gs_frame_encode(type, seq, payload, n, scratch, sizeof scratch, enc, sizeof enc);
    assert_true(len > 0);
    assert_int_equal(rig_feed(r, enc, len), 1);
    assert_int_equal(r->f.out[r->f.out_len - 1], 0);
    assert_int_equal(gs_frame_decode(r->f.out, r->f.out_len - 1, r->raw, sizeof r->raw, &r->reply), GS_FRAME_OK);
    assert_int_equal(r->reply.seq, seq);
    assert_int_equal(r->reply.version, GS_PROTO_VERSION);
    return &r->reply;
}

uint16_t rig_reject(rig *r, uint8_t type, const uint8_t *payload, size_t n, uint32_t *detail)
{
    uint32_t rejected = r->head.cnt.rejected;
    const gs_frame *f = rig_call(r, type, 0x1234, payload, n);
    assert_int_equal(f->type, GS_MSG_ERROR);
    assert_int_equal(f->payload_len, GS_ERROR_REP_SIZE);
    assert_int_equal(f->payload[GS_ERROR_REP_REQUEST_TYPE], type);
    assert_int_equal(r->head.cnt.rejected, rejected + 1);
    uint16_t code = (uint16_t)(f->payload[0] | f->payload[1] << 8);
    if (code >= 1 && code <= GS_ERR_COUNT)
        g_codes_seen[code]++;
    assert_int_equal(r->head.cnt.last_error, code);
    if (detail)
        *detail = (uint32_t)f->payload[4] | (uint32_t)f->payload[5] << 8 | (uint32_t)f->payload[6] << 16 |
                  (uint32_t)f->payload[7] << 24;
    return code;
}

size_t spans_payload_frame(uint8_t *out, const uint16_t (*spans)[4], uint16_t n, uint32_t frame)
{
    out[0] = (uint8_t)n;
    out[1] = (uint8_t)(n >> 8);
    out[2] = out[3] = 0;
    for (int k = 0; k < 4; k++)
        out[4 + k] = (uint8_t)(frame >> (8 * k));
    for (uint16_t i = 0; i < n; i++)
        for (int k = 0; k < 4; k++) {
            out[8 + 8 * i + 2 * k] = (uint8_t)spans[i][k];
            out[8 + 8 * i + 2 * k + 1] = (uint8_t)(spans[i][k] >> 8);
        }
    return 8u + 8u * n;
}

size_t spans_payload(uint8_t *out, const uint16_t (*spans)[4], uint16_t n)
{
    return spans_payload_frame(out, spans, n, 0);
}

int main(int argc, char **argv)
{
    const char *vectors = argc > 1 ? argv[1] : "../../proto/vectors.json";
    int failed = 0;
    failed += run_codec_tests();
    failed += run_spots_tests();
    failed += run_stream_tests(); /* before head: its last test checks every error code was seen */
    failed += run_head_tests();
    failed += run_vector_tests(vectors);
    failed += run_posix_tests();
    printf("gyrostar firmware tests: %s (%d failed)\n", failed ? "FAILED" : "all passed", failed);
    return failed ? 1 : 0;
}
