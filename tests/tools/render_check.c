/* render_check: facts about `render` job outputs for test_render.sh.
 *
 *   render_check normals NORMAL.pfm POSITION.pfm sphere CX CY CZ
 *   render_check normals NORMAL.pfm POSITION.pfm torus RMAJOR   (axis z, centre 0)
 *       {"hits":N,"mean_deg":A,"max_deg":B,"mean_dist":D}: the angle between
 *       each hit's rendered normal and the analytic normal of the exact
 *       shape at the hit's direction (sphere: normalise(hit - centre);
 *       torus: from the nearest point of the core circle), and the mean
 *       distance of the hits from the centre (sphere) or core circle.
 *   render_check pfm FILE.pfm
 *       {"width":W,"height":H,"channels":C,"nan":N}
 *   render_check panels FILE.png COLS ROWS
 *       {"covered":[..],"ink":[..]}: per panel (row-major), the pixels that
 *       differ from the panel's top-left pixel outside its label strip (the
 *       top eighth), and the dark (< 64) pixels inside that strip.
 * Exit status 1 on unreadable input, 2 on bad usage. */
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static float *read_pfm(const char *path, int *w, int *h, int *ch)
{
    FILE *f = fopen(path, "rb");
    char magic[3] = {0};
    double scale;
    if (!f || fscanf(f, "%2s %d %d %lf", magic, w, h, &scale) != 4) {
        if (f) fclose(f);
        return NULL;
    }
    fgetc(f);
    *ch = strcmp(magic, "PF") == 0 ? 3 : strcmp(magic, "Pf") == 0 ? 1 : 0;
    if (!*ch || scale >= 0 || *w <= 0 || *h <= 0) {
        fclose(f);
        return NULL;
    }
    size_t n = (size_t)*w * *h * *ch;
    float *v = malloc(sizeof(float) * n);
    /* rows bottom to top in the file; kept that way (only per-pixel use) */
    if (!v || fread(v, sizeof(float), n, f) != n) {
        free(v);
        v = NULL;
    }
    fclose(f);
    return v;
}

static int normals(int argc, char **argv)
{
    int w, h, c, w2, h2, c2;
    float *n = read_pfm(argv[2], &w, &h, &c), *p = read_pfm(argv[3], &w2, &h2, &c2);
    if (!n || !p || w != w2 || h != h2 || c != 3 || c2 != 3) return 1;
    int torus = strcmp(argv[4], "torus") == 0;
    if ((torus && argc != 6) || (!torus && argc != 8)) return 2;
    double cen[3] = {0, 0, 0}, rmaj = 0;
    if (torus)
        rmaj = atof(argv[5]);
    else
        for (int a = 0; a < 3; a++)
            cen[a] = atof(argv[5 + a]);
    double sum = 0, mx = 0, dist = 0;
    size_t hits = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) {
        const float *q = p + 3 * i, *m = n + 3 * i;
        if (isnan(q[0]) || isnan(m[0])) continue;
        double d[3];
        if (torus) {
            double rho = sqrt(q[0] * (double)q[0] + q[1] * (double)q[1]);
            d[0] = q[0] - rmaj * q[0] / rho;
            d[1] = q[1] - rmaj * q[1] / rho;
            d[2] = q[2];
        } else {
            for (int a = 0; a < 3; a++)
                d[a] = q[a] - cen[a];
        }
        double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), ml = 0, dot = 0;
        for (int a = 0; a < 3; a++) {
            ml += m[a] * (double)m[a];
            dot += m[a] * d[a];
        }
        double ang = acos(fmax(-1, fmin(1, dot / (len * sqrt(ml))))) * 180 / M_PI;
        sum += ang;
        dist += len;
        if (ang > mx) mx = ang;
        hits++;
    }
    printf("{\"hits\":%zu,\"mean_deg\":%.6f,\"max_deg\":%.6f,\"mean_dist\":%.6f}\n", hits,
           hits ? sum / hits : 0.0, mx, hits ? dist / hits : 0.0);
    free(n);
    free(p);
    return 0;
}

static int pfm(char **argv)
{
    int w, h, c;
    float *v = read_pfm(argv[2], &w, &h, &c);
    if (!v) return 1;
    size_t nan = 0;
    for (size_t i = 0; i < (size_t)w * h * c; i++)
        nan += isnan(v[i]) != 0;
    printf("{\"width\":%d,\"height\":%d,\"channels\":%d,\"nan\":%zu}\n", w, h, c, nan);
    free(v);
    return 0;
}

static int panels(char **argv)
{
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, argv[2])) return 1;
    img.format = PNG_FORMAT_RGB;
    unsigned char *px = malloc(PNG_IMAGE_SIZE(img));
    if (!px || !png_image_finish_read(&img, NULL, px, 0, NULL)) return 1;
    int cols = atoi(argv[3]), rows = atoi(argv[4]);
    if (cols < 1 || rows < 1) return 2;
    int pw = (int)img.width / cols, ph = (int)img.height / rows;
    printf("{\"covered\":[");
    for (int k = 0; k < cols * rows; k++) {
        int ox = (k % cols) * pw, oy = (k / cols) * ph;
        const unsigned char *bg = px + 3 * ((size_t)oy * img.width + ox);
        long n = 0;
        for (int y = ph / 8; y < ph; y++)
            for (int x = 0; x < pw; x++) {
                const unsigned char *q = px + 3 * ((size_t)(oy + y) * img.width + ox + x);
                n += q[0] != bg[0] || q[1] != bg[1] || q[2] != bg[2];
            }
        printf("%s%ld", k ? "," : "", n);
    }
    printf("],\"ink\":[");
    for (int k = 0; k < cols * rows; k++) {
        int ox = (k % cols) * pw, oy = (k / cols) * ph;
        long n = 0;
        for (int y = 0; y < ph / 8; y++)
            for (int x = 0; x < pw; x++) {
                const unsigned char *q = px + 3 * ((size_t)(oy + y) * img.width + ox + x);
                n += q[0] < 64 && q[1] < 64 && q[2] < 64;
            }
        printf("%s%ld", k ? "," : "", n);
    }
    printf("]}\n");
    free(px);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc >= 6 && strcmp(argv[1], "normals") == 0) return normals(argc, argv);
    if (argc == 3 && strcmp(argv[1], "pfm") == 0) return pfm(argv);
    if (argc == 5 && strcmp(argv[1], "panels") == 0) return panels(argv);
    fprintf(stderr, "usage: render_check normals|pfm|panels ...\n");
    return 2;
}
