/* Reservations against a shared limit (util/budget.h). */
#include "util/budget.h"

vx_budget_result vx_budget_reserve(vx_budget *b, uint64_t n, uint64_t limit)
{
    if (limit && n > limit) return VX_BUDGET_TOO_BIG;
    pthread_mutex_lock(&b->lock);
    vx_budget_result r = VX_BUDGET_OK;
    if (limit && b->used + n > limit)
        r = VX_BUDGET_BUSY;
    else
        b->used += n;
    pthread_mutex_unlock(&b->lock);
    return r;
}

void vx_budget_release(vx_budget *b, uint64_t n)
{
    pthread_mutex_lock(&b->lock);
    b->used = n > b->used ? 0 : b->used - n;
    pthread_mutex_unlock(&b->lock);
}

uint64_t vx_budget_used(vx_budget *b)
{
    pthread_mutex_lock(&b->lock);
    uint64_t u = b->used;
    pthread_mutex_unlock(&b->lock);
    return u;
}
