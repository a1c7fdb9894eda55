/* Bearer-token authentication of /v1/ routes (--token). The token is kept
 * only as its SHA-256, and a presented token is compared by digest in
 * constant time, so neither its length nor its content leaks. */
#ifndef VX_AUTH_H
#define VX_AUTH_H

typedef struct vx_auth {
    int on; /* a token is configured */
    unsigned char digest[32];
} vx_auth;

/* Sets a up for token ("" or NULL: no authentication). */
void vx_auth_init(vx_auth *a, const char *token);
/* 1 when an Authorization header value (NULL: none) carries the token as
 * "Bearer <token>" (scheme in any case, blanks after it skipped), else 0. */
int vx_auth_ok(const vx_auth *a, const char *authorization);

#endif
