/* planes.c: builds one tile's Paglieroni-Petersen parameter planes.
 *
 * The tile's cells are grouped in blocks of 2 x 2 (TD_PLANES_BLOCK_LOG2; a partial block
 * on the tile's east or north edge), and the planes are built over the blocks as if they
 * were cells: a block's H is the highest corner of its cells, its footprint the 2 sx x 2
 * sy rectangle that holds them. Per block c we store a cone of empty space: apex height
 * z_p(c) and slope s_p(c) (metres of height per metre of horizontal distance) such that
 * every block q of the tile satisfies
 *
 *     H(q) <= z_p(c) + s_p(c) * gap(c, q)                                        (1)
 *
 * where H(q) is q's highest corner (-inf for a block of holes) and gap(c, q) the
 * horizontal distance between the two blocks' footprints, not between their centres.
 * Why (1) makes a parametric step safe for every surface:
 *   - Every surface (plane, linear, triangle, bilinear) inside a cell lies at or below
 *     its highest corner, so at or below the H of its block: each is a convex
 *     combination of the cell's corners, or the flat top at the highest one.
 *   - Let P be any point of the ray above block c (anywhere over c's footprint, not only
 *     over its centre) at height z_P > z_p, and Q any terrain point in block q at
 *     horizontal distance rho from P. Since P lies in c's footprint and Q in q's,
 *     gap(c, q) <= rho, so the terrain at Q is at most z_p + s_p * rho. (A partial
 *     block's cells lie inside its nominal footprint, so its gaps only shrink.)
 *   - The ray descends at most g metres per horizontal metre (g < 0 when it rises), so
 *     it is above every terrain point within horizontal distance rho while
 *     z_P - g*rho > z_p + s_p*rho, i.e. for rho < (z_P - z_p) / (s_p + g); when
 *     s_p + g <= 0 it never meets the tile's terrain at all. Both sides are linear in
 *     rho, so the inequality at the step's end holds along the whole step.
 * Published cone maps measure centre-to-centre distances and place the obstacle at a
 * point; under interpolation they miss grazing hits (Ban et al., 2024). Using the
 * footprint gap removes that error at the cost of slightly shorter steps.
 *
 * Why blocks (issue 12: 6 bytes a cell with every structure; planes built no slower than
 * Embree builds its GRID): a cone per cell took 2 bytes a cell and K EDTs over every
 * cell. Per 2 x 2 block it takes half a byte a cell and a quarter of the EDTs. Measured
 * (make bench, section 1, one thread, K = 16): builds 0.32 -> 0.08 s on trinidad, 0.034
 * -> 0.010 s on picos, 0.016 -> 0.005 s on levi (Embree's GRID: 0.28, 0.047, 0.012 s),
 * for 2-3% more parametric steps (trinidad 10.83 -> 11.05 a ray, picos 14.52 -> 15.01,
 * levi 9.81 -> 10.15), which the smaller table more than pays for in time (trinidad
 * 2.21 -> 2.50 M rays/s). Per-cell cones reduced to their blocks' (the highest apex and
 * the largest slope of the four) cost 8% more steps than cones built over the blocks.
 *
 * Computing z_p and s_p from K slices (Paglieroni & Petersen 1994), "cell" below meaning
 * a block:
 *   z_k = zlo + k*(zhi - zlo)/(K-1), k = 0 .. K-1, over the tile's valid cell maxima.
 *   D_k(c) = min gap(c, q) over cells q with H(q) >= z_k. Every cell closer than D_k has
 *   H < z_k, so the terrain's height as a function of the distance r from c is bounded
 *   by the staircase B(r) = z_k on [D_{k-1}, D_k), and by zhi beyond D_{K-1}.
 *   The line z_p + s_p*r lies above that staircase iff it is above the left end of
 *   every step: z_p >= B(0) = z_{m+1}, where m is the last slice with D_m = 0, and
 *   z_p + s_p*D_{k-1} >= z_k for every later step (the pairing of D_{k-1} with z_k,
 *   not with z_{k-1}, is what makes the bound hold inside a slice), and >= zhi at the
 *   end. We take the lowest apex z_p = z_{m+1} and the smallest slope that satisfies
 *   every step. A cell with D_k = 0 for every k gets the flat cone z_p = zhi, s_p = 0.
 *   Flat tiles (zhi == zlo) reduce to one slice; no division by zero slice spacing.
 *   Holes have H = -inf and never block; an all-hole tile gets z_p = -inf, s_p = 0.
 *
 * gap(c, q) by an exact EDT: dilating the feature mask by one cell (8-neighbourhood)
 * and taking the centre-to-centre EDT of the dilated mask gives exactly the footprint
 * gap: a centre distance of max(|di|-1, 0)*sx by max(|dj|-1, 0)*sy. The EDT is weighted
 * by sx^2 and sy^2, so cells need not be square.
 *
 * Storage, 2 bytes a block: the apex is always one of the K slice heights z_{m+1} or
 * zhi, so a block stores its index into the tile's table of K + 1 heights (rounded up to
 * float); the slope is a byte code, the smallest whose value (a per-tile power of two
 * times td_planes_slope_unit, steps of at most 6.25%) is at least the computed slope.
 * Both round up, so the stored cone is never narrower than the computed one and (1)
 * holds as proven; a rounded-up slope only shortens a step. The scale puts the tile's
 * steepest slope under the top code; slopes below 2^-15 of it round up to the first
 * code. Measured on trinidad (bench, K = 16): 4x less memory than two floats per cell
 * (2 instead of 8 bytes) for about 1% more steps. Cost: K EDTs of the tile, streamed a
 * row at a time into the cones (20 bytes of scratch a cell instead of 32; that alone did
 * not change the time: the build is bound by arithmetic, not memory). The EDT's division
 * by a reciprocal table and the slope code from the bits instead of a binary search took
 * trinidad's build (one thread, K = 16) from 0.40 to 0.31 s (medians of 7, interleaved).
 * Then (callgrind, instructions in td_planes_build on trinidad): the column pass comparing
 * floats, vectorised; the row pass listing its finite columns without a branch and writing
 * each parabola's run of samples without a comparison each; the apex height kept per cell;
 * the cells' tests in a branch-free pass that vectorises, then only the cells whose cone
 * changes (cone_row): 5.03 -> 4.28 G instructions (-15%), the same planes bit for bit;
 * those loops also built for AVX2 where the processor has it (TD_ROW_CLONES, edt.h): 3.26 G
 * (-35%), the same planes bit for bit again; rows without a column of "none" taken whole
 * by the EDT, not listed: 3.02 G; the tile's height range by comparisons, not fminf/fmaxf
 * calls: 2.97 G. Skipping the cone pass's clear marks eight at a time
 * (a word) saved nothing (more mispredicted branches): not kept. Skipping cells whose
 * slope already reaches the top (later slices cannot widen it) saved as many instructions
 * as its test cost: not kept.
 *
 * Stages of td_planes_build, a function each: the cells' highest corners
 * (td_grid_cell_max), the blocks' (block_max) and their range, the dilation
 * (td_planes_max3x3, public so that a unit test holds it to brute force), the slice sweep
 * (sweep_slices, cone_row per block), the slope encoding (encode_slopes). Called per tile by td_accel_build and by
 * the server's tile store. */
#include "planes.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "edt.h"

/* Exact binary fractions (1 + m/16) * 2^e, code - 1 = 16e + m. */
#define TD_SLOPE_UNIT(c) ((1.0 + (double)(((c) - 1) % 16) / 16.0) * (double)(1L << (((c) - 1) / 16)))
#define TD_SLOPE_ROW(b)                                                                             \
    TD_SLOPE_UNIT(b + 1), TD_SLOPE_UNIT(b + 2), TD_SLOPE_UNIT(b + 3), TD_SLOPE_UNIT(b + 4),         \
        TD_SLOPE_UNIT(b + 5), TD_SLOPE_UNIT(b + 6), TD_SLOPE_UNIT(b + 7), TD_SLOPE_UNIT(b + 8),     \
        TD_SLOPE_UNIT(b + 9), TD_SLOPE_UNIT(b + 10), TD_SLOPE_UNIT(b + 11), TD_SLOPE_UNIT(b + 12),  \
        TD_SLOPE_UNIT(b + 13), TD_SLOPE_UNIT(b + 14), TD_SLOPE_UNIT(b + 15), TD_SLOPE_UNIT(b + 16)

const double td_planes_slope_unit[256] = {
    0.0,                                                                  /* code 0 */
    TD_SLOPE_ROW(0),   TD_SLOPE_ROW(16),  TD_SLOPE_ROW(32),  TD_SLOPE_ROW(48),  /* 1 .. 64 */
    TD_SLOPE_ROW(64),  TD_SLOPE_ROW(80),  TD_SLOPE_ROW(96),  TD_SLOPE_ROW(112), /* .. 128 */
    TD_SLOPE_ROW(128), TD_SLOPE_ROW(144), TD_SLOPE_ROW(160), TD_SLOPE_ROW(176), /* .. 192 */
    TD_SLOPE_ROW(192), TD_SLOPE_ROW(208), TD_SLOPE_ROW(224),                    /* .. 240 */
    TD_SLOPE_UNIT(241), TD_SLOPE_UNIT(242), TD_SLOPE_UNIT(243), TD_SLOPE_UNIT(244),
    TD_SLOPE_UNIT(245), TD_SLOPE_UNIT(246), TD_SLOPE_UNIT(247), TD_SLOPE_UNIT(248),
    TD_SLOPE_UNIT(249), TD_SLOPE_UNIT(250), TD_SLOPE_UNIT(251), TD_SLOPE_UNIT(252),
    TD_SLOPE_UNIT(253), TD_SLOPE_UNIT(254),
    INFINITY, /* code 255 */
};

/* The smallest code whose slope is at least s (s >= 0), from the bits of s / scale (a
 * power of two, so the quotient is exact): exponent i and the top four mantissa bits
 * rounded up give code 1 + 16 i + j. The check after it makes the rounding up certain. */
static uint8_t slope_code(double s, double scale)
{
    int code = 0;
    if (s > 0.0) {
        double u = s / scale;
        uint64_t bits;
        memcpy(&bits, &u, sizeof bits);
        int i = (int)((bits >> 52) & 0x7ff) - 1023; /* u in [2^i, 2^(i+1)) when normal */
        uint64_t frac = bits & (((uint64_t)1 << 52) - 1);
        int j = (int)((frac + (((uint64_t)1 << 48) - 1)) >> 48); /* ceil(16 * (mantissa - 1)) */
        if (j == 16) {
            i++;
            j = 0;
        }
        code = i < 0 ? 1 : (i > 15 || (i == 15 && j > 13) ? 255 : 1 + 16 * i + j);
        while (code < 255 && scale * td_planes_slope_unit[code] < s)
            code++;
    }
    return (uint8_t)code;
}

/* D^2 is kept as a float rounded down with a margin: 2^-16 covers the float's rounding
 * (2^-24) and the EDT's (a misplaced envelope intersection changes a distance by about
 * 4 n^2 ulps of a line of n samples: 2e-6 relative for n = 65536, the largest tile), so
 * the slope it gives is never too small; it is at most 8e-6 too large, far below the
 * slope code's steps. */
#define TD_PLANES_D2_DOWN (1.0 - 0x1p-16)

static float round_up(double v)
{
    float f = (float)v;
    if ((double)f < v)
        f = nextafterf(f, INFINITY);
    return f;
}

/* D^2 as a float at most d2 * (1 - 2^-17): the nearest float to d2 * TD_PLANES_D2_DOWN
 * always is, but for subnormals (spacings under 1e-19 m), which the test sends to 0: a
 * zero distance, so an infinite slope and no jump, which is safe. A selection, not a
 * branch: the row's loop vectorises. */
static inline float d2_down(double d2)
{
    float f = (float)(d2 * TD_PLANES_D2_DOWN);
    return (double)f > d2 * (1.0 - 0x1p-17) ? 0.0f : f;
}

/* A slope as a float at least s: the nearest float to s * (1 + 2^-22) always is, but for
 * subnormals, which the test catches. */
static inline float slope_up(double s)
{
    float f = (float)(s * (1.0 + 0x1p-22));
    if ((double)f < s)
        f = nextafterf(f, INFINITY);
    return f;
}

/* The scratch of one build, allocated and freed together. */
typedef struct planes_work {
    float *cell;          /* H: each cell's highest corner, -inf for a hole */
    float *h3;            /* H's maximum over each cell's 3x3 neighbourhood */
    uint32_t *col;        /* the slice's column distances (td_edt_columns) */
    float *sp;            /* slope so far, rounded up; < 0: apex not fixed yet */
    float *prev;          /* D_{k-1}^2, rounded down */
    double *za;           /* each cell's apex height once fixed, exact (a slice's z_k) */
    uint8_t *mark;        /* one row: the cells whose cone changes at this slice */
    double *d2;           /* one row's squared distances */
    td_edt_scratch scratch;
} planes_work;

static void planes_work_free(planes_work *w)
{
    free(w->cell);
    free(w->h3);
    free(w->col);
    free(w->sp);
    free(w->prev);
    free(w->za);
    free(w->mark);
    free(w->d2);
    td_edt_scratch_free(&w->scratch);
}

/* The planes of an nx x ny tile with k slices (shape, no values yet) and the scratch, which
 * works on the tile's blocks of cones (bnx x bny). */
static td_status planes_alloc(int32_t nx, int32_t ny, int k, td_planes **out, planes_work *w,
                              td_err *err)
{
    td_status rc = TD_OK;
    const int32_t bnx = td_planes_blocks(nx), bny = td_planes_blocks(ny);
    const size_t n = (size_t)bnx * (size_t)bny;
    td_planes *p = calloc(1, sizeof *p);

    memset(w, 0, sizeof *w);
    w->cell = malloc(sizeof(float) * n);
    w->h3 = malloc(sizeof(float) * n);
    w->col = malloc(sizeof(uint32_t) * n);
    w->sp = malloc(sizeof(float) * n);
    w->prev = malloc(sizeof(float) * n);
    w->za = malloc(sizeof(double) * n);
    w->mark = malloc((size_t)bnx);
    w->d2 = malloc(sizeof(double) * (size_t)bnx);
    if (!p || !w->cell || !w->h3 || !w->col || !w->sp || !w->prev || !w->za || !w->mark || !w->d2 ||
        !td_edt_scratch_init(&w->scratch, bnx > bny ? bnx : bny)) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for parameter planes");
        goto out;
    }
    p->k = k;
    p->nx = nx;
    p->ny = ny;
    p->bnx = bnx;
    p->bny = bny;
    p->slope_scale = 1.0;
    p->cone = malloc(sizeof(td_cone) * n);
    p->apex = malloc(sizeof(float) * ((size_t)k + 1));
    if (!p->cone || !p->apex) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for parameter planes");
        goto out;
    }
    p->bytes = sizeof *p + sizeof(td_cone) * n + sizeof(float) * ((size_t)k + 1);
out:
    *out = p;
    return rc;
}

TD_ROW_CLONES void td_planes_max3x3(const float *h, int32_t nx, int32_t ny, float *out)
{
    /* separable: rows into out, then columns in place through a rolling copy of the row
     * above */
    for (int32_t y = 0; y < ny; y++) {
        const float *hr = h + (size_t)y * (size_t)nx;
        float *o = out + (size_t)y * (size_t)nx;
        for (int32_t x = 0; x < nx; x++) {
            float m = hr[x];
            if (x > 0 && hr[x - 1] > m)
                m = hr[x - 1];
            if (x + 1 < nx && hr[x + 1] > m)
                m = hr[x + 1];
            o[x] = m;
        }
    }
    for (int32_t x = 0; x < nx; x++) {
        float above = -INFINITY;
        for (int32_t y = 0; y < ny; y++) {
            float *o = out + (size_t)y * (size_t)nx + (size_t)x;
            float here = *o, m = here;
            if (above > m)
                m = above;
            if (y + 1 < ny && o[nx] > m)
                m = o[nx];
            above = here;
            *o = m;
        }
    }
}

/* One row's cones at slice s (zk its height; d2 the row's D_s^2, unused at s == slices):
 * a cell's apex is fixed at the first slice it is clear of (B(0) = z_{m+1}), or at the top
 * if it never is; after that, its slope widens to reach the rise since the apex at
 * D_{s-1}. Three passes: the tests of every cell, branch-free so that they vectorise
 * (mark); the few cells whose cone changes; every cell's D_s^2 for the next slice (prev of
 * a cell whose apex is not fixed yet is not read). The apex height is kept per cell (za) so
 * the loops read no table through the cone's index. */
TD_ROW_CLONES static void cone_row(td_cone *cone, planes_work *w, size_t r0, int32_t nx, int s, int slices,
                     double zk, const double *d2)
{
    float *sp = w->sp + r0, *prev = w->prev + r0;
    double *za = w->za + r0;
    uint8_t *mark = w->mark;
    const int last = s == slices;
    for (int32_t x = 0; x < nx; x++) {
        /* the staircase rises to z_k at r = D_{k-1}: the slope must reach rise / D_{k-1}.
         * Compared squared (both sides >= 0; prev holds D^2) so the square root and the
         * division run only when the slope may grow; the 1e-9 slack takes the candidate
         * whenever rounding could decide. A cell without an apex changes when it is clear
         * of the slice (B(0) = z_{m+1}), or at the top. */
        double sc = (double)sp[x], rise = zk - za[x], pv = (double)prev[x];
        int grow = (sc >= 0.0) & (rise > 0.0) & (rise * rise >= sc * sc * pv * (1.0 - 1e-9));
        int fix = (sc < 0.0) & (last | (d2[x] > 0.0));
        mark[x] = (uint8_t)(grow | fix);
    }
    for (int32_t x = 0; x < nx; x++) {
        if (!mark[x])
            continue;
        if (sp[x] >= 0.0f) {
            double need = (zk - za[x]) / sqrt((double)prev[x]);
            if (need > (double)sp[x])
                sp[x] = slope_up(need);
        } else { /* or D_k = 0 for every slice: flat cone at the top */
            cone[r0 + (size_t)x].apex = (uint8_t)s;
            za[x] = zk;
            sp[x] = 0.0f;
        }
    }
    if (!last)
        for (int32_t x = 0; x < nx; x++)
            prev[x] = d2_down(d2[x]);
}

/* The slice sweep: one pass per slice, a row at a time: the row's distances go straight
 * into its cells' cones (no nx*ny array of distances is written or read back; the
 * per-cell state is 16 bytes). prev is rounded down and sp up, which only widens the
 * bound. Leaves each cell's apex index in p->cone and its slope in w->sp. */
static void sweep_slices(td_planes *p, planes_work *w, const td_grid *g, float zlo, float zhi,
                         int slices)
{
    const int32_t nx = p->bnx, ny = p->bny;
    const double bx = g->sx * (double)(1 << TD_PLANES_BLOCK_LOG2), by = g->sy * (double)(1 << TD_PLANES_BLOCK_LOG2);
    for (int s = 0; s <= slices; s++) {
        /* slice s < slices is a real slice; s == slices is the final step up to zhi */
        double zk = s == slices ? (double)zhi
                    : slices == 1 ? (double)zlo
                                  : (double)zlo + (double)s * ((double)zhi - (double)zlo) / (slices - 1);
        if (s < slices) {
            p->apex[s] = round_up(zk);
            /* feature mask H >= z_k dilated by one cell = (3x3 maximum of H) >= z_k */
            td_edt_columns(w->h3, zk, nx, ny, w->col);
        }
        for (int32_t y = 0; y < ny; y++) {
            const size_t r0 = (size_t)y * (size_t)nx;
            if (s < slices)
                td_edt_row(w->col + r0, nx, bx * bx, by * by, w->d2, &w->scratch);
            cone_row(p->cone, w, r0, nx, s, slices, zk, w->d2);
        }
    }
}

/* The range of the cells' highest corners, holes (-inf; never NaN) left out of the low
 * end: comparisons, not fminf/fmaxf calls, so the loop vectorises. */
TD_ROW_CLONES static void cell_range(const float *cell, size_t n, float *lo, float *hi)
{
    float zlo = INFINITY, zhi = -INFINITY;
    for (size_t c = 0; c < n; c++) {
        float v = cell[c], l = v == -INFINITY ? INFINITY : v;
        zlo = l < zlo ? l : zlo;
        zhi = v > zhi ? v : zhi;
    }
    *lo = zlo;
    *hi = zhi;
}

/* The blocks' highest corners (TD_PLANES_BLOCK_LOG2) from the cells' (nx x ny): what the
 * slices, the dilation and the distances are taken over, so a block's cone bounds the
 * tile from anywhere over the block (see the top of the file). */
static void block_max(const float *cell, int32_t nx, int32_t ny, int32_t bnx, int32_t bny, float *out)
{
    const int B = TD_PLANES_BLOCK_LOG2;
    for (int32_t bj = 0; bj < bny; bj++) {
        for (int32_t bi = 0; bi < bnx; bi++) {
            float m = -INFINITY;
            for (int32_t cj = bj << B; cj < ((bj + 1) << B) && cj < ny; cj++) {
                for (int32_t ci = bi << B; ci < ((bi + 1) << B) && ci < nx; ci++) {
                    float h = cell[(size_t)cj * (size_t)nx + (size_t)ci];
                    m = h > m ? h : m;
                }
            }
            out[(size_t)bj * (size_t)bnx + (size_t)bi] = m;
        }
    }
}

/* Slope encoding: the tile's scale (a power of two that puts its steepest finite slope
 * under the top code), then each cell's code, rounded up. */
static void encode_slopes(td_planes *p, const float *sp)
{
    const size_t n = (size_t)p->bnx * (size_t)p->bny;
    double smax = 0.0;
    for (size_t c = 0; c < n; c++)
        smax = (double)sp[c] > smax && isfinite(sp[c]) ? (double)sp[c] : smax; /* +inf -> code 255 */
    if (smax > 0.0) {
        /* the top code, scale * 59392, is at least 2^ceil(log2(smax)) >= smax */
        int e = (int)ceil(log2(smax)) - 15;
        p->slope_scale = ldexp(1.0, e < -1000 ? -1000 : (e > 1000 ? 1000 : e));
    }
    for (size_t c = 0; c < n; c++)
        p->cone[c].slope = slope_code((double)sp[c], p->slope_scale);
}

td_status td_planes_build(const td_grid *g, size_t tile, int k, td_planes **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_tile *t = &g->tiles[tile];
    td_planes *p = NULL;
    planes_work w;
    float *cell = NULL;
    float zlo = INFINITY, zhi = -INFINITY;
    int slices = k;
    size_t n = 0;

    *out = NULL;
    memset(&w, 0, sizeof w);
    if (k < 1 || k > TD_PLANES_K_MAX) {
        rc = td_err_set(err, TD_ERANGE, "parameter planes need 1 .. %d slices, not %d", TD_PLANES_K_MAX, k);
        goto out;
    }
    rc = planes_alloc(t->nx, t->ny, k, &p, &w, err);
    cell = malloc(sizeof(float) * (size_t)t->nx * (size_t)t->ny);
    if (!rc && !cell)
        rc = td_err_set(err, TD_ENOMEM, "out of memory for parameter planes");
    if (rc)
        goto out;
    n = (size_t)p->bnx * (size_t)p->bny;
    td_grid_cell_max(g, t, cell);
    block_max(cell, t->nx, t->ny, p->bnx, p->bny, w.cell);
    cell_range(w.cell, n, &zlo, &zhi);
    if (zhi == -INFINITY) { /* all holes: nothing to hit anywhere in the tile */
        for (int s = 0; s <= k; s++)
            p->apex[s] = -INFINITY;
        memset(p->cone, 0, sizeof(td_cone) * n);
        goto out;
    }
    if (zhi == zlo)
        slices = 1;
    for (int s = slices; s <= k; s++)
        p->apex[s] = round_up(zhi); /* the top, and unused entries of a flat tile */
    for (size_t c = 0; c < n; c++)
        w.sp[c] = -1.0f; /* apex not fixed yet */
    td_planes_max3x3(w.cell, p->bnx, p->bny, w.h3);
    sweep_slices(p, &w, g, zlo, zhi, slices);
    encode_slopes(p, w.sp);
out:
    free(cell);
    planes_work_free(&w);
    if (rc != TD_OK) {
        td_planes_free(p);
        p = NULL;
    }
    *out = p;
    return rc;
}

void td_planes_free(td_planes *p)
{
    if (p) {
        free(p->cone);
        free(p->apex);
        free(p);
    }
}
