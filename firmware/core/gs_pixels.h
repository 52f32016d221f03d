/* gs_pixels.h - pixel encodings on the wire (U16 little-endian, PACKED10 LSB-first). */
#ifndef GS_PIXELS_H
#define GS_PIXELS_H

#include <stddef.h>
#include <stdint.h>

/* Bytes that n pixels take in format fmt (GS_PIXFMT_*). */
size_t gs_pixels_bytes(size_t n, uint8_t fmt);
/* Encode n pixels (values already <= 1023 for PACKED10) into out; returns bytes written,
 * 0 if out (capacity cap) is too small or fmt unknown. */
size_t gs_pixels_encode(const uint16_t *px, size_t n, uint8_t fmt, uint8_t *out, size_t cap);

#endif
