/* Where the job table persists: one ops struct per backend. Today's only
 * backend is the local journal (vx_jobstate_local: jobs/journal.c, one file
 * of CRC-framed JSON lines); another (PostgreSQL) is one new file
 * implementing these ops, chosen through vx_jobs_desc.state.
 *
 * Records are JSON objects {"job": snapshot} that the job registry builds
 * (snapshot.c); a backend stores them as they are and gives them back.
 *
 * Contract:
 * - Durability: a record is durable when append returns 0. The registry
 *   acknowledges the state change it records (the HTTP answer, the next
 *   stage) only after that; when append fails the record must not come back
 *   from replay (the change is undone or logged as lost, never acknowledged).
 * - Ordering: replay yields the records in the order their appends
 *   returned. After compact returns 0, replay yields exactly its records, in
 *   its order, then those appended later; a failed compact leaves the state
 *   as before. A record that cannot be read back whole (a torn write, a bad
 *   checksum) is skipped and logged by the backend, never handed out.
 * - Threads: open, replay and close are called from the thread that opens or
 *   frees the job table, while no other op runs. append and compact are
 *   called from any thread (HTTP threads, the GL thread, CPU workers, the
 *   daemon's housekeeping) but always under the registry's lock, so never
 *   two at once. size may be called from any thread at any time. */
#ifndef VX_JOBS_STATE_H
#define VX_JOBS_STATE_H

#include <stddef.h>

#include <cjson/cJSON.h>

#include "util/err.h"

typedef struct vx_jobstate_ops {
    const char *name; /* "local" */
    /* Opens (creating) the state at where (the local journal: a file path).
     * Returns the backend's handle, or NULL with err. */
    void *(*open)(const char *where, vx_err *err);
    void (*close)(void *st);
    /* Calls fn for every record in order; returns their number, or -1. */
    long (*replay)(void *st, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err);
    /* Appends one record durably. owed: for a new job's first record, the
     * records the unfinished jobs (it included) are still to write, which
     * the backend may keep room for by refusing this one; 0 otherwise.
     * Errors: VX_ENOSPC insufficient_storage (full: the API answers 507),
     * VX_EIO. */
    int (*append)(void *st, const cJSON *rec, size_t owed, vx_err *err);
    /* Replaces the whole state with recs, atomically. */
    int (*compact)(void *st, cJSON *const *recs, size_t n, vx_err *err);
    /* Bytes the state holds, which grow with appends until a compact
     * (vx_jobs_maintain compacts past a limit); -1 = unknown, never
     * compacted for size. */
    long (*size)(void *st);
    /* 1 while appends reach what the next open replays (NULL: always);
     * any thread, any time. */
    int (*intact)(void *st);
} vx_jobstate_ops;

/* The local journal (state_local.c). */
extern const vx_jobstate_ops vx_jobstate_local;

#endif
