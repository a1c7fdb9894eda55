/* Private to src/store: the store's state, shared by store*.c. The bytes
 * live behind s->ops (blob.h); this state is the in-memory index. */
#ifndef VX_STORE_INT_H
#define VX_STORE_INT_H

#include <nettle/sha2.h>
#include <pthread.h>

#include "store/blob.h"
#include "store/store.h"
#include "util/path.h"
#include "util/sorted.h"

typedef struct mesh_entry {
    char id[65];
    char ext[8];
    char *meta; /* the metadata as compact JSON text (a fifth of a cJSON tree); NULL once deleted */
    int pins;   /* unfinished jobs using it */
    int deleted; /* gone from the API; the file stays while pinned */
    /* The version of its file last found to hash to its id (dev, inode,
     * size, mtime, ctime; all 0 = none yet): not hashed again while the
     * file's stat says the same. */
    int64_t checked[7];
    /* The version last found damaged (another hash, or another size than
     * the upload): not hashed again while the stat says the same (a huge
     * file in its place would tie up every reader). */
    int64_t bad[7];
} mesh_entry;

/* The index's key: a mesh entry's id. */
static inline const char *vx_store_entry_id(const void *e)
{
    return ((const mesh_entry *)e)->id;
}

typedef struct blob_entry {
    char id[65];
    int pins;
} blob_entry;

typedef struct result_entry {
    char jid[48];
    uint64_t bytes;
    double last_access; /* wall clock, so it survives restarts via mtime */
} result_entry;

struct vx_store {
    char dir[VX_PATH_MAX];
    vx_store_desc desc;
    const vx_blob_ops *ops; /* desc.blob_ops, or vx_blob_local */
    vx_blob *blob;
    pthread_mutex_t lock;
    vx_sorted meshes; /* of mesh_entry *, by id */
    size_t ndeleted;  /* entries of meshes[] that are deleted */
    blob_entry *blobs;
    size_t nblobs, capblobs;
    result_entry *results;
    size_t nresults, capresults;
    uint64_t results_bytes;
    uint64_t evicted; /* results the budget removed (atomic) */
    unsigned long upload_seq;
    int lock_fd;                    /* DATA/voxeld.lock, flock'd for the store's life */
    int dir_lock_fd;                /* DATA itself, flock'd too (-1: not lockable) */
    const vx_mesh_catalog *catalog; /* NULL = none (the index is the catalog) */
};

struct vx_upload {
    vx_store *s;
    int fd;
    char path[VX_PATH_MAX];
    struct sha256_ctx sha;
    uint64_t bytes;
    unsigned char head[512]; /* the first bytes, for sniffing (binary STL: 84) */
    size_t nhead;
    char buf[1 << 16]; /* write coalescing: network chunks are small */
    size_t nbuf;
};

/* Loads the mesh index from the byte store (vx_store_open); -1 (errno)
 * when the meshes namespace cannot be listed. */
int vx_store_load_meshes(vx_store *s);
/* Loads the results budget from the byte store (vx_store_open); -1 (errno)
 * when the results namespace cannot be listed. */
int vx_store_load_results(vx_store *s);
/* Removes the deleted meshes that no pin holds; caller holds the lock.
 * Returns how many went (their namespace then needs a sync). */
size_t vx_store_collect_meshes_locked(vx_store *s);
/* Hex SHA-256 of a digest into id. */
void vx_store_hex(const uint8_t digest[SHA256_DIGEST_SIZE], char id[65]);
/* After an ENOENT creating a file in DATA/tmp: makes DATA/tmp again (removed
 * behind the daemon); 1 when made, so that the caller tries once more. */
int store_tmp_again(vx_store *s);

#endif
