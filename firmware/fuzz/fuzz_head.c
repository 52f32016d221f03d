/* fuzz_head.c - libFuzzer target over the frame decoder and the command dispatcher.
 *
 * Input byte 0 selects the mode, byte 1 the fake sensor (size, planes, sensor faults):
 *   mode even: the rest is raw link bytes fed to the receive stream (COBS, CRC, resync);
 *   mode odd:  the rest is a script of requests [type u8][len u16 LE][payload], each sent
 *              as a valid frame (so the dispatcher sees arbitrary payloads past the CRC);
 *              bit 1 of the mode byte flips one byte of every 7th frame; at most 64 requests;
 *              between requests the stream timer runs (type & 3) exposure ends.
 * Invariants checked after every input: every byte the head sent decodes as a valid frame
 * with the current protocol version, and the window table respects its limits.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fake_hal.h"
#include "gs_head.h"

#define FUZZ_MAX_REQUESTS 64u /* bounds the work per input (each CAPTURE reads up to 8192 px) */

static fake_hal f;
static gs_hal hal;
static gs_head head;
static uint16_t line[GS_LIM_FRAME_CHUNK_MAX];
static uint8_t raw[GS_FRAME_MAX_RAW], enc[GS_FRAME_MAX_ENCODED + 1], scratch[GS_FRAME_MAX_RAW];

static void check_output(void)
{
    size_t start = 0;
    for (size_t i = 0; i < f.out_len; i++) {
        if (f.out[i] != 0)
            continue;
        gs_frame fr;
        if (gs_frame_decode(f.out + start, i - start, raw, sizeof raw, &fr) != GS_FRAME_OK ||
            fr.version != GS_PROTO_VERSION)
            abort();
        start = i + 1;
    }
    if (head.ws.n_pixels > GS_LIM_PIXEL_BUDGET || head.ws.n_windows > GS_LIM_MAX_WINDOWS ||
        head.ws.n_spans > GS_LIM_MAX_SPANS || head.stream.n_pending > GS_LIM_STREAM_PENDING_SETS)
        abort();
    if (head.stream.on && (head.stream.period_us < head.stream.exposure_us || head.stream.frame == 0))
        abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 2)
        return 0;
    uint8_t mode = data[0], cfg = data[1];
    data += 2;
    size -= 2;
    /* the decoder on its own, including inputs with zeros inside */
    gs_frame fr;
    (void)gs_frame_decode(data, size, raw, sizeof raw, &fr);

    uint16_t width = (cfg & 0x08) ? 1024 : (uint16_t)(1 + (cfg & 0x07) * 37);
    uint16_t height = (cfg & 0x08) ? 1024 : (uint16_t)(1 + ((cfg >> 4) & 0x03) * 50);
    fake_hal_init(&f, &hal, width, height, (cfg & 0x80) ? 2 : 1);
    /* sensor faults: transient (retried) or persistent busy (SENSOR_BUSY without reading) */
    f.busy_begins = (cfg & 0x40) ? ((cfg & 0x04) ? (int)GS_SENSOR_RETRIES + 5 : 3) : 0;
    f.frame_changes = (cfg & 0x04) ? 2 : 0;
    f.io_fail = (cfg & 0x30) == 0x30;
    gs_head_init(&head, &hal, line);

    if (!(mode & 1)) {
        gs_head_rx(&head, data, size);
    } else {
        size_t pos = 0;
        unsigned k = 0;
        while (pos + 3 <= size && k < FUZZ_MAX_REQUESTS) {
            uint8_t type = data[pos];
            size_t len = (size_t)(data[pos + 1] | data[pos + 2] << 8) % (GS_PROTO_MAX_PAYLOAD + 1u);
            pos += 3;
            if (len > size - pos)
                len = size - pos;
            size_t n = gs_frame_encode(type, (uint16_t)k, data + pos, len, scratch, sizeof scratch, enc, sizeof enc);
            pos += len;
            if (n && (mode & 2) && (k + 1u) % 7u == 0)
                enc[n / 2] ^= 0x5A;
            gs_head_rx(&head, enc, n);
            /* the stream's timer between requests: the low 2 bits of the type byte pick how
             * many exposure ends pass (so START_STREAM, SET_WINDOWS for frames and FRAME
             * pushes interleave); bit 2 of the mode byte raises the UART backlog */
            f.tx_backlog = (mode & 4) ? GS_LIM_STREAM_TX_BACKLOG_MAX + (size_t)(type & 1u) : 0u;
            for (unsigned t = 0; t < (type & 3u) && f.out_len < FAKE_OUT_CAP / 2u; t++) {
                uint64_t due = gs_head_poll(&head);
                if (due == UINT64_MAX)
                    break;
                if (f.now < due)
                    f.now = due;
                gs_head_poll(&head);
            }
            k++;
        }
    }
    check_output();
    return 0;
}
