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

#include "simd.h" /* TD_ROW_CLONES */

void td_edt_columns(const float *h, double z, int32_t nx, int32_t ny, uint32_t *col);
void td_edt_row(const uint32_t *colrow, int32_t nx, double wx, double wy, double *out,
                td_edt_scratch *s);

#endif
