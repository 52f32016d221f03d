/* gs_pixels.c - pixel packing. PACKED10: pixel i occupies bits [10i, 10i+10) of an
 * LSB-first bit stream (4 pixels in 5 bytes). */
#include "gs_pixels.h"

#include "gs_bytes.h"
#include "gs_proto_defs.h"

size_t gs_pixels_bytes(size_t n, uint8_t fmt)
{
    return fmt == GS_PIXFMT_U16 ? 2u * n : (10u * n + 7u) / 8u;
}

size_t gs_pixels_encode(const uint16_t *px, size_t n, uint8_t fmt, uint8_t *out, size_t cap)
{
    if (fmt > GS_PIXFMT_PACKED10 || gs_pixels_bytes(n, fmt) > cap)
        return 0;
    if (fmt == GS_PIXFMT_U16) {
        for (size_t i = 0; i < n; i++)
            gs_put_u16(out + 2u * i, px[i]);
        return 2u * n;
    }
    uint32_t acc = 0;
    unsigned bits = 0;
    size_t o = 0;
    for (size_t i = 0; i < n; i++) {
        acc |= (uint32_t)(px[i] & 0x3FFu) << bits;
        bits += 10u;
        while (bits >= 8u) {
            out[o++] = (uint8_t)acc;
            acc >>= 8;
            bits -= 8u;
        }
    }
    if (bits)
        out[o++] = (uint8_t)acc;
    return o;
}
