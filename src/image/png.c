/* PNG encoding through libpng (png.h). */
#include "image/png.h"

#include <errno.h>
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/log.h"

typedef struct png_ctx {
    char msg[200];
    int errno_at; /* errno when libpng gave up: a failed fwrite's */
} png_ctx;

/* libpng reports errors by calling this and expecting it not to return:
 * keep the message and jump back to the setjmp in vx_png_write_path. */
static void on_error(png_structp png, png_const_charp msg)
{
    png_ctx *c = png_get_error_ptr(png);
    c->errno_at = errno;
    snprintf(c->msg, sizeof c->msg, "%s", msg);
    png_longjmp(png, 1);
}

static void on_warning(png_structp png, png_const_charp msg)
{
    char q[256];
    VX_WARN("png.warning", "message=%s", vx_log_quote(q, sizeof q, msg));
}

int vx_png_write_path(const char *path, const void *pixels, int width, int height, int channels,
                      int bit_depth, vx_err *err)
{
    return vx_png_write_path_poll(path, pixels, width, height, channels, bit_depth, NULL, err);
}

int vx_png_write_path_poll(const char *path, const void *pixels, int width, int height,
                           int channels, int bit_depth, const vx_png_poll *poll, vx_err *err)
{
    if (width <= 0 || height <= 0 || channels < 1 || channels > 4 ||
        (bit_depth != 8 && bit_depth != 16))
        return vx_err_set(err, VX_EINTERNAL, "png_args",
                          "PNG %dx%d with %d channels of %d bits is not writable", width, height,
                          channels, bit_depth);
    static const int color_type[] = {PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA,
                                     PNG_COLOR_TYPE_RGB, PNG_COLOR_TYPE_RGB_ALPHA};

    /* messages name the file, not where the server keeps it (the log does) */
    const char *name = vx_path_base(path);
    FILE *f = fopen(path, "wb");
    if (!f)
        return vx_err_set(err, VX_EIO, "io_error", "cannot create %s: %s", name, strerror(errno));
    /* A failed write removes the partial file, but never a device or FIFO
     * the caller pointed us at. */
    struct stat sb;
    const int regular = fstat(fileno(f), &sb) == 0 && S_ISREG(sb.st_mode);
    png_ctx ctx = {{0}, 0};
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &ctx, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info) {
        png_destroy_write_struct(&png, NULL);
        fclose(f);
        if (regular) unlink(path);
        return vx_err_set(err, VX_EIO, "io_error", "libpng could not start writing %s", name);
    }
    /* Only f, png and info are used after a longjmp, and none of them is
     * modified after setjmp, so they need not be volatile. */
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        fclose(f);
        if (regular) unlink(path);
        VX_ERROR("png.write_failed", "path=%s", VX_Q(path));
        /* libpng's own words for a failed fwrite are "Write Error" */
        if (ctx.errno_at && !strcmp(ctx.msg, "Write Error"))
            return vx_err_set(err, VX_EIO, "io_error", "writing %s failed: %s", name,
                              strerror(ctx.errno_at));
        return vx_err_set(err, VX_EIO, "io_error", "writing %s failed: %s", name, ctx.msg);
    }
    png_init_io(png, f);
    png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, bit_depth,
                 color_type[channels - 1], PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    /* PNG stores 16-bit samples big-endian; ours are in host order. */
    if (bit_depth == 16) {
        const uint16_t probe = 1;
        if (*(const uint8_t *)&probe == 1) png_set_swap(png);
    }
    const size_t stride = (size_t)width * (size_t)channels * (size_t)(bit_depth / 8);
    size_t since = 0;
    for (int y = 0; y < height; y++) {
        png_write_row(png, (png_const_bytep)pixels + (size_t)y * stride);
        since += stride;
        if (poll && poll->fn && since >= VX_PNG_POLL_BYTES) {
            since = 0;
            if (poll->fn(poll->ud, (double)(y + 1) / height, err)) {
                png_destroy_write_struct(&png, &info);
                fclose(f);
                if (regular) unlink(path);
                return -1;
            }
        }
    }
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);

    /* Write errors (a full disk) surface at flush/close, not in fwrite. */
    int bad = ferror(f);
    if (fclose(f) != 0) bad = 1;
    if (bad) {
        int e = errno;
        if (regular) unlink(path);
        VX_ERROR("png.write_failed", "path=%s errno=%d", VX_Q(path), e);
        return vx_err_set(err, VX_EIO, "io_error", "writing %s failed: %s", name, strerror(e));
    }
    return 0;
}
