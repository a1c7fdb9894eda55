/* Uploads: streamed to DATA/tmp and hashed as they arrive (store.h). */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "store/store_int.h"
#include "util/log.h"

void vx_store_hex(const uint8_t digest[SHA256_DIGEST_SIZE], char id[65])
{
    for (int i = 0; i < SHA256_DIGEST_SIZE; i++)
        sprintf(id + 2 * i, "%02x", digest[i]);
}

vx_upload *vx_upload_begin(vx_store *s, vx_err *err)
{
    vx_upload *u = calloc(1, sizeof *u);
    if (!u) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    pthread_mutex_lock(&s->lock);
    unsigned long seq = ++s->upload_seq;
    pthread_mutex_unlock(&s->lock);
    u->s = s;
    snprintf(u->path, sizeof u->path, "%s/tmp/upload-%lu-%lu", s->dir, (unsigned long)getpid(),
             seq);
    u->fd = open(u->path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (u->fd < 0 && store_tmp_again(s))
        u->fd = open(u->path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (u->fd < 0) {
        int e = errno;
        VX_ERROR("store.upload_create_failed", "path=%s error=%d", VX_Q(u->path), e);
        vx_err_set(err, vx_err_io_kind(e), e == ENOSPC ? "insufficient_storage" : "upload_failed",
                   "cannot store the upload: %s", strerror(e));
        free(u);
        return NULL;
    }
    sha256_init(&u->sha);
    return u;
}

static int upload_flush(vx_upload *u, vx_err *err)
{
    size_t off = 0;
    while (off < u->nbuf) {
        ssize_t n = write(u->fd, u->buf + off, u->nbuf - off);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            int e = n == 0 ? ENOSPC : errno;
            return vx_err_set(err, vx_err_io_kind(e),
                              e == ENOSPC || e == EDQUOT ? "insufficient_storage" : "upload_failed",
                              "cannot store the upload: %s", strerror(e));
        }
        off += (size_t)n;
    }
    u->nbuf = 0;
    return 0;
}

int vx_upload_write(vx_upload *u, const void *data, size_t n, vx_err *err)
{
    const unsigned char *p = data;
    sha256_update(&u->sha, n, p);
    if (u->nhead < sizeof u->head) {
        size_t k = sizeof u->head - u->nhead < n ? sizeof u->head - u->nhead : n;
        memcpy(u->head + u->nhead, p, k);
        u->nhead += k;
    }
    u->bytes += n;
    while (n) {
        size_t k = sizeof u->buf - u->nbuf < n ? sizeof u->buf - u->nbuf : n;
        memcpy(u->buf + u->nbuf, p, k);
        u->nbuf += k;
        p += k;
        n -= k;
        if (u->nbuf == sizeof u->buf && upload_flush(u, err)) return -1;
    }
    return 0;
}

uint64_t vx_upload_bytes(const vx_upload *u)
{
    return u->bytes;
}

const unsigned char *vx_upload_head(const vx_upload *u, size_t *n)
{
    *n = u->nhead;
    return u->head;
}

const char *vx_upload_path(const vx_upload *u)
{
    return u->path;
}

int vx_upload_finish(vx_upload *u, char id[65], vx_err *err)
{
    if (upload_flush(u, err)) return -1;
    if (fsync(u->fd) != 0)
        return vx_err_set(err, vx_err_io_kind(errno),
                          errno == ENOSPC ? "insufficient_storage" : "upload_failed",
                          "cannot store the upload: %s", strerror(errno));
    uint8_t digest[SHA256_DIGEST_SIZE];
    sha256_digest(&u->sha, sizeof digest, digest);
    vx_store_hex(digest, id);
    return 0;
}

void vx_upload_abort(vx_upload *u)
{
    if (!u) return;
    if (u->fd >= 0) close(u->fd);
    unlink(u->path);
    free(u);
}
