/* test_codec.c - CRC-32C, COBS, frame encode/decode, receive stream, pixel packing. */
#include <string.h>

#include "gs_cobs.h"
#include "gs_crc32c.h"
#include "gs_frame.h"
#include "gs_pixels.h"
#include "test_util.h"

static void crc_check_value(void **state)
{
    (void)state;
    assert_int_equal(gs_crc32c((const uint8_t *)"123456789", 9), 0xE3069283u);
    assert_int_equal(GS_PROTO_CRC_CHECK, 0xE3069283u);
    assert_int_equal(gs_crc32c(NULL, 0), 0u);
    /* split computation equals one-shot */
    uint32_t c = gs_crc32c_update(0, (const uint8_t *)"1234", 4);
    assert_int_equal(gs_crc32c_update(c, (const uint8_t *)"56789", 5), 0xE3069283u);
}

static void cobs_roundtrip_all_lengths(void **state)
{
    (void)state;
    static uint8_t src[700], enc[720], dec[700];
    for (size_t n = 0; n <= 600; n += (n < 260 ? 1 : 17)) {
        for (size_t i = 0; i < n; i++)
            src[i] = (uint8_t)((i * 7 + n) % 5 ? (i * 13 + 1) : 0);
        size_t e = gs_cobs_encode(src, n, enc, sizeof enc);
        assert_true(e >= n + 1 && e <= GS_COBS_MAX_ENCODED(n));
        assert_null(memchr(enc, 0, e));
        size_t d = 0;
        assert_int_equal(gs_cobs_decode(enc, e, dec, sizeof dec, &d), 0);
        assert_int_equal(d, n);
        assert_memory_equal(dec, src, n);
    }
    /* 254 non-zero bytes: one full block, no trailing code byte (COBS paper) */
    for (int i = 0; i < 254; i++)
        src[i] = (uint8_t)(i + 1);
    assert_int_equal(gs_cobs_encode(src, 254, enc, sizeof enc), 255);
    assert_int_equal(enc[0], 0xFF);
}

static void cobs_rejects_bad_input(void **state)
{
    (void)state;
    uint8_t dec[16], enc[16];
    size_t d;
    const uint8_t zero_inside[] = {0x03, 0x11, 0x00};
    const uint8_t past_end[] = {0x05, 0x11, 0x22};
    const uint8_t zero_code[] = {0x00};
    assert_int_equal(gs_cobs_decode(zero_inside, 3, dec, sizeof dec, &d), -1);
    assert_int_equal(gs_cobs_decode(past_end, 3, dec, sizeof dec, &d), -1);
    assert_int_equal(gs_cobs_decode(zero_code, 1, dec, sizeof dec, &d), -1);
    const uint8_t ok[] = {0x05, 1, 2, 3, 4};
    assert_int_equal(gs_cobs_decode(ok, 5, dec, 3, &d), -2); /* destination too small */
    assert_int_equal(gs_cobs_encode(ok, 5, enc, 5), 0);       /* encoder capacity check */
}

static void frame_roundtrip_and_errors(void **state)
{
    (void)state;
    static uint8_t raw[GS_FRAME_MAX_RAW], enc[GS_FRAME_MAX_ENCODED + 1], dec[GS_FRAME_MAX_RAW];
    static uint8_t payload[GS_PROTO_MAX_PAYLOAD];
    for (size_t i = 0; i < sizeof payload; i++)
        payload[i] = (uint8_t)(i % 3 ? i : 0);
    gs_frame f;
    size_t sizes[] = {0, 1, 253, 254, GS_PROTO_MAX_PAYLOAD};
    for (size_t k = 0; k < 5; k++) {
        size_t n = gs_frame_encode(0x07, 0xABCD, payload, sizes[k], raw, sizeof raw, enc, sizeof enc);
        assert_true(n > 0);
        assert_int_equal(enc[n - 1], 0);
        assert_null(memchr(enc, 0, n - 1));
        assert_int_equal(gs_frame_decode(enc, n - 1, dec, sizeof dec, &f), GS_FRAME_OK);
        assert_int_equal(f.type, 0x07);
        assert_int_equal(f.seq, 0xABCD);
        assert_int_equal(f.payload_len, sizes[k]);
        assert_memory_equal(f.payload, payload, sizes[k]);
    }
    /* too large a payload is refused */
    assert_int_equal(gs_frame_encode(1, 1, payload, GS_PROTO_MAX_PAYLOAD + 1, raw, sizeof raw, enc, sizeof enc), 0);
    /* CRC: flip a payload bit */
    size_t n = gs_frame_encode(1, 2, (const uint8_t *)"abc", 3, raw, sizeof raw, enc, sizeof enc);
    enc[7] ^= 0x01;
    assert_int_equal(gs_frame_decode(enc, n - 1, dec, sizeof dec, &f), GS_FRAME_ERR_CRC);
    /* short: 9 raw bytes */
    uint8_t nine[9] = {1, 1, 1, 1, 1, 1, 1, 1, 1};
    n = gs_cobs_encode(nine, 9, enc, sizeof enc);
    assert_int_equal(gs_frame_decode(enc, n, dec, sizeof dec, &f), GS_FRAME_ERR_SHORT);
    /* COBS */
    const uint8_t bad[] = {0x09, 1, 2};
    assert_int_equal(gs_frame_decode(bad, 3, dec, sizeof dec, &f), GS_FRAME_ERR_COBS);
    /* decode buffer too small */
    n = gs_frame_encode(1, 2, payload, 100, raw, sizeof raw, enc, sizeof enc);
    assert_int_equal(gs_frame_decode(enc, n - 1, dec, 50, &f), GS_FRAME_ERR_TOO_BIG);
    /* length field lies but CRC is valid */
    uint8_t lie[] = {1, 1, 3, 0, 9, 0, 'a', 'b', 0, 0, 0, 0};
    uint32_t c = gs_crc32c(lie, 8);
    memcpy(lie + 8, (uint8_t[]){(uint8_t)c, (uint8_t)(c >> 8), (uint8_t)(c >> 16), (uint8_t)(c >> 24)}, 4);
    n = gs_cobs_encode(lie, sizeof lie, enc, sizeof enc);
    assert_int_equal(gs_frame_decode(enc, n, dec, sizeof dec, &f), GS_FRAME_ERR_LENGTH);
    assert_int_equal(f.length, 9);
    assert_int_equal(f.seq, 3);
}

static void rx_stream_resync_and_overrun(void **state)
{
    (void)state;
    static gs_rx_stream s;
    gs_rx_reset(&s);
    assert_int_equal(gs_rx_push(&s, 0), GS_RX_NONE); /* empty frame ignored */
    assert_int_equal(gs_rx_push(&s, 5), GS_RX_NONE);
    assert_int_equal(gs_rx_push(&s, 6), GS_RX_NONE);
    assert_int_equal(gs_rx_push(&s, 0), GS_RX_FRAME);
    assert_int_equal(s.len, 2);
    gs_rx_reset(&s);
    int overruns = 0;
    for (size_t i = 0; i < GS_FRAME_MAX_ENCODED + 100; i++)
        overruns += gs_rx_push(&s, 0x11) == GS_RX_OVERRUN;
    assert_int_equal(overruns, 1);
    assert_int_equal(gs_rx_push(&s, 0), GS_RX_NONE); /* the overlong frame ends: dropped */
    assert_int_equal(gs_rx_push(&s, 9), GS_RX_NONE);
    assert_int_equal(gs_rx_push(&s, 0), GS_RX_FRAME); /* resynchronised */
    assert_int_equal(s.len, 1);
}

static void pixel_packing(void **state)
{
    (void)state;
    const uint16_t px[5] = {1023, 0, 1, 2, 0x3FF};
    uint8_t out[16];
    assert_int_equal(gs_pixels_encode(px, 4, GS_PIXFMT_PACKED10, out, sizeof out), 5);
    const uint8_t want[5] = {0xFF, 0x03, 0x10, 0x80, 0x00}; /* hand computed, LSB-first */
    assert_memory_equal(out, want, 5);
    assert_int_equal(gs_pixels_encode(px, 5, GS_PIXFMT_PACKED10, out, sizeof out), 7);
    assert_int_equal(out[5], 0xFF);
    assert_int_equal(out[6], 0x03);
    assert_int_equal(gs_pixels_encode(px, 2, GS_PIXFMT_U16, out, sizeof out), 4);
    assert_int_equal(out[0], 0xFF);
    assert_int_equal(out[1], 0x03);
    assert_int_equal(gs_pixels_encode(px, 5, GS_PIXFMT_U16, out, 9), 0); /* capacity */
    assert_int_equal(gs_pixels_encode(px, 1, 2, out, sizeof out), 0);    /* unknown format */
    assert_int_equal(gs_pixels_bytes(9, GS_PIXFMT_PACKED10), 12);
}

int run_codec_tests(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(crc_check_value),          cmocka_unit_test(cobs_roundtrip_all_lengths),
        cmocka_unit_test(cobs_rejects_bad_input),   cmocka_unit_test(frame_roundtrip_and_errors),
        cmocka_unit_test(rx_stream_resync_and_overrun), cmocka_unit_test(pixel_packing),
    };
    return cmocka_run_group_tests_name("codec", tests, NULL, NULL);
}
