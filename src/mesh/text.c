/* Line-numbered errors of the text mesh readers (text.h). */
#include <stdio.h>

#include "mesh/text.h"
#include "util/log.h"

int vx_mesh_line_fail(vx_err *err, size_t lineno, const char *event, vx_err_kind kind,
                      const char *code, const char *fmt, va_list ap)
{
    char msg[400];
    vsnprintf(msg, sizeof msg, fmt, ap);
    vx_err_set(err, kind, code, "line %zu: %s", lineno, msg);
    VX_DEBUG(event, "code=%s line=%zu", code, lineno);
    return -1;
}
