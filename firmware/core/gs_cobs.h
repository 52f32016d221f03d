/* gs_cobs.h - Consistent Overhead Byte Stuffing (0x00 delimiter not included). */
#ifndef GS_COBS_H
#define GS_COBS_H

#include <stddef.h>
#include <stdint.h>

/* Worst-case encoded size of n raw bytes. */
#define GS_COBS_MAX_ENCODED(n) ((n) + (n) / 254u + 1u)

/* Encode src[0..n) into dst (capacity cap). Returns encoded length, or 0 if it does not fit. */
size_t gs_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap);

/* Decode src[0..n) (no zero bytes) into dst (capacity cap). Returns 0 and sets *out_len on
 * success; -1 on a zero byte or a code byte running past the end; -2 if dst is too small. */
int gs_cobs_decode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap, size_t *out_len);

#endif
