/* semihost.c - semihosting operations SYS_OPEN/CLOSE/SEEK/READ/GET_CMDLINE/WRITE0. */
#include "semihost.h"

#include <string.h>

static int call(int op, void *arg)
{
    register int r0 __asm__("r0") = op;
    register void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

int sh_open(const char *path, int mode)
{
    uint32_t a[3] = {(uint32_t)path, (uint32_t)mode, (uint32_t)strlen(path)};
    return call(0x01, a);
}

int sh_close(int handle)
{
    uint32_t a[1] = {(uint32_t)handle};
    return call(0x02, a);
}

int sh_seek(int handle, uint32_t pos)
{
    uint32_t a[2] = {(uint32_t)handle, pos};
    return call(0x0A, a);
}

size_t sh_read(int handle, void *buf, size_t len)
{
    uint32_t a[3] = {(uint32_t)handle, (uint32_t)buf, (uint32_t)len};
    return (size_t)call(0x06, a);
}

int sh_cmdline(char *buf, size_t cap)
{
    uint32_t a[2] = {(uint32_t)buf, (uint32_t)(cap - 1u)};
    int rc = call(0x15, a);
    if (rc == 0)
        buf[a[1] < cap ? a[1] : cap - 1u] = 0;
    return rc;
}

void sh_write0(const char *s) { call(0x04, (void *)s); }
