/* The CPU's vector instructions, as the engines' hand-vectorised forms ask
 * for them. Any thread. */
#ifndef VX_CPU_H
#define VX_CPU_H

#ifdef __cplusplus
extern "C" {
#endif

/* 1 where the CPU runs AVX2 (and FMA, for vx_cpu_avx2_fma) and the
 * environment does not set VX_NO_AVX2 (to a value other than "" or "0"):
 * the portable forms then run instead, as on a CPU without it (the tests
 * run both). Read once. */
int vx_cpu_avx2(void);
int vx_cpu_avx2_fma(void);

#ifdef __cplusplus
}
#endif

#endif
