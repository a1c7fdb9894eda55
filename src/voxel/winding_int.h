/* Private to the winding-number voxelizer (winding.c, wtree.c, wcone.c):
 * the cones that close a mesh's boundary, and a tree of
 * triangles for the fast evaluation of their generalized winding number
 * (Barill et al. 2018): near nodes are summed exactly (the solid angle of
 * each triangle, Van Oosterom & Strackee), far ones by a second-order
 * expansion of their dipole field about the node's area-weighted centre. */
#ifndef VX_VOXEL_WINDING_INT_H
#define VX_VOXEL_WINDING_INT_H

#include <stddef.h>
#include <stdint.h>

#include "mesh/mesh.h"
#include "util/err.h"

typedef struct vx_wtree_node {
    double p[3];         /* area-weighted centre of its triangles */
    double a[3];         /* sum of the vector areas (half cross products) */
    double m[9];         /* sum of (centroid - p) (x) vector area, row-major */
    double far2;         /* (beta * radius)^2: farther query points use the expansion */
    double lo[3], hi[3]; /* the bounding box of its vertices */
    double area;         /* sum of the triangles' areas, over 4 pi */
    int kid[2];          /* children, or -1 for a leaf */
    int first, n;        /* leaf: triangles first..first+n-1 (tree order) */
    int vfirst, nv;      /* leaf: its distinct corners vfirst..vfirst+nv-1 */
} vx_wtree_node;

typedef struct vx_wtree {
    size_t ntris;
    double *tv; /* 9 doubles a triangle (three vertices), in tree order */
    /* Each leaf's distinct corners (3 doubles each; a leaf's fan of
     * slivers shares most of them), and per triangle its corners' places
     * in its leaf's list: a leaf's unit vectors are made once each. */
    double *lv;
    uint8_t *corner; /* 3 a triangle, tree order */
    /* per triangle, tree order: its area vector, area over 4 pi and
     * bounding box (vx_wtree_bound's leaves) */
    double *tb;
    vx_wtree_node *node;
    int nnodes;
} vx_wtree;

/* Distance factor beta of the far-field test (|q - p| > beta * radius). */
#define VX_WTREE_BETA 2.0

/* Builds t over ntris triangles given as 9 doubles each (copied). 0, or -1
 * with VX_EINTERNAL out_of_memory. Any thread. */
int vx_wtree_build(vx_wtree *t, size_t ntris, const double *tv, vx_err *err);
/* The triangles' winding number at q: the sum of their signed solid angles
 * over 4 pi (positive where q sees a triangle's back, the inside of an
 * outward-oriented closed surface). Read-only: any number of threads. */
double vx_wtree_eval(const vx_wtree *t, const double q[3]);
/* vx_wtree_eval at the n points q[0..n) (1 <= n <= 4) into w[0..n), the
 * same bits, four at a time where the CPU has AVX2. Any number of threads. */
void vx_wtree_eval4(const vx_wtree *t, const double (*q)[3], int n, double *w);
/* An upper bound of |winding number| of the triangles at every point of
 * the box lo..hi (lo <= hi; a segment along an axis is one): each
 * triangle's solid angle is at most its area over its squared distance;
 * or a value >= limit once it reaches limit. side +1 bounds the winding
 * number from above, -1 its negative from above (a triangle seen from its
 * front from all of the box adds nothing to the first, one seen from its
 * back to the second), 0 its magnitude. Any number of threads. */
double vx_wtree_bound(const vx_wtree *t, const double lo[3], const double hi[3], double limit,
                      int side);
/* vx_wtree_bound of the n boxes lo[l]..hi[l] (1 <= n <= 4), each with its
 * own limit and side, into out[0..n): the same bits, four at a time where
 * the CPU has AVX2. Any number of threads. */
void vx_wtree_bound4(const vx_wtree *t, const double (*lo)[3], const double (*hi)[3],
                     const double *limit, const int *side, int n, double *out);
/* The exact winding number at q of one triangle (v: 9 doubles). */
double vx_wtree_tri(const double *v, const double q[3]);
void vx_wtree_free(vx_wtree *t);

/* The cone over m's boundary (wcone.c): for each boundary edge a -> b (its
 * uses net of the opposite ones, vertices welded by position) the triangle
 * (b, a, apex) into *cone (9 doubles each, owned by the caller; NULL and
 * *ncone 0 for a closed mesh), apex the mean of the end points of the
 * edges of its connected part of the boundary, so that each hole gets its
 * own cone and m plus the cones has no boundary. 0, or -1 with
 * VX_EINTERNAL out_of_memory. Any thread. */
int vx_wcone_build(const vx_mesh *m, double **cone, size_t *ncone, vx_err *err);

#endif
