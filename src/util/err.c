#include "util/err.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

int vx_err_setv(vx_err *err, vx_err_kind kind, const char *code, const char *fmt, va_list ap)
{
    if (!err) return -1;
    err->kind = kind;
    err->flags = 0;
    snprintf(err->code, sizeof err->code, "%s", code);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
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
    return errnum == ENOSPC || errnum == EDQUOT ? VX_ENOSPC : VX_EIO;
}

const char *vx_err_kind_name(vx_err_kind kind)
{
    static const char *names[] = {
        "ok",       "invalid",  "unprocessable",  "too_big",         "not_found",  "conflict",
        "media",    "busy",     "canceled",       "timeout",         "gpu",        "io",
        "internal", "no_space", "gone",           "unavailable",     "overloaded", "unauthorized",
        "method",   "length",   "header_too_big", "not_implemented", "range"};
    _Static_assert(sizeof names / sizeof names[0] == VX_EKIND_COUNT, "a name for each kind");
    if ((unsigned)kind < sizeof names / sizeof names[0]) return names[kind];
    return "unknown";
}
