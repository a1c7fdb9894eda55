/* Mesh intake: the one place that knows what an upload may be.
 *
 * The stored formats (their name in the Mesh JSON and their file
 * extension), the declared upload types (Content-Type) and how a declared
 * type combines with the type sniffed from the first bytes, the rule every
 * stored mesh passes (not all of its triangles degenerate) and the Mesh
 * JSON of a stored mesh. Pure functions, any thread: no HTTP, no store. */
#ifndef VX_INTAKE_H
#define VX_INTAKE_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

#include "mesh/mesh.h"
#include "util/err.h"

/* What the client declared an upload to be. */
typedef enum vx_intake_media {
    VX_INTAKE_SNIFF, /* no type, application/octet-stream: told by content */
    VX_INTAKE_OBJ,   /* model/obj */
    VX_INTAKE_DRACO, /* model/x-draco, application/x-draco */
    VX_INTAKE_TEXT,  /* text/plain: OBJ or .bpt, told by content */
    VX_INTAKE_BPT,   /* model/x-bpt */
    VX_INTAKE_STL,   /* model/stl, model/x.stl-binary, model/x.stl-ascii, application/sla */
    VX_INTAKE_PLY,   /* model/x-ply, model/ply, application/ply */
    VX_INTAKE_GLTF,  /* model/gltf+json */
    VX_INTAKE_GLB,   /* model/gltf-binary */
    VX_INTAKE_OFF,   /* model/x-off, application/off */
} vx_intake_media;

/* Reads a media type (lower case, no parameters; "" for no Content-Type)
 * into *out. -1 (VX_EMEDIA unsupported_media_type) for a type not taken. */
int vx_intake_media_of(const char *mt, vx_intake_media *out, vx_err *err);
/* The format an upload of size bytes declared as `declared` whose first n
 * bytes are head is parsed as, into *fmt. -1 (VX_EMEDIA
 * unsupported_media_type) when the bytes contradict the declared type, or
 * are no mesh format at all (no type, application/octet-stream, or
 * application/x-www-form-urlencoded: told by content). */
int vx_intake_resolve(vx_intake_media declared, const unsigned char *head, size_t n, uint64_t size,
                      vx_mesh_format *fmt, vx_err *err);

/* Name of a format in the Mesh JSON ("obj", "draco", "bpt", "stl", "ply",
 * "gltf", "glb", "off"); "obj" for 0. */
const char *vx_intake_format_name(vx_mesh_format fmt);
/* File extension a format is stored under ("obj", "drc", "bpt"); "obj" for 0. */
const char *vx_intake_format_ext(vx_mesh_format fmt);
/* The media type a stored mesh of format fmt is served as ("model/obj",
 * "model/stl", ...); "model/obj" for 0. */
const char *vx_intake_format_media(vx_mesh_format fmt);
/* The format of a Mesh JSON name; 0 for a name not in the table. */
vx_mesh_format vx_intake_format_by_name(const char *name);
/* File extension of the format a Mesh JSON names; "obj" for unknown names. */
const char *vx_intake_ext_of_name(const char *name);
/* The format whose stored extension ends path (".stl", ...), or 0. */
vx_mesh_format vx_intake_format_of_path(const char *path);

/* The largest coordinate a mesh (or a gregory frame) may have. The engines
 * work in 32-bit floats, and what they derive from coordinates (extents,
 * camera distances, an interpolating surface's bulge) must stay finite in
 * them too: a cube at 3e38 gave a Gregory surface of NaN and depths of inf. */
#define VX_MESH_COORD_MAX 1e30

/* The rules a parsed upload must pass before it is stored: 0, or -1
 * (VX_EUNPROC) coordinate_out_of_range (past +-VX_MESH_COORD_MAX) or
 * degenerate_mesh (every triangle of zero area). */
int vx_intake_check(const vx_mesh *m, vx_err *err);
/* The Mesh JSON (api/openapi.yaml, Mesh) of mesh m stored as id from a
 * bytes-byte upload in format fmt, created now. Owned; NULL without memory. */
cJSON *vx_intake_meta(const char *id, vx_mesh_format fmt, uint64_t bytes, const vx_mesh *m);

#endif
