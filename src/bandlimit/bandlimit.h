/* Band-limited voxel shapes (seed 002, Chiba, Aoki & Saito): a solid is
 * point-sampled at resolution R, low-pass filtered, and only its N^3 lowest
 * frequencies are kept (the voxel representation); renders interpolate it
 * back by zero padding to M = L*N samples per axis, take the iso-surface
 * f = iso and shade with normals from the exact spectral gradient.
 *
 * Conventions. The sampling box is a cube of edge P (world units); sample
 * i (0..R-1 per axis) sits at box_origin + (i + 1/2) P/R. The spectrum is
 * normalised as Fourier coefficients (the unnormalised DFT divided by R^3),
 * so f~(x) = sum_k c_k H(k) exp(2 pi i k.(x - x_0)/P) with x_0 the first
 * sample, and the mean density is c_0. Kept frequencies: |k| < N/2 on every
 * axis (the Nyquist plane k = -N/2 is dropped so that f~ stays real);
 * storage is kz-major, then ky, then kx = 0..N/2-1 (the half spectrum of a
 * real function), ky and kz in FFT order (index j means k = j for j < N/2,
 * j - N above; index N/2 is always zero).
 *
 * Memory. Algorithm I (lowpass.c) holds R * N * N/2 complex floats plus a
 * few R^2 planes, never R^3 numbers; the interpolation (interp.c) goes
 * plane by plane and holds M * N * N/2 complex floats plus its output.
 * Functions are reentrant; FFTW planning is serialised internally. */
#ifndef VX_BANDLIMIT_H
#define VX_BANDLIMIT_H

#include <stddef.h>
#include <stdint.h>

#include "util/err.h"
#include "voxel/voxel.h"

typedef struct vx_bl_filter {
    double d0; /* exponential filter H = exp(-(D/d0)^n), D = |k| in frequency-index units */
    double n;
} vx_bl_filter;

/* Fills plane (R*R floats, x fastest) with the density samples of z slab
 * k; returns 0 or -1 with err (e.g. canceled). */
typedef int (*vx_bl_sample_fn)(void *ud, int k, float *plane, vx_err *err);

/* A vx_bl_sample_fn over solids from the voxel engine: the density at a
 * sample is the number of grids (all R^3, the sampling box) whose bit is
 * set there. progress (may be NULL) is called every 32 slabs with k / R. */
typedef struct vx_bl_bits {
    const vx_bitgrid *grids;
    int n;
    int (*progress)(void *ud, double fraction, vx_err *err);
    void *ud;
} vx_bl_bits;
int vx_bl_sample_bits(void *bits, int k, float *plane, vx_err *err);

typedef struct vx_bl_lowpass_stats {
    uint64_t peak_bytes; /* largest sum of buffers held at once */
    double ms;           /* FFT work (sampling callback time excluded) */
    double sample_ms;    /* time spent in the sampling callback */
} vx_bl_lowpass_stats;

/* Number of complex values of a spectrum of N (N * N * N/2). */
size_t vx_bl_spectrum_len(int N);
/* Bytes Algorithm I needs for R -> N (what lowpass reports as peak). */
uint64_t vx_bl_lowpass_bytes(int R, int N);

/* Algorithm I (seed 002 §5.1): calls sample(k) for k = 0..R-1 and returns
 * the filtered N^3 spectrum (owned, free with vx_bl_free; 2 floats per
 * complex value, layout above). R >= N, both even; nthreads FFTW threads.
 * Any thread. */
float *vx_bl_lowpass(int R, int N, const vx_bl_filter *flt, vx_bl_sample_fn sample, void *ud,
                     int nthreads, vx_bl_lowpass_stats *st, vx_err *err);
/* Keeps FFTW wisdom in DIR/fftw3f.wisdom: loaded when DIR changes, plans
 * then measured (FFTW_MEASURE: slower to make once, faster to run) and new
 * wisdom written back after planning. NULL = none, plans estimated
 * (FFTW_ESTIMATE), the default. Any thread. */
void vx_bl_wisdom_dir(const char *dir);
/* Bounds the time FFTW may take measuring each plan the calling thread
 * makes (FFTW's own time limit: past it, the best plan found so far), so
 * that a job's time limit is not overrun inside the planner. 0 = none,
 * the default. */
void vx_bl_plan_time_limit(double seconds);
/* The reference: one full R^3 real-to-complex FFT of the samples, then the
 * same selection and filter (R^3 floats + R^2 (R/2+1) complex: tests and
 * the benchmark only; always estimated, never measured). Any thread. */
float *vx_bl_lowpass_full(int R, int N, const vx_bl_filter *flt, vx_bl_sample_fn sample, void *ud,
                          int nthreads, vx_bl_lowpass_stats *st, vx_err *err);
/* Frees what the functions here allocate (fftwf_free); NULL is a no-op. */
void vx_bl_free(void *p);

/* A regular grid of samples of the band-limited density (and optionally
 * its gradient) covering the sampling box: point m (0..M-1 per axis) is at
 * origin + m * h, h = P/M, values x fastest. The grid is periodic (the
 * spectrum is); the caster does not wrap. */
typedef struct vx_bl_volume {
    int M;
    double origin[3], h;
    float *f;    /* M^3 */
    float *g[3]; /* gradient (world units) or NULL */
    float *bmax; /* per 8^3 block: max of f over the block's closure (caster) */
    float *blip; /* per block: Lipschitz bound of the trilinear f in it (caster) */
    int nb;      /* blocks per axis */
} vx_bl_volume;

/* Bytes of a volume of M (with or without the gradient). */
uint64_t vx_bl_volume_bytes(int M, int with_grad);
/* Band-limited interpolation by zero padding (seed 002 appendix), slab
 * by slab (never an M^3 complex array); with_grad also fills g from the
 * spectrum times j 2 pi k / P (the exact gradient). x0 = the position of
 * sample 0 (box origin + P/(2R)), P the box edge; M >= N, even; v->origin
 * becomes x0. Fills v (owned arrays; vx_bl_volume_free). The calling
 * thread's stop hook (util/stop.h) is polled between planes. */
int vx_bl_interp(const float *spec, int N, int M, const double x0[3], double P, int with_grad,
                 int nthreads, vx_bl_volume *v, vx_err *err);
/* Exact evaluation of the band-limited density and gradient at x (world),
 * O(N^3): the reference the tests and the 2% check use. */
double vx_bl_eval(const float *spec, int N, const double x0[3], double P, const double x[3],
                  double grad[3]);
void vx_bl_volume_free(vx_bl_volume *v);
/* Computes v->bmax and v->blip (blocks of 8 cells) for the caster; 0 or -1
 * (out of memory; the stop hook, polled per slab of blocks). */
int vx_bl_volume_blocks(vx_bl_volume *v, vx_err *err);
/* Trilinear value of f (and of g when grad != NULL and v->g is set) at
 * world point x, clamped to the grid. */
double vx_bl_volume_sample(const vx_bl_volume *v, const double x[3], double grad[3]);

/* ---- the caster (render.c) ---- */

typedef struct vx_bl_camera {
    double eye[3];                  /* perspective: the eye; orthographic: the image centre */
    double fwd[3], right[3], up[3]; /* orthonormal */
    int ortho;
    double ortho_height; /* orthographic: world extent of the image height */
    double fov_deg;      /* perspective: vertical field of view */
    double depth_add;    /* added to every depth (an orthographic eye moved nearer) */
} vx_bl_camera;

/* Per-pixel result of casting: NaN everywhere for a miss. */
typedef struct vx_bl_hits {
    int width, height;
    float *pos;   /* 3 per pixel, world */
    float *nrm;   /* 3 per pixel, world unit normal (facing the viewer's side of the surface) */
    float *depth; /* distance along the view direction from the eye plane */
} vx_bl_hits;

/* Ray through pixel (px, py) (py = 0 is the top row). */
void vx_bl_camera_ray(const vx_bl_camera *c, int width, int height, double px, double py,
                      double o[3], double d[3]);
int vx_bl_hits_alloc(vx_bl_hits *h, int width, int height, vx_err *err);
void vx_bl_hits_free(vx_bl_hits *h);
/* Casts every pixel against the iso-surface f = iso of v: steps of one
 * grid spacing from the box entry (blocks below iso are skipped whole),
 * the first sample >= iso and the one before bracket the surface, refined
 * (where the block's Lipschitz bound proves that no crossing can lie
 * within (iso - f) / bound, the walk steps that far instead of one
 * spacing, so the first crossing is the same),
 * to sub-sample accuracy on the trilinear field; normal = -gradient
 * (trilinear in v->g) when v->g is set, else left NaN for the screen-space
 * methods. Needs vx_bl_volume_blocks. nthreads CPU threads; the calling
 * thread's stop hook (util/stop.h) is polled between tiles (-1 with its
 * err). */
int vx_bl_cast(const vx_bl_volume *v, double iso, const vx_bl_camera *cam, int nthreads,
               vx_bl_hits *h, vx_err *err);

/* ---- the older normal estimators for comparison (compare.c; seed 002 §2) ---- */

typedef enum vx_bl_normals {
    VX_BL_SPECTRAL = 0, /* exact spectral gradient (the seed's method) */
    VX_BL_DEPTH_ONLY,   /* (1) brightness from depth alone */
    VX_BL_CENTRAL,      /* (2) central differences on the voxels, interpolated (Phong-style) */
    VX_BL_CROSS_MASK,   /* (3) cross mask: depth-buffer neighbours left/right x up/down */
    VX_BL_SOBEL2D,      /* (4) 2-D Sobel on the depth (position) buffer */
    VX_BL_SOBEL3D,      /* (5) 3-D Sobel on the voxels, interpolated */
    VX_BL_NORMALS_COUNT
} vx_bl_normals;
extern const char *const vx_bl_normals_names[VX_BL_NORMALS_COUNT + 1];

/* Voxel-space methods: fills v->g (owned by v) from v->f with central
 * differences or the 3-D Sobel operator (periodic). 0 or -1. */
int vx_bl_voxel_gradient(vx_bl_volume *v, vx_bl_normals method, vx_err *err);
/* Screen-space methods: fills h->nrm from h->pos (cross mask, Sobel 2-D) or
 * with the direction to the viewer (depth only). */
void vx_bl_screen_normals(vx_bl_hits *h, const vx_bl_camera *cam, vx_bl_normals method);

/* ---- shading ---- */
typedef struct vx_bl_light {
    double dir[3]; /* towards the light, world, unit */
    double color[3];
} vx_bl_light;
typedef struct vx_bl_shade_desc {
    const vx_bl_light *lights;
    int nlights;
    double ambient, color[3], background[3];
    int depth_only; /* brightness from depth instead of normals (method 1) */
} vx_bl_shade_desc;
/* Lambert + ambient into rgb (3 floats per pixel, 0..1, top row first).
 * 0, or -1 with err when the thread's stop hook (util/stop.h) says stop. */
int vx_bl_shade(const vx_bl_hits *h, const vx_bl_shade_desc *d, float *rgb, vx_err *err);
/* Draws text (lowercase letters, digits, '-') at (x, y) top-left, scale s,
 * into rgb (width w) in colour c. */
void vx_bl_label(float *rgb, int w, int h, int x, int y, int s, const char *text, const float c[3]);

#endif
