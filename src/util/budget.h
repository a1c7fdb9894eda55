/* vx_budget: a process-wide amount (bytes of memory) that concurrent users
 * reserve before they spend it and release after, so that their sum stays
 * under a limit. The daemon reserves the worst-case memory of a mesh parse
 * (vx_mesh_parse_cost) before parsing an upload. Thread-safe. */
#ifndef VX_BUDGET_H
#define VX_BUDGET_H

#include <pthread.h>
#include <stdint.h>

typedef struct vx_budget {
    pthread_mutex_t lock;
    uint64_t used;
} vx_budget;

#define VX_BUDGET_INIT                                                                             \
    {                                                                                              \
        PTHREAD_MUTEX_INITIALIZER, 0                                                               \
    }

typedef enum vx_budget_result {
    VX_BUDGET_OK = 0,  /* reserved: release it later */
    VX_BUDGET_BUSY,    /* does not fit now, would with fewer reservations */
    VX_BUDGET_TOO_BIG, /* more than the whole limit: never fits */
} vx_budget_result;

/* Reserves n against limit (0 = no limit: always reserved). */
vx_budget_result vx_budget_reserve(vx_budget *b, uint64_t n, uint64_t limit);
/* Gives back n reserved with vx_budget_reserve. */
void vx_budget_release(vx_budget *b, uint64_t n);
/* The sum reserved now. */
uint64_t vx_budget_used(vx_budget *b);

#endif
