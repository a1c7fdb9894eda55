/* What may be a mesh's name: the one rule the daemon (?name=, a
 * Content-Disposition filename, download names) and voxelctl (which names
 * an upload after its file only when the name is one) share. */
#ifndef VX_UTIL_NAME_H
#define VX_UTIL_NAME_H

#include <stddef.h>

#define VX_NAME_MAX 100

/* 1 when s[0..len) is a mesh name: 1 to VX_NAME_MAX bytes of valid UTF-8
 * without control characters (C0, C1), invisible format characters (bidi
 * overrides and isolates, zero widths, the BOM), '/', '\\' or '"', and
 * not "." or ".."; else 0. */
int vx_name_ok(const char *s, size_t len);

#endif
