/* gs_crc32c.h - CRC-32C (Castagnoli, reflected poly 0x82F63B78, init/xorout 0xFFFFFFFF).
 * Check value over "123456789" is 0xE3069283 (GS_PROTO_CRC_CHECK). */
#ifndef GS_CRC32C_H
#define GS_CRC32C_H

#include <stddef.h>
#include <stdint.h>

/* Continue a CRC: start with crc = 0 for a fresh computation. */
uint32_t gs_crc32c_update(uint32_t crc, const uint8_t *data, size_t len);
static inline uint32_t gs_crc32c(const uint8_t *data, size_t len) { return gs_crc32c_update(0u, data, len); }

#endif
