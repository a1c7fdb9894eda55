/* Streaming compression of result files (compress.h): libmicrohttpd pulls
 * the body through a content reader; each pull reads at most one input
 * chunk from the file and hands out what the encoder has made. zstd level 1
 * and gzip level 1: a download should go at the speed of the network, and
 * voxel grids compress very well even at the fastest levels. */
#include "compress.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include "metrics.h"
#include "util/log.h"

#define CHUNK (256 * 1024)

typedef struct zsrc {
    int fd;
    vx_req_coding coding;
    ZSTD_CCtx *zc;
    z_stream gz;
    int gz_on;
    unsigned char in[CHUNK], out[CHUNK];
    size_t ilen, ipos; /* input not yet taken by the encoder */
    size_t olen, opos; /* output not yet handed out */
    int eof, done;
    uint64_t *sent; /* the request's bytes_out: compressed bytes handed out */
} zsrc;

const char *vx_compress_token(vx_req_coding coding)
{
    return coding == VX_CODING_ZSTD ? "zstd" : coding == VX_CODING_GZIP ? "gzip" : NULL;
}

/* Reads the next input chunk once the encoder has taken the last. 0 or -1. */
static int read_more(zsrc *s)
{
    if (s->ipos < s->ilen || s->eof) return 0;
    ssize_t n;
    do
        n = read(s->fd, s->in, sizeof s->in);
    while (n < 0 && errno == EINTR);
    if (n < 0) return -1;
    s->ilen = (size_t)n;
    s->ipos = 0;
    if (n == 0) s->eof = 1;
    return 0;
}

/* Runs the encoder once into the empty output buffer. 0 or -1. */
static int encode(zsrc *s)
{
    if (read_more(s)) return -1;
    s->opos = s->olen = 0;
    if (s->coding == VX_CODING_ZSTD) {
        ZSTD_inBuffer in = {s->in, s->ilen, s->ipos};
        ZSTD_outBuffer out = {s->out, sizeof s->out, 0};
        size_t rc = ZSTD_compressStream2(s->zc, &out, &in, s->eof ? ZSTD_e_end : ZSTD_e_continue);
        if (ZSTD_isError(rc)) return -1;
        s->ipos = in.pos;
        s->olen = out.pos;
        if (s->eof && rc == 0) s->done = 1;
        return 0;
    }
    s->gz.next_in = s->in + s->ipos;
    s->gz.avail_in = (uInt)(s->ilen - s->ipos);
    s->gz.next_out = s->out;
    s->gz.avail_out = (uInt)sizeof s->out;
    int rc = deflate(&s->gz, s->eof ? Z_FINISH : Z_NO_FLUSH);
    if (rc == Z_STREAM_ERROR) return -1;
    s->ipos = s->ilen - s->gz.avail_in;
    s->olen = sizeof s->out - s->gz.avail_out;
    if (rc == Z_STREAM_END) s->done = 1;
    return 0;
}

static ssize_t reader(void *cls, uint64_t pos, char *buf, size_t max)
{
    zsrc *s = cls;
    (void)pos;
    while (s->opos == s->olen) {
        if (s->done) return MHD_CONTENT_READER_END_OF_STREAM;
        if (encode(s)) {
            VX_WARN("http.compress_failed", "coding=%s", vx_compress_token(s->coding));
            return MHD_CONTENT_READER_END_WITH_ERROR;
        }
    }
    size_t n = s->olen - s->opos < max ? s->olen - s->opos : max;
    memcpy(buf, s->out + s->opos, n);
    s->opos += n;
    *s->sent += n; /* the request is alive while its body is read */
    return (ssize_t)n;
}

static void src_free(void *cls)
{
    zsrc *s = cls;
    if (!s) return;
    ZSTD_freeCCtx(s->zc);
    if (s->gz_on) deflateEnd(&s->gz);
    if (s->fd >= 0) close(s->fd);
    free(s);
}

struct MHD_Response *vx_compress_response(int fd, vx_req_coding coding, uint64_t *sent)
{
    zsrc *s = calloc(1, sizeof *s);
    if (!s) {
        close(fd);
        return NULL;
    }
    s->fd = fd;
    s->coding = coding;
    s->sent = sent;
    int ok = 0;
    if (coding == VX_CODING_ZSTD) {
        s->zc = ZSTD_createCCtx();
        ok = s->zc && !ZSTD_isError(ZSTD_CCtx_setParameter(s->zc, ZSTD_c_compressionLevel, 1));
    } else if (coding == VX_CODING_GZIP) {
        /* windowBits 15 + 16: a gzip header and trailer around deflate. */
        ok = deflateInit2(&s->gz, 1, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) == Z_OK;
        s->gz_on = ok;
    }
    struct MHD_Response *r =
        ok ? MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 64 * 1024, reader, s, src_free)
           : NULL;
    if (!r) src_free(s);
    return r;
}
