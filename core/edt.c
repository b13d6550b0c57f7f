/* edt.c: the Felzenszwalb-Huttenlocher distance transform of a level set (cells with
 * h >= z), O(n) per line.
 *
 * Columns first: the input is binary, so along a column the transform is the distance in
 * cells to the nearest feature, two sweeps (td_edt_columns). Then per row, from those
 * distances as costs f(q) = wy*dy^2 (+inf where a column has no feature), d(p) = min_q
 * wx*(p-q)^2 + f(q) as the lower envelope of parabolas rooted at the finite samples
 * (td_edt_row): the exact squared Euclidean distance in metres on grids whose spacing
 * differs in x and y. Samples with infinite cost never enter the envelope, so no inf - inf
 * arises. */
#include "edt.h"

#include <math.h>
#include <stdlib.h>

int td_edt_scratch_init(td_edt_scratch *s, int32_t n)
{
    s->n = n;
    s->f = malloc(sizeof(double) * (size_t)n);
    s->zs = malloc(sizeof(double) * ((size_t)n + 1));
    s->g = malloc(sizeof(double) * (size_t)n);
    s->rcp = malloc(sizeof(double) * (size_t)n);
    s->rcp_w = 0.0;
    s->fe = malloc(sizeof(double) * (size_t)n);
    s->v = malloc(sizeof(int32_t) * (size_t)n);
    s->qs = malloc(sizeof(int32_t) * (size_t)n);
    return s->f && s->zs && s->g && s->rcp && s->fe && s->v && s->qs;
}

void td_edt_scratch_free(td_edt_scratch *s)
{
    free(s->f);
    free(s->zs);
    free(s->v);
    free(s->g);
    free(s->rcp);
    free(s->fe);
    free(s->qs);
    s->f = s->zs = s->g = s->rcp = s->fe = NULL;
    s->v = s->qs = NULL;
}

/* One line of n samples from its m finite ones (positions qs, costs f, ascending), d[0..n)
 * out. The envelope keeps each parabola's root v, cost fe and f + w*v^2 (g), and divides
 * through a table of 1 / (2 w i): a multiplication in the inner loop instead of a division
 * (intersections then differ from a division's by an ulp or two, which can only pick
 * between parabolas equal to about 4 n^2 ulps; the planes keep D^2 rounded down by 2^-16,
 * see planes.c). */
TD_ROW_CLONES static void edt_1d(const int32_t *qs, const double *f, int32_t m, double *d, int32_t n, double w,
                   td_edt_scratch *s)
{
    int32_t k = -1;
    int32_t *v = s->v;
    double *zs = s->zs, *g = s->g, *fe = s->fe, *rcp = s->rcp;
    if (s->rcp_w != w) {
        rcp[0] = INFINITY;
        for (int32_t i = 1; i < s->n; i++)
            rcp[i] = 1.0 / (2.0 * w * (double)i);
        s->rcp_w = w;
    }
    for (int32_t i = 0; i < m; i++) {
        const int32_t q = qs[i];
        double gq = f[i] + w * (double)q * (double)q, sq = -INFINITY;
        while (k >= 0) {
            sq = (gq - g[k]) * rcp[q - v[k]];
            if (sq > zs[k])
                break;
            k--;
        }
        k++;
        v[k] = q;
        g[k] = gq;
        fe[k] = f[i];
        zs[k] = k == 0 ? -INFINITY : sq; /* the intersection with the parabola below it */
    }
    zs[k + 1] = INFINITY;
    /* parabola j owns the samples q with zs[j] < q <= zs[j + 1] (none when m == 0: all
     * +inf): a run each, written without a comparison per sample */
    int32_t q = 0;
    for (int32_t j = 0; j <= k && q < n; j++) {
        const double top = zs[j + 1], fv = fe[j];
        const int32_t end = top >= (double)(n - 1) ? n : top < 0.0 ? 0 : (int32_t)top + 1;
        const int32_t vj = v[j];
        for (; q < end; q++) {
            double dq = (double)(q - vj);
            d[q] = w * dq * dq + fv;
        }
    }
    for (; q < n; q++)
        d[q] = INFINITY;
}

TD_ROW_CLONES void td_edt_columns(const float *h, double z, int32_t nx, int32_t ny, uint32_t *col)
{
    /* south to north: 0 on a feature, else one more than the cell below; then north to
     * south, the smaller of that and one more than the cell above. TD_EDT_NONE + ny
     * cannot overflow, so "none" needs no test in the loops. A float h is >= z exactly
     * when it is >= the least float >= z, so the loops compare floats (four a vector). */
    float zf = (float)z;
    if ((double)zf < z)
        zf = nextafterf(zf, INFINITY);
    for (int32_t x = 0; x < nx; x++)
        col[x] = TD_EDT_NONE & (0u - (uint32_t)!(h[x] >= zf));
    for (int32_t y = 1; y < ny; y++) {
        const float *hr = h + (size_t)y * (size_t)nx;
        const uint32_t *below = col + (size_t)(y - 1) * (size_t)nx;
        uint32_t *row = col + (size_t)y * (size_t)nx;
        for (int32_t x = 0; x < nx; x++) /* masked, branch-free: it vectorises */
            row[x] = (below[x] + 1u) & (0u - (uint32_t)!(hr[x] >= zf));
    }
    for (int32_t y = ny - 2; y >= 0; y--) {
        const uint32_t *above = col + (size_t)(y + 1) * (size_t)nx;
        uint32_t *row = col + (size_t)y * (size_t)nx;
        for (int32_t x = 0; x < nx; x++) {
            uint32_t b = above[x] + 1u;
            row[x] = b < row[x] ? b : row[x];
        }
    }
}

TD_ROW_CLONES void td_edt_row(const uint32_t *colrow, int32_t nx, double wx, double wy, double *out,
                td_edt_scratch *s)
{
    /* the finite samples and their costs: counted first (a reduction, it vectorises); a
     * row without a column of "none" (the common case below the top slices) takes every
     * column as it is, the others are listed without a branch (every column is written,
     * only those with a feature are counted) */
    int32_t m = 0, zeros = 0;
    for (int32_t x = 0; x < nx; x++) {
        m += colrow[x] < TD_EDT_NONE;
        zeros += colrow[x] == 0u;
    }
    if (m == nx) {
        for (int32_t x = 0; x < nx; x++) {
            double c = (double)colrow[x];
            s->qs[x] = x;
            s->f[x] = wy * c * c;
        }
    } else {
        m = 0;
        for (int32_t x = 0; x < nx; x++) {
            s->qs[m] = x;
            m += colrow[x] < TD_EDT_NONE;
        }
        for (int32_t i = 0; i < m; i++) {
            double c = (double)colrow[s->qs[i]];
            s->f[i] = wy * c * c;
        }
    }
    if (zeros == nx) { /* a row of features only is its own transform */
        for (int32_t x = 0; x < nx; x++)
            out[x] = 0.0;
    } else {
        edt_1d(s->qs, s->f, m, out, nx, wx, s);
    }
}
