/* test_posix.c - the POSIX port's pixel file: creation, header checks, sequence lock,
 * bounds, temperature; the exposure hand-shake with the simulator; and its pseudo-terminal. */
#define _GNU_SOURCE
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "gs_bytes.h"
#include "hal_posix.h"
#include "test_util.h"

static char path[64];

static void tmp_path(void) { snprintf(path, sizeof path, "/tmp/gs-test-px-%d.raw", (int)getpid()); }

static void poke(size_t off, const void *data, size_t n)
{
    int fd = open(path, O_RDWR);
    assert_true(fd >= 0);
    assert_int_equal(pwrite(fd, data, n, (off_t)off), (ssize_t)n);
    close(fd);
}

static void pixel_file_create_and_read(void **state)
{
    (void)state;
    tmp_path();
    unlink(path);
    static gs_posix p;
    memset(&p, 0, sizeof p);
    char err[256];
    assert_int_equal(gs_posix_sensor_open(&p, path, 32, 16, 2, err, sizeof err), 0);
    struct stat st;
    assert_int_equal(stat(path, &st), 0);
    assert_int_equal(st.st_size, 64 + 2 * 32 * 16 * 2);
    gs_hal hal;
    gs_posix_hal(&p, &hal);
    gs_sensor_geometry g;
    hal.sensor_geometry(hal.ctx, &g);
    assert_int_equal(g.width, 32);
    assert_int_equal(g.planes, 2);
    /* write pixels and the header fields the way the simulator does */
    uint8_t px[4];
    gs_put_u16(px, 1000);
    gs_put_u16(px + 2, 0xFFFF);
    poke(64 + 2 * (3 * 32 + 5), px, 4);
    gs_put_u16(px, 77);
    poke(64 + 2 * 32 * 16 + 2 * 7, px, 2); /* dark plane pixel 7 */
    uint8_t hdr[4];
    gs_put_u32(hdr, 12);
    poke(GS_PIXFILE_OFF_FRAME, hdr, 4);
    gs_put_u16(hdr, (uint16_t)-250);
    poke(GS_PIXFILE_OFF_TEMP, hdr, 2);
    uint32_t frame = 0;
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_OK);
    assert_int_equal(frame, 12);
    uint16_t out[4];
    assert_int_equal(hal.sensor_read(hal.ctx, 0, 3 * 32 + 5, 2, out), GS_SENSOR_OK);
    assert_int_equal(out[0], 1000);
    assert_int_equal(out[1], 0xFFFF);
    assert_int_equal(hal.sensor_read(hal.ctx, 1, 7, 1, out), GS_SENSOR_OK);
    assert_int_equal(out[0], 77);
    assert_int_equal(hal.sensor_end(hal.ctx, frame), GS_SENSOR_OK);
    assert_int_equal(hal.temperature_cdeg(hal.ctx), -250);
    /* bounds */
    assert_int_equal(hal.sensor_read(hal.ctx, 0, 32 * 16 - 1, 2, out), GS_SENSOR_IO);
    assert_int_equal(hal.sensor_read(hal.ctx, 2, 0, 1, out), GS_SENSOR_IO);
    /* sequence lock: odd seq = writer busy; a change between begin and end is detected */
    gs_put_u32(hdr, 1);
    poke(GS_PIXFILE_OFF_SEQ, hdr, 4);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_BUSY);
    gs_put_u32(hdr, 2);
    poke(GS_PIXFILE_OFF_SEQ, hdr, 4);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_OK);
    gs_put_u32(hdr, 4);
    poke(GS_PIXFILE_OFF_SEQ, hdr, 4);
    assert_int_equal(hal.sensor_end(hal.ctx, frame), GS_SENSOR_BUSY);
    gs_posix_sensor_close(&p);
    /* reopen with the wrong geometry and a non-pixel file: clear errors */
    assert_int_equal(gs_posix_sensor_open(&p, path, 64, 16, 2, err, sizeof err), -1);
    assert_non_null(strstr(err, "32x16"));
    poke(0, "XXXX", 4);
    assert_int_equal(gs_posix_sensor_open(&p, path, 32, 16, 2, err, sizeof err), -1);
    assert_non_null(strstr(err, "not a gyrostar pixel file"));
    assert_int_equal(gs_posix_sensor_open(&p, "/nonexistent-dir/x.raw", 32, 16, 2, err, sizeof err), -1);
    unlink(path);
}

static void exposure_handshake(void **state)
{
    (void)state;
    tmp_path();
    unlink(path);
    static gs_posix p;
    memset(&p, 0, sizeof p);
    char err[256], sock_path[64];
    assert_int_equal(gs_posix_sensor_open(&p, path, 32, 16, 1, err, sizeof err), 0);
    snprintf(sock_path, sizeof sock_path, "/tmp/gs-test-sock-%d", (int)getpid());
    unlink(sock_path);
    /* the simulator's end: a datagram socket bound at the path */
    int sim = socket(AF_UNIX, SOCK_DGRAM, 0);
    assert_true(sim >= 0);
    struct sockaddr_un a;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    memcpy(a.sun_path, sock_path, strlen(sock_path));
    assert_int_equal(bind(sim, (struct sockaddr *)&a, sizeof a), 0);
    assert_int_equal(gs_posix_expose_open(&p, sock_path, 0, err, sizeof err), 0);
    gs_hal hal;
    gs_posix_hal(&p, &hal);
    uint32_t frame = 0;
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_OK); /* nothing announced yet */
    /* an exposure that started 5 ms ago and lasted 1 ms: the announcement carries it */
    uint64_t t0 = gs_posix_time_us(NULL) - 5000u;
    hal.sensor_expose(hal.ctx, t0, 1000u);
    uint8_t msg[64];
    assert_int_equal(recv(sim, msg, sizeof msg, MSG_DONTWAIT), GS_EXPOSE_MSG_SIZE);
    assert_memory_equal(msg, "GSEX", 4);
    assert_int_equal(gs_get_u32(msg + 4), 1);
    assert_int_equal(gs_get_u64(msg + 8), t0);
    assert_int_equal(gs_get_u32(msg + 16), 1000);
    /* the file still holds an older frame: past the deadline it is never served */
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_BUSY);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_BUSY);
    assert_int_equal(p.expose_timeouts, 1);
    /* a frame tagged with another exposure's start is not it either */
    uint8_t tag[12];
    gs_put_u32(tag, 1);
    gs_put_u64(tag + 4, t0 + 1);
    poke(GS_PIXFILE_OFF_EXPOSURE_NO, tag, 12);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_BUSY);
    gs_put_u64(tag + 4, t0);
    poke(GS_PIXFILE_OFF_EXPOSURE_NO, tag, 12);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_OK);
    assert_int_equal(hal.sensor_end(hal.ctx, frame), GS_SENSOR_OK);
    /* a readout during the exposure waits for its frame (here: until the deadline) */
    uint64_t t1 = gs_posix_time_us(NULL);
    hal.sensor_expose(hal.ctx, t1, 3000u);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_BUSY);
    assert_true(gs_posix_time_us(NULL) >= t1 + 3000u);
    assert_int_equal(p.expose_timeouts, 2);
    /* nobody listening: counted, and readouts fail at once */
    close(sim);
    unlink(sock_path);
    hal.sensor_expose(hal.ctx, gs_posix_time_us(NULL), 1000000u);
    assert_int_equal(p.expose_unsent, 1);
    assert_int_equal(hal.sensor_begin(hal.ctx, &frame), GS_SENSOR_BUSY);
    gs_posix_sensor_close(&p);
    char longp[200];
    memset(longp, 'x', sizeof longp - 1);
    longp[sizeof longp - 1] = 0;
    assert_int_equal(gs_posix_expose_open(&p, longp, 0, err, sizeof err), -1);
    assert_non_null(strstr(err, "exposure socket path"));
    unlink(path);
}

static void pty_round_trip(void **state)
{
    (void)state;
    static gs_posix p;
    memset(&p, 0, sizeof p);
    char err[256];
    assert_int_equal(gs_posix_uart_open(&p, err, sizeof err), 0);
    assert_non_null(strstr(p.slave_path, "/dev/pts/"));
    gs_hal hal;
    gs_posix_hal(&p, &hal);
    hal.uart_write(hal.ctx, (const uint8_t *)"hi\0", 3);
    uint8_t buf[8];
    assert_int_equal(read(p.slave, buf, sizeof buf), 3);
    assert_memory_equal(buf, "hi\0", 3); /* raw mode: bytes pass unchanged */
    uint64_t t0 = gs_posix_time_us(NULL);
    hal.sleep_until_us(hal.ctx, t0 + 2000);
    assert_true(gs_posix_time_us(NULL) >= t0 + 2000);
    close(p.master);
    close(p.slave);
}

int run_posix_tests(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(pixel_file_create_and_read),
        cmocka_unit_test(exposure_handshake),
        cmocka_unit_test(pty_round_trip),
    };
    return cmocka_run_group_tests_name("posix port", tests, NULL, NULL);
}
