/* The job journal: an append-only file of JSON records, one per line
 * framed by its CRC-32 ("#crc32hex JSON"), each fsync'd before the state
 * change it records is acknowledged. A write that fails part-way (ENOSPC)
 * is cut off again, so it never takes the next record with it. Replay
 * reads the records back in order, skips lines whose CRC fails, and cuts a
 * torn last line (a crash mid-write: that record was never acknowledged).
 * Compaction rewrites the file with one record per live job, atomically.
 * 1 MiB stays allocated past the end (fallocate), so that records still go
 * in on a full disk. Thread-safe. */
#ifndef VX_JOURNAL_H
#define VX_JOURNAL_H

#include <stddef.h>

#include <cjson/cJSON.h>

#include "util/err.h"

typedef struct vx_journal vx_journal;

/* The largest record's JSON (a job's snapshot: its params at most a
 * --max-json-bytes body, large inline inputs stored as blobs): append
 * refuses a larger one, and replay reads a longer line as damage, held in
 * memory no further than this. */
#define VX_JOURNAL_MAX_RECORD (64 << 20)

/* Opens (creating) the journal at path. Owned. */
vx_journal *vx_journal_open(const char *path, vx_err *err);
void vx_journal_close(vx_journal *j);
/* Calls fn for every complete record in file order. Returns the number of
 * records, or -1. Corrupt lines in the middle (one over
 * VX_JOURNAL_MAX_RECORD too) are logged and skipped; a torn tail is
 * truncated away. The file is read in pieces; one with damage is first
 * copied to PATH.damaged-TIME, its runs of zeros as holes. */
long vx_journal_replay(vx_journal *j, void (*fn)(const cJSON *rec, void *ud), void *ud,
                       vx_err *err);
/* Appends one record and makes it durable (fdatasync); on failure the file
 * is as before (VX_ENOSPC insufficient_storage when the disk is full;
 * VX_ETOOBIG too_large over VX_JOURNAL_MAX_RECORD).
 * owed: for a new job's first record, the records the jobs accepted so far
 * (it included) still have to write, 0 for any other record. Such a record
 * must leave them room in the space reserved past the end (at least half of
 * it), or is refused (VX_ENOSPC) where the reserve cannot be topped up. */
int vx_journal_append(vx_journal *j, const cJSON *rec, size_t owed, vx_err *err);
/* Replaces the whole journal with recs (temp file, fsync, rename). */
int vx_journal_compact(vx_journal *j, cJSON *const *recs, size_t n, vx_err *err);
/* Bytes in the file now. */
long vx_journal_size(vx_journal *j);
/* 1 while the file appended to is the one at the journal's path (0: it was
 * removed or another file put in its place: appends reach no restart). */
int vx_journal_intact(vx_journal *j);

#endif
