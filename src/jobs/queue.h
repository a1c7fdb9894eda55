/* A bounded FIFO of pointers with blocking pop, used for the job queue (HTTP
 * threads push, the GL thread pops) and the CPU worker queue. Thread-safe. */
#ifndef VX_QUEUE_H
#define VX_QUEUE_H

#include <stddef.h>

typedef struct vx_queue vx_queue;

/* capacity 0 = unbounded. Owned. */
vx_queue *vx_queue_new(size_t capacity);
/* Frees the queue (not the items); NULL is a no-op. */
void vx_queue_free(vx_queue *q);
/* Appends; -1 when full (unless force) or closed. */
int vx_queue_push(vx_queue *q, void *item, int force);
/* Waits up to timeout_s (< 0: forever) for an item; NULL on timeout or when
 * the queue is closed and empty. */
void *vx_queue_pop(vx_queue *q, double timeout_s);
/* Removes item if it is still queued; 1 if it was. */
int vx_queue_remove(vx_queue *q, void *item);
size_t vx_queue_depth(vx_queue *q);
size_t vx_queue_capacity(vx_queue *q);
/* Waits up to timeout_s (< 0: forever) until fewer than n items are
 * queued or the queue is closed: 0, or -1 on timeout. */
int vx_queue_wait_below(vx_queue *q, size_t n, double timeout_s);
/* Wakes every waiter; later pushes fail, pops drain what is left. */
void vx_queue_close(vx_queue *q);

#endif
