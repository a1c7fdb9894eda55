/* Compressed result downloads: a libmicrohttpd response whose body is a
 * file compressed on the fly with libzstd or zlib (gzip), a chunk at a
 * time, so that memory stays bounded (about 0.5 MiB a download plus the
 * library's window) whatever the file's size. */
#ifndef VX_COMPRESS_H
#define VX_COMPRESS_H

#include <microhttpd.h>

#include "request.h"

/* The Content-Encoding token of a coding ("zstd", "gzip"; NULL for identity). */
const char *vx_compress_token(vx_req_coding coding);
/* A response of unknown length streaming fd (owned: closed with the
 * response, or here on failure) compressed with coding (zstd or gzip),
 * adding the bytes it hands out to *sent (the request's bytes_out, for
 * its log line and metrics); NULL when no memory or the library cannot
 * start. Any thread. */
struct MHD_Response *vx_compress_response(int fd, vx_req_coding coding, uint64_t *sent);

#endif
