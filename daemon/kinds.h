/* The daemon's job table (daemon/kinds.c): the kinds it runs, wired into
 * the job runner through vx_jobs_desc.kinds. Any thread. */
#ifndef VX_DAEMON_KINDS_H
#define VX_DAEMON_KINDS_H

#include <stddef.h>

#include "jobs/kind.h"

/* The table, for vx_jobs_desc.kinds. */
extern const vx_kinds vx_daemon_kinds;

/* The row named name, or NULL when it is unknown. */
const vx_kind *vx_kind_find(const char *name);
/* Number of rows, for listings (/v1/info). */
size_t vx_kind_count(void);
/* Row i (< vx_kind_count()), else NULL. */
const vx_kind *vx_kind_at(size_t i);

#endif
