#include "util/err.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

size_t vx_err_utf8_len(const unsigned char *s, size_t n)
{
    unsigned c = s[0], cp, min;
    size_t len;
    if (c < 0x80) return 1;
    if (c >= 0xc2 && c <= 0xdf)
        len = 2, cp = c & 0x1f, min = 0x80;
    else if (c >= 0xe0 && c <= 0xef)
        len = 3, cp = c & 0x0f, min = 0x800;
    else if (c >= 0xf0 && c <= 0xf4)
        len = 4, cp = c & 0x07, min = 0x10000;
    else
        return 0;
    if (n < len) return 0;
    for (size_t i = 1; i < len; i++) {
        if ((s[i] & 0xc0) != 0x80) return 0;
        cp = cp << 6 | (s[i] & 0x3f);
    }
    return cp < min || cp > 0x10ffff || (cp >= 0xd800 && cp <= 0xdfff) ? 0 : len;
}

void vx_err_utf8_clean(char *s)
{
    unsigned char *p = (unsigned char *)s;
    size_t n = strlen(s);
    for (size_t i = 0; i < n;) {
        size_t k = vx_err_utf8_len(p + i, n - i);
        if (!k) {
            p[i++] = '?';
            continue;
        }
        if (k == 1 && (p[i] < 0x20 || p[i] == 0x7f)) p[i] = '?';
        i += k;
    }
}

int vx_err_setv(vx_err *err, vx_err_kind kind, const char *code, const char *fmt, va_list ap)
{
    if (!err) return -1;
    err->kind = kind;
    err->flags = 0;
    snprintf(err->code, sizeof err->code, "%s", code);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    /* Messages quote what clients sent (a line of a file, a name) and go
     * into JSON bodies, job records and logs: keep them UTF-8 whatever
     * the input, also where the buffer cut a character. */
    vx_err_utf8_clean(err->message);
    return -1;
}

int vx_err_set(vx_err *err, vx_err_kind kind, const char *code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vx_err_setv(err, kind, code, fmt, ap);
    va_end(ap);
    return -1;
}

int vx_err_set_flagged(vx_err *err, vx_err_kind kind, unsigned flags, const char *code,
                       const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vx_err_setv(err, kind, code, fmt, ap);
    va_end(ap);
    if (err) err->flags = flags;
    return -1;
}

int vx_err_has(const vx_err *err, unsigned flags)
{
    return err && (err->flags & flags) == flags;
}

void vx_err_clear(vx_err *err)
{
    if (!err) return;
    err->kind = VX_EOK;
    err->flags = 0;
    err->code[0] = 0;
    err->message[0] = 0;
}

vx_err_kind vx_err_io_kind(int errnum)
{
    /* a remote byte store, unreachable for now */
    if (errnum == EAGAIN || errnum == ECONNREFUSED || errnum == EHOSTUNREACH ||
        errnum == ETIMEDOUT || errnum == ECONNRESET)
        return VX_EUNAVAIL;
    /* a file system mounted read-only: the operator's to fix, not the request's */
    if (errnum == EROFS) return VX_EUNAVAIL;
    return errnum == ENOSPC || errnum == EDQUOT ? VX_ENOSPC : VX_EIO;
}

const char *vx_err_kind_name(vx_err_kind kind)
{
    static const char *names[] = {
        "ok",       "invalid",  "unprocessable",  "too_big",         "not_found",  "conflict",
        "media",    "busy",     "canceled",       "timeout",         "gpu",        "io",
        "internal", "no_space", "gone",           "unavailable",     "overloaded", "unauthorized",
        "method",   "length",   "header_too_big", "not_implemented", "range",      "precondition",
        "forbidden"};
    _Static_assert(sizeof names / sizeof names[0] == VX_EKIND_COUNT, "a name for each kind");
    if ((unsigned)kind < sizeof names / sizeof names[0]) return names[kind];
    return "unknown";
}
