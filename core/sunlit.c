/* sunlit.c: the per-block sun bound of sunlit.h, built by one sweep against the sun.
 *
 * Called by td_render when a scene has shadows (one build per render, its time counted in
 * the shadows stage), read by td_occluded. Layout: one float per block of 2^shift cells
 * a side, in rows along the axis the sun crosses more slowly. The sweep visits those rows
 * starting from the sun's side, so every block's successors are done before it:
 * O(blocks), each block reading at most 4 maxima of two blocks and 3 bounds of the row
 * before, all in contiguous rows. */
#include "sunlit.h"

#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "maxmip.h"

/* Blocks of 2^shift cells a side: the finest shift from TD_SUNLIT_MIN_SHIFT up whose
 * blocks number at most TD_SUNLIT_MAX_BLOCKS (4 MB of bounds). A shadow ray ends at the
 * first cell where it rises above its block's bound, and a block's bound is at least its
 * own highest corner, so smaller blocks end rays sooner, for a build that grows with the
 * blocks. Measured (callgrind, trinidad's four bench views, shadows stage with the build,
 * M instructions): 16-cell blocks 144.5 / 323.8 / 184.1 / 420.6 (level, grazing sunset,
 * rolled, straight down); 4-cell blocks 133.2 / 232.2 / 139.1 / 370.8; 2-cell blocks save
 * 2.5-14 M more in the rays and spend 18 M more in the build. */
#define TD_SUNLIT_MIN_SHIFT 2
#define TD_SUNLIT_MAX_BLOCKS ((size_t)1 << 20)

/* The sweep's geometry: axis a is the sun's dominant one (the one it crosses blocks of
 * fastest), b the other; along a the step D crosses exactly one block (sign sa), along b
 * it moves del blocks (|del| <= 1). Bounds are kept in rows along b (td_sunlit's strides
 * say which way that is on the grid), with PAD blocks of -inf at each end of the sweep's
 * scratch rows so that a window needs no clamping. */
typedef struct sweep {
    int32_t na, nb; /* blocks along a and b */
    int a_is_x, sa;
    double del, decay;
} sweep;

#define PAD 2 /* the windows below reach at most 2 blocks either side */

/* The nearest float at or above b (a bound must not round down): one ulp up from the
 * rounded float when it fell short (its bits + 1 when positive, - 1 when negative; the
 * selects let the row loops vectorise). */
static inline float float_up(double b)
{
    float f = (float)b;
    uint32_t u, up;
    memcpy(&u, &f, sizeof u);
    up = f == 0.0f ? 1u : f > 0.0f ? u + 1u : u - 1u;
    u = (double)f < b ? up : u;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Each block's highest corner, rounded up, into the sweep's rows (row ia, column ib at
 * bm[ia * nb + ib]), a tile at a time when blocks are no larger than tiles: its
 * level-`shift` max-mipmap codes where it has them (decoded as td_maxmip_bound, a row of
 * codes at a time), else td_view_max over each block's cells (and for every block when
 * blocks are larger than tiles: the grid as one tile of blocks). */
static void block_maxima(const td_view *v, const sweep *w, int shift, float *bm)
{
    const td_grid *g = v->grid;
    const int32_t S = (int32_t)1 << shift, bw = w->a_is_x ? w->na : w->nb;
    const int32_t bh = w->a_is_x ? w->nb : w->na;
    const int per_tile = shift <= g->tile_log2;
    const int32_t tb = per_tile ? (int32_t)1 << (g->tile_log2 - shift) : 0;
    const size_t si = w->a_is_x ? (size_t)w->nb : 1, sj = w->a_is_x ? 1 : (size_t)w->nb;
    const size_t nt = per_tile ? (size_t)g->tiles_x * (size_t)g->tiles_y : 1;
    for (size_t ti = 0; ti < nt; ti++) {
        const td_tile *t = &g->tiles[ti];
        const td_maxmip *mm = v->accel && per_tile ? v->accel[ti].maxmip : NULL;
        int32_t bx0 = per_tile ? t->i0 >> shift : 0, by0 = per_tile ? t->j0 >> shift : 0;
        int32_t bx1 = per_tile && bx0 + tb < bw ? bx0 + tb : bw;
        int32_t by1 = per_tile && by0 + tb < bh ? by0 + tb : bh;
        for (int32_t by = by0; by < by1; by++) {
            float *row = bm + (size_t)by * sj;
            if (mm && shift <= mm->levels) {
                const uint16_t *c = mm->code + mm->offset[shift] + (size_t)(by - by0) * (size_t)mm->dim[shift];
                for (int32_t bx = bx0; bx < bx1; bx++)
                    row[(size_t)bx * si] = float_up(mm->base + (double)c[bx - bx0] * mm->step);
            } else {
                for (int32_t bx = bx0; bx < bx1; bx++)
                    row[(size_t)bx * si] = float_up(td_view_max(v, bx * S, bx * S + S - 1, by * S, by * S + S - 1));
            }
        }
    }
}

/* out[ib] = the max of p[PAD + ib + k] over k = lo .. hi (|lo|, |hi| <= PAD), a pass a k
 * over contiguous rows. */
static void window_max(const float *p, int32_t lo, int32_t hi, size_t nb, float *out)
{
    memcpy(out, p + PAD + lo, nb * sizeof *out);
    for (int32_t k = lo + 1; k <= hi; k++)
        for (size_t i = 0; i < nb; i++)
            out[i] = p[PAD + k + (ptrdiff_t)i] > out[i] ? p[PAD + k + (ptrdiff_t)i] : out[i];
}

/* The sweep against the sun (see the top of sunlit.h), rows of blocks from the sun's side.
 * Within D the rays from block ib of row ia cross the b-range [ib + min(del, 0),
 * ib + 1 + max(del, 0)) of rows ia and next and land in [ib + del, ib + 1 + del) of row
 * next: the blocks ib + r0 .. ib + r1 and ib + n0 .. ib + n1, offsets that are the same for
 * every ib (widened by a hair of b against the rounding of del; none when the sun is
 * exactly along an axis: del is then exactly 0 and the blocks line up). sc is scratch for
 * two padded rows (nb + 2 PAD floats) and two plain ones. */
static void sweep_rows(const sweep *w, const float *bm, float *h, float *sc)
{
    const double eps = w->del == 0.0 ? 0.0 : 1e-9;
    const int32_t r0 = (int32_t)floor((w->del < 0.0 ? w->del : 0.0) - eps);
    const int32_t r1 = (int32_t)ceil(1.0 + (w->del > 0.0 ? w->del : 0.0) + eps) - 1;
    const int32_t n0 = (int32_t)floor(w->del - eps), n1 = (int32_t)ceil(1.0 + w->del + eps) - 1;
    const size_t nb = (size_t)w->nb;
    float *pm = sc, *pn = pm + nb + 2 * PAD, *m = pn + nb + 2 * PAD, *n = m + nb;
    for (int k = 0; k < PAD; k++)
        pm[k] = pn[k] = pm[nb + PAD + (size_t)k] = pn[nb + PAD + (size_t)k] = -INFINITY;
    for (int32_t s = 0; s < w->na; s++) {
        int32_t ia = w->sa > 0 ? w->na - 1 - s : s, next = ia + w->sa;
        int has_next = next >= 0 && next < w->na;
        const float *b0 = bm + (size_t)ia * nb, *b1 = has_next ? bm + (size_t)next * nb : b0;
        const float *h1 = has_next ? h + (size_t)next * nb : NULL;
        float *out = h + (size_t)ia * nb;
        for (size_t k = 0; k < nb; k++) /* the row's and the next row's maxima; next bounds */
            pm[PAD + k] = b0[k] > b1[k] ? b0[k] : b1[k];
        for (size_t k = 0; k < nb; k++)
            pn[PAD + k] = h1 ? h1[k] : -INFINITY;
        window_max(pm, r0, r1, nb, m);
        window_max(pn, n0, n1, nb, n);
        for (size_t k = 0; k < nb; k++) {
            float d = float_up((double)n[k] - w->decay); /* m is a float already */
            out[k] = m[k] > d ? m[k] : d;
        }
    }
}

/* The finest shift from TD_SUNLIT_MIN_SHIFT up whose blocks over the grid's cells number
 * at most TD_SUNLIT_MAX_BLOCKS. */
static int block_shift(const td_grid *g)
{
    int shift = TD_SUNLIT_MIN_SHIFT;
    while (shift < 30 && (size_t)((g->w - 2) >> shift) + 1 >
                             TD_SUNLIT_MAX_BLOCKS / ((size_t)((g->h - 2) >> shift) + 1))
        shift++;
    return shift;
}

td_status td_sunlit_build(const td_view *v, const double sun[3], td_sunlit **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_grid *g = v->grid;
    double hs = hypot(sun[0], sun[1]);
    td_sunlit *s = NULL;
    float *bm = NULL;
    *out = NULL;
    if (!(sun[2] > 0.0) || !(hs > 1e-9) || isnan(g->zmax) || g->w < 2 || g->h < 2)
        goto out; /* no bound: the sun at the zenith, below the horizon, or no terrain */
    const int shift = block_shift(g);
    const int32_t S = (int32_t)1 << shift;
    const int32_t bw = ((g->w - 2) >> shift) + 1, bh = ((g->h - 2) >> shift) + 1;
    const double rx = fabs(sun[0]) / hs / g->sx, ry = fabs(sun[1]) / hs / g->sy; /* cells a metre */
    sweep w;
    w.a_is_x = rx >= ry;
    w.na = w.a_is_x ? bw : bh;
    w.nb = w.a_is_x ? bh : bw;
    w.sa = (w.a_is_x ? sun[0] : sun[1]) > 0.0 ? 1 : -1;
    w.del = (w.a_is_x ? ry / rx : rx / ry) * ((w.a_is_x ? sun[1] : sun[0]) < 0.0 ? -1.0 : 1.0);
    /* D crosses one block along a; the decay is kept a hair short of D tan */
    w.decay = S / (w.a_is_x ? rx : ry) * (sun[2] / hs) * (1.0 - 1e-9);
    size_t n = (size_t)bw * (size_t)bh, rows = 4 * (size_t)w.nb + 4 * PAD; /* n <= 2^20 */
    s = calloc(1, sizeof *s);
    bm = malloc((n + rows) * sizeof *bm);
    if (!s || !bm || !(s->h = malloc(n * sizeof *s->h))) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the sun bound (%zu blocks)", n);
        goto out;
    }
    s->shift = shift;
    s->bw = bw;
    s->bh = bh;
    s->si = w.a_is_x ? (size_t)bh : 1;
    s->sj = w.a_is_x ? 1 : (size_t)bw;
    s->bytes = sizeof *s + n * sizeof *s->h;
    block_maxima(v, &w, shift, bm);
    sweep_rows(&w, bm, s->h, bm + n);
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
