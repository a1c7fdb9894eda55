/* Vector instructions (cpu.h). */
#include "util/cpu.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>

static pthread_once_t once = PTHREAD_ONCE_INIT;
static int avx2, avx2_fma;

static void probe(void)
{
    const char *off = getenv("VX_NO_AVX2");
    if (off && *off && strcmp(off, "0") != 0) return;
#if defined(__x86_64__)
    __builtin_cpu_init();
    avx2 = __builtin_cpu_supports("avx2") != 0;
    avx2_fma = avx2 && __builtin_cpu_supports("fma");
#endif
}

int vx_cpu_avx2(void)
{
    pthread_once(&once, probe);
    return avx2;
}

int vx_cpu_avx2_fma(void)
{
    pthread_once(&once, probe);
    return avx2_fma;
}
