/* The local job state: the journal file (journal.h) behind the state ops
 * (state.h). */
#include "jobs/journal.h"
#include "jobs/state.h"

static void *local_open(const char *where, vx_err *err)
{
    return vx_journal_open(where, err);
}

static void local_close(void *st)
{
    vx_journal_close(st);
}

static long local_replay(void *st, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err)
{
    return vx_journal_replay(st, fn, ud, err);
}

static int local_append(void *st, const cJSON *rec, size_t owed, vx_err *err)
{
    return vx_journal_append(st, rec, owed, err);
}

static int local_compact(void *st, cJSON *const *recs, size_t n, vx_err *err)
{
    return vx_journal_compact(st, recs, n, err);
}

static long local_size(void *st)
{
    return vx_journal_size(st);
}

static int local_intact(void *st)
{
    return vx_journal_intact(st);
}

const vx_jobstate_ops vx_jobstate_local = {
    .name = "local",
    .open = local_open,
    .close = local_close,
    .replay = local_replay,
    .append = local_append,
    .compact = local_compact,
    .size = local_size,
    .intact = local_intact,
};
