/* Mesh names (name.h). */
#include "util/name.h"

#include "util/err.h"

/* The UTF-8 of a C1 control or an invisible format character that can
 * disguise a file name (bidi overrides and isolates, zero widths, the BOM):
 * its length at s, else 0. */
static size_t disguising_char(const unsigned char *s, size_t left)
{
    if (left >= 2 && s[0] == 0xC2 && s[1] >= 0x80 && s[1] <= 0x9F) return 2; /* U+0080-009F */
    if (left >= 2 && s[0] == 0xD8 && s[1] == 0x9C) return 2;                 /* U+061C */
    if (left < 3) return 0;
    if (s[0] == 0xE2 && s[1] == 0x80 &&
        ((s[2] >= 0x8B && s[2] <= 0x8F) || (s[2] >= 0xAA && s[2] <= 0xAE)))
        return 3; /* U+200B-200F, U+202A-202E */
    if (s[0] == 0xE2 && s[1] == 0x81 && s[2] >= 0xA0 && s[2] <= 0xAF) return 3; /* U+2060-206F */
    if (s[0] == 0xEF && s[1] == 0xBB && s[2] == 0xBF) return 3;                 /* U+FEFF */
    return 0;
}

int vx_name_ok(const char *s, size_t len)
{
    if (!len || len > VX_NAME_MAX) return 0;
    if ((len == 1 && s[0] == '.') || (len == 2 && s[0] == '.' && s[1] == '.')) return 0;
    for (size_t i = 0, k; i < len; i += k) {
        unsigned char c = (unsigned char)s[i];
        k = vx_err_utf8_len((const unsigned char *)s + i, len - i);
        if (!k) return 0;
        if (c < 0x20 || c == 0x7f || c == '/' || c == '\\' || c == '"') return 0;
        if (c >= 0x80 && disguising_char((const unsigned char *)s + i, len - i)) return 0;
    }
    return 1;
}
