/* hal_posix.c - POSIX HAL: pty UART, mmap'd pixel file with a sequence lock, monotonic clock. */
#define _GNU_SOURCE
#include "hal_posix.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "gs_bytes.h"

uint64_t gs_posix_time_us(void *ctx)
{
    (void)ctx;
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

static void sleep_until_us(void *ctx, uint64_t t_us)
{
    (void)ctx;
    struct timespec ts = {(time_t)(t_us / 1000000u), (long)(t_us % 1000000u) * 1000L};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

static void uart_write(void *ctx, const uint8_t *data, size_t n)
{
    gs_posix *p = ctx;
    size_t done = 0;
    while (done < n) {
        ssize_t w = write(p->master, data + done, n - done);
        if (w > 0) {
            done += (size_t)w;
            continue;
        }
        if (w < 0 && errno == EINTR)
            continue;
        struct pollfd pfd = {p->master, POLLOUT, 0};
        if (w < 0 && errno == EAGAIN && poll(&pfd, 1, p->tx_timeout_ms) > 0)
            continue;
        p->tx_dropped += (uint32_t)(n - done); /* nobody is reading: drop, do not hang */
        return;
    }
}

/* Bytes written to the pty but not yet read by the other end (a paced link relay reads
 * them only as fast as the line carries them): the UART's transmit queue. */
static size_t uart_tx_backlog(void *ctx)
{
    gs_posix *p = ctx;
    int n = 0;
    if (ioctl(p->slave, FIONREAD, &n) != 0 || n < 0)
        return 0;
    return (size_t)n;
}

static uint32_t load_u32(const uint8_t *map, size_t off)
{
    uint32_t v;
    __atomic_load((const uint32_t *)(const void *)(map + off), &v, __ATOMIC_ACQUIRE);
    return v;
}

static uint64_t load_u64(const uint8_t *map, size_t off)
{
    uint64_t v;
    __atomic_load((const uint64_t *)(const void *)(map + off), &v, __ATOMIC_ACQUIRE);
    return v;
}

static void geometry(void *ctx, gs_sensor_geometry *g) { *g = ((gs_posix *)ctx)->geom; }

static void expose_drain(gs_posix *p)
{
    uint8_t buf[64];
    while (recv(p->expose_fd, buf, sizeof buf, MSG_DONTWAIT) > 0) {
    }
}

/* Exposure start: tell the sensor which exposure to render (see hal_posix.h). */
static void sensor_expose(void *ctx, uint64_t t_start_us, uint32_t exposure_us)
{
    gs_posix *p = ctx;
    if (!p->expose_on)
        return;
    expose_drain(p); /* wake-ups of earlier frames */
    p->expose_no = p->expose_no == UINT32_MAX ? 1u : p->expose_no + 1u;
    p->expose_t_us = t_start_us;
    p->expose_pending = 1;
    p->expose_late = 0;
    uint8_t msg[GS_EXPOSE_MSG_SIZE];
    memcpy(msg, GS_EXPOSE_MAGIC, 4);
    gs_put_u32(msg + 4, p->expose_no);
    gs_put_u64(msg + 8, t_start_us);
    gs_put_u32(msg + 16, exposure_us);
    ssize_t s = sendto(p->expose_fd, msg, sizeof msg, MSG_DONTWAIT, (const struct sockaddr *)&p->expose_addr,
                       p->expose_addr_len);
    if (s == (ssize_t)sizeof msg) {
        p->expose_deadline_us = t_start_us + exposure_us + p->expose_wait_us;
    } else {
        p->expose_unsent++; /* nobody renders it: readouts fail at once */
        p->expose_deadline_us = t_start_us;
    }
}

/* 1 if the stable frame (seq even, read before) was rendered for the current exposure. */
static int frame_is_current(const gs_posix *p)
{
    return load_u32(p->map, GS_PIXFILE_OFF_EXPOSURE_NO) == p->expose_no &&
           load_u64(p->map, GS_PIXFILE_OFF_EXPOSURE_T) == p->expose_t_us;
}

/* Sleep until the sensor's wake-up datagram or at most max_us (the header is the truth: a
 * writer that does not answer is still seen within one slice). */
static void expose_wait(gs_posix *p, uint64_t max_us)
{
    if (max_us > 2000u)
        max_us = 2000u;
    struct timespec ts = {0, (long)max_us * 1000L};
    struct pollfd pfd = {p->expose_fd, POLLIN, 0};
    if (ppoll(&pfd, 1, &ts, NULL) > 0)
        expose_drain(p);
}

static gs_sensor_status sensor_begin(void *ctx, uint32_t *frame)
{
    gs_posix *p = ctx;
    for (;;) {
        uint32_t seq = load_u32(p->map, GS_PIXFILE_OFF_SEQ);
        if (seq & 1u)
            return GS_SENSOR_BUSY;
        if (!p->expose_pending || frame_is_current(p)) {
            *frame = load_u32(p->map, GS_PIXFILE_OFF_FRAME);
            p->lock_seq = seq;
            return GS_SENSOR_OK;
        }
        uint64_t now = gs_posix_time_us(p);
        if (now >= p->expose_deadline_us) {
            if (!p->expose_late) {
                p->expose_late = 1;
                p->expose_timeouts++;
            }
            return GS_SENSOR_BUSY; /* the exposure's frame never came: never serve another */
        }
        expose_wait(p, p->expose_deadline_us - now);
    }
}

static gs_sensor_status sensor_read(void *ctx, uint8_t plane, uint32_t index, uint16_t count, uint16_t *out)
{
    gs_posix *p = ctx;
    uint64_t plane_px = (uint64_t)p->geom.width * p->geom.height;
    if (plane >= p->geom.planes || (uint64_t)index + count > plane_px)
        return GS_SENSOR_IO;
    const uint8_t *src = p->map + GS_PIXFILE_HEADER + 2u * (plane * plane_px + index);
    for (uint16_t i = 0; i < count; i++)
        out[i] = gs_get_u16(src + 2u * i);
    return GS_SENSOR_OK;
}

static gs_sensor_status sensor_end(void *ctx, uint32_t frame)
{
    gs_posix *p = ctx;
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    uint32_t seq = load_u32(p->map, GS_PIXFILE_OFF_SEQ);
    return (seq == p->lock_seq && load_u32(p->map, GS_PIXFILE_OFF_FRAME) == frame) ? GS_SENSOR_OK : GS_SENSOR_BUSY;
}

static int16_t temperature(void *ctx)
{
    gs_posix *p = ctx;
    return (int16_t)gs_get_u16(p->map + GS_PIXFILE_OFF_TEMP);
}

int gs_posix_sensor_open(gs_posix *p, const char *path, uint16_t width, uint16_t height, uint8_t planes,
                         char *err, size_t errlen)
{
    if (width == 0 || height == 0 || planes < 1 || planes > 2) {
        snprintf(err, errlen, "bad sensor geometry %ux%u with %u planes", width, height, planes);
        return -1;
    }
    int fd = open(path, O_RDWR);
    if (fd < 0 && errno == ENOENT) {
        fd = open(path, O_RDWR | O_CREAT | O_EXCL, 0644);
        if (fd >= 0) {
            uint8_t hdr[GS_PIXFILE_HEADER] = {0};
            memcpy(hdr, GS_PIXFILE_MAGIC, 4);
            gs_put_u16(hdr + 4, GS_PIXFILE_LAYOUT);
            gs_put_u16(hdr + 6, GS_PIXFILE_HEADER);
            gs_put_u16(hdr + 8, width);
            gs_put_u16(hdr + 10, height);
            gs_put_u16(hdr + 12, planes);
            gs_put_u16(hdr + 14, 10);
            off_t size = (off_t)(GS_PIXFILE_HEADER + 2ull * width * height * planes);
            if (pwrite(fd, hdr, sizeof hdr, 0) != (ssize_t)sizeof hdr || ftruncate(fd, size) != 0) {
                snprintf(err, errlen, "cannot create %s: %s", path, strerror(errno));
                close(fd);
                return -1;
            }
        }
    }
    if (fd < 0) {
        snprintf(err, errlen, "cannot open sensor file %s: %s", path, strerror(errno));
        return -1;
    }
    struct stat st;
    uint8_t hdr[GS_PIXFILE_HEADER];
    if (fstat(fd, &st) != 0 || st.st_size < (off_t)GS_PIXFILE_HEADER ||
        pread(fd, hdr, sizeof hdr, 0) != (ssize_t)sizeof hdr || memcmp(hdr, GS_PIXFILE_MAGIC, 4) != 0) {
        snprintf(err, errlen, "%s is not a gyrostar pixel file (magic GSPX, 64-byte header)", path);
        close(fd);
        return -1;
    }
    uint16_t fw = gs_get_u16(hdr + 8), fh = gs_get_u16(hdr + 10), fp = gs_get_u16(hdr + 12);
    if (gs_get_u16(hdr + 4) != GS_PIXFILE_LAYOUT || gs_get_u16(hdr + 6) != GS_PIXFILE_HEADER) {
        snprintf(err, errlen, "%s: unsupported pixel file layout %u / header size %u", path,
                 gs_get_u16(hdr + 4), gs_get_u16(hdr + 6));
        close(fd);
        return -1;
    }
    if (fw != width || fh != height || fp < 1 || fp > 2) {
        snprintf(err, errlen, "%s holds a %ux%u sensor with %u planes, expected %ux%u", path, fw, fh, fp, width,
                 height);
        close(fd);
        return -1;
    }
    size_t need = GS_PIXFILE_HEADER + 2u * (size_t)width * height * fp;
    if ((size_t)st.st_size < need) {
        snprintf(err, errlen, "%s is %lld bytes, its header needs %zu", path, (long long)st.st_size, need);
        close(fd);
        return -1;
    }
    void *map = mmap(NULL, need, PROT_READ, MAP_SHARED, fd, 0);
    close(fd);
    if (map == MAP_FAILED) {
        snprintf(err, errlen, "cannot mmap %s: %s", path, strerror(errno));
        return -1;
    }
    p->map = map;
    p->map_len = need;
    p->geom.width = width;
    p->geom.height = height;
    p->geom.planes = (uint8_t)fp;
    return 0;
}

void gs_posix_sensor_close(gs_posix *p)
{
    if (p->map)
        munmap(p->map, p->map_len);
    p->map = NULL;
    if (p->expose_on)
        close(p->expose_fd);
    p->expose_on = 0;
}

int gs_posix_expose_open(gs_posix *p, const char *sock_path, uint32_t wait_us, char *err, size_t errlen)
{
    size_t n = strlen(sock_path);
    if (n == 0 || n >= sizeof p->expose_addr.sun_path) {
        snprintf(err, errlen, "exposure socket path must be 1..%zu bytes", sizeof p->expose_addr.sun_path - 1);
        return -1;
    }
    int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd < 0) {
        snprintf(err, errlen, "cannot create the exposure socket: %s", strerror(errno));
        return -1;
    }
    struct sockaddr_un self;
    memset(&self, 0, sizeof self);
    self.sun_family = AF_UNIX;
    if (bind(fd, (const struct sockaddr *)&self, sizeof(sa_family_t)) != 0) { /* auto-bind */
        snprintf(err, errlen, "cannot bind the exposure socket: %s", strerror(errno));
        close(fd);
        return -1;
    }
    memset(&p->expose_addr, 0, sizeof p->expose_addr);
    p->expose_addr.sun_family = AF_UNIX;
    memcpy(p->expose_addr.sun_path, sock_path, n);
    p->expose_addr_len = (socklen_t)(offsetof(struct sockaddr_un, sun_path) + n + 1u);
    p->expose_fd = fd;
    p->expose_wait_us = wait_us;
    p->expose_no = 0;
    p->expose_pending = 0;
    p->expose_on = 1;
    return 0;
}

int gs_posix_uart_open(gs_posix *p, char *err, size_t errlen)
{
    if (openpty(&p->master, &p->slave, NULL, NULL, NULL) != 0) {
        snprintf(err, errlen, "openpty failed: %s", strerror(errno));
        return -1;
    }
    struct termios tio;
    if (tcgetattr(p->slave, &tio) == 0) {
        cfmakeraw(&tio);
        tcsetattr(p->slave, TCSANOW, &tio);
    }
    const char *name = ttyname(p->slave);
    snprintf(p->slave_path, sizeof p->slave_path, "%s", name ? name : "?");
    fcntl(p->master, F_SETFL, fcntl(p->master, F_GETFL) | O_NONBLOCK);
    p->tx_timeout_ms = 1000;
    return 0;
}

void gs_posix_hal(gs_posix *p, gs_hal *hal)
{
    memset(hal, 0, sizeof *hal);
    hal->ctx = p;
    hal->port_id = 1;
    hal->time_us = gs_posix_time_us;
    hal->sleep_until_us = sleep_until_us;
    hal->uart_write = uart_write;
    hal->uart_tx_backlog = uart_tx_backlog;
    hal->sensor_geometry = geometry;
    hal->sensor_begin = sensor_begin;
    hal->sensor_read = sensor_read;
    hal->sensor_end = sensor_end;
    hal->sensor_expose = sensor_expose;
    hal->temperature_cdeg = temperature;
}
