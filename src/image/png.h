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

#endif
