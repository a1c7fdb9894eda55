/* PNG encoding through libpng. Any thread. */
#ifndef VX_PNG_H
#define VX_PNG_H

#include <stdint.h>

#include "util/err.h"

/* Writes a PNG of width x height pixels with `channels` (1..4) samples of
 * bit_depth 8 (uint8_t) or 16 (uint16_t, host order), top row first.
 * Returns 0 or -1 (VX_EIO). */
int vx_png_write_path(const char *path, const void *pixels, int width, int height, int channels,
                      int bit_depth, vx_err *err);

/* Called while a PNG is written, about every VX_PNG_POLL_BYTES of pixel
 * data, with the fraction written: returning -1 (err filled) stops the
 * writer, which removes the partial file and fails with that err. */
typedef struct vx_png_poll {
    int (*fn)(void *ud, double fraction, vx_err *err);
    void *ud;
} vx_png_poll;
#define VX_PNG_POLL_BYTES (1 << 20)

/* vx_png_write_path with a poll (NULL = none). */
int vx_png_write_path_poll(const char *path, const void *pixels, int width, int height,
                           int channels, int bit_depth, const vx_png_poll *poll, vx_err *err);

#endif
