/* AllocCap (alloc_cap.h) and the replaced global operator new and delete
 * that count for it. */
#include "mesh/alloc_cap.h"

#include <cstdlib>
#include <new>

#include <malloc.h>

namespace
{
thread_local uint64_t t_cap, t_used, t_peak;
thread_local bool t_active, t_tripped;

void *counted_new(std::size_t n)
{
    if (t_active) {
        if (n > t_cap || t_used > t_cap - n) {
            t_tripped = true;
            return nullptr;
        }
    }
    void *p = std::malloc(n ? n : 1);
    if (p && t_active) {
        t_used += malloc_usable_size(p);
        if (t_used > t_peak) t_peak = t_used;
    }
    return p;
}

void counted_delete(void *p) noexcept
{
    if (p && t_active) {
        size_t n = malloc_usable_size(p);
        t_used = n > t_used ? 0 : t_used - n;
    }
    std::free(p);
}

void *throwing_new(std::size_t n)
{
    for (;;) {
        void *p = counted_new(n);
        if (p) return p;
        std::new_handler h = t_tripped ? nullptr : std::get_new_handler();
        if (!h) throw std::bad_alloc();
        h();
    }
}
} // namespace

namespace vx
{
AllocCap::AllocCap(uint64_t cap)
{
    t_cap = cap;
    t_used = t_peak = 0;
    t_tripped = false;
    t_active = true;
}
AllocCap::~AllocCap()
{
    t_active = false;
}
bool AllocCap::tripped() const
{
    return t_tripped;
}
uint64_t AllocCap::limit() const
{
    return t_cap;
}
uint64_t AllocCap::peak() const
{
    return t_peak;
}
} // namespace vx

/* The replaceable global allocation functions: the plain and array forms,
 * with and without nothrow and size; the aligned forms keep the library's
 * (aligned_alloc and free, never counted). */
void *operator new(std::size_t n)
{
    return throwing_new(n);
}
void *operator new[](std::size_t n)
{
    return throwing_new(n);
}
void *operator new(std::size_t n, const std::nothrow_t &) noexcept
{
    return counted_new(n);
}
void *operator new[](std::size_t n, const std::nothrow_t &) noexcept
{
    return counted_new(n);
}
void operator delete(void *p) noexcept
{
    counted_delete(p);
}
void operator delete[](void *p) noexcept
{
    counted_delete(p);
}
void operator delete(void *p, std::size_t) noexcept
{
    counted_delete(p);
}
void operator delete[](void *p, std::size_t) noexcept
{
    counted_delete(p);
}
void operator delete(void *p, const std::nothrow_t &) noexcept
{
    counted_delete(p);
}
void operator delete[](void *p, const std::nothrow_t &) noexcept
{
    counted_delete(p);
}
