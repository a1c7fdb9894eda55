/* Sorted pointer array (sorted.h). */
#include "util/sorted.h"

#include <stdlib.h>
#include <string.h>

void vx_sorted_init(vx_sorted *s, const char *(*key)(const void *item))
{
    memset(s, 0, sizeof *s);
    s->key = key;
}

void vx_sorted_free(vx_sorted *s)
{
    free(s->items);
    s->items = NULL;
    s->n = s->cap = 0;
}

size_t vx_sorted_find(const vx_sorted *s, const char *key, int *found)
{
    size_t lo = 0, hi = s->n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        int c = strcmp(s->key(s->items[mid]), key);
        if (c == 0) {
            *found = 1;
            return mid;
        }
        if (c < 0)
            lo = mid + 1;
        else
            hi = mid;
    }
    *found = 0;
    return lo;
}

void *vx_sorted_get(const vx_sorted *s, const char *key)
{
    int found;
    size_t at = vx_sorted_find(s, key, &found);
    return found ? s->items[at] : NULL;
}

int vx_sorted_insert(vx_sorted *s, void *item)
{
    int found;
    size_t at = vx_sorted_find(s, s->key(item), &found);
    if (found) return -1;
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 256;
        void **n = realloc(s->items, cap * sizeof *n);
        if (!n) return -1;
        s->items = n;
        s->cap = cap;
    }
    memmove(s->items + at + 1, s->items + at, (s->n - at) * sizeof *s->items);
    s->items[at] = item;
    s->n++;
    return 0;
}

void *vx_sorted_remove_at(vx_sorted *s, size_t i)
{
    void *item = s->items[i];
    memmove(s->items + i, s->items + i + 1, (s->n - i - 1) * sizeof *s->items);
    s->n--;
    return item;
}

size_t vx_sorted_after(const vx_sorted *s, const char *key)
{
    if (!key || !*key) return 0;
    int found;
    size_t i = vx_sorted_find(s, key, &found);
    return found ? i + 1 : i;
}
