#include "mesh/intake.h"

#include <stdio.h>
#include <string.h>

#include "util/fsutil.h"

/* The stored formats: name in the Mesh JSON, file extension. The first row
 * is what an unknown format falls back to. */
static const struct {
    vx_mesh_format fmt;
    const char *name, *ext;
} formats[] = {
    {VX_MESH_OBJ, "obj", "obj"},
    {VX_MESH_DRACO, "draco", "drc"},
    {VX_MESH_BPT, "bpt", "bpt"},
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
    {"", VX_INTAKE_SNIFF},
    {"application/octet-stream", VX_INTAKE_SNIFF},
};

int vx_intake_media_of(const char *mt, vx_intake_media *out, vx_err *err)
{
    for (size_t i = 0; i < sizeof media_types / sizeof media_types[0]; i++)
        if (!strcmp(mt, media_types[i].type)) {
            *out = media_types[i].media;
            return 0;
        }
    return vx_err_set(err, VX_EMEDIA, "unsupported_media_type",
                      "cannot take '%.100s': send model/obj, model/x-bpt, model/x-draco or "
                      "application/octet-stream",
                      mt);
}

int vx_intake_resolve(vx_intake_media declared, const unsigned char *head, size_t n,
                      vx_mesh_format *fmt, vx_err *err)
{
    vx_mesh_format sniffed = vx_mesh_sniff(head, n);
    const char *why = NULL;
    switch (declared) {
    case VX_INTAKE_OBJ:
    case VX_INTAKE_TEXT:
        /* Text is OBJ unless text/plain holds a .bpt. */
        if (sniffed == VX_MESH_DRACO)
            why = "Content-Type says text (OBJ or .bpt) but the body is a Draco file";
        *fmt = declared == VX_INTAKE_TEXT && sniffed == VX_MESH_BPT ? VX_MESH_BPT : VX_MESH_OBJ;
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
        if (!sniffed) why = "the body is neither text (OBJ, .bpt) nor a Draco file";
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

int vx_intake_check(const vx_mesh *m, vx_err *err)
{
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
    cJSON_AddNumberToObject(o, "nonmanifold_edges", (double)m->nonmanifold_edges);
    cJSON_AddNumberToObject(o, "degenerate_triangles", (double)m->degenerate_tris);
    cJSON_AddNumberToObject(o, "texcoords", (double)m->ntexcoords);
    cJSON_AddNumberToObject(o, "normals", (double)m->nnormals);
    cJSON_AddNumberToObject(o, "patches", (double)m->npatches);
    char t[32];
    vx_rfc3339(vx_now(), t);
    cJSON_AddStringToObject(o, "created", t);
    return o;
}
