/* The job journal: an append-only file of JSON records, one per line, each
 * fsync'd before the state change it records is acknowledged. Replay reads
 * them back in order and ignores a torn last line (a crash mid-write: that
 * record was never acknowledged). Compaction rewrites the file with one
 * record per live job, atomically. Thread-safe. */
#ifndef VX_JOURNAL_H
#define VX_JOURNAL_H

#include <stddef.h>

#include <cjson/cJSON.h>

#include "util/err.h"

typedef struct vx_journal vx_journal;

/* Opens (creating) the journal at path. Owned. */
vx_journal *vx_journal_open(const char *path, vx_err *err);
void vx_journal_close(vx_journal *j);
/* Calls fn for every complete record in file order. Returns the number of
 * records, or -1. Corrupt lines in the middle are logged and skipped. */
long vx_journal_replay(vx_journal *j, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err);
/* Appends one record and makes it durable (fdatasync). */
int vx_journal_append(vx_journal *j, const cJSON *rec, vx_err *err);
/* Replaces the whole journal with recs (temp file, fsync, rename). */
int vx_journal_compact(vx_journal *j, cJSON *const *recs, size_t n, vx_err *err);
/* Bytes in the file now. */
long vx_journal_size(vx_journal *j);

#endif
