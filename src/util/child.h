/* Work that must be stoppable while it is inside a library call that never
 * returns early (OpenSubdiv's refinement, an encoder): it runs in a forked
 * child process, and the caller polls while it waits, killing the child
 * when the poll says stop (a job's time limit, a cancel). */
#ifndef VX_CHILD_H
#define VX_CHILD_H

#include <stddef.h>

#include "util/err.h"

/* What the child runs: returns 0 and fills out (out_size bytes, handed
 * back to the parent), or -1 with err. It must not touch locks other
 * threads of the parent may have held at the fork (no logging), nor start
 * threads; malloc and file writes are fine. */
typedef int (*vx_child_fn)(void *ud, void *out, size_t out_size, vx_err *err);
/* Called every poll_ms while the child runs: returns 0 to go on, or -1
 * with err to stop it. */
typedef int (*vx_child_poll)(void *ud, vx_err *err);

/* Runs fn(ud, out, out_size) in a child process and returns its result:
 * 0 with out filled, or -1 with the child's err, the poll's err (the child
 * is then killed and reaped before this returns), or VX_EINTERNAL
 * child_failed when the child died without an answer (out of memory: the
 * kernel killed it). A stopped child takes at most poll_ms plus the time a
 * SIGKILL takes to land. Any thread. */
int vx_child_call(vx_child_fn fn, void *ud, void *out, size_t out_size, vx_child_poll poll_fn,
                  void *poll_ud, int poll_ms, vx_err *err);

#endif
