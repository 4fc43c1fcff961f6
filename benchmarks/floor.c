/* The honest floor of the sweep engine: the same Euler equations and square-wave input as
 * NeuronSweep (Brian2 cpp_standalone), written by hand for the machine.
 *
 * Compiled by benchmarks/bench_sweep.py at benchmark time with the system compiler:
 *     cc -O3 -march=native -ffast-math -shared -fPIC floor.c -o floor.so
 * and called through ctypes, one thread.
 *
 * - Blocks of BLOCK neurons run the WHOLE simulation while their state (v, u, parameters,
 *   drive, counts: 10 arrays x 64 lanes x 8 bytes = 5 KiB) stays in L1.
 * - Lanes are the innermost loop (SIMD across neurons); threshold and reset are selects
 *   (branch-free), so the lane loop vectorises.
 * - The input's sign is computed once per input sample (per_sample steps), not per step.
 * - float64 and float32 versions from one body (FLOOR_KERNEL below).
 */
#include <math.h>
#include <stdint.h>

#define BLOCK 64

#define FLOOR_KERNEL(NAME, T)                                                                \
void NAME(const double *k, const double *a, const double *b, const double *c,               \
          const double *d, const double *f_in, const double *I_amp, const double *v0,       \
          const double *u0, int64_t n, int64_t n_steps, double dt, int64_t per_sample,      \
          double rate, int64_t settle_step, double p2, double p1, double p0, double v_peak, \
          int32_t *counts)                                                                  \
{                                                                                            \
    T v[BLOCK], u[BLOCK], kk[BLOCK], ak[BLOCK], bb[BLOCK], cc[BLOCK], dd[BLOCK];             \
    T drive[BLOCK], amp[BLOCK];                                                              \
    double two_f[BLOCK];                                                                     \
    int32_t cnt[BLOCK];                                                                      \
    const T dt_ = (T)dt, p2_ = (T)p2, p1_ = (T)p1, p0_ = (T)p0, vp = (T)v_peak;              \
    const int64_t n_samples = (n_steps + per_sample - 1) / per_sample;                      \
    for (int64_t start = 0; start < n; start += BLOCK) {                                     \
        const int64_t m = n - start < BLOCK ? n - start : BLOCK;                             \
        for (int j = 0; j < BLOCK; j++) {  /* a short last block repeats its first lane */   \
            const int64_t i = start + (j < m ? j : 0);                                       \
            v[j] = (T)v0[i]; u[j] = (T)u0[i]; kk[j] = (T)k[i]; ak[j] = (T)(a[i] * k[i]);     \
            bb[j] = (T)b[i]; cc[j] = (T)c[i]; dd[j] = (T)d[i]; two_f[j] = 2.0 * f_in[i];     \
            amp[j] = (T)I_amp[i]; cnt[j] = 0;                                                \
        }                                                                                    \
        for (int64_t sample = 0; sample < n_samples; sample++) {                             \
            const double t_in = (double)sample / rate;                                       \
            for (int j = 0; j < BLOCK; j++) {                                                \
                const int64_t half = (int64_t)floor(two_f[j] * t_in);                        \
                drive[j] = amp[j] * (T)(1 - 2 * (half & 1));                                 \
            }                                                                                \
            const int64_t first = sample * per_sample;                                       \
            const int64_t last = first + per_sample < n_steps ? first + per_sample : n_steps; \
            for (int64_t step = first; step < last; step++) {                                \
                const int32_t counting = step >= settle_step;                                \
                for (int j = 0; j < BLOCK; j++) {                                            \
                    const T vj = v[j], uj = u[j];                                            \
                    const T dv = kk[j] * (p2_ * vj * vj + p1_ * vj + p0_ - uj + drive[j]);  \
                    const T du = ak[j] * (bb[j] * vj - uj);                                  \
                    const T vn = vj + dt_ * dv, un = uj + dt_ * du;                          \
                    const int32_t fired = vn >= vp;                                          \
                    v[j] = fired ? cc[j] : vn;                                               \
                    u[j] = fired ? un + dd[j] : un;                                          \
                    cnt[j] += fired & counting;                                              \
                }                                                                            \
            }                                                                                \
        }                                                                                    \
        for (int64_t j = 0; j < m; j++) counts[start + j] = cnt[j];                          \
    }                                                                                        \
}

FLOOR_KERNEL(floor_counts_f64, double)
FLOOR_KERNEL(floor_counts_f32, float)
