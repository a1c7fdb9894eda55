/* vx_mesh: a polygon mesh as uploaded, plus the triangulated view that the
 * rasterizing engines draw.
 *
 * The face structure is kept (quads and n-gons matter to Gregory patches);
 * `tri` is a triangulation of every face (a fan where the face is convex, ear
 * clipping where it is not), made once at load time. When
 * every face is already a triangle, `face_start` is NULL and `tri` aliases
 * `face_idx` (no copy). Positions are doubles: engines normalise in double
 * before converting to float for upload.
 *
 * Readers (OBJ, Draco, .bpt, STL, PLY, OFF; glTF through tinygltf) and
 * writers (OBJ, binary PLY, Draco, glb) live beside this file. Any thread may call these functions
 * on meshes it owns. */
#ifndef VX_MESH_H
#define VX_MESH_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "util/err.h"

typedef enum vx_mesh_format {
    VX_MESH_OBJ = 1,
    VX_MESH_DRACO = 2,
    VX_MESH_BPT = 3,  /* Newell's Bézier patch text format (mesh/bpt.c) */
    VX_MESH_STL = 4,  /* binary or ASCII (mesh/import.cc, from here on) */
    VX_MESH_PLY = 5,  /* ASCII, binary little or big endian */
    VX_MESH_GLTF = 6, /* glTF 2.0 JSON with data: URI buffers */
    VX_MESH_GLB = 7,  /* binary glTF 2.0 */
    VX_MESH_OFF = 8,  /* Object File Format (OFF, COFF, NOFF, ...) */
} vx_mesh_format;

/* An undirected edge between welded vertices lo < hi, and its uses lo -> hi
 * less its uses hi -> lo (vx_mesh_net_edges). */
typedef struct vx_mesh_edge {
    uint32_t lo, hi;
    int32_t net;
} vx_mesh_edge;

typedef struct vx_mesh {
    size_t nverts;
    double *pos; /* 3 * nverts */

    size_t nfaces;
    uint32_t *face_start; /* nfaces + 1 offsets into face_idx, or NULL: all triangles */
    uint32_t *face_idx;   /* zero-based vertex indices, face after face */

    size_t ntris;
    uint32_t *tri; /* 3 * ntris; aliases face_idx when face_start == NULL */

    /* Bicubic Bézier patches (.bpt uploads), else 0 / NULL: 16 indices into
     * pos per patch, net point (i, j) at 4*j + i with i along u. The faces
     * are then a tessellation of the patches, for the engines that draw
     * triangles; the gregory kind uses the patches themselves. */
    size_t npatches;
    uint32_t *patch_idx;

    /* What load-time analysis found (vx_mesh_analyze). */
    double bbox_min[3], bbox_max[3];
    size_t faces_by_size[3];      /* triangles, quads, n-gons (n >= 5) */
    size_t boundary_edges;        /* undirected edges used by exactly one face; 0 = closed */
    size_t boundary_edges_welded; /* the same with vertices at one position as one vertex */
    size_t nonmanifold_edges;     /* undirected edges used by three or more faces */
    /* edges (vertices welded) two faces go along the same way: their
     * orientations disagree (0 on a consistently oriented mesh) */
    size_t misoriented_edges;
    size_t degenerate_tris; /* triangles of zero area (kept, reported) */
    /* the welded edges whose uses do not cancel, as analysis found them
     * (net_known), where there are at most VX_MESH_NET_KEEP; else
     * vx_mesh_net_edges finds them again */
    vx_mesh_edge *net;
    size_t nnet;
    int net_known;
    size_t ntexcoords, nnormals; /* vt / vn records seen (not kept) */
} vx_mesh;

/* Limits a reader enforces while it streams; 0 = no limit. */
typedef struct vx_mesh_limits {
    size_t max_vertices;
    size_t max_triangles; /* counted on the triangulated view */
} vx_mesh_limits;

/* Returns an owned empty mesh, or NULL on allocation failure. */
vx_mesh *vx_mesh_new(void);
/* Frees the mesh and its arrays; NULL is a no-op. */
void vx_mesh_free(vx_mesh *m);

/* Number of vertices of face f, and a pointer to its indices (owned by m). */
uint32_t vx_mesh_face_size(const vx_mesh *m, size_t f);
const uint32_t *vx_mesh_face(const vx_mesh *m, size_t f);

/* 1 with *rep the vertex when face v[0..n) uses one twice (the readers
 * refuse such a face: its fan would fold over itself), else 0. scratch
 * holds n indices (sorted there when n > 16). */
int vx_mesh_face_repeat(const uint32_t *v, size_t n, uint32_t *scratch, uint32_t *rep);

/* The most vertices of a face that vx_mesh_analyze triangulates by ear
 * clipping when it is not convex (a fan beyond). */
#define VX_MESH_EAR_MAX 64

/* Builds `tri` from the faces (a fan from the first vertex for a convex
 * face, ear clipping in its plane for one that is not) if needed and fills bbox, faces_by_size,
 * boundary/non-manifold edge counts (boundary edges also with vertices
 * welded by position) and degenerate_tris. Readers call it;
 * code that builds a mesh by hand calls it before use. */
int vx_mesh_analyze(vx_mesh *m, vx_err *err);

/* The most net edges vx_mesh_analyze keeps in the mesh (12 bytes each). */
#define VX_MESH_NET_KEEP ((size_t)1 << 20)

/* The edges of m, vertices welded by position, whose uses one way do not
 * cancel those the other way: a closed, consistently oriented mesh has
 * none; each hole's rim is a loop of them. Into *out (malloc'd, *n of
 * them; NULL and 0 when none), from the analysis when it kept them. 0, or
 * -1 with VX_EINTERNAL out_of_memory or VX_ETOOBIG mesh_too_big. */
int vx_mesh_net_edges(const vx_mesh *m, vx_mesh_edge **out, size_t *n, vx_err *err);

/* canon[v] (malloc'd, nverts entries): the first vertex at v's exact
 * position (the coordinates' bits, -0 read as +0), so that vertices split
 * at seams weld into one; NULL without memory. Any thread. */
uint32_t *vx_mesh_weld(const vx_mesh *m);

/* 0 when every triangle index names a vertex, else -1 with VX_EINTERNAL
 * mesh_invalid: what an engine checks before it reads positions by index
 * (a hand-built or corrupted mesh must fail there, not fault). Any thread. */
int vx_mesh_check_indices(const vx_mesh *m, vx_err *err);

/* Opens path to read a mesh from, or NULL with VX_EIO mesh_io naming it. */
FILE *vx_mesh_open(const char *path, vx_err *err);
/* Reads an OBJ file, streaming it line by line (memory: the mesh plus one
 * line). Keeps v and f; validates vt, vn and every f index form (v, v/t,
 * v//n, v/t/n, negative indices). Errors (VX_EINVAL, code obj_*) name the
 * line: index out of range, NaN/Inf, junk tokens, a face using one vertex
 * twice; no faces is VX_EUNPROC (obj_no_faces); a limit is VX_ETOOBIG.
 * Returns an owned analysed mesh or NULL. */
vx_mesh *vx_obj_read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err);
vx_mesh *vx_obj_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err);

/* Reads a Draco file through libdraco. A point cloud is VX_EUNPROC
 * (draco_point_cloud); truncated or corrupt data is VX_EINVAL (draco_corrupt).
 * Returns an owned analysed mesh or NULL. */
vx_mesh *vx_draco_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err);
/* The same from an open file, read from its current position to the end
 * (vx_mesh_read_path hands over the file it sniffed). */
vx_mesh *vx_draco_read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err);

/* What the header of a Draco file declares, before any data. */
typedef struct vx_draco_header {
    unsigned major, minor;   /* bitstream version */
    unsigned method;         /* 0 sequential, 1 edgebreaker */
    uint64_t faces;          /* triangles */
    uint64_t points;         /* vertices (edgebreaker: before attribute seams split them) */
    uint64_t extra_points;   /* edgebreaker: split and non-manifold vertices, temporary */
    unsigned attribute_sets; /* edgebreaker: attributes with their own connectivity */
} vx_draco_header;

/* Checks the header of a Draco file of file_size bytes whose first n bytes
 * are data (the whole file, or a window at its start) before libdraco sees
 * it: libdraco sizes its tables from the declared counts (24 bytes per face
 * for edgebreaker's corner table) before reading any data. Refuses unknown
 * versions (1.0 to 2.2 are read), methods and traversals, metadata that
 * does not parse, counts that contradict each other or that the bytes after
 * the header cannot hold (sequential: 3 bytes per face; edgebreaker: 2048
 * faces per byte, 50 times the densest encoding libdraco makes),
 * all VX_EINVAL draco_corrupt; a point cloud is VX_EUNPROC
 * draco_point_cloud; faces over lim->max_triangles or vertices over
 * lim->max_vertices are VX_ETOOBIG mesh_too_big. Returns 0 and fills *h,
 * -1 with err set, or 1 when the window ends before the counts (n <
 * file_size only). */
int vx_draco_check_header(const unsigned char *data, size_t n, uint64_t file_size,
                          const vx_mesh_limits *lim, vx_draco_header *h, vx_err *err);

/* The most bytes libdraco may allocate through operator new to decode a
 * file of file_size bytes with header h (2 file_size + (96 + 64 sets) a
 * face + 96 a point + 4 MiB, about twice the measured peaks). The reader
 * enforces it on the decoding thread: libdraco also sizes tables from
 * counts deep in the data, past any header check (a texture-coordinate
 * predictor's orientation count, up to 2^31); past the bound the decode
 * stops with VX_EINVAL draco_corrupt. */
uint64_t vx_draco_decode_bound(const vx_draco_header *h, uint64_t file_size);

/* Quads per patch side in the tessellation a .bpt read makes (8 x 8 quads,
 * 128 triangles per patch). */
#define VX_BPT_TESS 8

/* Reads a .bpt file (Newell's teapot format: the patch count; one line of
 * 16 one-based point indices per patch, comma- or blank-separated; the point
 * count; one "x,y,z" line per point), streaming it line by line. The file's
 * k-th index of a patch goes to slot k (i = k % 4 along u, j = k / 4 along
 * v): that order gives the teapot's normals dS/du x dS/dv pointing outward.
 * Points the file writes twice (equal coordinates) are one point: patch_idx
 * names the first of them (the duplicates stay in pos, unused). pos holds
 * the points, then the tessellation's new vertices (Bézier
 * evaluated in double); faces are VX_BPT_TESS^2 quads per patch, sharing the
 * patch corners (the control points) and the vertices of a patch edge whose
 * four control-point indices another patch uses too (either direction);
 * quads that a collapsed edge degenerates become triangles. Errors
 * (VX_EINVAL, code bpt_*) name the line: bpt_count, bpt_index, bpt_nan,
 * bpt_junk, bpt_line_too_long, bpt_truncated; a limit is VX_ETOOBIG
 * mesh_too_big. Returns an owned analysed mesh or NULL. */
vx_mesh *vx_bpt_read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err);
vx_mesh *vx_bpt_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err);

/* What the header of an STL, PLY, OFF or glTF file declares, checked
 * against the bytes that follow it (mesh/declared.c). Every count is an
 * upper bound on what a reader can make of the file, so the memory of the
 * decode can be bounded before it starts. */
typedef struct vx_mesh_declared {
    uint64_t vertices;  /* positions (glTF: over every node instance) */
    uint64_t faces;     /* polygons */
    uint64_t indices;   /* face corners */
    uint64_t triangles; /* of the fan triangulation */
    int exact;          /* triangles is the count the file holds (binary STL, glTF) */
} vx_mesh_declared;

/* Checks the header counts of a file of format fmt (STL, PLY, OFF, glTF,
 * glb) whose first n bytes are data (the whole file, or for parse-cost
 * estimates a window at its start) and that is size bytes long. Counts
 * that the bytes cannot hold, a malformed header, a glTF buffer that is
 * not embedded (only data: URIs and the glb BIN chunk are read), accessors
 * or buffer views out of their buffer's bounds, and glTF node graphs with
 * cycles are VX_EINVAL <fmt>_corrupt (stl_corrupt, ply_corrupt, ...) with
 * the format's name in the message; declared counts over lim are
 * VX_ETOOBIG mesh_too_big. Returns 0 and fills *d, -1 with err set, or 1
 * when the window ends before the header does (n < size only). */
int vx_declared_check(vx_mesh_format fmt, const unsigned char *data, size_t n, uint64_t size,
                      const vx_mesh_limits *lim, vx_mesh_declared *d, vx_err *err);
/* The most bytes that decoding a size-byte file of format fmt with header
 * counts d may allocate through operator new (the glTF decode runs held
 * to it, see mesh/import.cc). */
uint64_t vx_declared_decode_bound(vx_mesh_format fmt, uint64_t size, const vx_mesh_declared *d);
/* Tells the formats of mesh/declared.c by their first n bytes and their
 * size: glb ("glTF" magic), PLY ("ply" line), binary STL (80-byte header
 * and a triangle count that gives exactly size bytes, or up to 511 fewer
 * when the bytes are not text), glTF JSON (a '{' first), OFF (a first word
 * [prefix]OFF, or that with the first count glued to it), ASCII STL
 * ("solid" and then "facet" or "endsolid", or a first line longer than
 * the window); else vx_mesh_sniff. */
vx_mesh_format vx_mesh_sniff_sized(const unsigned char *head, size_t n, uint64_t size);

/* Reads an STL, PLY, glTF, glb or OFF file (mesh/import.cc: PLY and OFF
 * by vx_ply_read_mem and vx_off_read_mem, STL by its own parser, glTF
 * through tinygltf): the file is checked by vx_declared_check first, and
 * the glTF decode runs under vx_declared_decode_bound (past it: VX_EINVAL
 * gltf_corrupt). Node
 * transforms are applied (glTF); STL and glTF vertices with equal
 * positions are merged into one. Polygons are kept (quads stay quads).
 * Errors: VX_EINVAL <fmt>_corrupt naming the format, VX_EUNPROC
 * <fmt>_no_faces, VX_ETOOBIG mesh_too_big. Returns an owned analysed mesh
 * or NULL. */
vx_mesh *vx_import_read_path(const char *path, vx_mesh_format fmt, const vx_mesh_limits *lim,
                             vx_err *err);
/* Reads an OFF file from memory (mesh/off.c, voxeld's own: assimp's OFF importer
 * crashed on fuzzed input): header counts checked first, polygons kept,
 * errors VX_EINVAL off_corrupt naming the line, VX_EUNPROC off_no_faces,
 * VX_ETOOBIG mesh_too_big. Owned analysed mesh or NULL. */
vx_mesh *vx_off_read_mem(const unsigned char *data, size_t n, const vx_mesh_limits *lim,
                         vx_err *err);
/* Reads a PLY file from memory (mesh/ply.c, voxeld's own: assimp's PLY importer
 * read past its buffer on fuzzed input): ASCII, binary little or big
 * endian; the vertex element's x, y, z and the face element's
 * vertex_indices (or vertex_index) list, every other element and property
 * skipped; header counts checked first, polygons kept. Errors VX_EINVAL
 * ply_corrupt, VX_EUNPROC ply_no_faces, VX_ETOOBIG mesh_too_big. Owned
 * analysed mesh or NULL. */
vx_mesh *vx_ply_read_mem(const unsigned char *data, size_t n, const vx_mesh_limits *lim,
                         vx_err *err);
/* The same from memory (the fuzz targets); OFF and PLY go to
 * vx_off_read_mem and vx_ply_read_mem. */
vx_mesh *vx_import_read_mem(const unsigned char *data, size_t n, vx_mesh_format fmt,
                            const vx_mesh_limits *lim, vx_err *err);

/* Reads any format: STL, PLY, glTF, glb and OFF by the path's extension
 * (how the store names them), the rest told by the first bytes
 * (vx_mesh_sniff). */
vx_mesh *vx_mesh_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err);
/* The same from the open file fd (reopened through /proc/self/fd, so the
 * file read is the one fd names whatever its path now holds), its format
 * told by name's extension or its first bytes. fd stays open. */
vx_mesh *vx_mesh_read_fd(int fd, const char *name, const vx_mesh_limits *lim, vx_err *err);
/* Reads path as the given format (no sniffing). */
vx_mesh *vx_mesh_read_as(const char *path, vx_mesh_format fmt, const vx_mesh_limits *lim,
                         vx_err *err);

/* Sniffs the first bytes of a file: VX_MESH_DRACO for the "DRACO" magic;
 * for text, VX_MESH_BPT when the first non-blank line is a single unsigned
 * integer (never valid OBJ), else VX_MESH_OBJ; 0 for binary junk. */
vx_mesh_format vx_mesh_sniff(const unsigned char *head, size_t n);

/* Worst-case peak memory, in bytes, of reading a `bytes`-byte file at path
 * in format fmt under lim: what the daemon reserves from --max-parse-memory
 * before it parses an upload. Measured peaks (RSS over the process before
 * the read, 40 MB files) and the bounds used:
 *   OBJ    8 x bytes + 16 MiB. Faces of nine one-digit indices are the worst
 *          (8.0x: face indices, offsets, the fan triangulation and the edge
 *          table); quads 6.4x, repeated triangles 3.7x, vertices only 3.4x,
 *          a typical scanned mesh 1.1x.
 *   .bpt   6.5 KiB a patch (its tessellation: 77 vertices, 64 quads, 128
 *          triangles, edges; measured 5.1 to 6.1 KiB) for the patch count on
 *          the first line, bounded by bytes / 32 (the shortest patch line)
 *          and --max-triangles / 128; plus 40 bytes a point for bytes / 6
 *          points (the shortest point line; measured 5.2x for a file of
 *          points) + 16 MiB.
 *   Draco  the file (read whole) + vx_draco_decode_bound (libdraco, held
 *          to it) + 32 bytes a face and a point (the mesh and its analysis)
 *          + 12 MiB, from the counts the header declares; when the header
 *          cannot be read, the counts its check allows. Measured: 70 bytes
 *          a face with its vertices for positions only, 150 with texture
 *          coordinates and normals.
 * Returns the estimate; a file the reader will refuse early gets a small
 * one. */
uint64_t vx_mesh_parse_cost(const char *path, vx_mesh_format fmt, uint64_t bytes,
                            const vx_mesh_limits *lim);

/* Optional per-vertex normals and per-face groups for the writers. */
typedef struct vx_mesh_write_opts {
    const float *normals;        /* 3 * nverts, or NULL */
    const uint32_t *face_group;  /* nfaces group ids (patch ids), or NULL */
    const char *group_prefix;    /* OBJ group name prefix, default "patch" */
    int draco_quantization_bits; /* position quantisation, 0 = 16 */
} vx_mesh_write_opts;

/* Writers. OBJ keeps the face structure (and writes vn, and "g" groups when
 * face_group is set); PLY is binary little-endian with float positions,
 * optional normals and a per-face "patch" int when face_group is set; Draco
 * writes the triangulated view. Return 0 or -1 (VX_EIO). */
int vx_obj_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err);
int vx_ply_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err);
int vx_draco_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path,
                        vx_err *err);
/* glb (binary glTF 2.0) of the triangulated view through libdraco's glTF
 * encoder, uncompressed: one mesh, one node, float positions (and normals
 * when given), 32-bit indices. 0 or -1 (VX_EIO). */
int vx_glb_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err);

#endif
