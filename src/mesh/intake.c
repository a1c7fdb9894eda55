#include "mesh/intake.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "util/fsutil.h"

/* The stored formats: name in the Mesh JSON, file extension, the media
 * type GET /v1/meshes/{id}/file answers with, and the name error messages
 * use. The first row is what an unknown format falls back to. The declared
 * types an upload may send are media_types below; the bytes are told
 * apart by vx_mesh_sniff_sized (mesh/declared.c, mesh/obj.c). */
static const struct {
    vx_mesh_format fmt;
    const char *name, *ext, *media, *label;
} formats[] = {
    {VX_MESH_OBJ, "obj", "obj", "model/obj", "OBJ"},
    {VX_MESH_DRACO, "draco", "drc", "model/x-draco", "Draco"},
    {VX_MESH_BPT, "bpt", "bpt", "model/x-bpt", ".bpt"},
    {VX_MESH_STL, "stl", "stl", "model/stl", "STL"},
    {VX_MESH_PLY, "ply", "ply", "model/x-ply", "PLY"},
    {VX_MESH_GLTF, "gltf", "gltf", "model/gltf+json", "glTF"},
    {VX_MESH_GLB, "glb", "glb", "model/gltf-binary", "glb"},
    {VX_MESH_OFF, "off", "off", "model/x-off", "OFF"},
};
#define NFORMATS (sizeof formats / sizeof formats[0])

/* The media types an upload may declare ("" is no Content-Type). */
static const struct {
    const char *type;
    vx_intake_media media;
} media_types[] = {
    {"model/obj", VX_INTAKE_OBJ},
    {"text/plain", VX_INTAKE_TEXT},
    {"model/x-bpt", VX_INTAKE_BPT},
    {"model/x-draco", VX_INTAKE_DRACO},
    {"application/x-draco", VX_INTAKE_DRACO},
    {"model/stl", VX_INTAKE_STL},
    {"model/x.stl-binary", VX_INTAKE_STL},
    {"model/x.stl-ascii", VX_INTAKE_STL},
    {"application/sla", VX_INTAKE_STL},
    {"model/x-ply", VX_INTAKE_PLY},
    {"model/ply", VX_INTAKE_PLY},
    {"application/ply", VX_INTAKE_PLY},
    {"model/gltf+json", VX_INTAKE_GLTF},
    {"model/gltf-binary", VX_INTAKE_GLB},
    {"model/x-off", VX_INTAKE_OFF},
    {"application/off", VX_INTAKE_OFF},
    {"", VX_INTAKE_SNIFF},
    {"application/octet-stream", VX_INTAKE_SNIFF},
    /* What curl --data-binary sends unless told otherwise. */
    {"application/x-www-form-urlencoded", VX_INTAKE_SNIFF},
};

int vx_intake_media_of(const char *mt, vx_intake_media *out, vx_err *err)
{
    for (size_t i = 0; i < sizeof media_types / sizeof media_types[0]; i++)
        if (!strcmp(mt, media_types[i].type)) {
            *out = media_types[i].media;
            return 0;
        }
    return vx_err_set(err, VX_EMEDIA, "unsupported_media_type",
                      "cannot take '%.100s': send model/obj, model/stl, model/x-ply, "
                      "model/gltf+json, model/gltf-binary, model/x-off, model/x-bpt, "
                      "model/x-draco or application/octet-stream",
                      mt);
}

static size_t format_row(vx_mesh_format fmt);

/* The format a declared type names (0 for none, or text). */
static vx_mesh_format declared_format(vx_intake_media d)
{
    switch (d) {
    case VX_INTAKE_STL:
        return VX_MESH_STL;
    case VX_INTAKE_PLY:
        return VX_MESH_PLY;
    case VX_INTAKE_GLTF:
        return VX_MESH_GLTF;
    case VX_INTAKE_GLB:
        return VX_MESH_GLB;
    case VX_INTAKE_OFF:
        return VX_MESH_OFF;
    default:
        return 0;
    }
}

int vx_intake_resolve(vx_intake_media declared, const unsigned char *head, size_t n, uint64_t size,
                      vx_mesh_format *fmt, vx_err *err)
{
    vx_mesh_format sniffed = vx_mesh_sniff_sized(head, n, size);
    vx_mesh_format named = declared_format(declared);
    const char *why = NULL;
    char msg[160];
    if (named) {
        /* Trusted unless the bytes are another format for certain; a
         * malformed file then fails in its reader, naming the format. */
        *fmt = named;
        int other = sniffed && sniffed != named && sniffed != VX_MESH_OBJ &&
                    !(named == VX_MESH_GLTF && sniffed == VX_MESH_GLB) &&
                    !(named == VX_MESH_GLB && sniffed == VX_MESH_GLTF);
        if (other) {
            snprintf(msg, sizeof msg, "Content-Type says %s but the body is a %s file",
                     formats[format_row(named)].label, formats[format_row(sniffed)].label);
            why = msg;
        }
        return why ? vx_err_set(err, VX_EMEDIA, "unsupported_media_type", "%s", why) : 0;
    }
    /* A text type on a Draco file, or on bytes no text format holds (a
     * NUL byte: binary STL, glb; PLY's binary body follows a text header). */
    if (declared == VX_INTAKE_OBJ || declared == VX_INTAKE_TEXT) {
        if (sniffed == VX_MESH_DRACO)
            why = "Content-Type says text (OBJ or .bpt) but the body is a Draco file";
        else if (memchr(head, 0, n) && sniffed != VX_MESH_PLY)
            why = "Content-Type says text (OBJ or .bpt) but the body holds binary data";
    }
    switch (declared) {
    case VX_INTAKE_OBJ:
        *fmt = VX_MESH_OBJ;
        break;
    case VX_INTAKE_TEXT:
        /* Text is OBJ unless text/plain holds another text format. */
        *fmt = sniffed == VX_MESH_BPT || sniffed == VX_MESH_STL || sniffed == VX_MESH_PLY ||
                       sniffed == VX_MESH_OFF || sniffed == VX_MESH_GLTF
                   ? sniffed
                   : VX_MESH_OBJ;
        break;
    case VX_INTAKE_DRACO:
        if (sniffed != VX_MESH_DRACO)
            why = "Content-Type says Draco but the body does not start with DRACO";
        *fmt = VX_MESH_DRACO;
        break;
    case VX_INTAKE_BPT:
        if (sniffed != VX_MESH_BPT)
            why = "Content-Type says .bpt but the first line is not a patch count";
        *fmt = VX_MESH_BPT;
        break;
    default:
        if (!sniffed)
            why = "the body is no mesh format that voxeld reads (OBJ, STL, PLY, glTF, glb, OFF, "
                  "Draco, .bpt)";
        *fmt = sniffed;
        break;
    }
    return why ? vx_err_set(err, VX_EMEDIA, "unsupported_media_type", "%s", why) : 0;
}

static size_t format_row(vx_mesh_format fmt)
{
    for (size_t i = 0; i < NFORMATS; i++)
        if (formats[i].fmt == fmt) return i;
    return 0;
}

const char *vx_intake_format_name(vx_mesh_format fmt)
{
    return formats[format_row(fmt)].name;
}

const char *vx_intake_format_ext(vx_mesh_format fmt)
{
    return formats[format_row(fmt)].ext;
}

const char *vx_intake_format_media(vx_mesh_format fmt)
{
    return formats[format_row(fmt)].media;
}

vx_mesh_format vx_intake_format_by_name(const char *name)
{
    for (size_t i = 0; i < NFORMATS; i++)
        if (name && !strcmp(formats[i].name, name)) return formats[i].fmt;
    return 0;
}

const char *vx_intake_ext_of_name(const char *name)
{
    return vx_intake_format_ext(vx_intake_format_by_name(name));
}

vx_mesh_format vx_intake_format_of_path(const char *path)
{
    const char *dot = strrchr(path, '.');
    for (size_t i = 0; dot && !strchr(dot, '/') && i < NFORMATS; i++)
        if (!strcmp(dot + 1, formats[i].ext)) return formats[i].fmt;
    return 0;
}

int vx_intake_check(const vx_mesh *m, vx_err *err)
{
    /* every engine works in 32-bit floats (GL, the patches, the writers):
     * every vertex, used by a face or not (the bbox holds the used ones) */
    for (size_t i = 0; i < 3 * m->nverts; i++)
        if (!(fabs(m->pos[i]) <= VX_MESH_COORD_MAX))
            return vx_err_set(err, VX_EUNPROC, "coordinate_out_of_range",
                              "vertex %zu reaches %.9g along axis %d, beyond +-%g: the engines "
                              "work in 32-bit floats, and what they derive must stay finite",
                              i / 3, m->pos[i], (int)(i % 3), VX_MESH_COORD_MAX);
    if (m->degenerate_tris == m->ntris)
        return vx_err_set(err, VX_EUNPROC, "degenerate_mesh",
                          "every triangle of the mesh has zero area");
    return 0;
}

cJSON *vx_intake_meta(const char *id, vx_mesh_format fmt, uint64_t bytes, const vx_mesh *m)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "id", id);
    cJSON_AddStringToObject(o, "format", vx_intake_format_name(fmt));
    cJSON_AddNumberToObject(o, "bytes", (double)bytes);
    cJSON_AddNumberToObject(o, "vertices", (double)m->nverts);
    cJSON_AddNumberToObject(o, "triangles", (double)m->ntris);
    cJSON *f = cJSON_AddObjectToObject(o, "faces");
    cJSON_AddNumberToObject(f, "total", (double)m->nfaces);
    cJSON_AddNumberToObject(f, "triangles", (double)m->faces_by_size[0]);
    cJSON_AddNumberToObject(f, "quads", (double)m->faces_by_size[1]);
    cJSON_AddNumberToObject(f, "ngons", (double)m->faces_by_size[2]);
    cJSON *bb = cJSON_AddObjectToObject(o, "bbox");
    cJSON_AddItemToObject(bb, "min", cJSON_CreateDoubleArray(m->bbox_min, 3));
    cJSON_AddItemToObject(bb, "max", cJSON_CreateDoubleArray(m->bbox_max, 3));
    cJSON_AddNumberToObject(o, "boundary_edges", (double)m->boundary_edges);
    cJSON_AddNumberToObject(o, "boundary_edges_welded", (double)m->boundary_edges_welded);
    cJSON_AddNumberToObject(o, "nonmanifold_edges", (double)m->nonmanifold_edges);
    cJSON_AddNumberToObject(o, "misoriented_edges", (double)m->misoriented_edges);
    cJSON_AddNumberToObject(o, "degenerate_triangles", (double)m->degenerate_tris);
    cJSON_AddNumberToObject(o, "texcoords", (double)m->ntexcoords);
    cJSON_AddNumberToObject(o, "normals", (double)m->nnormals);
    cJSON_AddNumberToObject(o, "patches", (double)m->npatches);
    char t[32];
    vx_rfc3339(vx_now(), t);
    cJSON_AddStringToObject(o, "created", t);
    return o;
}
