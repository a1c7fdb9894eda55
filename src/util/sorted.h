/* A growable array of pointers kept sorted by a string key (strcmp order),
 * with binary search: the job registry's and the store's indexes, and their
 * paging by "the first entry after this key". Items are not owned. Not
 * thread-safe: callers hold their own lock. items[0..n) may be read (and
 * compacted in place, keeping the order) directly. */
#ifndef VX_SORTED_H
#define VX_SORTED_H

#include <stddef.h>

typedef struct vx_sorted {
    void **items;
    size_t n, cap;
    const char *(*key)(const void *item); /* the key of an item */
} vx_sorted;

/* An empty array ordered by key(item). */
void vx_sorted_init(vx_sorted *s, const char *(*key)(const void *item));
/* Frees the array (not the items); s is empty again afterwards. */
void vx_sorted_free(vx_sorted *s);
/* Index of the item with this key (*found = 1), or where it would go. */
size_t vx_sorted_find(const vx_sorted *s, const char *key, int *found);
/* The item with this key, or NULL. */
void *vx_sorted_get(const vx_sorted *s, const char *key);
/* Inserts item at its place. Returns 0, or -1 (nothing changed) when an
 * item with its key is there already or there is no memory. */
int vx_sorted_insert(vx_sorted *s, void *item);
/* Removes and returns items[i] (i < n). */
void *vx_sorted_remove_at(vx_sorted *s, size_t i);
/* Index of the first item whose key is greater than key, for paging; 0
 * when key is NULL or empty. */
size_t vx_sorted_after(const vx_sorted *s, const char *key);

#endif
