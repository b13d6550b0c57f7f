/* sunlit.c: the sun bound of sunlit.h, per column of blocks and strip along the sun, built
 * by one sweep against the sun.
 *
 * Called by td_render when a scene has shadows (one build per render, its time counted in
 * the shadows stage, unless the caller keeps one for the sun: the server does, per
 * dataset, td_snapshot_sunlit), and by the map tiles; read by td_occluded. Layout: one
 * float per column of blocks of 2^shift cells a side (along the axis the sun crosses
 * faster) and strip, the strips of a column contiguous. The sweep visits the columns from the sun's side, so every column's
 * successor is done before it: per column, each strip's maximum over the <= 3 blocks it
 * crosses (a window over the column's block maxima, shifted by the column's offset) and
 * one bound of the column before, all in contiguous rows. */
#include "sunlit.h"

#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "bigalloc.h"
#include "maxmip.h"
#include "simd.h"

/* Blocks of 2^shift cells a side: the finest shift from TD_SUNLIT_MIN_SHIFT up whose
 * columns times strips number at most TD_SUNLIT_MAX_BOUNDS (8 MB; a kept bound's:
 * TD_SUNLIT_MAX_BOUNDS_KEPT). A shadow ray ends at the
 * first cell where it rises above its block's bound, and a block's bound is at least its
 * own highest corner, so smaller blocks end rays sooner, for a build that grows with the
 * blocks. Measured (callgrind, trinidad's four bench views, shadows stage with the build,
 * M instructions, blocks' rows): 16-cell blocks 144.5 / 323.8 / 184.1 / 420.6 (level,
 * grazing sunset, rolled, straight down); 4-cell blocks 133.2 / 232.2 / 139.1 / 370.8;
 * 2-cell blocks save 2.5-14 M more in the rays and spend 18 M more in the build. With
 * strips, 2-cell blocks on picos (714 x 482; trinidad's 2401 x 1201 takes 4 within the
 * cap): level 73.7 -> 62.4, rolled 148.1 -> 117.5, straight down 239.4 -> 195.4, grazing
 * sunset 18.0 -> 22.4 (its shadow side's build, from the 4 x 4 minima, 4 times the
 * entries). */
#define TD_SUNLIT_MIN_SHIFT 1
/* Strips against the blocks' rows (the sweep before 2026-11-30, whose landing windows
 * widened a block per block), callgrind, shadows stage with the build, M instructions,
 * triangle surface, the bench's views: trinidad level 60.6 -> 60.6, grazing sunset
 * 132.9 -> 110.2 (shadow steps 894,382 -> 685,290), rolled 73.7 -> 74.8, straight down
 * 172.7 -> 174.7; picos level 81.0 -> 73.6, grazing 99.4 -> 100.4, rolled 223.6 -> 208.4,
 * straight down 240.6 -> 238.9. Lit rays walk fewer cells where far terrain set the
 * bound (low sun, long walks); where the block's own top did, a packet's strips cost a
 * little. */
#define TD_SUNLIT_MAX_BOUNDS ((uint64_t)1 << 21)
/* A bound kept across renders (td_sunlit_build's `kept`: the server's, td_snapshot_sunlit)
 * is built once for many renders of the same heights and sun, so its blocks may be finer:
 * up to twice the bounds (16 MB, and as much again for the shadow side). Trinidad's
 * 2401 x 1201 then takes 2-cell blocks instead of 4. Measured 2026-12-02 (shadows stage,
 * plane, the bound kept, best of 3 x 9, one thread): level 2.55 -> 2.30 ms (steps per
 * shadow ray 1.13 -> 1.05), grazing sunset 5.91 -> 4.65 (3.87 -> 2.59), rolled 3.37 ->
 * 3.12, straight down 10.32 -> 8.30 (2.71 -> 1.78); built for each render instead, the
 * finer bound cost more than it saved on the level view (3.06 -> 4.96 ms) and the
 * grazing sunset (7.01 -> 9.26), which is why a render's own bound keeps the cap above.
 * Smaller grids take blocks of one cell (TD_SUNLIT_MIN_SHIFT_KEPT; block_maxima reads
 * their corners, block_minima the 4 x 4 minima as for 2-cell blocks): the same stage on
 * the bench views of picos (714 x 482) level 2.35 -> 1.97 ms, rolled 7.84 -> 7.00,
 * straight down 12.15 -> 9.30, and of levi level 3.39 -> 2.92, rolled 4.91 -> 4.34,
 * straight down 8.42 -> 7.02; the grazing sunsets, whose rays end at once (surely
 * shadowed or lit), within 3%. Picos's kept bound is then 3.4 MB, an SRTM tile's 11.5.
 * The price is the first render with a sun, which builds the kept bound (best of 15):
 * trinidad 0.45 -> 3.14 ms (sun 80/35) and 0.91 -> 6.38 ms (258/3), picos 0.21 -> 0.80
 * and 0.41 -> 2.10, an SRTM tile 2.18 -> 5.36 (315/45), the demo data 0.18 -> 0.70 and
 * 0.18 -> 1.40; repaid after one to a few renders of the same sun where shadow rays walk
 * (trinidad straight down, picos), after about ten on trinidad's level view. So the
 * server keeps a render's own bound at a sun's first use and builds the finer one at its
 * second (td_snapshot_sunlit): a sun used once costs no more than before. */
#define TD_SUNLIT_MAX_BOUNDS_KEPT ((uint64_t)1 << 22)
#define TD_SUNLIT_MIN_SHIFT_KEPT 0
/* The shadow side is built when at least 1 / TD_SUNLIT_LO_AHEAD of the upper bounds come
 * from terrain further on by more than a decay: low sun over relief, where rays from the
 * surface walk far (build_lo). Measured (callgrind, shadows stage with the build, M
 * instructions, triangle; the share of such bounds in brackets): picos grazing sunset
 * (92%) 100.4 -> 18.1, picos rolled (22%) 208.4 -> 148.1, trinidad grazing sunset (27%)
 * 110.2 -> 114.7 (its shadowed rays are few: 18,639 of 115,829); picos level (5%) and
 * straight down (8%), and trinidad's other views (0%) do not build it. */
#define TD_SUNLIT_LO_AHEAD 8

/* The sweep's geometry: axis a is the sun's dominant one (the one it crosses blocks of
 * fastest), b the other; along a the step D crosses exactly one block (sign sa), along b
 * it moves del blocks (|del| <= 1, the sign of the sun's b). The blocks' maxima are kept
 * in rows along b, a row per column. */
typedef struct sweep {
    int32_t na, nb; /* blocks along a and b */
    int a_is_x, sa;
    double del, decay;
} sweep;

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
    if (shift == 0) { /* blocks of one cell (a kept bound's, TD_SUNLIT_MIN_SHIFT_KEPT): its corners */
        const size_t si = w->a_is_x ? (size_t)w->nb : 1, sj = w->a_is_x ? 1 : (size_t)w->nb;
        const size_t W = g->cz.stride;
        for (int32_t j = 0; j < g->h - 1; j++)
            for (int32_t i = 0; i < g->w - 1; i++) {
                const float *p = td_grid_corner(&g->cz, i, j);
                float m = -INFINITY; /* a void's NaN dropped, as td_view_max drops it */
                m = p[0] > m ? p[0] : m;
                m = p[1] > m ? p[1] : m;
                m = p[W] > m ? p[W] : m;
                m = p[W + 1] > m ? p[W + 1] : m;
                bm[(size_t)j * sj + (size_t)i * si] = m;
            }
        return;
    }
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

/* The nearest float at or below b */
static inline float float_down(double b) { return -float_up(-b); }

/* Each block's lowest sample (its cells' corners; NaN where one is void) into the sweep's
 * rows like block_maxima, from the tiles' max-mipmaps' min4 (maxmip.h: 4 x 4 blocks, the
 * tiles' multiples of 4 cells); blocks of 2 x 2 cells or one cell (shift 1, 0) take
 * their 4 x 4 block's, which is at most theirs. Returns 0 (bm unusable) when a tile has none. */
static int block_minima(const td_view *v, const sweep *w, int shift, float *bm)
{
    const td_grid *g = v->grid;
    const size_t si = w->a_is_x ? (size_t)w->nb : 1, sj = w->a_is_x ? 1 : (size_t)w->nb;
    const int32_t bw = w->a_is_x ? w->na : w->nb, bh = w->a_is_x ? w->nb : w->na;
    const int up = 2 - shift; /* 4 x 4 blocks are 2^up blocks a side */
    const size_t nt = (size_t)g->tiles_x * (size_t)g->tiles_y;
    int ok = v->accel != NULL && g->tile_log2 >= 2 && shift >= 0 && shift <= 2;
    for (size_t ti = 0; ti < nt && ok; ti++) {
        const td_tile *t = &g->tiles[ti];
        const td_maxmip *mm = v->accel[ti].maxmip;
        const int32_t bx0 = t->i0 >> shift, by0 = t->j0 >> shift;
        ok = mm && mm->min4;
        for (int32_t by = by0; ok && by < bh && (by - by0) >> up < mm->min4_h; by++) {
            const float *m4 = mm->min4 + (size_t)((by - by0) >> up) * (size_t)mm->min4_w;
            for (int32_t bx = bx0; bx < bw && (bx - bx0) >> up < mm->min4_w; bx++)
                bm[(size_t)by * sj + (size_t)bx * si] = m4[(bx - bx0) >> up];
        }
    }
    /* a last block the grid's cells fill only in part: a ray may leave the grid through its
       missing part, where nothing is under it, so it claims nothing (NaN, as a void's
       block): shadow rays from the grid's last half cell below its lowest sample, leaving
       the grid there, were called shadowed (fuzz_render, seed edge-block) */
    const int32_t S = (int32_t)1 << shift;
    for (int32_t by = 0; ok && (int64_t)bw * S > g->w - 1 && by < bh; by++)
        bm[(size_t)by * sj + (size_t)(bw - 1) * si] = NAN;
    for (int32_t bx = 0; ok && (int64_t)bh * S > g->h - 1 && bx < bw; bx++)
        bm[(size_t)(bh - 1) * sj + (size_t)bx * si] = NAN;
    return ok;
}

/* The strips that cross column ia's blocks and M(ia, k) for them (sunlit.h), or with
 * lower the lowest samples m(ia, k): strip k crosses the blocks ib = k + lo .. k + hi of
 * the column, lo and hi the same for every k, its range of B widened by a hair against the
 * rounding of del and of a point's B - del A, which also takes both blocks a point on
 * their common edge is in (a ray along that edge walks the cells of one of them: with the
 * sun exactly along an axis, the strip of a point on a block's edge B = k crosses blocks
 * k - 1 and k). Strips t (k = kmin + t) in [*ta, *tb) cross the column; m[t] for them: a
 * block off the column counts -inf (lower: NaN, as a void's block does: no claim). row is
 * the column's block maxima or minima (nb of them). */
static void strip_extrema(const sweep *w, const td_sunlit *s, int32_t ia, const float *row, int lower,
                          size_t *ta, size_t *tb, float *pad, float *m)
{
    const double q = s->del, eps = 1e-9, x = q * ia;
    const int64_t lo = (int64_t)floor(x + (q < 0.0 ? q : 0.0) - eps);
    const int64_t hi = (int64_t)ceil(1.0 + x + (q > 0.0 ? q : 0.0) + eps) - 1;
    const int64_t nst = s->nst, a = -(int64_t)s->kmin - hi, b = w->nb - (int64_t)s->kmin - lo;
    const float off = lower ? NAN : -INFINITY;
    *ta = (size_t)(a < 0 ? 0 : (a > nst ? nst : a));
    *tb = (size_t)(b < (int64_t)*ta ? (int64_t)*ta : (b > nst ? nst : b));
    /* pad[t]: block kmin + lo + t, or off the column, for t in [ta, tb + hi - lo) */
    const int64_t pe = (int64_t)*tb + (hi - lo), ib0 = (int64_t)s->kmin + lo;
    const int64_t t0 = -ib0 > (int64_t)*ta ? (-ib0 < pe ? -ib0 : pe) : (int64_t)*ta; /* blocks from t0 */
    const int64_t t1 = w->nb - ib0 < pe ? (w->nb - ib0 > t0 ? w->nb - ib0 : t0) : pe; /* to t1 */
    for (int64_t t = (int64_t)*ta; t < t0; t++)
        pad[t] = off;
    if (t1 > t0)
        memcpy(pad + t0, row + (ib0 + t0), (size_t)(t1 - t0) * sizeof *pad);
    for (int64_t t = t1; t < pe; t++)
        pad[t] = off;
    if (*tb > *ta)
        memcpy(m + *ta, pad + *ta, (*tb - *ta) * sizeof *m);
    for (int64_t k = 1; k <= hi - lo; k++) {
        const float *p = pad + k;
        if (lower) /* a NaN stays */
            for (size_t t = *ta; t < *tb; t++)
                m[t] = p[t] < m[t] || p[t] != p[t] ? p[t] : m[t];
        else
            for (size_t t = *ta; t < *tb; t++)
                m[t] = p[t] > m[t] ? p[t] : m[t];
    }
}

/* The sweep against the sun (sunlit.h): columns from the sun's side, each strip's bound
 * the larger of its maxima in this column and the next and the next column's bound less
 * the decay (lower: the shadow side, the larger of its lowest sample in this column and
 * the next column's L less the decay, -inf where a void or the grid's edge is in reach),
 * -inf for the strips that do not cross the column (a ray there has left the grid). The
 * work is the strips that cross each column (about its blocks), not all of them. sc is
 * scratch for 3 nst + 3 floats: the extrema of this column and the next, each -inf off
 * the strips it has, and strip_extrema's pad. Returns, of the upper bound, how many of
 * the bounds of every 8th column the terrain further on set by more than a decay. */
static size_t sweep_strips(const sweep *w, const td_sunlit *s, const float *bm, int lower,
                           double decay, float *h, float *sc)
{
    const size_t nst = (size_t)s->nst;
    float *m = sc, *mn = m + nst, *pad = mn + nst, *tmp;
    size_t ra = 0, rb = 0, na_ = 0, nb_ = 0, ahead = 0; /* the strips m and mn hold */
    for (size_t t = 0; t < 2 * nst; t++)
        sc[t] = -INFINITY;
    for (int32_t st = 0; st < w->na; st++) {
        int32_t ia = w->sa > 0 ? w->na - 1 - st : st, next = ia + w->sa;
        float *out = h + (size_t)ia * nst;
        const float *hn = next >= 0 && next < w->na ? h + (size_t)next * nst : NULL;
        size_t ta, tb;
        for (size_t t = ra; t < rb; t++) /* m held the column before next: clear it */
            m[t] = -INFINITY;
        strip_extrema(w, s, ia, bm + (size_t)ia * (size_t)w->nb, lower, &ta, &tb, pad, m);
        for (size_t t = 0; t < ta; t++)
            out[t] = -INFINITY;
        if (lower) {
            for (size_t t = ta; t < tb; t++) {
                float d = hn ? float_down((double)hn[t] - decay) : -INFINITY;
                out[t] = m[t] != m[t] ? -INFINITY : m[t] > d ? m[t] : d;
            }
        } else {
            const float far = (float)decay;
            for (size_t t = ta; t < tb; t++) {
                float d = hn ? float_up((double)hn[t] - decay) : -INFINITY, a = m[t] > mn[t] ? m[t] : mn[t];
                out[t] = a > d ? a : d;
                pad[t] = a; /* (strip_extrema's, free again) */
            }
            for (size_t t = ta; st % 8 == 0 && t < tb; t++) /* apart: the loop above vectorises */
                ahead += out[t] > pad[t] + far;
        }
        for (size_t t = tb; t < nst; t++)
            out[t] = -INFINITY;
        tmp = mn, mn = m, m = tmp; /* this column's maxima are the next one's mn */
        ra = na_, rb = nb_, na_ = ta, nb_ = tb;
    }
    return ahead;
}

/* The shadow side (sunlit.h) when the upper bound's sweep found as many of its bounds set
 * by terrain further on (ahead, every 8th column) as 1 / TD_SUNLIT_LO_AHEAD of the
 * blocks (of every 8th column), the blocks are
 * 4 x 4 cells and every tile's max-mipmap has its minima; s->lo stays NULL otherwise. bm is
 * scratch for the blocks, sc for the sweep. */
static td_status build_lo(const td_view *v, const sweep *w, int shift, double decay, size_t ahead,
                          td_sunlit *s, float *bm, float *sc, td_err *err)
{
    td_status rc = TD_OK;
    size_t nh = (size_t)w->na * (size_t)s->nst;
    if (ahead < (size_t)w->na * (size_t)w->nb / 8 / TD_SUNLIT_LO_AHEAD || !block_minima(v, w, shift, bm))
        goto out;
    s->lo = td_bigalloc(nh * sizeof *s->lo);
    if (!s->lo) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the shadow bound (%zu bounds)", nh);
        goto out;
    }
    sweep_strips(w, s, bm, 1, decay, s->lo, sc);
    s->bytes += nh * sizeof *s->lo;
out:
    return rc;
}

/* The finest shift from min_shift up whose columns times strips number at most
 * max_bounds for any sun (strips: at most the blocks across plus along, plus 4). */
static int block_shift(const td_grid *g, int min_shift, uint64_t max_bounds)
{
    int shift = min_shift;
    for (; shift < 30; shift++) {
        uint64_t bw = (uint64_t)((g->w - 2) >> shift) + 1, bh = (uint64_t)((g->h - 2) >> shift) + 1;
        uint64_t na = bw > bh ? bw : bh;
        if (na * (bw + bh + 4) <= max_bounds)
            break;
    }
    return shift;
}

/* The blocks' shift of a kept bound (td_sunlit_build's kept) or of a render's own */
static int bound_shift(const td_grid *g, int kept)
{
    return kept ? block_shift(g, TD_SUNLIT_MIN_SHIFT_KEPT, TD_SUNLIT_MAX_BOUNDS_KEPT)
                : block_shift(g, TD_SUNLIT_MIN_SHIFT, TD_SUNLIT_MAX_BOUNDS);
}

int td_sunlit_kept_finer(const td_grid *g) { return bound_shift(g, 1) < bound_shift(g, 0); }

td_status td_sunlit_build(const td_view *v, const double sun[3], int kept, td_sunlit **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_grid *g = v->grid;
    double hs = hypot(sun[0], sun[1]);
    td_sunlit *s = NULL;
    float *bm = NULL;
    *out = NULL;
    if (!(sun[2] > 0.0) || !(hs > 1e-9) || isnan(g->zmax) || g->w < 2 || g->h < 2)
        goto out; /* no bound: the sun at the zenith, below the horizon, or no terrain */
    const int shift = bound_shift(g, kept);
    const int32_t S = (int32_t)1 << shift;
    const int32_t bw = ((g->w - 2) >> shift) + 1, bh = ((g->h - 2) >> shift) + 1;
    const double rx = fabs(sun[0]) / hs / g->sx, ry = fabs(sun[1]) / hs / g->sy; /* cells a metre */
    sweep w;
    w.a_is_x = rx >= ry;
    w.na = w.a_is_x ? bw : bh;
    w.nb = w.a_is_x ? bh : bw;
    w.sa = (w.a_is_x ? sun[0] : sun[1]) > 0.0 ? 1 : -1;
    w.del = (w.a_is_x ? ry / rx : rx / ry) * ((w.a_is_x ? sun[1] : sun[0]) < 0.0 ? -1.0 : 1.0);
    /* D crosses one block along a; the decay is kept a hair short of D tan (the shadow
       side's a hair over it) */
    const double dtan = S / (w.a_is_x ? rx : ry) * (sun[2] / hs);
    w.decay = dtan * (1.0 - 1e-9);
    /* the strips: B - del A over the grid's [0, na] x [0, nb], a strip to spare each side */
    const double q = w.del * w.sa; /* B's change per unit of A along the sun */
    const double lam0 = q > 0.0 ? -q * w.na : 0.0, lam1 = w.nb + (q < 0.0 ? -q * w.na : 0.0);
    const int32_t kmin = (int32_t)floor(lam0) - 1, nst = (int32_t)ceil(lam1) + 1 - kmin + 1;
    size_t n = (size_t)bw * (size_t)bh, nh = (size_t)w.na * (size_t)nst; /* nh <= 2^22 */
    s = calloc(1, sizeof *s);
    bm = td_bigalloc((n + 3 * (size_t)nst + 3) * sizeof *bm);
    if (!s || !bm || !(s->h = td_bigalloc(nh * sizeof *s->h))) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the sun bound (%zu bounds)", nh);
        goto out;
    }
    s->shift = shift;
    s->a_is_x = w.a_is_x;
    s->inv = 1.0 / S;
    s->del = q;
    s->na = w.na;
    s->nst = nst;
    s->kmin = kmin;
    s->bytes = sizeof *s + nh * sizeof *s->h;
    memcpy(s->sun, sun, sizeof s->sun);
    s->gw = g->w;
    s->gh = g->h;
    block_maxima(v, &w, shift, bm);
    size_t ahead = sweep_strips(&w, s, bm, 0, w.decay, s->h, bm + n);
    rc = build_lo(v, &w, shift, dtan * (1.0 + 1e-9), ahead, s, bm, bm + n, err);
    if (rc)
        goto out;
    *out = s;
    s = NULL;
out:
    free(bm);
    td_sunlit_free(s);
    return rc;
}

int td_sunlit_fits(const td_sunlit *s, const td_view *v, const double sun[3])
{
    return s && memcmp(s->sun, sun, sizeof s->sun) == 0 && s->gw == v->grid->w && s->gh == v->grid->h;
}

void td_sunlit_free(td_sunlit *s)
{
    if (s) {
        free(s->h);
        free(s->lo);
        free(s);
    }
}
