/* sunlit.h: heights above which a point is surely in the sun, per block of cells.
 *
 * For the sun's direction s (unit, s_z > 0; horizontal part s_h, slope tan = s_z/|s_h|)
 * and a point p, the ray toward the sun is unobstructed when p_z > H(p) with
 *
 *     H(p) = sup over d > 0 of  T(p + d s_h) - d tan          (T: the terrain's height).
 *
 * Blocks are 2^shift x 2^shift cells; A and B are a point's block coordinates along the
 * axis s_h crosses blocks of faster (a) and the other (b), and along s_h B changes by
 * del (|del| <= 1) per unit of A. The bound is kept per column of blocks along a (A in
 * [ia, ia + 1]) and strip k of lateral coordinate B - del A in [k, k + 1): a ray toward
 * the sun stays in its strip, so its bound is the same strip's one column on, from
 *
 *     H(ia, k) = max( M(ia, k), M(ia', k), H(ia', k) - D tan )     (ia' = ia + the sun's step)
 *
 * with D the distance over which s_h crosses exactly one column (a ray from column ia is
 * in column ia' after D, in the same strip) and M(ia, k) the highest corner of the <= 3
 * blocks strip k crosses in column ia (td_view_max, or the max-mipmap's code for the
 * block: both bound every surface). The decay D tan per column makes far ridges matter
 * only as much as they can: with the sun at 30 degrees over 73 m cells and 16-cell blocks,
 * a ridge 680 m lower per column away. Blocks of rows (the sweep before 2026-11-30) took
 * the bound of the <= 2 blocks a block's rays land in, a window one block wider with each
 * step: a far ridge raised the bound of a band as wide as it is far, and lit rays walked
 * on (sunlit.c has the figures). Blocks are 2 x 2 cells, or the next power of two up
 * that keeps the columns times strips to 2^21 (for a bound kept across renders: from
 * blocks of one cell up, within 2^22; sunlit.c says why). A shadow ray whose
 * point is above its bound (with the walk's margin) is lit: td_occluded ends it there.
 * Sun at the zenith (no horizontal part) or below the horizon: no bound is built.
 *
 * The shadow side, per column and strip the same way: with m(ia, k) the lowest sample of
 * the blocks strip k crosses in column ia (every surface lies at or above it there), a
 * ray that passes through column ia in strip k below
 *
 *     L(ia, k) = max( m(ia, k), L(ia', k) - D tan )
 *
 * is below the surface there or goes on below L one column on (-inf where a void or the
 * grid's edge is within the strip's blocks: a hole lets a ray pass under the surface
 * without crossing it). A shadow ray that starts above the surface and passes below it
 * crosses it on the way, and td_occluded's walk finds that crossing (it tests every cell
 * the ray crosses, each surface's crossings inside a cell too). So a ray from a point
 * above the surface under it and below its strip's L (margins of zeps either way) is
 * shadowed: td_occluded answers at once. Built when low sun over relief makes rays from
 * the surface walk far (sunlit.c, build_lo), from the max-mipmaps' 4 x 4 minima (a 2 x 2
 * block takes its 4 x 4 block's); lo is NULL otherwise, and where a tile has no minima
 * (a prepared grid's). */
#ifndef TD_SUNLIT_H
#define TD_SUNLIT_H

#include <math.h>
#include <stddef.h>

#include "trace.h"

typedef struct td_sunlit {
    int shift;      /* blocks of 2^shift cells a side */
    int a_is_x;     /* the columns are along x (else y) */
    double inv;     /* 2^-shift: blocks a cell */
    double del;     /* B's change per unit of A along the sun */
    int32_t na;     /* columns of blocks along a */
    int32_t nst;    /* strips */
    int32_t kmin;   /* the first strip's k */
    float *h;       /* na * nst bounds: column ia, strip k at h[ia * nst + k - kmin] */
    float *lo;      /* the shadow side's L, laid out as h (-inf: no claim), or NULL */
    size_t bytes;
    double sun[3];  /* the sun it was built for, and the grid's size: what td_sunlit_fits */
    int32_t gw, gh; /* checks before a bound built for one render serves another */
} td_sunlit;

/* Builds the bound for the view and the sun's unit direction; *out NULL (and TD_OK) when
 * the sun gives none. `kept`: the bound will serve many renders (a server's), so its
 * blocks may be finer (TD_SUNLIT_MAX_BOUNDS_KEPT in sunlit.c): a dearer build, cheaper
 * shadow rays. */
td_status td_sunlit_build(const td_view *v, const double sun[3], int kept, td_sunlit **out, td_err *err);
void td_sunlit_free(td_sunlit *s);

/* Whether a kept bound (td_sunlit_build's `kept`) of grid g takes finer blocks than a
 * render's own: else the two are the same bound. */
int td_sunlit_kept_finer(const td_grid *g);

/* Whether s was built for exactly this sun (the same bits) and a grid of v's size. A
 * bound holds for every view of the heights it was built from (it bounds the terrain,
 * whatever structures the view holds), so a server may keep one across renders of the
 * same heights and sun (render.h, td_render_opts.sunlit): the answers are the same. */
int td_sunlit_fits(const td_sunlit *s, const td_view *v, const double sun[3]);

/* The strip of the point (u, v) of the grid, in cells (u in [0, w - 1], v in [0, h - 1]):
 * the index of its column 0 bound in h, or -1 for a point off the grid. A ray toward the
 * sun keeps its strip (its B - del A is the same all along, to the rounding the strips'
 * margins take). */
static inline ptrdiff_t td_sunlit_strip(const td_sunlit *s, double u, double v)
{
    double A = (s->a_is_x ? u : v) * s->inv, B = (s->a_is_x ? v : u) * s->inv;
    double k = floor(B - s->del * A) - s->kmin;
    return k >= 0.0 && k < s->nst ? (ptrdiff_t)k : -1;
}

/* The bound at the point (u, v) of the grid, in cells (+inf off the grid) */
static inline double td_sunlit_at(const td_sunlit *s, double u, double v)
{
    ptrdiff_t k = td_sunlit_strip(s, u, v);
    double A = (s->a_is_x ? u : v) * s->inv;
    size_t ia = A < s->na - 1 ? (size_t)A : (size_t)(s->na - 1);
    return k >= 0 ? (double)s->h[ia * (size_t)s->nst + (size_t)k] : INFINITY;
}

/* The bound of strip k (td_sunlit_strip's, not -1) in the column of cell (ci, cj) */
static inline double td_sunlit_col(const td_sunlit *s, ptrdiff_t k, int32_t ci, int32_t cj)
{
    return (double)s->h[(size_t)((s->a_is_x ? ci : cj) >> s->shift) * (size_t)s->nst + (size_t)k];
}

/* The shadow side's L of strip k (td_sunlit_strip's, not -1) in the column of cell
 * (ci, cj), with lo built */
static inline double td_sunlit_lo(const td_sunlit *s, ptrdiff_t k, int32_t ci, int32_t cj)
{
    return (double)s->lo[(size_t)((s->a_is_x ? ci : cj) >> s->shift) * (size_t)s->nst + (size_t)k];
}

#endif
