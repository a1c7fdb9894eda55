/* File-system helpers for durable writes. Any thread. */
#ifndef VX_FSUTIL_H
#define VX_FSUTIL_H

#include <stddef.h>
#include <stdint.h>

#include "util/clock.h" /* vx_now, vx_mono: their callers include this header */
#include "util/err.h"
#include "util/path.h"

/* mkdir -p with mode 0750; 0 or -1 (VX_EIO). */
int vx_mkdirs(const char *path, vx_err *err);
/* After an ENOENT (errno) creating a file in dir: makes dir again, one
 * level only (removed behind the daemon; its parent is not made), mode
 * 0750, logged as store.dir_made_again. 1 when dir is there now (made, or
 * by another thread meanwhile), so that the caller tries once more; else 0
 * with errno ENOENT (ENOSPC or EDQUOT for a full disk). */
int vx_mkdir_again(const char *dir);
/* fsync of a directory, so renames and creations inside it survive a crash. */
int vx_fsync_dir(const char *dir, vx_err *err);
/* Writes data to path atomically: temp file, fsync, rename, fsync dir. */
int vx_write_atomic(const char *path, const void *data, size_t len, vx_err *err);
/* Opens a regular file to read, never waiting on a FIFO: the descriptor,
 * or -1 with errno (EISDIR a directory, EINVAL another file that is not
 * regular). */
int vx_open_regular(const char *path);
/* Reads a whole (small) file into an owned NUL-terminated buffer; NULL on error. */
char *vx_read_file(const char *path, size_t max, size_t *len, vx_err *err);
/* rm -r of a directory tree (results); 0 or -1. */
int vx_remove_tree(const char *path);
/* Total bytes of the regular files under a directory tree. */
uint64_t vx_tree_bytes(const char *path);
/* A wall-clock time (vx_now) as RFC 3339 UTC with milliseconds. */
void vx_rfc3339(double t, char out[32]);
/* Writes all n bytes (retrying short writes and EINTR); 0, or -1 with errno
 * set (a write that makes no progress is ENOSPC). */
int vx_write_all(int fd, const void *p, size_t n);
/* Writes n bytes to a new file path (O_EXCL, mode 0640) and fsyncs it; 0,
 * or -1 with errno set (path is then removed). */
int vx_write_new(const char *path, const void *data, size_t n);
/* Copies src to a new file dst (O_EXCL) and fsyncs it, runs of zeros left
 * as holes (a sparse source, a damaged journal's tail of zeros, copies as a
 * few blocks); 0, or -1 with errno set (dst is then removed). */
int vx_copy_file(const char *src, const char *dst);
/* Bytes an unprivileged process may still write on dir's file system; 0 or -1. */
int vx_disk_free(const char *dir, uint64_t *free_bytes);
/* Removes every occurrence of dir (and the '/' after it) from msg, in
 * place: messages that reach clients name no server paths. */
void vx_scrub_path(char *msg, const char *dir);
/* The file name of path, after its last '/' (path itself without one):
 * what an error message names, not where the server keeps the file. */
const char *vx_path_base(const char *path);
/* Parses a size with an optional K/M/G/T suffix (powers of 1024); 0 or -1. */
int vx_parse_size(const char *s, uint64_t *out);

#endif
