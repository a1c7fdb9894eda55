/* The narrow band of a bit grid's distance field (band.h).
 *
 * Along one axis, a voxel d voxels away (d > 0) is at (d - 1/2) voxels from
 * a centre: in quarter voxels squared G(d) = (2d - 1)^2, 1, 9, 25 for d = 1,
 * 2, 3. A voxel of state s is at level q when the nearest cube of state !s
 * costs G(|dx|) + G(|dy|) + G(|dz|) = q, with q < 36 (3 voxels). For each
 * row and state t, near[a] marks the voxels with a t voxel within a of them
 * along x; level q is then reached where some near[a] of the row at (dy,
 * dz) with G(a) + G(|dy|) + G(|dz|) <= q has the voxel's bit: a union of
 * 64-bit words, the terms taken in order of cost. */
#include "voxel/band.h"

#include <string.h>

const int vx_band_q[VX_BAND_LEVELS + 1] = {0, 1, 2, 3, 9, 10, 11, 18, 19, 25, 26, 27, 34, 35};

enum { NK = 8 + 2 * VX_BAND_HALF, NJ = VX_BAND_TY + 2 * VX_BAND_HALF };

/* near words of both states side by side: [0] t = 1, [1] t = 0 */
typedef uint64_t v2 __attribute__((vector_size(16)));

typedef struct term {
    int level;
    int at; /* near word a of the row at (dy, dz): 4 (dz NJ + dy) + a */
} term;

static const int G[4] = {0, 1, 9, 25};

/* The terms in order of cost, each with the level its cost is (costs are
 * exactly the levels' q). */
static int terms(term *t)
{
    int n = 0;
    for (int l = 1; l <= VX_BAND_LEVELS; l++)
        for (int a = 0; a <= 3; a++)
            for (int dz = -3; dz <= 3; dz++)
                for (int dy = -3; dy <= 3; dy++) {
                    int q = G[a] + G[dy < 0 ? -dy : dy] + G[dz < 0 ? -dz : dz];
                    if (q != vx_band_q[l]) continue;
                    t[n++] = (term){l, 4 * (dz * NJ + dy) + a};
                }
    return n;
}

int vx_band_columns(const vx_band_rows *r)
{
    return (r->dims[0] + 63) / 64 + 2;
}

/* The near words of one column for every window row (4 v2: a = 0..3),
 * their near[3] ORed over 7 rows in y (1 v2 a row of the task), then the
 * window rows' columns (W + 2 words: column -1 to W). */
size_t vx_band_scratch_bytes(const vx_band_rows *r)
{
    size_t W = (size_t)vx_band_columns(r);
    return ((size_t)NK * NJ * 4 + (size_t)NK * VX_BAND_TY) * sizeof(v2) +
           (size_t)NK * NJ * (W + 2) * sizeof(uint64_t);
}

static const uint32_t *row_of(const vx_band_rows *r, int j, int k)
{
    if (j < 0 || j >= r->dims[1] || k < 0 || k >= r->dims[2] || k < r->k0 || k >= r->k1)
        return NULL;
    return r->bits + ((size_t)(k - r->k0) * r->dims[1] + j) * r->wx;
}

unsigned vx_band_byte(const vx_band_rows *r, int i, int j, int k)
{
    const uint32_t *row = i < 0 || i >= r->dims[0] ? NULL : row_of(r, j, k);
    if (!row) return 0;
    const unsigned b = (row[i >> 5] >> (i & 31)) & 0xffu;
    return r->dims[0] - i < 8 ? b & ((1u << (r->dims[0] - i)) - 1u) : b;
}

/* Column q (x from 64 (q - 1)) of a row; 0 outside the grid. */
static uint64_t column(const vx_band_rows *r, const uint32_t *row, int q)
{
    const int nx = r->dims[0], c = q - 1;
    if (!row || c < 0 || 64 * c >= nx) return 0;
    uint64_t w = row[2 * c];
    if ((size_t)(2 * c + 1) < r->wx) w |= (uint64_t)row[2 * c + 1] << 32;
    if (nx - 64 * c < 64) w &= ((uint64_t)1 << (nx - 64 * c)) - 1;
    return w;
}

/* near[a] of a column b (a before it, d after) for both states */
static void near_of(uint64_t a, uint64_t b, uint64_t d, v2 *n)
{
    v2 A = {a, ~a}, B = {b, ~b}, D = {d, ~d};
    n[0] = B;
    n[1] = n[0] | B >> 1 | D << 63 | B << 1 | A >> 63;
    n[2] = n[1] | B >> 2 | D << 62 | B << 2 | A >> 62;
    n[3] = n[2] | B >> 3 | D << 61 | B << 3 | A >> 61;
}

void vx_band_task(const vx_band_rows *r, int z0, int y0, void *scratch, uint8_t *need, uint8_t *lev)
{
    static __thread term tt[7 * 7 * 4];
    static __thread int nt, first[VX_BAND_LEVELS + 2]; /* level l: tt[first[l] .. first[l + 1]) */
    if (!nt) {
        nt = terms(tt);
        for (int l = 1, i = 0; l <= VX_BAND_LEVELS + 1; l++) {
            first[l] = i;
            while (i < nt && tt[i].level == l)
                i++;
        }
    }
    const int W = vx_band_columns(r), WC = W + 2;
    v2 *near = scratch;                                            /* [NK * NJ][4] */
    v2 *ybox = near + (size_t)NK * NJ * 4;                         /* [NK * VX_BAND_TY] */
    uint64_t *cols = (uint64_t *)(ybox + (size_t)NK * VX_BAND_TY); /* [NK * NJ][WC] */
    for (int kk = 0; kk < NK; kk++)
        for (int jj = 0; jj < NJ; jj++) {
            const uint32_t *row = row_of(r, y0 - VX_BAND_HALF + jj, z0 - VX_BAND_HALF + kk);
            uint64_t *c = cols + (size_t)(kk * NJ + jj) * WC;
            for (int q = -1; q <= W; q++)
                c[q + 1] = column(r, row, q);
        }
    for (int p = 0; p < W; p++) {
        /* band voxels in column p have both states within 3 of them */
        uint64_t or_ = 0, and_ = ~(uint64_t)0;
        for (int w = 0; w < NK * NJ; w++) {
            const uint64_t *c = cols + (size_t)w * WC + p;
            or_ |= c[0] | c[1] | c[2];
            and_ &= c[0] & c[1] & c[2];
        }
        need[p] = or_ != 0 && and_ != ~(uint64_t)0;
        if (!need[p]) continue;
        for (int w = 0; w < NK * NJ; w++) {
            const uint64_t *c = cols + (size_t)w * WC + p;
            near_of(c[0], c[1], c[2], near + 4 * w);
        }
        for (int kk = 0; kk < NK; kk++)
            for (int y = 0; y < VX_BAND_TY; y++) {
                const v2 *n = near + 4 * (kk * NJ + y) + 3;
                v2 b = {0, 0};
                for (int dy = 0; dy <= 2 * VX_BAND_HALF; dy++, n += 4)
                    b |= *n;
                ybox[kk * VX_BAND_TY + y] = b;
            }
        for (int z = 0; z < 8; z++)
            for (int y = 0; y < VX_BAND_TY; y++) {
                const int w0 = (z + VX_BAND_HALF) * NJ + y + VX_BAND_HALF;
                const uint64_t own = cols[(size_t)w0 * WC + p + 1];
                uint8_t *out = lev + ((size_t)(z * VX_BAND_TY + y) * W + p) * 64;
                memset(out, 0, 64);
                /* the voxels with one of the other state in the 7^3 box
                 * around them: the band's voxels are among them */
                v2 box = {0, 0};
                for (int dz = 0; dz <= 2 * VX_BAND_HALF; dz++)
                    box |= ybox[(z + dz) * VX_BAND_TY + y];
                if (!((own & box[1]) | (~own & box[0]))) continue;
                /* acc[0]: a set voxel near (for unset voxels); acc[1]: an unset one */
                const v2 *n = near + 4 * w0;
                v2 acc = {0, 0};
                uint64_t done = 0;
                for (int l = 1; l <= VX_BAND_LEVELS; l++) {
                    /* a level's terms in four chains, not one: the ORs
                     * of one chain wait on each other */
                    v2 p0 = {0, 0}, p1 = p0, p2 = p0, p3 = p0;
                    int i = first[l];
                    for (; i + 4 <= first[l + 1]; i += 4) {
                        p0 |= n[tt[i].at];
                        p1 |= n[tt[i + 1].at];
                        p2 |= n[tt[i + 2].at];
                        p3 |= n[tt[i + 3].at];
                    }
                    for (; i < first[l + 1]; i++)
                        p0 |= n[tt[i].at];
                    acc |= (p0 | p1) | (p2 | p3);
                    uint64_t fresh = ((own & acc[1]) | (~own & acc[0])) & ~done;
                    done |= fresh;
                    for (; fresh; fresh &= fresh - 1)
                        out[__builtin_ctzll(fresh)] = (uint8_t)l;
                    if (done == ~(uint64_t)0) break;
                }
            }
    }
}
