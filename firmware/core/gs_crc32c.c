/* gs_crc32c.c - table-driven CRC-32C (1 KiB table in flash). */
#include "gs_crc32c.h"

static const uint32_t crc_table[256] = {
#define GS_C(c) ((c) & 1u ? ((c) >> 1) ^ 0x82F63B78u : (c) >> 1)
#define GS_T(n) GS_C(GS_C(GS_C(GS_C(GS_C(GS_C(GS_C(GS_C((uint32_t)(n)))))))))
#define GS_T4(n) GS_T(n), GS_T((n) + 1), GS_T((n) + 2), GS_T((n) + 3)
#define GS_T16(n) GS_T4(n), GS_T4((n) + 4), GS_T4((n) + 8), GS_T4((n) + 12)
#define GS_T64(n) GS_T16(n), GS_T16((n) + 16), GS_T16((n) + 32), GS_T16((n) + 48)
    GS_T64(0), GS_T64(64), GS_T64(128), GS_T64(192)
#undef GS_T64
#undef GS_T16
#undef GS_T4
#undef GS_T
#undef GS_C
};

uint32_t gs_crc32c_update(uint32_t crc, const uint8_t *data, size_t len)
{
    crc = ~crc;
    for (size_t i = 0; i < len; i++)
        crc = crc_table[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
    return ~crc;
}
