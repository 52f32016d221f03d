/* hal_posix.h - POSIX port of the HAL: UART on a pseudo-terminal, sensor pixels in an
 * mmap'd file written by the simulator, CLOCK_MONOTONIC microseconds.
 *
 * Pixel file layout (all little-endian), see firmware/README.md:
 *   0  char[4] magic "GSPX"      4  u16 layout version (1)   6  u16 header size (64)
 *   8  u16 width                10  u16 height              12  u16 planes (1 or 2)
 *   14 u16 bits (10)            16  u32 seq (sequence lock: odd while the writer updates)
 *   20 u32 frame counter        24  u64 writer time of the frame (us, informative)
 *   32 i16 temperature (0.01 degC)   34 u16 reserved (0)
 *   36 u32 exposure number the frame was rendered for (0: none)
 *   40 u64 start of that exposure (us, this port's clock)   48..63 reserved (0)
 *   64 plane 0 (light) u16[height][width], then plane 1 (dark) if planes == 2.
 *
 * Exposure hand-shake (optional, gs_posix_expose_open): at each exposure start the port
 * sends the simulator's sensor a datagram on a Unix socket,
 *   0 char[4] "GSEX"   4 u32 exposure number   8 u64 t_start_us   16 u32 exposure_us
 * and the sensor renders that exposure, tags the frame with (number, t_start_us) in the
 * header and may answer any datagram to wake the port. Readouts (sensor_begin) then wait
 * for the frame carrying the current tag, until exposure end + wait_us; after that they
 * report BUSY, so CAPTURE fails with SENSOR_BUSY instead of serving another exposure.
 */
#ifndef HAL_POSIX_H
#define HAL_POSIX_H

#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>
#include <sys/un.h>

#include "gs_hal.h"

#define GS_PIXFILE_MAGIC "GSPX"
#define GS_PIXFILE_LAYOUT 1u
#define GS_PIXFILE_HEADER 64u
#define GS_PIXFILE_OFF_SEQ 16u
#define GS_PIXFILE_OFF_FRAME 20u
#define GS_PIXFILE_OFF_TEMP 32u
#define GS_PIXFILE_OFF_EXPOSURE_NO 36u
#define GS_PIXFILE_OFF_EXPOSURE_T 40u
#define GS_EXPOSE_MAGIC "GSEX"
#define GS_EXPOSE_MSG_SIZE 20u

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
    /* exposure hand-shake with the simulator (expose_on = 0: read whatever the file holds) */
    int expose_on;
    int expose_fd;             /* datagram socket, auto-bound so the sensor can answer */
    struct sockaddr_un expose_addr;
    socklen_t expose_addr_len;
    uint32_t expose_wait_us;   /* how long after the exposure end readouts wait for its frame */
    uint32_t expose_no;        /* exposures announced */
    uint64_t expose_t_us;      /* start of the current exposure */
    uint64_t expose_deadline_us;
    int expose_pending;        /* readouts must serve the current exposure's frame */
    int expose_late;           /* the current exposure's frame missed its deadline */
    uint32_t expose_timeouts;  /* exposures whose frame never came */
    uint32_t expose_unsent;    /* announcements the socket refused (no sensor listening) */
} gs_posix;

/* Map the pixel file (create it, zero-filled with `planes` planes, if missing). Checks the
 * header against width/height. Returns 0, or -1 with a message in err. */
int gs_posix_sensor_open(gs_posix *p, const char *path, uint16_t width, uint16_t height, uint8_t planes,
                         char *err, size_t errlen);
void gs_posix_sensor_close(gs_posix *p);
/* Announce every exposure to the sensor at Unix datagram socket sock_path and serve only its
 * frame (waiting up to wait_us after the exposure end). Returns 0 or -1 with a message. */
int gs_posix_expose_open(gs_posix *p, const char *sock_path, uint32_t wait_us, char *err, size_t errlen);
/* Open the pseudo-terminal (raw mode). Returns 0 or -1 with a message in err. */
int gs_posix_uart_open(gs_posix *p, char *err, size_t errlen);
/* Fill a HAL table whose ctx is p. */
void gs_posix_hal(gs_posix *p, gs_hal *hal);
uint64_t gs_posix_time_us(void *ctx);

#endif
