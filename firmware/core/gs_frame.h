/* gs_frame.h - link frames: COBS(header || payload || CRC-32C) + 0x00, and the
 * receive-side stream splitter. Header: version u8, type u8, seq u16, length u16 (LE). */
#ifndef GS_FRAME_H
#define GS_FRAME_H

#include <stddef.h>
#include <stdint.h>

#include "gs_cobs.h"
#include "gs_proto_defs.h"

#define GS_FRAME_MAX_RAW (GS_PROTO_HEADER_SIZE + GS_PROTO_MAX_PAYLOAD + GS_PROTO_CRC_SIZE)
#define GS_FRAME_MAX_ENCODED GS_COBS_MAX_ENCODED(GS_FRAME_MAX_RAW)

typedef enum {
    GS_FRAME_OK = 0,
    GS_FRAME_ERR_COBS = -1,    /* bad COBS code / zero inside the frame */
    GS_FRAME_ERR_SHORT = -2,   /* shorter than header + CRC */
    GS_FRAME_ERR_CRC = -3,     /* CRC-32C mismatch */
    GS_FRAME_ERR_LENGTH = -4,  /* header length disagrees with payload bytes (CRC valid) */
    GS_FRAME_ERR_TOO_BIG = -5  /* larger than the receive buffer */
} gs_frame_status;

typedef struct {
    uint8_t version;
    uint8_t type;
    uint16_t seq;
    uint16_t length;        /* header length field */
    const uint8_t *payload; /* points into the caller's raw buffer */
    size_t payload_len;     /* payload bytes actually present */
} gs_frame;

/* Decode one encoded frame (delimiter excluded) using raw[0..raw_cap) as scratch.
 * GS_FRAME_ERR_LENGTH still fills *f (CRC was valid, so the header can be trusted). */
gs_frame_status gs_frame_decode(const uint8_t *enc, size_t n, uint8_t *raw, size_t raw_cap, gs_frame *f);

/* Encode a frame with trailing 0x00 into out (capacity cap), using raw[0..raw_cap) as
 * scratch where header+payload+CRC are assembled. Returns bytes written, 0 if it does not fit. */
size_t gs_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, size_t len,
                       uint8_t *raw, size_t raw_cap, uint8_t *out, size_t cap);

/* Stream splitter: collects bytes until 0x00; too-long frames are discarded to the next 0x00. */
typedef struct {
    uint8_t buf[GS_FRAME_MAX_ENCODED];
    size_t len;
    uint8_t discarding;
} gs_rx_stream;

typedef enum { GS_RX_NONE = 0, GS_RX_FRAME = 1, GS_RX_OVERRUN = 2 } gs_rx_event;

void gs_rx_reset(gs_rx_stream *s);
/* Push one byte. GS_RX_FRAME: buf[0..len) holds a complete encoded frame (consume it, then
 * call gs_rx_reset). GS_RX_OVERRUN: the frame under way exceeded the buffer and is dropped. */
gs_rx_event gs_rx_push(gs_rx_stream *s, uint8_t byte);

#endif
