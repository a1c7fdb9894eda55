/* A growable byte buffer for tests that write files in memory (the PLY
 * and STL reader tests), and the xorshift generator they draw from. The
 * helpers abort on allocation failure (test fixtures). */
#ifndef VX_TEXT_BUF_H
#define VX_TEXT_BUF_H

#include <stddef.h>
#include <stdint.h>

typedef struct tbuf {
    char *p; /* NUL-terminated after the n bytes; free() it */
    size_t n, cap;
} tbuf;

/* Appends n bytes of d. */
void tbuf_put(tbuf *b, const void *d, size_t n);
/* Appends printf output (at most 511 bytes a call). */
void tbuf_printf(tbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* The next xorshift64 value of *state (never 0). */
uint64_t test_rand(uint64_t *state);

#endif
