/* fake_hal.c - see fake_hal.h. */
#include "fake_hal.h"

#include <stddef.h>
#include <string.h>

uint16_t fake_pixel(const fake_hal *f, uint8_t plane, uint32_t index)
{
    /* cheap hash (no division): light spans 0..2047, so about half the values saturate */
    uint32_t h = (index ^ (index >> 7)) * 2654435761u + f->frame * 40503u;
    if (plane == 1)
        return (uint16_t)(40u + (h >> 28));
    return (uint16_t)(h >> 21);
}

static uint64_t time_us(void *ctx)
{
    fake_hal *f = ctx;
    return f->now++;
}

static void sleep_until_us(void *ctx, uint64_t t)
{
    fake_hal *f = ctx;
    if (t > f->now)
        f->now = t;
}

static void uart_write(void *ctx, const uint8_t *d, size_t n)
{
    fake_hal *f = ctx;
    if (n > FAKE_OUT_CAP - f->out_len)
        n = FAKE_OUT_CAP - f->out_len;
    memcpy(f->out + f->out_len, d, n);
    f->out_len += n;
}

static size_t tx_backlog(void *ctx) { return ((fake_hal *)ctx)->tx_backlog; }

static void geometry(void *ctx, gs_sensor_geometry *g) { *g = ((fake_hal *)ctx)->geom; }

static gs_sensor_status begin(void *ctx, uint32_t *frame)
{
    fake_hal *f = ctx;
    if (f->busy_begins > 0) {
        f->busy_begins--;
        return GS_SENSOR_BUSY;
    }
    *frame = f->frame;
    return GS_SENSOR_OK;
}

static gs_sensor_status read_px(void *ctx, uint8_t plane, uint32_t index, uint16_t count, uint16_t *out)
{
    fake_hal *f = ctx;
    if (f->io_fail || plane >= f->geom.planes || (uint64_t)index + count > (uint64_t)f->geom.width * f->geom.height)
        return GS_SENSOR_IO;
    for (uint16_t i = 0; i < count; i++)
        out[i] = plane == 0 && f->image ? f->image[index + i] : fake_pixel(f, plane, index + i);
    return GS_SENSOR_OK;
}

static gs_sensor_status end(void *ctx, uint32_t frame)
{
    fake_hal *f = ctx;
    if (f->frame_changes > 0) {
        f->frame_changes--;
        f->frame++;
        return GS_SENSOR_BUSY;
    }
    return frame == f->frame ? GS_SENSOR_OK : GS_SENSOR_BUSY;
}

static void configure(void *ctx, uint32_t e, uint16_t g)
{
    fake_hal *f = ctx;
    f->cfg_exposure_us = e;
    f->cfg_gain_x16 = g;
    f->configures++;
}

static void expose(void *ctx, uint64_t t_start_us, uint32_t exposure_us)
{
    fake_hal *f = ctx;
    f->exposes++;
    f->expose_t_us = t_start_us;
    f->expose_us = exposure_us;
}

static int16_t temperature(void *ctx) { return ((fake_hal *)ctx)->temp_cdeg; }
static void kick(void *ctx) { ((fake_hal *)ctx)->kicks++; }

void fake_hal_init(fake_hal *f, gs_hal *hal, uint16_t width, uint16_t height, uint8_t planes)
{
    memset(f, 0, offsetof(fake_hal, out)); /* the output buffer itself need not be cleared */
    f->out_len = 0;
    f->now = 1000000u;
    f->geom.width = width;
    f->geom.height = height;
    f->geom.planes = planes;
    f->frame = 7;
    f->temp_cdeg = 2150;
    memset(hal, 0, sizeof *hal);
    hal->ctx = f;
    hal->port_id = 0;
    hal->time_us = time_us;
    hal->sleep_until_us = sleep_until_us;
    hal->uart_write = uart_write;
    hal->uart_tx_backlog = tx_backlog;
    hal->sensor_geometry = geometry;
    hal->sensor_begin = begin;
    hal->sensor_read = read_px;
    hal->sensor_end = end;
    hal->sensor_configure = configure;
    hal->sensor_expose = expose;
    hal->temperature_cdeg = temperature;
    hal->watchdog_kick = kick;
}
