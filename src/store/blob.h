/* Byte storage under the store: the seam between the store and its
 * backends (local: the data dir; file: a shared POSIX dir; s3: an
 * S3-compatible object store).
 *
 * A backend holds named byte objects under keys, relative paths such as
 * "meshes/<sha256>.obj", "blobs/<sha256>.json" or "results/<job id>/a.png".
 * The first path component is the namespace ("meshes", "blobs", "results").
 * The store (store.c and friends) keeps every index, pin and budget in
 * memory and calls these ops for the bytes only; adding a backend is one new
 * blob_<name>.c with its vx_blob_ops and a flag that sets
 * vx_store_desc.blob_ops.
 *
 * Contract, for every backend:
 * - Errors: each op returns 0, or -1 with errno set (ENOENT: no such key;
 *   ENOSPC/EDQUOT: out of space, which the store reports as VX_ENOSPC;
 *   EAGAIN: a remote backend is unreachable for now (connection errors,
 *   timeouts and 5xx answers after its retries), VX_EUNAVAIL (503 with
 *   Retry-After); EIO and others: VX_EIO). Ops that take a vx_err fill it as well (messages
 *   name no server path; paths go to the log only).
 * - Atomicity: a key is either absent or has its complete bytes; put_file,
 *   put_bytes and move replace a key atomically (never a partial object).
 * - Durability: stage and put_bytes return after the bytes are on stable
 *   storage (local: written, fsync'd, renamed, directory fsync'd for
 *   put_bytes). put_file, move and remove are atomic at once but durable
 *   only after the next sync of their namespace returns 0 (local: the
 *   rename or unlink, then an fsync of the directory).
 * - Ordering: ops on one key take effect in call order; across keys the
 *   only ordering is the one sync gives (the store puts a mesh's data, syncs,
 *   and only then puts its metadata: metadata present = mesh complete).
 * - Threads: any thread, concurrently (HTTP handlers commit meshes, job
 *   workers and the GL thread put blobs and results, the eviction timer
 *   removes them); a backend locks what it shares itself (local: nothing but
 *   an atomic counter). The store serialises the calls whose order matters
 *   (put then pin, unpin then remove) under its own lock, so ops may block
 *   on I/O but must never call back into the store.
 * - Serving: path gives a local file path for a key, for the engines (which
 *   read and write local files) and for HTTP responses; a remote backend
 *   keeps a local cache dir and answers with the cached copy. */
#ifndef VX_BLOB_H
#define VX_BLOB_H

#include <stddef.h>
#include <stdint.h>

#include "util/err.h"

typedef struct vx_blob vx_blob;

/* Where a backend keeps the bytes and how it reaches them; zero fields mean
 * the default. The local backend reads none of it. */
typedef struct vx_blob_conf {
    const char *url;              /* file:///DIR or s3://BUCKET/PREFIX?endpoint=URL&region=R */
    const char *credentials_file; /* s3: NULL = AWS_ACCESS_KEY_ID & co from the environment */
    uint64_t cache_max_bytes;     /* s3: local copies kept (LRU); 0 = no limit */
    uint64_t part_size;           /* s3: multipart above this, in parts of it; 0 = 64 MiB */
    double timeout_s;             /* s3: connect timeout, and the longest stall; 0 = 30 */
    int retries;                  /* s3: tries after the first on 5xx/connection errors; 0 = 3,
                                     -1 = none */
} vx_blob_conf;

typedef struct vx_blob_ops {
    const char *name; /* "local", "file", "s3" */
    /* 1 when other daemons may share the bytes (file, s3): the store then
     * removes only what it indexed itself (no startup clean-up of objects
     * it does not know, no removal of content-addressed blobs). */
    int shared;
    /* Opens the backend for the data dir (which exists; local: the bytes'
     * root, others: their local state and cache) as conf says (NULL: all
     * defaults). */
    vx_blob *(*open)(const char *data_dir, const vx_blob_conf *conf, vx_err *err);
    void (*close)(vx_blob *b);
    /* Writes n bytes to a fresh staged object of namespace ns (made with
     * make_prefix before), durably, and
     * names it in tmp (not visible under any key; pass to put_file, or
     * drop with discard). */
    int (*stage)(vx_blob *b, const char *ns, const void *data, size_t n, char *tmp, size_t tmpn);
    /* Drops a staged object (or an upload temp file) that was not put. */
    void (*discard)(vx_blob *b, const char *tmp);
    /* Moves a staged object, or a complete fsync'd local file on the data
     * dir's file system, to key (replacing it); see sync for durability. */
    int (*put_file)(vx_blob *b, const char *src, const char *key);
    /* Stores data under key atomically and durably (also its namespace). */
    int (*put_bytes)(vx_blob *b, const char *key, const void *data, size_t n, vx_err *err);
    /* The bytes of key, owned, NUL-terminated (*n = length, max as in
     * vx_read_file); NULL with err kind VX_ENOTFOUND, VX_ETOOBIG or VX_EIO. */
    char *(*read)(vx_blob *b, const char *key, size_t max, size_t *n, vx_err *err);
    /* 0 when key is a readable object, 1 when it is a prefix (that
     * make_prefix made, or that holds objects), -1 (ENOENT) when neither;
     * with its size in bytes (a prefix: the sum of its objects) and the time
     * it was last put or touched (wall clock) where not NULL. */
    int (*stat)(vx_blob *b, const char *key, uint64_t *bytes, double *mtime);
    /* Marks key (an object or prefix) used now (the results' LRU order). */
    int (*touch)(vx_blob *b, const char *key);
    /* Renames an object; see sync for durability. */
    int (*move)(vx_blob *b, const char *from, const char *to);
    /* Removes an object (ENOENT is success); see sync for durability. */
    int (*remove)(vx_blob *b, const char *key);
    /* Removes a prefix and every object under it (a job's results). */
    int (*remove_prefix)(vx_blob *b, const char *prefix);
    /* Makes prefix exist, empty or not (local: mkdir -p), so that path()
     * of it names a dir the engines can write into. */
    int (*make_prefix)(vx_blob *b, const char *prefix, vx_err *err);
    /* Makes the puts, moves and removes done so far directly under ns (a
     * namespace or a prefix) durable. */
    int (*sync)(vx_blob *b, const char *ns, vx_err *err);
    /* Calls fn with each name directly under ns (objects and prefixes, in
     * no particular order, "." names skipped); fn returns nonzero to stop.
     * Keys may be removed from inside fn. 0, or -1 when ns is unreadable. */
    int (*list)(vx_blob *b, const char *ns, int (*fn)(const char *name, void *ud), void *ud);
    /* A local file path for key into buf (the key need not exist; a
     * remote backend fetches the object, or every object under the prefix,
     * into its cache first: -1 with errno when that fails). */
    int (*path)(vx_blob *b, const char *key, char *buf, size_t n);
    /* 1 when the bytes are reachable now (for /readyz; quick: one try). */
    int (*ping)(vx_blob *b);
} vx_blob_ops;

/* The default backend: the data dir itself (src/store/blob_local.c). */
extern const vx_blob_ops vx_blob_local;
/* file:///DIR: the local layout rooted at a shared DIR (blob_local.c). */
extern const vx_blob_ops vx_blob_file;
/* s3://BUCKET/PREFIX: an S3-compatible store through libcurl, signed with
 * AWS Signature V4, with a local cache (src/store/blob_s3.c). */
extern const vx_blob_ops vx_blob_s3;

/* The backend a --blob-store URL names (NULL or "" = local), or NULL with
 * err set (VX_EINVAL) for an unknown scheme. */
const vx_blob_ops *vx_blob_backend(const char *url, vx_err *err);

#endif
