#include "auth.h"

#include <nettle/memops.h>
#include <nettle/sha2.h>
#include <string.h>
#include <strings.h>

_Static_assert(sizeof(((vx_auth *)0)->digest) == SHA256_DIGEST_SIZE, "digest size");

static void digest(const char *s, size_t n, unsigned char out[SHA256_DIGEST_SIZE])
{
    struct sha256_ctx ctx;
    sha256_init(&ctx);
    sha256_update(&ctx, n, (const uint8_t *)s);
    sha256_digest(&ctx, SHA256_DIGEST_SIZE, out);
}

void vx_auth_init(vx_auth *a, const char *token)
{
    memset(a, 0, sizeof *a);
    if (!token || !token[0]) return;
    digest(token, strlen(token), a->digest);
    a->on = 1;
}

int vx_auth_ok(const vx_auth *a, const char *authorization)
{
    const char *t = authorization;
    if (!t || strncasecmp(t, "Bearer ", 7) != 0) return 0;
    t += 7;
    while (*t == ' ' || *t == '\t')
        t++;
    /* the header's trailing blanks are not part of its value (RFC 9110 5.5) */
    size_t n = strlen(t);
    while (n && (t[n - 1] == ' ' || t[n - 1] == '\t'))
        n--;
    unsigned char d[SHA256_DIGEST_SIZE];
    digest(t, n, d);
    return memeql_sec(d, a->digest, sizeof d);
}
