/* gs_frame.c - frame encode/decode and the receive stream splitter. */
#include "gs_frame.h"

#include <string.h>

#include "gs_bytes.h"
#include "gs_crc32c.h"

gs_frame_status gs_frame_decode(const uint8_t *enc, size_t n, uint8_t *raw, size_t raw_cap, gs_frame *f)
{
    size_t len = 0;
    int rc = gs_cobs_decode(enc, n, raw, raw_cap, &len);
    if (rc == -2)
        return GS_FRAME_ERR_TOO_BIG;
    if (rc != 0)
        return GS_FRAME_ERR_COBS;
    if (len < GS_PROTO_HEADER_SIZE + GS_PROTO_CRC_SIZE)
        return GS_FRAME_ERR_SHORT;
    size_t body = len - GS_PROTO_CRC_SIZE;
    if (gs_crc32c(raw, body) != gs_get_u32(raw + body))
        return GS_FRAME_ERR_CRC;
    f->version = raw[0];
    f->type = raw[1];
    f->seq = gs_get_u16(raw + 2);
    f->length = gs_get_u16(raw + 4);
    f->payload = raw + GS_PROTO_HEADER_SIZE;
    f->payload_len = body - GS_PROTO_HEADER_SIZE;
    return f->length == f->payload_len ? GS_FRAME_OK : GS_FRAME_ERR_LENGTH;
}

size_t gs_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, size_t len,
                       uint8_t *raw, size_t raw_cap, uint8_t *out, size_t cap)
{
    if (len > GS_PROTO_MAX_PAYLOAD || raw_cap < GS_PROTO_HEADER_SIZE + len + GS_PROTO_CRC_SIZE)
        return 0;
    raw[0] = (uint8_t)GS_PROTO_VERSION;
    raw[1] = type;
    gs_put_u16(raw + 2, seq);
    gs_put_u16(raw + 4, (uint16_t)len);
    if (len && payload != raw + GS_PROTO_HEADER_SIZE)
        memmove(raw + GS_PROTO_HEADER_SIZE, payload, len);
    size_t body = GS_PROTO_HEADER_SIZE + len;
    gs_put_u32(raw + body, gs_crc32c(raw, body));
    if (cap < 1)
        return 0;
    size_t n = gs_cobs_encode(raw, body + GS_PROTO_CRC_SIZE, out, cap - 1u);
    if (n == 0)
        return 0;
    out[n] = 0;
    return n + 1u;
}

void gs_rx_reset(gs_rx_stream *s)
{
    s->len = 0;
    s->discarding = 0;
}

gs_rx_event gs_rx_push(gs_rx_stream *s, uint8_t byte)
{
    if (byte == 0) {
        if (s->discarding) {
            gs_rx_reset(s);
            return GS_RX_NONE;
        }
        return s->len ? GS_RX_FRAME : GS_RX_NONE;
    }
    if (s->discarding)
        return GS_RX_NONE;
    if (s->len >= sizeof s->buf) {
        s->discarding = 1;
        s->len = 0;
        return GS_RX_OVERRUN;
    }
    s->buf[s->len++] = byte;
    return GS_RX_NONE;
}
