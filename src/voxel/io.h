/* Writers for voxelize's outputs: raw8, raw1 (io.c), binvox (binvox.c) and OpenVDB
 * (vdb.cc, the only C++ file; OpenVDB's templates stay behind this C API).
 *
 * Layouts (n = nx * ny * nz, voxel (i,j,k) has linear index
 * i + nx * (j + ny * k), that is x fastest, then y, then z):
 *   raw8    n bytes, 0 or 1, in linear-index order; no header.
 *   raw1    ceil(n / 8) bytes: voxel with linear index L is bit L % 8 (least
 *           significant first) of byte L / 8, packed continuously (rows are
 *           not padded); the unused high bits of the last byte are 0.
 *   binvox  the binvox 1 format: ASCII header "#binvox 1", "dim d d d",
 *           "translate x y z", "scale s", "data", then (value, count) byte
 *           pairs (count 1..255) in binvox's order, where y runs fastest:
 *           index = i * d * d + k * d + j with binvox (x, y, z) = grid
 *           (i, j, k) (no axis swap). binvox grids are cubes: d is the
 *           largest of nx, ny, nz and the other axes are padded with empty
 *           voxels at their high end, so translate = origin and
 *           scale = d * h keep voxel (i,j,k) where it is in the grid.
 *   vdb     an OpenVDB file with one grid, by vx_vdb_class: a level set
 *           FloatGrid "surface" (grid class level set: the narrow-band
 *           signed distance, 3 voxels each side, to the boundary between set
 *           and unset voxels, exact (band.h); negative inside, background
 *           3 h), a fog FloatGrid "density" (1 inside,
 *           active, background 0) or, with sample counts, "coverage"
 *           (samples inside / samples per voxel, active where > 0), or a
 *           BoolGrid "voxels" (active and true = inside). Index (i,j,k) maps
 *           to the voxel centre: transform = uniform scale h then
 *           translation origin + h/2. Grid metadata carries the job
 *           parameters. Fully set 8^3 leaves are stored as tiles.
 *   nrrd    an NRRD 0004 header (type uint8, sizes nx ny nz, space
 *           directions h along each axis, space origin = voxel (0,0,0)'s
 *           centre, encoding raw), a blank line, then the raw8 body.
 *   npy     NumPy's .npy 1.0: dtype |u1, shape (nx, ny, nz), Fortran order
 *           (so a[i, j, k] is voxel (i,j,k)), then the raw8 body.
 *   vox     MagicaVoxel 150: the grid in bricks of 256^3 (the format's
 *           model limit), one SIZE + XYZI model (colour index 1) per brick
 *           that holds voxels, and a scene graph (nTRN 0 -> nGRP 1 -> per
 *           model nTRN -> nSHP) whose translation t = brick origin +
 *           floor(size / 2) puts model voxel v at grid index
 *           t + v - floor(size / 2). VX_ETOOBIG vox_too_large past 2^31
 *           bytes (the format's 32-bit chunk sizes).
 * All writers write to a temporary name beside path and rename, so a
 * failed write leaves no partial file at path. */
#ifndef VX_VOXEL_IO_H
#define VX_VOXEL_IO_H

#include "voxel/voxel.h"

/* The trees a .vdb writer made, kept past the write (vx_voxel_io.vdb_keep). */
typedef struct vx_vdb_tree vx_vdb_tree;

/* Progress/cancel hook for long writes: called with 0..1 between z slabs;
 * a nonzero return stops the write (err filled by the callee). */
typedef struct vx_voxel_io {
    int (*progress)(void *ud, double fraction, vx_err *err);
    void *ud;
    /* binvox: bytes of transposed columns per group of 32-column blocks
     * (0 = 16 MiB; at least one block): smaller groups read the grid more
     * often, larger ones take more memory (twice this). */
    size_t binvox_group_bytes;
    /* binvox: bytes the fast coder's event lists may take (0 = a quarter of
     * the bit grid's, at least 4 MiB); past them the grid is coded again
     * from transposed columns instead (binvox.c). */
    size_t binvox_event_bytes;
    /* vdb: not NULL: once the file is in place the writer leaves its tree
     * in *vdb_keep (NULL if it failed before) for the caller to free with
     * vx_vdb_tree_free, whatever the writer returns: freeing is off the
     * write's path (a level set's 68,000 float leaves at 1024^3 take
     * 20 ms), and the memory stays the caller's until then. NULL: the
     * writer frees it before returning. */
    vx_vdb_tree **vdb_keep;
} vx_voxel_io;

/* Frees a tree a vdb writer kept (NULL is fine). */
void vx_vdb_tree_free(vx_vdb_tree *t);
/* Bytes the kept tree t holds in memory (OpenVDB's memUsage of its grids). */
uint64_t vx_vdb_tree_bytes(const vx_vdb_tree *t);

/* Parameters recorded as grid metadata in .vdb files (strings may be NULL). */
typedef struct vx_vdb_meta {
    const char *method, *inside, *fill, *mesh;
    int supersample, threshold;
    const char *samples; /* "cube" or "faces"; NULL: not written */
} vx_vdb_meta;

int vx_voxel_write_raw8(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err);
int vx_voxel_write_raw1(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err);
int vx_voxel_write_binvox(const vx_bitgrid *g, const char *path, const vx_voxel_io *io,
                          vx_err *err);
int vx_voxel_write_nrrd(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err);
int vx_voxel_write_npy(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err);
int vx_voxel_write_vox(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err);
/* The grid a .vdb holds (voxelize's vdb_grid; the names' order). */
typedef enum vx_vdb_class { VX_VDB_LEVEL_SET = 0, VX_VDB_FOG, VX_VDB_BOOL } vx_vdb_class;
/* Writes the grid of class cls; VX_VDB_FOG takes its values from g->counts
 * when the grid has them (coverage), else 1 inside. Builds the tree a leaf
 * at a time on OpenVDB's thread pool. */
int vx_voxel_write_vdb(const vx_bitgrid *g, vx_vdb_class cls, const vx_vdb_meta *meta,
                       const char *path, const vx_voxel_io *io, vx_err *err);

/* The largest |index| a .vdb's voxels may have: OpenVDB's coordinates are
 * 32-bit, and its nodes' bounds (origin + edge) must not wrap either. */
#define VX_VDB_MAX_INDEX (1L << 30)

/* vx_voxel_write_vdb with voxel (0,0,0) at index `at` of the file's index
 * space (multiples of 8, leaf-aligned): a brick of a larger grid whose
 * corner g->grid.origin is the whole grid's (index_offset already folded
 * in), `at` recorded as metadata "brick_offset". NULL at: not a brick. */
int vx_voxel_write_vdb_at(const vx_bitgrid *g, const int at[3], vx_vdb_class cls,
                          const vx_vdb_meta *meta, const char *path, const vx_voxel_io *io,
                          vx_err *err);

/* The merge of brick .vdb files (vx_voxel_write_vdb_at, disjoint, one index
 * space) into one sparse grid by OpenVDB's Tree::merge, pruned when
 * written: memory is the merged tree plus the brick being read. */
typedef struct vx_vdb_merge vx_vdb_merge;
/* A new empty merge, or NULL (VX_EINTERNAL out_of_memory). */
vx_vdb_merge *vx_vdb_merge_new(vx_err *err);
/* Frees m (NULL is fine). */
void vx_vdb_merge_free(vx_vdb_merge *m);
/* Reads the one grid of the brick file at path into m. Errors: VX_EIO
 * io_error (unreadable), VX_EINTERNAL (a grid type unlike the others',
 * out_of_memory). */
int vx_vdb_merge_add(vx_vdb_merge *m, const char *path, vx_err *err);
/* Bytes the merged tree holds now. */
uint64_t vx_vdb_merge_bytes(const vx_vdb_merge *m);
/* Bytes the level set of the merged bool tree of the whole grid of dims
 * would add (its band, and the rows held while it is made). */
uint64_t vx_vdb_merge_level_set_bytes(const vx_vdb_merge *m, const int dims[3]);
/* Prunes the merged tree and writes it to path as the one grid of a
 * voxelize .vdb of the whole grid `grid` (index 0 = its voxel (0,0,0)):
 * bool bricks as "voxels", or with cls VX_VDB_LEVEL_SET as the level set
 * "surface" of their topology; float bricks as they are named. Same
 * temp-and-rename contract as the writers. */
int vx_vdb_merge_write(vx_vdb_merge *m, vx_vdb_class cls, const vx_grid *grid,
                       const vx_vdb_meta *meta, const char *path, const vx_voxel_io *io,
                       vx_err *err);

/* A dense float field as an OpenVDB FloatGrid named `name` (render's band-
 * limited density): value (i,j,k) = v[i + d0 (j + d1 k)] at world point
 * origin + (i,j,k) h (the transform is scale h, then translation origin);
 * active where |value| >= 1e-4 (the band-limited density rings slightly
 * everywhere; below that it is the background 0). mesh (may be NULL) goes
 * into the metadata. Same temp-and-rename contract. Any thread. */
int vx_voxel_write_vdb_float(const float *v, const int dims[3], const double origin[3], double h,
                             const char *name, const char *mesh, const char *path, vx_err *err);

/* Nonzero when voxel size h can make a .vdb: OpenVDB's linear transforms
 * refuse a scale whose determinant h^3 is under 3e-15 ("Non-zero scale
 * values required"), so h must be at least ~1.4423e-5 world units (with a
 * margin of 1e-6 on h^3 for the ulps OpenVDB's map loses). */
int vx_vdb_voxel_size_ok(double h);
/* The smallest h that can (for messages). */
double vx_vdb_min_voxel_size(void);
/* The largest voxel size a grid of class cls can have: a level set's
 * background, 3 voxels, must be a finite float (FLT_MAX / 3); HUGE_VAL for
 * fog and bool. */
double vx_vdb_max_voxel_size(int cls);

/* Bytes the vdb writer may hold in memory beyond the bit grid, known from
 * the dims (OpenVDB's trees for a grid whose every leaf is partial: the
 * worst case; a 0/1 fog grid's leaves hold masks only, as a bool grid's; a
 * level set's topology only, its band is vx_voxel_vdb_grid_bytes's);
 * coverage: the grid has sample counts. */
uint64_t vx_voxel_vdb_bytes(const int dims[3], vx_vdb_class cls, int coverage);
/* The same for the grid g itself (a level set: from its partial leaves,
 * counted in parallel; other classes as vx_voxel_vdb_bytes). */
uint64_t vx_voxel_vdb_grid_bytes(const vx_bitgrid *g, vx_vdb_class cls);

#endif
