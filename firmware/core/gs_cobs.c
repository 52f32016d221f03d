/* gs_cobs.c - COBS encoder/decoder with every length checked. */
#include "gs_cobs.h"

size_t gs_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap)
{
    if (cap < GS_COBS_MAX_ENCODED(n))
        return 0;
    size_t out = 1, code_at = 0;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (src[i] == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        } else {
            dst[out++] = src[i];
            if (++code == 0xFF) {
                dst[code_at] = code;
                if (i + 1u == n)
                    return out; /* a full block ends the data: no trailing code byte */
                code_at = out++;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    return out;
}

int gs_cobs_decode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap, size_t *out_len)
{
    size_t in = 0, out = 0;
    while (in < n) {
        uint8_t code = src[in++];
        if (code == 0)
            return -1;
        size_t run = (size_t)code - 1u;
        if (run > n - in)
            return -1;
        if (run > cap - out)
            return -2;
        for (size_t k = 0; k < run; k++) {
            if (src[in] == 0)
                return -1;
            dst[out++] = src[in++];
        }
        if (code != 0xFF && in < n) {
            if (out >= cap)
                return -2;
            dst[out++] = 0;
        }
    }
    *out_len = out;
    return 0;
}
