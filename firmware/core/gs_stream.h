/* gs_stream.h - streaming: exposures free-run on the MCU clock (frame k integrates over
 * [t_first + (k - first)·period, + exposure] and is read at its end while frame k+1
 * integrates), window sets wait in a short queue for the frame they name, and every frame
 * read is pushed unasked as FRAME messages. A frame is dropped, never queued, when the UART
 * still holds more than stream_tx_backlog_max bytes (link back-pressure). No malloc. */
#ifndef GS_STREAM_H
#define GS_STREAM_H

#include <stddef.h>
#include <stdint.h>

#include "gs_head.h"

/* START_STREAM payload q (n bytes) with seq at MCU time now: 0 and the reply in the tx
 * payload area (*len bytes), or a GS_ERR_* code with *detail. */
uint16_t gs_stream_start(gs_head *h, const uint8_t *q, size_t n, uint16_t seq, uint64_t now, size_t *len,
                         uint32_t *detail);
/* STOP_STREAM: the stream's counters into the tx payload area; returns the reply length. */
size_t gs_stream_stop(gs_head *h);
/* SET_WINDOWS during a stream: validate the n spans (wire bytes) and queue them for frame
 * `named` (0: the next readout). 0 and *applies (the first frame using them) or a GS_ERR_*
 * code with *detail; a rejected set changes nothing. */
uint16_t gs_stream_set_windows(gs_head *h, const uint8_t *wire, uint16_t n, uint32_t named, uint32_t *applies,
                               uint32_t *detail);
/* The stream's timer work due now; the next time (us) it is due, UINT64_MAX when idle. */
uint64_t gs_stream_poll(gs_head *h);

#endif
