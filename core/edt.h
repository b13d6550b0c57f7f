/* edt.h: exact squared Euclidean distance transform, with separate weights along x and
 * y, of a level set of a height field (the cells with h >= z), streamed a row at a time
 * (Felzenszwalb & Huttenlocher 2012, "Distance Transforms of Sampled Functions": two
 * separable passes, the second the lower envelope of parabolas). The parameter planes'
 * slices are its users: no nx*ny array of doubles is written or read back. */
#ifndef TD_EDT_H
#define TD_EDT_H

#include <stdint.h>

/* Scratch for a transform of up to n = max(nx, ny) samples per line. */
typedef struct td_edt_scratch {
    int32_t n;
    double *f, *zs;     /* n, n+1 */
    double *g;          /* n: f + w*q^2 of the envelope's parabolas */
    double *rcp;        /* n: 1 / (2 w i), for the weight rcp_w */
    double rcp_w;
    double *fe;         /* n: the envelope's parabolas' costs */
    int32_t *v;         /* n: their roots */
    int32_t *qs;        /* n: the line's samples with a finite cost */
} td_edt_scratch;

int td_edt_scratch_init(td_edt_scratch *s, int32_t n);
void td_edt_scratch_free(td_edt_scratch *s);

/* td_edt_columns: col[c] = distance in cells from c to the nearest cell of its column
 * with h >= z, or at least TD_EDT_NONE if the column has none (nx*ny, row-major).
 * td_edt_row: for row y, from col's row y, out[x] = min over cells q with h >= z of
 * wx*(x-qx)^2 + wy*(y-qy)^2 (+inf if there is none). nx, ny <= s->n. */
#define TD_EDT_NONE ((uint32_t)1 << 30)

/* The transform's and the planes' row loops vectorise. On x86-64 their functions are built
 * twice (put TD_ROW_CLONES on the definition), for the baseline (SSE2) and for AVX2, and
 * the loader picks the one the processor runs (GCC/clang function multiversioning): twice
 * the width, 35% fewer instructions for the planes of trinidad. Never FMA (not in the list,
 * and C11 mode contracts nothing), so both give the same results bit for bit. */
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define TD_SANITIZED 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define TD_SANITIZED 1
#endif
/* Not under a sanitizer: the loader runs the resolvers before the sanitizer's runtime is
 * up, and their instrumentation crashes (seen with ThreadSanitizer). */
#if defined(__x86_64__) && defined(__has_attribute) && !defined(TD_SANITIZED)
#if __has_attribute(target_clones) && defined(__ELF__)
#define TD_ROW_CLONES __attribute__((target_clones("avx2", "default")))
#endif
#endif
#ifndef TD_ROW_CLONES
#define TD_ROW_CLONES
#endif

void td_edt_columns(const float *h, double z, int32_t nx, int32_t ny, uint32_t *col);
void td_edt_row(const uint32_t *colrow, int32_t nx, double wx, double wy, double *out,
                td_edt_scratch *s);

#endif
