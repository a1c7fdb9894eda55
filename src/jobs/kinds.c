/* The job table: every kind the daemon runs is one row here, and one
 * params schema in api/openapi.yaml. */
#include <string.h>

#include "bandlimit/job.h"
#include "gregory/job.h"
#include "gregory/catmull_clark.h"
#include "jobs/kind.h"
#include "preview/preview.h"
#include "voxel/job.h"

static const vx_kind *const table[] = {
    &vx_kind_preview, &vx_kind_voxelize, &vx_kind_render, &vx_kind_gregory, &vx_kind_catmull_clark,
};

const vx_kind *vx_kind_find(const char *name)
{
    for (size_t i = 0; i < sizeof table / sizeof table[0]; i++)
        if (strcmp(table[i]->name, name) == 0) return table[i];
    return NULL;
}

size_t vx_kind_count(void)
{
    return sizeof table / sizeof table[0];
}
const vx_kind *vx_kind_at(size_t i)
{
    return i < vx_kind_count() ? table[i] : NULL;
}
