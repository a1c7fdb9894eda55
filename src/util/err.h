/* vx_err: the error a failing call hands back to its caller.
 *
 * Every fallible function returns 0 / -1 (or a pointer / NULL) and fills a
 * caller-supplied vx_err. The code is a stable machine-readable string that
 * ends up in the HTTP error body; the kind alone decides the HTTP status,
 * which only daemon/respond.c maps, and flags refine a kind for callers'
 * control flow. Neither is ever told from the code. Functions log where an
 * error is detected; callers propagate silently. */
#ifndef VX_ERR_H
#define VX_ERR_H

#include <stdarg.h>
#include <stddef.h>

typedef enum vx_err_kind {
    VX_EOK = 0,
    VX_EINVAL,    /* malformed input: bad syntax, truncated data (400) */
    VX_EUNPROC,   /* well-formed but unusable: bad params, no faces (422) */
    VX_ETOOBIG,   /* a configured limit was exceeded (413; a params value over a limit is VX_EUNPROC
                     from check()) */
    VX_ENOTFOUND, /* unknown id (404) */
    VX_ECONFLICT, /* state does not allow the operation (409) */
    VX_EMEDIA,    /* unsupported content type (415) */
    VX_EBUSY,     /* queue full (429) */
    VX_ECANCELED, /* job canceled */
    VX_ETIMEOUT,  /* job ran past its time limit */
    VX_EGPU,      /* GL error, out of GPU memory, context lost */
    VX_EIO,       /* file system error (500) */
    VX_EINTERNAL, /* a bug or an allocation failure (500) */
    VX_ENOSPC,    /* the data dir is full or under its free-space floor (507) */
    /* Appended: job errors are journaled by number. */
    VX_EGONE,      /* it existed and was removed (410) */
    VX_EUNAVAIL,   /* the daemon is starting or stopping: retry in seconds (503) */
    VX_EOVERLOAD,  /* a shared budget is spent for now: retry soon (503) */
    VX_EAUTH,      /* no valid credentials (401) */
    VX_EMETHOD,    /* the resource does not take the method (405) */
    VX_ELENGTH,    /* a body whose length is not declared (411) */
    VX_EHEADER,    /* the request head is over its limit (431) */
    VX_ENOTIMPL,   /* a protocol feature that is not implemented (501) */
    VX_ERANGE,     /* a byte range outside the representation (416) */
    VX_EPRECOND,   /* an If-Match the resource does not meet (412) */
    VX_EFORBIDDEN, /* a request this daemon does not take from where it came (403) */
    VX_EKIND_COUNT
} vx_err_kind;

/* Flags refine a kind for the caller's control flow; never the status. */
enum {
    /* VX_ECANCELED by the daemon's shutdown, not by a client: the job goes
     * back to the queue. */
    VX_EF_SHUTDOWN = 1u << 0,
};

typedef struct vx_err {
    vx_err_kind kind;
    unsigned flags;    /* VX_EF_*, 0 unless the setter says */
    char code[48];     /* e.g. "obj_index_out_of_range" */
    char message[512]; /* human readable, names the line/parameter */
} vx_err;

/* Fills err (may be NULL) and returns -1, so callers can `return vx_err_set(...)`. */
int vx_err_set(vx_err *err, vx_err_kind kind, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* vx_err_set with flags (VX_EF_*). */
int vx_err_set_flagged(vx_err *err, vx_err_kind kind, unsigned flags, const char *code,
                       const char *fmt, ...) __attribute__((format(printf, 5, 6)));
int vx_err_setv(vx_err *err, vx_err_kind kind, const char *code, const char *fmt, va_list ap);
/* Length of the well-formed UTF-8 sequence at s (n >= 1 bytes left), or 0:
 * no overlongs, surrogates or code points above U+10FFFF. Any thread. */
size_t vx_err_utf8_len(const unsigned char *s, size_t n);
/* Replaces, in place, every byte of s that is not part of well-formed
 * UTF-8, and every control character, with '?'. Every message set through
 * vx_err_set* has been through it. */
void vx_err_utf8_clean(char *s);
/* 1 when err (may be NULL) carries every flag of flags. */
int vx_err_has(const vx_err *err, unsigned flags);
/* Resets err to VX_EOK. */
void vx_err_clear(vx_err *err);
/* VX_ENOSPC for ENOSPC / EDQUOT, VX_EUNAVAIL for EAGAIN, ECONNREFUSED,
 * EHOSTUNREACH, ETIMEDOUT and ECONNRESET (a remote byte store that is
 * unreachable for now) and EROFS (a read-only mount), else VX_EIO: the
 * kind of a failed write. */
vx_err_kind vx_err_io_kind(int errnum);
/* Short name of a kind, for logs. */
const char *vx_err_kind_name(vx_err_kind kind);

#define VX_FREE(p)                                                                                 \
    do {                                                                                           \
        free(p);                                                                                   \
        (p) = NULL;                                                                                \
    } while (0)

#endif
