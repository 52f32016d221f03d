/* test_util.h - a head wired to the fake HAL, plus request/reply helpers for cmocka tests. */
#ifndef TEST_UTIL_H
#define TEST_UTIL_H

#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "fake_hal.h"
#include "gs_head.h"

typedef struct {
    fake_hal f;
    gs_hal hal;
    gs_head head;
    uint16_t line[GS_LIM_FRAME_CHUNK_MAX];
    uint8_t raw[GS_FRAME_MAX_RAW];
    gs_frame reply;
} rig;

extern rig g_rig;
/* How often rig_reject saw each error code (index = code; codes are 1..GS_ERR_COUNT). */
extern unsigned g_codes_seen[GS_ERR_COUNT + 1];

rig *rig_boot(uint16_t width, uint16_t height, uint8_t planes);
/* Send one request frame; return the reply frame (asserts exactly one frame came back). */
const gs_frame *rig_call(rig *r, uint8_t type, uint16_t seq, const uint8_t *payload, size_t n);
/* Send a request that must be rejected; returns the error code, stores detail. */
uint16_t rig_reject(rig *r, uint8_t type, const uint8_t *payload, size_t n, uint32_t *detail);
/* Feed raw bytes (any framing); returns the number of reply frames produced. */
int rig_feed(rig *r, const uint8_t *bytes, size_t n);
/* Build a span table payload for SET_WINDOWS from n rows of {id,row,c0,c1}. */
size_t spans_payload(uint8_t *out, const uint16_t (*spans)[4], uint16_t n);
/* The same, naming the stream frame the set is for. */
size_t spans_payload_frame(uint8_t *out, const uint16_t (*spans)[4], uint16_t n, uint32_t frame);

int run_codec_tests(void);
int run_head_tests(void);
int run_vector_tests(const char *path);
int run_posix_tests(void);
int run_stream_tests(void);
int run_spots_tests(void);

#endif
