/* hal_posix.h - POSIX port of the HAL: UART on a pseudo-terminal, sensor pixels in an
 * mmap'd file written by the simulator, CLOCK_MONOTONIC microseconds.
 *
 * Pixel file layout (all little-endian), see firmware/README.md:
 *   0  char[4] magic "GSPX"      4  u16 layout version (1)   6  u16 header size (64)
 *   8  u16 width                10  u16 height              12  u16 planes (1 or 2)
 *   14 u16 bits (10)            16  u32 seq (sequence lock: odd while the writer updates)
 *   20 u32 frame counter        24  u64 writer time of the frame (us, informative)
 *   32 i16 temperature (0.01 degC)   34..63 reserved (0)
 *   64 plane 0 (light) u16[height][width], then plane 1 (dark) if planes == 2.
 */
#ifndef HAL_POSIX_H
#define HAL_POSIX_H

#include <stddef.h>
#include <stdint.h>

#include "gs_hal.h"

#define GS_PIXFILE_MAGIC "GSPX"
#define GS_PIXFILE_LAYOUT 1u
#define GS_PIXFILE_HEADER 64u
#define GS_PIXFILE_OFF_SEQ 16u
#define GS_PIXFILE_OFF_FRAME 20u
#define GS_PIXFILE_OFF_TEMP 32u

typedef struct {
    int master;            /* pty master (our UART) */
    int slave;             /* kept open so the pty survives client reconnects */
    char slave_path[128];
    uint8_t *map;
    size_t map_len;
    gs_sensor_geometry geom;
    uint32_t lock_seq;     /* seq read by sensor_begin */
    uint32_t tx_dropped;   /* bytes dropped because nobody read the pty for tx_timeout_ms */
    int tx_timeout_ms;
} gs_posix;

/* Map the pixel file (create it, zero-filled with `planes` planes, if missing). Checks the
 * header against width/height. Returns 0, or -1 with a message in err. */
int gs_posix_sensor_open(gs_posix *p, const char *path, uint16_t width, uint16_t height, uint8_t planes,
                         char *err, size_t errlen);
void gs_posix_sensor_close(gs_posix *p);
/* Open the pseudo-terminal (raw mode). Returns 0 or -1 with a message in err. */
int gs_posix_uart_open(gs_posix *p, char *err, size_t errlen);
/* Fill a HAL table whose ctx is p. */
void gs_posix_hal(gs_posix *p, gs_hal *hal);
uint64_t gs_posix_time_us(void *ctx);

#endif
