/* main.c - gyrostar-head host program: the head firmware core on a pseudo-terminal.
 *
 *   gyrostar-head --sensor FILE [--width W] [--height H] [--planes 1|2] [--link PATH]
 *                 [--expose-socket PATH [--expose-wait-ms N]] [--exit-with-parent]
 *
 * Prints "gyrostar-head: pty <slave path>" on stdout once the UART is up; with --link
 * it also makes PATH a symlink to the pty (removed on exit; an existing PATH that is not a
 * symlink is refused). SIGINT/SIGTERM exit cleanly. Exit 0; 2 for bad arguments or files
 * (usage, sensor file, link path); 3 when the pty cannot be opened.
 * --exit-with-parent: exit when the launching process dies (checked every 0.5 s idle), so a
 * killed test or flatsat runner never leaves a host program behind.
 * --expose-socket: announce each exposure start to the simulator's sensor listening on that
 * Unix datagram socket and read only the frame it renders for it (hal_posix.h), waiting up
 * to --expose-wait-ms (default 200) after the exposure end; the counts go to stderr on exit.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "gs_head.h"
#include "hal_posix.h"

static gs_head g_head;
static uint16_t g_line[GS_LIM_FRAME_CHUNK_MAX];
static gs_posix g_port;
static volatile sig_atomic_t g_stop;

static void on_signal(int sig) { (void)sig; g_stop = 1; }

static int usage(const char *msg)
{
    fprintf(stderr, "gyrostar-head: %s\nusage: gyrostar-head --sensor FILE [--width W] [--height H] "
                    "[--planes 1|2] [--link PATH] [--expose-socket PATH [--expose-wait-ms N]] "
                    "[--exit-with-parent]\n", msg);
    return 2;
}

static int parse_u16(const char *s, uint16_t *out)
{
    char *end = NULL;
    errno = 0;
    unsigned long v = strtoul(s, &end, 10);
    if (errno || !end || *end || v == 0 || v > 65535u)
        return -1;
    *out = (uint16_t)v;
    return 0;
}

int main(int argc, char **argv)
{
    const char *sensor = NULL, *link = NULL, *expose = NULL;
    uint16_t expose_wait_ms = 200;
    pid_t watch_parent = 0;
    uint16_t width = GS_SENSOR_DEFAULT_WIDTH, height = GS_SENSOR_DEFAULT_HEIGHT, planes = 2;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--exit-with-parent")) {
            watch_parent = getppid();
            continue;
        }
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage("camera-head firmware, host build");
            return 0;
        }
        if (!v)
            return usage("missing value after an option");
        if (!strcmp(a, "--sensor"))
            sensor = v;
        else if (!strcmp(a, "--link"))
            link = v;
        else if (!strcmp(a, "--expose-socket"))
            expose = v;
        else if (!strcmp(a, "--expose-wait-ms")) {
            if (parse_u16(v, &expose_wait_ms))
                return usage("--expose-wait-ms needs 1..65535");
        }
        else if (!strcmp(a, "--width")) {
            if (parse_u16(v, &width))
                return usage("--width needs 1..65535");
        } else if (!strcmp(a, "--height")) {
            if (parse_u16(v, &height))
                return usage("--height needs 1..65535");
        } else if (!strcmp(a, "--planes")) {
            if (parse_u16(v, &planes) || planes > 2)
                return usage("--planes needs 1 or 2");
        } else
            return usage("unknown option");
        i++;
    }
    if (!sensor)
        return usage("--sensor FILE is required");
    struct stat st;
    if (link && lstat(link, &st) == 0 && !S_ISLNK(st.st_mode)) {
        /* only a stale link of an earlier run is replaced, never a file or folder */
        fprintf(stderr, "gyrostar-head: --link %s exists and is not a symlink: not replaced\n", link);
        return 2;
    }
    char err[256];
    if (gs_posix_sensor_open(&g_port, sensor, width, height, (uint8_t)planes, err, sizeof err) ||
        (expose && gs_posix_expose_open(&g_port, expose, 1000u * expose_wait_ms, err, sizeof err))) {
        fprintf(stderr, "gyrostar-head: %s\n", err);
        return 2; /* the files it was given: a usage error */
    }
    if (gs_posix_uart_open(&g_port, err, sizeof err)) {
        fprintf(stderr, "gyrostar-head: %s\n", err);
        return 3; /* the pty: a device error */
    }
    if (link) {
        unlink(link); /* a stale link from an earlier run (checked above: a symlink or nothing) */
        if (symlink(g_port.slave_path, link) != 0) {
            fprintf(stderr, "gyrostar-head: cannot create link %s: %s\n", link, strerror(errno));
            gs_posix_sensor_close(&g_port);
            return 2;
        }
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    gs_hal hal;
    gs_posix_hal(&g_port, &hal);
    gs_head_init(&g_head, &hal, g_line);
    printf("gyrostar-head: pty %s\n", g_port.slave_path);
    fflush(stdout);

    uint8_t buf[4096];
    uint32_t dropped = 0;
    while (!g_stop) {
        struct pollfd pfd = {g_port.master, POLLIN, 0};
        uint64_t due = gs_head_poll(&g_head); /* stream timer work; next due time */
        uint64_t wait_us = 500000u, now = gs_posix_time_us(&g_port);
        if (due != UINT64_MAX)
            wait_us = due > now ? (due - now < wait_us ? due - now : wait_us) : 0u;
        struct timespec ts = {(time_t)(wait_us / 1000000u), (long)(wait_us % 1000000u) * 1000L};
        int r = ppoll(&pfd, 1, &ts, NULL);
        if (r < 0 && errno != EINTR)
            break;
        if (r == 0 && watch_parent > 0 && getppid() != watch_parent)
            break; /* the launcher died: we were re-parented */
        if (r <= 0 || !(pfd.revents & POLLIN))
            continue;
        ssize_t n = read(g_port.master, buf, sizeof buf);
        if (n > 0)
            gs_head_rx(&g_head, buf, (size_t)n);
        if (g_port.tx_dropped != dropped) { /* a stalled reader lost replies */
            dropped = g_port.tx_dropped;
            gs_head_note_overrun(&g_head);
        }
    }
    if (link)
        unlink(link);
    if (g_port.expose_on)
        fprintf(stderr, "gyrostar-head: %u exposures, %u frames late, %u announcements unsent\n",
                g_port.expose_no, g_port.expose_timeouts, g_port.expose_unsent);
    gs_posix_sensor_close(&g_port);
    return 0;
}
