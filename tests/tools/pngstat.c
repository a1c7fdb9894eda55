/* pngstat FILE.png [--bg R,G,B[,A]]
 *
 * Prints one JSON object describing where the non-background pixels of a PNG
 * are, so shell tests can check that a rendered mesh is where it should be:
 *   {"width":W,"height":H,"channels":C,"bit_depth":D,"covered":N,
 *    "bbox":[x0,y0,x1,y1] or null,"centroid":[cx,cy] or null,
 *    "center_pixel":[r,g,b,a]}
 * channels and bit_depth are the file's own (IHDR; a palette image has 1
 * channel). Pixels are compared after conversion to 8-bit RGBA (palette and
 * grey expanded, 16-bit scaled, missing alpha = 255), and center_pixel is in
 * that form. A pixel is covered when it differs from the background: by
 * default the top-left pixel's RGBA; with --bg R,G,B only R,G,B are
 * compared, with --bg R,G,B,A all four (0..255 each). bbox is inclusive,
 * in pixels, y down from the top row; centroid is the mean pixel index, so
 * a centred shape has centroid ((W-1)/2, (H-1)/2); center_pixel is the pixel
 * at (W/2, H/2). Exit status: 0 on success, 1 when FILE is not a readable,
 * valid PNG, 2 on bad usage. */
#include <png.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct image {
    FILE *f;
    png_structp png;
    png_infop info;
    uint8_t *px; /* 8-bit RGBA, top row first */
    png_bytep *rows;
    uint32_t w, h;
    int channels, depth;
    char msg[200];
} image;

static void on_error(png_structp png, png_const_charp msg)
{
    image *im = png_get_error_ptr(png);
    snprintf(im->msg, sizeof im->msg, "%s", msg);
    png_longjmp(png, 1);
}

static void on_warning(png_structp png, png_const_charp msg) {}

/* Everything that must survive the longjmp lives in *im (memory, not
 * registers), so nothing here needs to be volatile. */
static int read_png(const char *path, image *im)
{
    im->f = fopen(path, "rb");
    if (!im->f) {
        snprintf(im->msg, sizeof im->msg, "cannot open");
        return -1;
    }
    uint8_t sig[8];
    if (fread(sig, 1, 8, im->f) != 8 || png_sig_cmp(sig, 0, 8)) {
        snprintf(im->msg, sizeof im->msg, "no PNG signature");
        return -1;
    }
    im->png = png_create_read_struct(PNG_LIBPNG_VER_STRING, im, on_error, on_warning);
    if (!im->png) return -1;
    im->info = png_create_info_struct(im->png);
    if (!im->info) return -1;
    if (setjmp(png_jmpbuf(im->png))) return -1;
    png_init_io(im->png, im->f);
    png_set_sig_bytes(im->png, 8);
    png_read_info(im->png, im->info);
    im->w = png_get_image_width(im->png, im->info);
    im->h = png_get_image_height(im->png, im->info);
    im->channels = png_get_channels(im->png, im->info);
    im->depth = png_get_bit_depth(im->png, im->info);
    int type = png_get_color_type(im->png, im->info);

    png_set_expand(im->png); /* palette -> RGB, grey < 8 bits -> 8, tRNS -> alpha */
    png_set_scale_16(im->png);
    if (type == PNG_COLOR_TYPE_GRAY || type == PNG_COLOR_TYPE_GRAY_ALPHA)
        png_set_gray_to_rgb(im->png);
    png_set_add_alpha(im->png, 0xff, PNG_FILLER_AFTER); /* no-op when alpha exists */
    png_set_interlace_handling(im->png);
    png_read_update_info(im->png, im->info);
    if (png_get_rowbytes(im->png, im->info) != (size_t)im->w * 4) {
        snprintf(im->msg, sizeof im->msg, "unexpected row size after conversion");
        return -1;
    }
    im->px = malloc((size_t)im->w * im->h * 4);
    im->rows = malloc(im->h * sizeof *im->rows);
    if (!im->px || !im->rows) {
        snprintf(im->msg, sizeof im->msg, "out of memory for %ux%u pixels", im->w, im->h);
        return -1;
    }
    for (uint32_t y = 0; y < im->h; y++)
        im->rows[y] = im->px + (size_t)y * im->w * 4;
    png_read_image(im->png, im->rows);
    png_read_end(im->png, NULL);
    return 0;
}

static void image_free(image *im)
{
    if (im->png) png_destroy_read_struct(&im->png, im->info ? &im->info : NULL, NULL);
    if (im->f) fclose(im->f);
    free(im->px);
    free(im->rows);
}

static int usage(void)
{
    fprintf(stderr, "usage: pngstat FILE.png [--bg R,G,B[,A]]\n");
    return 2;
}

int main(int argc, char **argv)
{
    const char *path = NULL;
    int bg[4] = {0, 0, 0, 0}, nbg = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--bg") == 0 && i + 1 < argc) {
            char tail;
            nbg = sscanf(argv[++i], "%d,%d,%d,%d%c", &bg[0], &bg[1], &bg[2], &bg[3], &tail);
            if (nbg != 3 && nbg != 4) return usage();
            for (int k = 0; k < nbg; k++)
                if (bg[k] < 0 || bg[k] > 255) return usage();
        } else if (argv[i][0] == '-' && argv[i][1]) {
            return usage();
        } else if (!path) {
            path = argv[i];
        } else {
            return usage();
        }
    }
    if (!path) return usage();

    image im;
    memset(&im, 0, sizeof im);
    if (read_png(path, &im)) {
        fprintf(stderr, "pngstat: %s: not a valid PNG: %s\n", path, im.msg[0] ? im.msg : "?");
        image_free(&im);
        return 1;
    }
    if (nbg == 0) {
        for (int k = 0; k < 4; k++)
            bg[k] = im.px[k];
        nbg = 4;
    }

    uint64_t covered = 0;
    double sx = 0, sy = 0;
    uint32_t x0 = UINT32_MAX, y0 = UINT32_MAX, x1 = 0, y1 = 0;
    for (uint32_t y = 0; y < im.h; y++)
        for (uint32_t x = 0; x < im.w; x++) {
            const uint8_t *p = im.px + ((size_t)y * im.w + x) * 4;
            int differs = 0;
            for (int k = 0; k < nbg; k++)
                differs |= p[k] != bg[k];
            if (!differs) continue;
            covered++;
            sx += x;
            sy += y;
            if (x < x0) x0 = x;
            if (x > x1) x1 = x;
            if (y < y0) y0 = y;
            if (y > y1) y1 = y;
        }
    const uint8_t *c = im.px + ((size_t)(im.h / 2) * im.w + im.w / 2) * 4;
    printf("{\"width\":%u,\"height\":%u,\"channels\":%d,\"bit_depth\":%d,\"covered\":%llu,", im.w,
           im.h, im.channels, im.depth, (unsigned long long)covered);
    if (covered)
        printf("\"bbox\":[%u,%u,%u,%u],\"centroid\":[%.3f,%.3f],", x0, y0, x1, y1,
               sx / (double)covered, sy / (double)covered);
    else
        printf("\"bbox\":null,\"centroid\":null,");
    printf("\"center_pixel\":[%d,%d,%d,%d]}\n", c[0], c[1], c[2], c[3]);
    image_free(&im);
    return 0;
}
