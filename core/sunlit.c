/* sunlit.c: the per-block sun bound of sunlit.h, built by one sweep against the sun.
 *
 * Called by td_render when a scene has shadows (one build per render, its time counted in
 * the shadows stage), read by td_occluded. Layout: one float per block of 16 x 16 cells,
 * row-major, south first, like the grid's tiles. The sweep visits rows of blocks along
 * the sun's dominant axis starting from the far side, so every block's successors are
 * done before it: O(blocks), and each block reads at most 6 block maxima and 3 bounds. */
#include "sunlit.h"

#include <math.h>
#include <stdlib.h>

#define TD_SUNLIT_SHIFT 4

static inline double dmax(double a, double b) { return a > b ? a : b; }

/* The sweep's geometry: axis a is the sun's dominant one (the one it crosses blocks of
 * fastest), b the other; along a the step D crosses exactly one block (sign sa), along b
 * it moves del blocks (|del| <= 1). */
typedef struct sweep {
    int32_t na, nb;  /* blocks along a and b */
    int a_is_x, sa;
    double del, decay;
} sweep;

static size_t idx(const sweep *w, int32_t bw, int32_t ia, int32_t ib)
{
    int32_t x = w->a_is_x ? ia : ib, y = w->a_is_x ? ib : ia;
    return (size_t)y * (size_t)bw + (size_t)x;
}

/* The max of vals over the blocks of row ia that meet the b-range [lo, hi), clamped. */
static double row_max(const sweep *w, int32_t bw, const float *vals, int32_t ia, double lo, double hi)
{
    double m = -INFINITY;
    int32_t k0 = (int32_t)floor(lo), k1 = (int32_t)ceil(hi) - 1;
    if (ia >= 0 && ia < w->na) {
        for (int32_t k = k0 < 0 ? 0 : k0; k <= k1 && k < w->nb; k++)
            m = dmax(m, (double)vals[idx(w, bw, ia, k)]);
    }
    return m;
}

/* The nearest float at or above b (a bound must not round down). */
static inline float float_up(double b)
{
    float f = (float)b;
    return (double)f < b ? nextafterf(f, INFINITY) : f;
}

/* The block maxima (td_view_max over each block's cells, a max-mipmap's bound among them). */
static void block_maxima(const td_view *v, int32_t bw, int32_t bh, float *bm)
{
    const int32_t S = (int32_t)1 << TD_SUNLIT_SHIFT;
    for (int32_t by = 0; by < bh; by++)
        for (int32_t bx = 0; bx < bw; bx++)
            bm[(size_t)by * (size_t)bw + (size_t)bx] =
                float_up(td_view_max(v, bx * S, bx * S + S - 1, by * S, by * S + S - 1));
}

/* The sweep against the sun (see the top of sunlit.h); h may alias nothing. Values are
 * rounded up to float. */
static void sweep_rows(const sweep *w, int32_t bw, const float *bm, float *h)
{
    /* a hair of b around the translates against the rounding of del (none when the sun
       is exactly along an axis: del is then exactly 0 and the blocks line up) */
    const double eps = w->del == 0.0 ? 0.0 : 1e-9;
    for (int32_t s = 0; s < w->na; s++) {
        int32_t ia = w->sa > 0 ? w->na - 1 - s : s, next = ia + w->sa;
        for (int32_t ib = 0; ib < w->nb; ib++) {
            double lo = ib + (w->del < 0.0 ? w->del : 0.0) - eps;
            double hi = ib + 1.0 + (w->del > 0.0 ? w->del : 0.0) + eps;
            double m = dmax(row_max(w, bw, bm, ia, lo, hi), row_max(w, bw, bm, next, lo, hi));
            double hn = row_max(w, bw, h, next, ib + w->del - eps, ib + 1.0 + w->del + eps);
            h[idx(w, bw, ia, ib)] = float_up(dmax(m, hn - w->decay));
        }
    }
}

td_status td_sunlit_build(const td_view *v, const double sun[3], td_sunlit **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_grid *g = v->grid;
    const int32_t S = (int32_t)1 << TD_SUNLIT_SHIFT;
    double hs = hypot(sun[0], sun[1]);
    td_sunlit *s = NULL;
    float *bm = NULL;
    *out = NULL;
    if (!(sun[2] > 0.0) || !(hs > 1e-9) || isnan(g->zmax) || g->w < 2 || g->h < 2)
        goto out; /* no bound: the sun at the zenith, below the horizon, or no terrain */
    int32_t bw = (g->w - 1 + S - 1) / S, bh = (g->h - 1 + S - 1) / S;
    size_t n = (size_t)bw * (size_t)bh;
    s = calloc(1, sizeof *s);
    bm = malloc(n * sizeof *bm);
    if (!s || !bm || !(s->h = malloc(n * sizeof *s->h))) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the sun bound (%zu blocks)", n);
        goto out;
    }
    s->shift = TD_SUNLIT_SHIFT;
    s->bw = bw;
    s->bh = bh;
    s->bytes = sizeof *s + n * sizeof *s->h;
    block_maxima(v, bw, bh, bm);
    {
        double rx = fabs(sun[0]) / hs / g->sx, ry = fabs(sun[1]) / hs / g->sy; /* cells a metre */
        sweep w;
        w.a_is_x = rx >= ry;
        w.na = w.a_is_x ? bw : bh;
        w.nb = w.a_is_x ? bh : bw;
        w.sa = (w.a_is_x ? sun[0] : sun[1]) > 0.0 ? 1 : -1;
        w.del = (w.a_is_x ? ry / rx : rx / ry) * ((w.a_is_x ? sun[1] : sun[0]) < 0.0 ? -1.0 : 1.0);
        /* D crosses one block along a; the decay is kept a hair short of D tan */
        w.decay = S / (w.a_is_x ? rx : ry) * (sun[2] / hs) * (1.0 - 1e-9);
        sweep_rows(&w, bw, bm, s->h);
    }
    *out = s;
    s = NULL;
out:
    free(bm);
    td_sunlit_free(s);
    return rc;
}

void td_sunlit_free(td_sunlit *s)
{
    if (s) {
        free(s->h);
        free(s);
    }
}
