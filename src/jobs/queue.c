#include "jobs/queue.h"

#include <errno.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "util/clock.h"

struct vx_queue {
    pthread_mutex_t lock;
    pthread_cond_t cond;  /* an item came, or the queue closed */
    pthread_cond_t space; /* an item left, or the queue closed */
    void **items;         /* ring buffer */
    size_t head, count, cap, capacity;
    int closed;
};

vx_queue *vx_queue_new(size_t capacity)
{
    vx_queue *q = calloc(1, sizeof *q);
    if (!q) return NULL;
    q->capacity = capacity;
    q->cap = 16;
    q->items = calloc(q->cap, sizeof *q->items);
    if (!q->items) {
        free(q);
        return NULL;
    }
    pthread_mutex_init(&q->lock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&q->cond, &ca);
    pthread_cond_init(&q->space, &ca);
    pthread_condattr_destroy(&ca);
    return q;
}

void vx_queue_free(vx_queue *q)
{
    if (!q) return;
    pthread_mutex_destroy(&q->lock);
    pthread_cond_destroy(&q->cond);
    pthread_cond_destroy(&q->space);
    free(q->items);
    free(q);
}

static int grow(vx_queue *q)
{
    size_t ncap = q->cap * 2;
    void **n = malloc(ncap * sizeof *n);
    if (!n) return -1;
    for (size_t i = 0; i < q->count; i++)
        n[i] = q->items[(q->head + i) % q->cap];
    free(q->items);
    q->items = n;
    q->cap = ncap;
    q->head = 0;
    return 0;
}

int vx_queue_push(vx_queue *q, void *item, int force)
{
    pthread_mutex_lock(&q->lock);
    int rc = -1;
    if (!q->closed && (force || !q->capacity || q->count < q->capacity) &&
        (q->count < q->cap || grow(q) == 0)) {
        q->items[(q->head + q->count) % q->cap] = item;
        q->count++;
        pthread_cond_signal(&q->cond);
        rc = 0;
    }
    pthread_mutex_unlock(&q->lock);
    return rc;
}

void *vx_queue_pop(vx_queue *q, double timeout_s)
{
    struct timespec dl;
    vx_mono_deadline(timeout_s, &dl);
    pthread_mutex_lock(&q->lock);
    while (q->count == 0 && !q->closed && timeout_s != 0) {
        int rc = timeout_s < 0 ? pthread_cond_wait(&q->cond, &q->lock)
                               : pthread_cond_timedwait(&q->cond, &q->lock, &dl);
        if (rc == ETIMEDOUT) break;
    }
    void *item = NULL;
    if (q->count) {
        item = q->items[q->head];
        q->head = (q->head + 1) % q->cap;
        q->count--;
        pthread_cond_broadcast(&q->space);
    }
    pthread_mutex_unlock(&q->lock);
    return item;
}

int vx_queue_wait_below(vx_queue *q, size_t n, double timeout_s)
{
    struct timespec dl;
    vx_mono_deadline(timeout_s, &dl);
    pthread_mutex_lock(&q->lock);
    while (q->count >= n && !q->closed && timeout_s != 0) {
        int rc = timeout_s < 0 ? pthread_cond_wait(&q->space, &q->lock)
                               : pthread_cond_timedwait(&q->space, &q->lock, &dl);
        if (rc == ETIMEDOUT) break;
    }
    int below = q->count < n || q->closed;
    pthread_mutex_unlock(&q->lock);
    return below ? 0 : -1;
}

int vx_queue_remove(vx_queue *q, void *item)
{
    pthread_mutex_lock(&q->lock);
    int found = 0;
    for (size_t i = 0; i < q->count; i++) {
        if (q->items[(q->head + i) % q->cap] != item) continue;
        for (size_t k = i; k + 1 < q->count; k++)
            q->items[(q->head + k) % q->cap] = q->items[(q->head + k + 1) % q->cap];
        q->count--;
        pthread_cond_broadcast(&q->space);
        found = 1;
        break;
    }
    pthread_mutex_unlock(&q->lock);
    return found;
}

size_t vx_queue_depth(vx_queue *q)
{
    pthread_mutex_lock(&q->lock);
    size_t n = q->count;
    pthread_mutex_unlock(&q->lock);
    return n;
}

size_t vx_queue_capacity(vx_queue *q)
{
    return q->capacity;
}

void vx_queue_close(vx_queue *q)
{
    pthread_mutex_lock(&q->lock);
    q->closed = 1;
    pthread_cond_broadcast(&q->cond);
    pthread_cond_broadcast(&q->space);
    pthread_mutex_unlock(&q->lock);
}
