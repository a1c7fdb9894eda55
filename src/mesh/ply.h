/* The PLY header (mesh/ply.c), parsed once for both the declared-count
 * check (mesh/declared.c) and the reader (vx_ply_read_mem, mesh.h). */
#ifndef VX_MESH_PLY_H
#define VX_MESH_PLY_H

#include <stddef.h>
#include <stdint.h>

#include "util/err.h"

#define VX_PLY_MAX_HEADER (64 * 1024)
#define VX_PLY_MAX_ELEMENTS 64
#define VX_PLY_MAX_PROPS 512 /* over all elements (splat files have ~60 per vertex) */

typedef enum vx_ply_format { VX_PLY_ASCII, VX_PLY_LE, VX_PLY_BE } vx_ply_format;

/* Value types; VX_PLY_NONE is a scalar property's count type. */
typedef enum vx_ply_type {
    VX_PLY_NONE,
    VX_PLY_I8,
    VX_PLY_U8,
    VX_PLY_I16,
    VX_PLY_U16,
    VX_PLY_I32,
    VX_PLY_U32,
    VX_PLY_F32,
    VX_PLY_F64,
} vx_ply_type;

typedef struct vx_ply_prop {
    char name[32];
    uint8_t type;       /* the value type (of a list's items) */
    uint8_t count_type; /* a list's count type; VX_PLY_NONE for a scalar */
} vx_ply_prop;

typedef struct vx_ply_elem {
    char name[32];
    uint64_t count;
    int first_prop, nprops; /* into vx_ply_header.props */
} vx_ply_elem;

typedef struct vx_ply_header {
    vx_ply_format format;
    int nelems, nprops;
    vx_ply_elem elems[VX_PLY_MAX_ELEMENTS];
    vx_ply_prop props[VX_PLY_MAX_PROPS];
    size_t body; /* offset of the first byte after the end_header line */
} vx_ply_header;

/* The size in bytes of a binary value of type t (0 for VX_PLY_NONE). */
int vx_ply_type_size(vx_ply_type t);

/* Parses the header at the start of p (n bytes of a size-byte file).
 * Returns 0 with h filled, 1 when n < size and the header goes on past the
 * n bytes (call again with more), or -1 with err VX_EINVAL ply_corrupt
 * naming the line. */
int vx_ply_header_parse(const unsigned char *p, size_t n, uint64_t size, vx_ply_header *h,
                        vx_err *err);

#endif
