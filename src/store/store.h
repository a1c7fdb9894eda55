/* The data directory: content-addressed meshes and per-job results.
 *
 *   DATA/meshes/<sha256>.<obj|drc>   the uploaded bytes, as sent
 *   DATA/meshes/<sha256>.json        its metadata (the API's Mesh resource)
 *   DATA/meshes/<sha256>.deleted     the metadata of a deleted mesh whose file
 *                                    unfinished jobs still hold (see pins)
 *   DATA/blobs/<sha256>.json         large inline job inputs (gregory frames)
 *   DATA/results/<job id>/<name>.<ext>
 *   DATA/tmp/                        uploads in flight (emptied at start)
 *   DATA/journal.log                 job journal (src/jobs/journal.c)
 *
 * A mesh is acknowledged only after its file and metadata are fsync'd and
 * renamed into place (file first, metadata last: metadata present = mesh
 * complete). Results live under a byte/idle-age budget, least recently used
 * evicted first. All functions are thread-safe. The bytes of meshes, blobs
 * and results go through a byte-store backend (store/blob.h); the layout
 * above is the local one's. Source: store_open.c (life), store_upload.c,
 * store.c (meshes), store_blob.c, store_result.c; store_int.h (state). */
#ifndef VX_STORE_H
#define VX_STORE_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

#include "util/err.h"

typedef struct vx_store vx_store;

struct vx_blob_ops;

typedef struct vx_store_desc {
    uint64_t results_max_bytes; /* 0 = no byte budget */
    double results_max_age_s;   /* since last access; 0 = no age limit */
    /* Where the bytes live (store/blob.h); NULL = the data dir itself
     * (vx_blob_local). Index, pins and budget stay in this process. */
    const struct vx_blob_ops *blob_ops;
    const struct vx_blob_conf *blob_conf; /* its configuration; NULL = defaults */
} vx_store_desc;

/* Opens (creating) the data dir. Owned; close with vx_store_close. */
vx_store *vx_store_open(const char *data_dir, const vx_store_desc *desc, vx_err *err);
void vx_store_close(vx_store *s);
const char *vx_store_dir(const vx_store *s);
/* 1 when a file can be created in the data dir now, or only room is
 * missing (ENOSPC, EDQUOT: the free space check's to report). */
int vx_store_writable(vx_store *s);
/* The byte store's backend name ("local", "file", "s3"), and 1 when it is
 * reachable now (one quick try: /readyz). */
const char *vx_store_backend(const vx_store *s);
int vx_store_reachable(vx_store *s);

/* An upload streamed to a temp file and hashed as it arrives. */
typedef struct vx_upload vx_upload;
vx_upload *vx_upload_begin(vx_store *s, vx_err *err);
int vx_upload_write(vx_upload *u, const void *data, size_t n, vx_err *err);
uint64_t vx_upload_bytes(const vx_upload *u);
/* The first bytes received (up to 64), for sniffing the format. */
const unsigned char *vx_upload_head(const vx_upload *u, size_t *n);
/* Flushes and fsyncs the temp file and writes the hex SHA-256 into id. */
int vx_upload_finish(vx_upload *u, char id[65], vx_err *err);
const char *vx_upload_path(const vx_upload *u);
/* Removes the temp file and frees u; NULL is a no-op. */
void vx_upload_abort(vx_upload *u);

/* Moves a finished upload into the store as mesh `id` with the extension
 * and metadata given, durably; frees u. Sets *existed when the mesh was
 * already there (u is then discarded). */
int vx_store_mesh_commit(vx_store *s, vx_upload *u, const char *id, const char *ext,
                         const cJSON *meta, int *existed, vx_err *err);
/* An upload u of mesh id's bytes (finished) that the store has, deleted
 * but pinned included: where the stored file is missing or no longer
 * hashes to id, writes it again from u (logged store.mesh_repaired); u
 * stays the caller's to free. 0, or -1 with err (store_failed). */
int vx_store_mesh_repair(vx_store *s, vx_upload *u, const char *id, const char *ext, vx_err *err);
/* Owned copy of a mesh's metadata, or NULL (VX_ENOTFOUND mesh_not_found). */
cJSON *vx_store_mesh_meta(vx_store *s, const char *id, vx_err *err);
/* Path of the mesh file into buf, also of a deleted mesh that pins still
 * hold (the runner's); -1 (VX_ENOTFOUND) when unknown, VX_EGONE
 * mesh_damaged when the file is missing or does not hash to id (hashed
 * once per version of the file: again when its stat changes). */
int vx_store_mesh_path(vx_store *s, const char *id, char *buf, size_t n, vx_err *err);
/* Mesh id's file opened read-only after the same checks, the fd checked
 * being the one returned (so the bytes read are the ones hashed); -1 with
 * err as vx_store_mesh_path. The caller closes it. */
int vx_store_mesh_open(vx_store *s, const char *id, vx_err *err);
/* The same with the file's path into buf (its extension names the format:
 * vx_mesh_read_fd) and the version checked (its stat: device, inode, size,
 * times) into version. */
int vx_store_mesh_open_path(vx_store *s, const char *id, char *buf, size_t n, int64_t version[7],
                            vx_err *err);
/* 0 when the file fd is still the version vx_store_mesh_open_path checked,
 * as after reading it; else -1 with VX_EGONE mesh_damaged (written in
 * place meanwhile). */
int vx_store_mesh_still_intact(const char *id, int fd, const int64_t version[7], vx_err *err);
/* Deletes a mesh: it disappears from meta, list and count at once (404 for
 * new jobs); its file stays while pins hold it (vx_store_mesh_path still
 * answers), and goes with the last unpin. */
int vx_store_mesh_delete(vx_store *s, const char *id, vx_err *err);
/* Pins: an unfinished job holds its meshes and blobs so that a delete does
 * not take them from under it. Pins live in memory only; the job journal
 * rebuilds them at start (then vx_store_collect removes what no pin holds).
 * Pins mesh id once more: -1 (VX_ENOTFOUND mesh_not_found) when it is not
 * stored or, unless deleted_ok, deleted. */
int vx_store_mesh_pin(vx_store *s, const char *id, int deleted_ok, vx_err *err);
/* Drops one pin; the last one of a deleted mesh removes its files. */
void vx_store_mesh_unpin(vx_store *s, const char *id);
/* Removes the deleted meshes and the blobs that no pin holds. Called once,
 * after the journal replay has pinned what unfinished jobs use. */
void vx_store_collect(vx_store *s);
/* Page of metadata sorted by id, starting after `after` (NULL = first).
 * Returns an owned array; next[0] = 0 when this is the last page; NULL
 * with err only when a catalog cannot answer. */
cJSON *vx_store_mesh_list(vx_store *s, const char *after, int limit, char next[65], vx_err *err);
/* Meshes stored (the catalog's count when it answers). */
size_t vx_store_mesh_count(vx_store *s);

/* A catalog of the meshes that exist, shared by several daemons on one
 * blob store (cluster mode: PostgreSQL's vx_meshes, src/jobs/cluster.c).
 * With one, what the API sees of meshes (metadata, list, count, delete,
 * whether an upload is new) is the catalog's; the store keeps the bytes,
 * and its own index only as a cache of them. A delete only tells the
 * catalog: the bytes stay for the jobs that name the mesh until the
 * catalog's owner purges them (vx_store_mesh_purge). Each call returns -1
 * with err when the catalog cannot answer (the API's 503). */
typedef struct vx_mesh_catalog {
    void *ud;
    /* Held (shared) from before an upload's bytes go in until put. */
    int (*lock)(void *ud, const char *id, vx_err *err);
    void (*unlock)(void *ud, const char *id);
    /* *existed = 1 when the mesh was there, live, already. */
    int (*put)(void *ud, const char *id, const cJSON *meta, int *existed, vx_err *err);
    /* 1 with *meta (owned), 0 when there is no such live mesh. */
    int (*get)(void *ud, const char *id, cJSON **meta, vx_err *err);
    /* 0, or VX_ENOTFOUND mesh_not_found. */
    int (*remove)(void *ud, const char *id, vx_err *err);
    cJSON *(*list)(void *ud, const char *after, int limit, char next[65], vx_err *err);
    long (*count)(void *ud, vx_err *err);
} vx_mesh_catalog;
/* Sets the catalog (NULL: none, this store's index is the catalog); it
 * must stay valid until unset. */
void vx_store_set_catalog(vx_store *s, const vx_mesh_catalog *c);
/* The catalog's purge of a deleted mesh: removes its bytes (format: its
 * metadata's) and this store's entry. -1 while a job here pins it. */
int vx_store_mesh_purge(vx_store *s, const char *id, const char *format);
/* 1 when mesh id's bytes are in the store. Without a catalog, as
 * vx_store_mesh_meta; with one, the catalog may name a mesh whose bytes
 * are not here (a store emptied or replaced under the same database): an
 * upload of it must then store them again. */
int vx_store_mesh_stored(vx_store *s, const char *id);
/* The metadata of every live mesh in this store's own index (owned
 * array): what a new catalog adds. */
cJSON *vx_store_mesh_local(vx_store *s);
/* 1 when id is 64 lowercase hex digits. */
int vx_store_valid_mesh_id(const char *id);

/* Blobs: large inline job inputs, content-addressed (id = hex SHA-256 of
 * the bytes), kept while a pin holds them. Stores data durably (written and
 * fsync'd, unless it is there already), pins it and writes its id. */
int vx_store_blob_put(vx_store *s, const void *data, size_t n, char id[65], vx_err *err);
/* Pins a stored blob (journal replay); -1 (VX_ENOTFOUND blob_not_found). */
int vx_store_blob_pin(vx_store *s, const char *id, vx_err *err);
/* Drops one pin; the last one removes the blob. */
void vx_store_blob_unpin(vx_store *s, const char *id);
/* The bytes of a blob (owned, NUL-terminated, *n = length), or NULL
 * (VX_ENOTFOUND blob_not_found, VX_EIO). */
char *vx_store_blob_read(vx_store *s, const char *id, size_t *n, vx_err *err);
/* Number of blobs held. */
size_t vx_store_blob_count(vx_store *s);

/* Creates DATA/results/<jid>/ (empty) and writes its path into buf. */
int vx_store_result_dir(vx_store *s, const char *jid, char *buf, size_t n, vx_err *err);
/* Records a finished result dir in the budget (after its files are written):
 * makes it durable in the store (a remote one: uploads it) and indexes it.
 * -1 with err when it could not be made durable (the local copy stays
 * indexed until vx_store_result_remove). */
int vx_store_result_commit(vx_store *s, const char *jid, vx_err *err);
/* Path of an output file; marks the result used (LRU). -1 with VX_EGONE
 * code result_evicted when the result dir is gone. */
int vx_store_result_file(vx_store *s, const char *jid, const char *file, char *buf, size_t n,
                         vx_err *err);
void vx_store_result_remove(vx_store *s, const char *jid);
/* The id a cluster wrote into its shared store (cluster mode checks that
 * every replica's store is the one its database names): 1 with it in out,
 * 0 when the store has none, -1 with err when it cannot be read. */
int vx_store_id_read(vx_store *s, char out[65], vx_err *err);
/* Writes id as the store's id (replacing any). 0, or -1 with err. */
int vx_store_id_write(vx_store *s, const char *id, vx_err *err);
/* A local store's results sorted at start-up by keep (called under the
 * store's lock; it may not call back): 1 keeps them; 0 removes them (jobs
 * gone or not succeeded: a crash's partial outputs, a delete's files a
 * crash kept); -1 moves them into a new DATA/lost+found/results-TIME/ (jobs
 * no record names: a journal lost or damaged), logged at error. A shared
 * store's are left alone. Returns how many were removed or moved. */
size_t vx_store_results_prune(vx_store *s, int (*keep)(void *ud, const char *jid), void *ud);
/* Evicts least recently used results until the budget holds; returns how
 * many were removed. Called after each job and periodically. */
int vx_store_results_evict(vx_store *s);
uint64_t vx_store_results_bytes(vx_store *s);
/* Results the budget has evicted since the store was opened. */
uint64_t vx_store_results_evicted(vx_store *s);

#endif
