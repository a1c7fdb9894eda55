/* The daemon's job table: every kind the daemon runs is one row here, and
 * one params schema in api/openapi.yaml. The daemon hands it to the job
 * runner (vx_jobs_desc.kinds); src/jobs names no engine. */
#include "kinds.h"

#include "bandlimit/job.h"
#include "gregory/catmull_clark.h"
#include "gregory/job.h"
#include "preview/preview.h"
#include "voxel/job.h"

static const vx_kind *const table[] = {
    &vx_kind_preview, &vx_kind_voxelize, &vx_kind_render, &vx_kind_gregory, &vx_kind_catmull_clark,
};

const vx_kinds vx_daemon_kinds = {table, sizeof table / sizeof table[0]};

const vx_kind *vx_kind_find(const char *name)
{
    return vx_kinds_find(&vx_daemon_kinds, name);
}

size_t vx_kind_count(void)
{
    return vx_daemon_kinds.n;
}

const vx_kind *vx_kind_at(size_t i)
{
    return i < vx_daemon_kinds.n ? vx_daemon_kinds.rows[i] : NULL;
}
