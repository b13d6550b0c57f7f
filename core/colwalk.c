/* colwalk.c: the column walk of colwalk.h (a vertical plane's rays along one walk of its
 * cells, each tested from where the ray below it hit).
 *
 * The line is E + s h in the horizontal distance s, in cells u = U + s du, v = V + s dv.
 * Cells are entered as trace.c's walk enters them: a point on a grid line belongs to the
 * cell the line goes on into (td_cell_along, surface.h), leaving across a sample point moves both indices.
 * A cell's profile is its surface's height at the line's entry (s_in) and exit (s_out) and,
 * on the triangle surface, where the line crosses the diagonal a + b = 1 (trace.c's
 * triangle_cross splits the segment there); each ray's f = z - height is tested over it by
 * the cell walk's rules and expressions (surface.h: td_seg_hit, the first zero or change of
 * sign; td_quad_hit, the bilinear patch's quadratic; plane_cross's top and walls), so the
 * two agree to the rounding of the parameter. The
 * linear surface's height in the eye's own cell is the line from where the line enters that
 * cell behind the eye to where it leaves (trace.c's linear_under). */
#include "colwalk.h"

#include <math.h>

#include "grid.h"
#include "maxmip.h"
#include "simd.h"
#include "surface.h"

#define CW_BOX_LOG2 3 /* boxes of 8 x 8 cells: the max-mipmap's level 3 */

enum { CW_START, CW_U, CW_V, CW_UV }; /* how a cell was entered (trace.c's ENTRY_*) */

static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

int td_colwalk_init(td_colwalk *cw, const td_view *v, td_surface sf, const double o[3])
{
    const td_grid *g = v->grid;
    const double U = o[0] / g->sx, V = o[1] / g->sy;
    int ok = (unsigned)sf < TD_SURFACE_COUNT && g->w >= 2 && g->h >= 2 && U > 0.0 && V > 0.0 &&
             U < (double)(g->w - 1) && V < (double)(g->h - 1) && isfinite(o[2]) && g->zmax == g->zmax;
    if (ok) {
        *cw = (td_colwalk){.v = v, .sf = sf, .o = {o[0], o[1], o[2]}, .U = U, .V = V,
                           .zmax = g->zmax,
                           .zeps = 1e-6 * (1.0 + dmax(fabs((double)g->zmin), fabs((double)g->zmax)))};
        /* every corner of the cells the eye may be in (two a side on a line), no void */
        const int32_t i0 = (int32_t)U, j0 = (int32_t)V;
        for (int32_t j = j0 - 1; ok && j <= j0 + 2; j++)
            for (int32_t i = i0 - 1; ok && i <= i0 + 2; i++)
                if (i >= 0 && j >= 0 && i < g->w && j < g->h) {
                    double z = td_grid_sample(g, i, j);
                    ok = z == z && o[2] > z + cw->zeps;
                }
    }
    return ok;
}

/* A box of cells [i0, i1) x [j0, j1) around cell (ci, cj) and the bound of every surface
 * over it: the max-mipmap's 8 x 8 block, or the tile without one. The walk keeps the last
 * box (valid): a new ray over the same box asks nothing new. */
typedef struct cw_box {
    int32_t i0, i1, j0, j1;
    double top;
    int valid;
} cw_box;

static cw_box box_of(const td_view *v, int32_t ci, int32_t cj)
{
    const td_grid *g = v->grid;
    const td_tile *t = td_grid_tile_of_cell(g, ci, cj);
    const td_maxmip *mm = v->accel ? v->accel[t - g->tiles].maxmip : NULL;
    cw_box b = {t->i0, t->i0 + t->nx, t->j0, t->j0 + t->ny, t->zmax < t->zmin ? -INFINITY : (double)t->zmax, 1};
    if (mm && mm->levels >= CW_BOX_LOG2) {
        int32_t bi = (ci - t->i0) >> CW_BOX_LOG2, bj = (cj - t->j0) >> CW_BOX_LOG2;
        b.i0 = t->i0 + (bi << CW_BOX_LOG2);
        b.j0 = t->j0 + (bj << CW_BOX_LOG2);
        b.i1 = b.i0 + (1 << CW_BOX_LOG2) < b.i1 ? b.i0 + (1 << CW_BOX_LOG2) : b.i1;
        b.j1 = b.j0 + (1 << CW_BOX_LOG2) < b.j1 ? b.j0 + (1 << CW_BOX_LOG2) : b.j1;
        b.top = td_maxmip_bound(mm, CW_BOX_LOG2, bi, bj);
    }
    return b;
}

static inline int in_box(const cw_box *b, int32_t ci, int32_t cj)
{
    return b->valid && ci >= b->i0 && ci < b->i1 && cj >= b->j0 && cj < b->j1;
}

/* The line's walk (see the top of the file). */
typedef struct cw_line {
    double U, V, du, dv, iu, iv;
    int su, sv;
    int32_t cmax_i, cmax_j;
} cw_line;

/* The time the line crosses column line i (row line j): +inf when it runs along them. */
static inline double time_u(const cw_line *l, double i) { return l->su ? (i - l->U) * l->iu : INFINITY; }
static inline double time_v(const cw_line *l, double j) { return l->sv ? (j - l->V) * l->iv : INFINITY; }

/* The cell the line is in at s along one axis (origin P, step d cells a metre, sign sg,
 * crossing times of line k: time(k)), by the crossing times the cell-by-cell walk goes by,
 * not by the rounded position P + s d: in cell c while time(c) <= s < time(c + 1) going up,
 * time(c + 1) <= s < time(c) going down. A line nearly along a grid line is a rounding off
 * it in position long before it crosses it (fuzz_render: an eye on row line 6 looking
 * west, crossing it 64 m out, put a cell in the row below after a box crossed 40 m out, on
 * the plane surface a column lower). */
static int32_t cell_by_time(const cw_line *l, int axis, double s)
{
    const double P = axis ? l->V : l->U, d = axis ? l->dv : l->du;
    const int sg = axis ? l->sv : l->su;
    const int32_t hi = axis ? l->cmax_j : l->cmax_i;
    int32_t c = td_cell_along(P + s * d, sg, 0, hi);
    if (sg > 0) {
        while (c > 0 && (axis ? time_v(l, c) : time_u(l, c)) > s)
            c--;
        while (c < hi && (axis ? time_v(l, c + 1) : time_u(l, c + 1)) <= s)
            c++;
    } else if (sg < 0) {
        while (c < hi && (axis ? time_v(l, c + 1) : time_u(l, c + 1)) > s)
            c++;
        while (c > 0 && (axis ? time_v(l, c) : time_u(l, c)) <= s)
            c--;
    }
    return c;
}

/* The surface sf's height at local (a, b) of a cell (the linear surface's on its boundary,
 * where it is the edge's line, as the bilinear patch's is). */
static inline __attribute__((always_inline)) double height(const td_surface sf, const double c[4], double a,
                                                           double b)
{
    return sf == TD_SURFACE_TRIANGLE ? td_patch_triangle(c, a, b) : td_patch_bilinear(c, a, b);
}

/* The height plane's walls make a hit depend on which side of a sample point a ray's line
 * passes: a line through one clips the corner of the column beside it, or not, and meets
 * its wall there, or not. Each ray of a column has its own line, the shared one to within a
 * rounding of its direction; where the shared line leaves a cell within 1e-9 of its
 * parameter of a sample point (its crossings of the column and the row line that near),
 * the rays still unfinished that are low enough there for a wall of the two cells beside
 * the point (clear_of_walls) are left to the plain walk (the caller traces them; fuzz_render
 * found an eye on a sample looking along the diagonal, whose line clipped a corner cell at
 * the grid's edge for td_trace and not for the column walk). The other surfaces are
 * continuous across a cell's edges and corners: a side's choice moves no hit. */
static inline int near_vertex(double tu, double tv)
{
    return tu < INFINITY && tv < INFINITY && fabs(tu - tv) <= 1e-9 * (1.0 + fabs(tu));
}

/* Whether a ray at height z at the sample point where the line leaves cell (ci, cj) clears
 * the tops of the two cells beside that point (the one across the column line and the one
 * across the row line; off the grid or holes: nothing to meet). */
static int clear_of_walls(const td_grid *g, const cw_line *l, int32_t ci, int32_t cj, double z)
{
    const int32_t cell[2][2] = {{ci + l->su, cj}, {ci, cj + l->sv}};
    int clear = 1;
    for (int k = 0; k < 2 && clear; k++) {
        const int32_t i = cell[k][0], j = cell[k][1];
        if (i >= 0 && j >= 0 && i <= l->cmax_i && j <= l->cmax_j) {
            const float *p = td_grid_corner(&g->cz, i, j);
            const size_t W = g->cz.stride;
            const double c[4] = {p[0], p[1], p[W], p[W + 1]};
            const int hole = !(c[0] == c[0] && c[1] == c[1] && c[2] == c[2] && c[3] == c[3]);
            clear = hole || z > td_patch_plane(c);
        }
    }
    return clear;
}

/* A hit's record (td_colhit): its bilinear height and its unit normal, from the cell's
 * corners c at local (a, b) = the hit's position, clamped (trace.c's surface_normal and
 * unit_normal, the surfaces' gradients). */
static inline __attribute__((always_inline)) void finish(const td_surface sf, const cw_line *l,
                                                         const double c[4], double s, int wall, int32_t ci,
                                                         int32_t cj, double sx, double sy, td_colhit *h)
{
    const double a = td_clamp01(l->U + s * l->du - ci), b = td_clamp01(l->V + s * l->dv - cj);
    double nv[3] = {0.0, 0.0, 1.0}, gr[2];
    if (sf == TD_SURFACE_PLANE) { /* the top, or the wall the ray came through */
        nv[0] = wall == CW_U ? -(double)l->su : 0.0;
        nv[1] = wall == CW_V ? -(double)l->sv : 0.0;
        nv[2] = wall ? 0.0 : 1.0;
    } else {
        /* the linear surface's normal is the bilinear one's (trace.c's table) */
        if (sf == TD_SURFACE_TRIANGLE)
            td_gradient_triangle(c, a, b, gr);
        else
            td_gradient_bilinear(c, a, b, gr);
        nv[0] = -gr[0] / sx;
        nv[1] = -gr[1] / sy;
    }
    h->s = s;
    h->zb = td_patch_bilinear(c, a, b);
    td_unit_normal(nv, h->n);
    h->ci = ci;
    h->cj = cj;
}

/* The walk of one line for surface sf (see the top of the file); the cell's profile in
 * locals: entry s_in (height ha), exit s_out (hb), the diagonal's crossing sd (hd) where
 * the line crosses it inside the cell (split), the plane's top. */
static inline __attribute__((always_inline)) uint32_t walk(const td_colwalk *cw, const td_surface sf,
                                                           double hx, double hy, double s0, int n,
                                                           const double *e, td_colhit *hit)
{
    const td_view *v = cw->v;
    const td_grid *g = v->grid;
    const size_t W = g->cz.stride;
    const double oz = cw->o[2], zeps = cw->zeps, zsky = cw->zmax + cw->zeps;
    cw_line l = {.U = cw->U, .V = cw->V, .du = hx / g->sx, .dv = hy / g->sy,
                 .cmax_i = g->w - 2, .cmax_j = g->h - 2};
    l.su = l.du > 0.0 ? 1 : (l.du < 0.0 ? -1 : 0);
    l.sv = l.dv > 0.0 ? 1 : (l.dv < 0.0 ? -1 : 0);
    l.iu = l.su ? 1.0 / l.du : 0.0;
    l.iv = l.sv ? 1.0 / l.dv : 0.0;
    const double U = l.U, V = l.V, du = l.du, dv = l.dv;
    /* the bilinear patch's quadratic coefficient along the line, per unit of twist */
    const double Aq = -du * dv;
    /* where the line leaves the grid */
    const double s1 = dmin(l.su ? time_u(&l, l.su > 0 ? g->w - 1 : 0) : INFINITY,
                           l.sv ? time_v(&l, l.sv > 0 ? g->h - 1 : 0) : INFINITY);
    uint32_t steps = 0;
    int k = 0, entry = CW_START, fresh = 1;
    int under = 0;   /* the lowest unfinished ray has been under the surface (through a hole) */
    int stopped = 0; /* the walk stopped after such a ray's hit */
    double s_in = s0 > 0.0 ? s0 : 0.0, hb = 0.0;
    int32_t ci = cell_by_time(&l, 0, s_in), cj = cell_by_time(&l, 1, s_in);
    int done = !(s1 > s_in) || (l.su == 0 && l.sv == 0);
    cw_box b = {.valid = 0};
    while (!done) {
        /* the box around the cell: crossed at once when ray k passes over it */
        if (!in_box(&b, ci, cj))
            b = box_of(v, ci, cj);
        const double tx = l.su ? time_u(&l, l.su > 0 ? b.i1 : b.i0) : INFINITY;
        const double ty = l.sv ? time_v(&l, l.sv > 0 ? b.j1 : b.j0) : INFINITY;
        const double sx = dmin(dmin(tx, ty), s1);
        const double ek = e[k];
        steps++;
        /* (on the plane surface not by a box's corner: the line's side of it decides a
           wall, see near_vertex) */
        if (oz + ek * (ek >= 0.0 ? s_in : sx) > b.top + zeps && !(sf == TD_SURFACE_PLANE && near_vertex(tx, ty))) {
            if (sx >= s1) {
                done = 1;
            } else {
                const int kind = tx < ty ? CW_U : (ty < tx ? CW_V : CW_UV);
                s_in = sx;
                entry = kind;
                fresh = 1;
                ci = kind != CW_V ? (l.su > 0 ? b.i1 : b.i0 - 1) : cell_by_time(&l, 0, sx);
                cj = kind != CW_U ? (l.sv > 0 ? b.j1 : b.j0 - 1) : cell_by_time(&l, 1, sx);
                done = ci < 0 || cj < 0 || ci > l.cmax_i || cj > l.cmax_j;
            }
            continue;
        }
        /* the box's cells, until it is left or ray k is done */
        const int k0 = k;
        for (;;) {
            const double nu = time_u(&l, l.su > 0 ? ci + 1 : ci), nv = time_v(&l, l.sv > 0 ? cj + 1 : cj);
            const int kind = nu < nv ? CW_U : (nv < nu ? CW_V : CW_UV);
            double s_out = dmin(dmin(nu, nv), s1);
            s_out = s_out < s_in ? s_in : s_out; /* rounding at a corner: an empty segment */
            steps++;
            const float *p = td_grid_corner(&g->cz, ci, cj);
            const double c[4] = {p[0], p[1], p[W], p[W + 1]};
            if (c[0] == c[0] && c[1] == c[1] && c[2] == c[2] && c[3] == c[3]) { /* else a hole */
                const double ua = U + s_in * du - ci, va = V + s_in * dv - cj;
                const double ub = U + s_out * du - ci, vb = V + s_out * dv - cj;
                double ha = 0.0, hd = 0.0, sd = s_out, top = 0.0;
                int split = 0;
                if (sf == TD_SURFACE_PLANE) {
                    top = td_patch_plane(c);
                } else {
                    /* the entry's height is the cell before's exit height (the same point
                       of their shared edge, where every surface is the edge's line) */
                    const double hprev = hb;
                    hb = height(sf, c, td_clamp01(ub), td_clamp01(vb));
                    if (sf == TD_SURFACE_LINEAR && entry == CW_START) {
                        /* the start's cell: the line from where it enters the cell behind */
                        double tb = dmax(l.su ? time_u(&l, l.su > 0 ? ci : ci + 1) : -INFINITY,
                                         l.sv ? time_v(&l, l.sv > 0 ? cj : cj + 1) : -INFINITY);
                        double hback =
                            td_patch_bilinear(c, td_clamp01(U + tb * du - ci), td_clamp01(V + tb * dv - cj));
                        ha = s_out > tb ? hback + (hb - hback) * td_clamp01((s_in - tb) / (s_out - tb))
                                        : td_patch_bilinear(c, td_clamp01(ua), td_clamp01(va));
                    } else {
                        ha = fresh ? height(sf, c, td_clamp01(ua), td_clamp01(va)) : hprev;
                    }
                    if (sf == TD_SURFACE_TRIANGLE) {
                        const double da = ua + va - 1.0, db = ub + vb - 1.0;
                        if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
                            split = 1;
                            sd = s_in + (s_out - s_in) * (da / (da - db));
                            hd = c[1] + (c[2] - c[1]) * td_clamp01(V + sd * dv - cj);
                        }
                    }
                }
                fresh = 0;
                /* the rays from k on, each tested over the profile (trace.c's rules) */
                for (; k < n; k++) {
                    const double ek2 = e[k];
                    double s = INFINITY;
                    int wall = 0, hit_now = 0;
                    if (sf == TD_SURFACE_PLANE) {
                        const double za = oz + ek2 * s_in, zb = oz + ek2 * s_out;
                        if (za <= top) {
                            s = s_in;
                            wall = za < top && (entry == CW_U || entry == CW_V) ? entry : 0;
                            hit_now = 1;
                        } else if (zb <= top) {
                            const double sh = s_in + (za - top) / -ek2;
                            s = sh < s_in ? s_in : (sh > s_out ? s_out : sh);
                            hit_now = 1;
                        }
                    } else {
                        const double fa = oz + ek2 * s_in - ha, fb = oz + ek2 * s_out - hb;
                        under |= fa < 0.0;
                        if (sf == TD_SURFACE_BILINEAR) {
                            hit_now = td_quad_hit(s_in, fa, s_out, fb, (c[0] - c[1] - c[2] + c[3]) * Aq, &s);
                        } else if (split) {
                            const double fd = oz + ek2 * sd - hd;
                            hit_now = td_seg_hit(s_in, fa, sd, fd, &s) || td_seg_hit(sd, fd, s_out, fb, &s);
                        } else {
                            hit_now = td_seg_hit(s_in, fa, s_out, fb, &s);
                        }
                    }
                    if (!hit_now)
                        break;
                    finish(sf, &l, c, s, wall, ci, cj, g->sx, g->sy, &hit[k]);
                    if (under) { /* the rays above it may meet the terrain where it was under */
                        k++;
                        done = stopped = 1;
                        break;
                    }
                }
                if (done)
                    break;
            } else {
                fresh = 1;
            }
            if (sf == TD_SURFACE_PLANE && k < n && near_vertex(nu, nv) &&
                !clear_of_walls(g, &l, ci, cj, oz + e[k] * s_out - zeps)) {
                under = stopped = done = 1; /* the rays from k on: the plain walk's */
                break;
            }
            if (k == n || s_out >= s1) {
                done = 1;
                break;
            }
            s_in = s_out;
            entry = kind;
            ci += kind != CW_V ? l.su : 0;
            cj += kind != CW_U ? l.sv : 0;
            if (ci < 0 || cj < 0 || ci > l.cmax_i || cj > l.cmax_j) {
                done = 1;
                break;
            }
            if (e[k] >= 0.0 && oz + e[k] * s_in > zsky) { /* above every sample from here on */
                done = 1;
                break;
            }
            if (k != k0 || !in_box(&b, ci, cj))
                break; /* a new box, or a new ray for this one */
        }
    }
    /* the walk ended with ray k unfinished (a miss: off the grid, or above every sample),
       unless it stopped after a ray that had been under the surface (stopped) */
    if (k < n && !stopped)
        hit[k++] = (td_colhit){.s = INFINITY, .zb = NAN, .ci = -1, .cj = -1};
    for (; k < n; k++) /* the rays above: misses too, or not known once a ray went under */
        hit[k] = (td_colhit){.s = under ? NAN : INFINITY, .zb = NAN, .ci = -1, .cj = -1};
    return steps;
}

/* walk() compiled for each surface of TD_SURFACE_LIST (its tests inline, no switch a
 * cell), walk_TD_SURFACE_PLANE .. */
#define CW_WALK_FN(sf, name)                                                                              \
    TD_PACKET_CLONES static uint32_t walk_##sf(const td_colwalk *cw, double hx, double hy, double s0, int n, \
                                               const double *e, td_colhit *hit)                          \
    {                                                                                                     \
        return walk(cw, sf, hx, hy, s0, n, e, hit);                                                       \
    }
TD_SURFACE_LIST(CW_WALK_FN)
#undef CW_WALK_FN

uint32_t td_colwalk_trace(const td_colwalk *cw, double hx, double hy, double s0, int n,
                          const double *e, td_colhit *hit)
{
    uint32_t (*const fn[TD_SURFACE_COUNT])(const td_colwalk *, double, double, double, int, const double *,
                                           td_colhit *) = {
#define CW_WALK_ENTRY(sf, name) [sf] = walk_##sf,
        TD_SURFACE_LIST(CW_WALK_ENTRY)
#undef CW_WALK_ENTRY
    };
    return fn[cw->sf](cw, hx, hy, s0, n, e, hit);
}
