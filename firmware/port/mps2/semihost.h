/* semihost.h - ARM semihosting calls (bkpt 0xAB) used to read the sensor array from a host
 * file under QEMU (-semihosting-config enable=on,target=native). */
#ifndef SEMIHOST_H
#define SEMIHOST_H

#include <stddef.h>
#include <stdint.h>

int sh_open(const char *path, int mode);                   /* handle or -1; mode 1 = "rb" */
int sh_close(int handle);
int sh_seek(int handle, uint32_t pos);                     /* 0 on success */
size_t sh_read(int handle, void *buf, size_t len);          /* bytes NOT read (0 = all) */
int sh_cmdline(char *buf, size_t cap);                      /* 0 on success, NUL-terminated */
void sh_write0(const char *s);                              /* debug console */

#endif
