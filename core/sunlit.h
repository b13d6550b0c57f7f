/* sunlit.h: heights above which a point is surely in the sun, per block of cells.
 *
 * For the sun's direction s (unit, s_z > 0; horizontal part s_h, slope tan = s_z/|s_h|)
 * and a point p, the ray toward the sun is unobstructed when p_z > H(p) with
 *
 *     H(p) = sup over d > 0 of  T(p + d s_h) - d tan          (T: the terrain's height).
 *
 * Per block B of 2^shift x 2^shift cells this keeps an upper bound H_B of H over the
 * block, built once per render and sun by one sweep against the sun, from
 *
 *     H_B <= max( M(the blocks the rays from B cross within a step D),
 *                 max(H_B' over the <= 2 blocks B + D s_h lands in) - D tan )
 *
 * with D the distance over which s_h crosses exactly one block along its dominant axis
 * (so B + D s_h lies in the next row of blocks, in at most two of them) and M a block's
 * highest corner (td_view_max, or the max-mipmap's code for the block: both bound every
 * surface). The decay D tan per block makes far ridges matter only as much as they can:
 * with the sun at 30 degrees over 73 m cells and 16-cell blocks, a ridge 680 m lower per
 * block away. Blocks are 4 x 4 cells, or the next power of two up that keeps them to
 * 2^20 (sunlit.c says why). A shadow ray whose point is
 * above its block's bound (with the walk's margin) is lit: td_occluded ends it there.
 * Sun at the zenith (no horizontal part) or below the horizon: no bound is built. */
#ifndef TD_SUNLIT_H
#define TD_SUNLIT_H

#include "trace.h"

typedef struct td_sunlit {
    int shift;     /* blocks of 2^shift cells a side */
    int32_t bw, bh; /* blocks across and up */
    size_t si, sj;  /* block (bi, bj)'s bound is h[bj * sj + bi * si]: rows along the axis
                       the sun crosses more slowly (the build's sweep order) */
    float *h;      /* bw * bh bounds (+inf: no bound) */
    size_t bytes;
} td_sunlit;

/* Builds the bound for the view and the sun's unit direction; *out NULL (and TD_OK) when
 * the sun gives none. */
td_status td_sunlit_build(const td_view *v, const double sun[3], td_sunlit **out, td_err *err);
void td_sunlit_free(td_sunlit *s);

/* The bound at cell (ci, cj) (a cell of the grid). */
static inline double td_sunlit_at(const td_sunlit *s, int32_t ci, int32_t cj)
{
    return (double)s->h[(size_t)(cj >> s->shift) * s->sj + (size_t)(ci >> s->shift) * s->si];
}

#endif
