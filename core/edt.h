/* edt.h: exact squared Euclidean distance transform of a binary grid with separate
 * weights along x and y (Felzenszwalb & Huttenlocher 2012, "Distance Transforms of
 * Sampled Functions": two separable passes of the lower envelope of parabolas). */
#ifndef TD_EDT_H
#define TD_EDT_H

#include <stdint.h>

/* Scratch for a transform of up to n = max(nx, ny) samples per line. */
typedef struct td_edt_scratch {
    int32_t n;
    double *f, *d, *zs; /* n, n, n+1 */
    double *g;          /* n: f + w*q^2 of the envelope's parabolas */
    double *rcp;        /* n: 1 / (2 w i), for the weight rcp_w */
    double rcp_w;
    int32_t *v;         /* n */
} td_edt_scratch;

int td_edt_scratch_init(td_edt_scratch *s, int32_t n);
void td_edt_scratch_free(td_edt_scratch *s);

/* In: dist[c] = 0 for feature cells, +inf otherwise (binary input only; nx*ny, row-major).
 * Out: dist[c] = min over features q of wx*(cx-qx)^2 + wy*(cy-qy)^2 (+inf if none).
 * Row-major layout, nx, ny <= s->n. */
void td_edt_2d(double *dist, int32_t nx, int32_t ny, double wx, double wy, td_edt_scratch *s);

/* The same transform streamed a row at a time, for a level set of a height field (the
 * parameter planes' slices): no nx*ny array of doubles is written or read back.
 * td_edt_columns: col[c] = distance in cells from c to the nearest cell of its column
 * with h >= z, or at least TD_EDT_NONE if the column has none (nx*ny, row-major).
 * td_edt_row: out[x] = the squared distance of td_edt_2d for row y, from col's row y. */
#define TD_EDT_NONE ((uint32_t)1 << 30)
void td_edt_columns(const float *h, double z, int32_t nx, int32_t ny, uint32_t *col);
void td_edt_row(const uint32_t *colrow, int32_t nx, double wx, double wy, double *out,
                td_edt_scratch *s);

#endif
