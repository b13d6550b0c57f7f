/* trace.c: one ray against the height field, by three methods over four surfaces.
 *
 * Every method is the same cell walk (Amanatides & Woo) with a different way of
 * skipping cells the ray cannot hit:
 *
 *   incremental   skips nothing: every cell the ray crosses is intersected;
 *   hierarchical  skips whole blocks of a tile's max-mipmap the ray passes above;
 *   parametric    skips the span over which the ray stays above the current cell's cone
 *                 of empty space (planes.c explains why that is safe);
 *   silhouette    the incremental walk: its camera rays come with a start from the
 *                 render's silhouette partition (silhouette.h) through td_trace_from;
 *   auto          picks one of these per tile from what is resident and how many cells
 *                 the ray crosses there.
 *
 * Each iteration of the walk is one step: a tile test, a block test, a cone step or a
 * cell intersection. Counters live in locals and are written once at the end.
 *
 * One place for each thing (a new surface, lattice or method is a row and its functions):
 *   surfaces[]     one row per surface: its patch, its height under a ray, its
 *                  intersection over one cell, its normal's gradient, solid or two-sided;
 *   crossing()     the tie rule (below) that picks the boundary a ray leaves a cell by;
 *   enter_cell()   the only write of the walk's position; advance() moves to the
 *                  neighbour across a crossing, leave_box_at() past a skipped box;
 *   cell_test()    the one cell intersection, walk_cell() its quick rejection;
 *   method_runs[]  how each method crosses a tile; tile_enter() enters a tile (skip it
 *                  whole, or pick the method); td_trace() ends the walk off the grid;
 *   walk_grid() .. walk_clip()  the walk's setup in the parts rays share (grid, origin,
 *                  direction) and each ray's clip: td_trace_fan (a render's camera rays)
 *                  and td_occluded_par (its shadow rays) set up the shared part once, and
 *                  every ray still takes the one walk, so its answer is the one-ray call's;
 *   vstep() ..     the one twin (trace_lanes.inc): setup and the cell walk for four rays
 *                  at once (eight with AVX-512), in vectors, each lane the scalar code's operations in its order (the
 *                  Packets section says why that is the same bits, and the tests hold it
 *                  there); a change to a surface or to the walk's first cells changes both.
 *                  fan_packet() walks a fan's camera rays with it, occ_packets() a render's
 *                  shadow rays.
 *
 * Watertightness. The crossing test is a sign test on f(t) = z_ray(t) - surface(t).
 * Inside a cell the triangle and linear surfaces make f linear in t (on each side of
 * the diagonal), the bilinear surface quadratic. On a cell edge all three surfaces are
 * the same linear interpolation of the edge's two samples, so f at a boundary crossing
 * is computed by one function of (t, the edge's samples) that the cells on both sides
 * share: the value leaving one cell is bit-for-bit the value entering the next, across
 * tile seams too, and after a skip the value is recomputed by that same function. A
 * crossing can therefore never fall between two cells. Skips land on cell boundaries
 * (block faces; the entry boundary of the cell where a cone step ends), never inside a
 * cell, for the same reason.
 *
 * Precision. Ray setup is in double; a direction whose largest component lies outside
 * [2^-20, 2^20] is scaled by a power of two to about 1 (exact, undone on t at the end),
 * and components below 1e-200 are flushed to zero, so reciprocals never overflow. Positions are kept
 * in cell units (u = x/sx, v = y/sy) and boundary times recomputed from integer cell
 * indices at every step, so nothing drifts. Heights and acceleration data are float.
 * Every skip test keeps a margin of zeps above the bound: a ray closer than that to a
 * block maximum or a cone is walked cell by cell, never skipped.
 *
 * Alternative rejected: single-precision ray arithmetic in the walk. On x86-64 scalar
 * float and double cost the same, and float t loses about 1e-7 of the ray's length,
 * which for grazing rays (1e-3 rad and below) moves hits by metres; the data itself
 * (heights, maxima, cones) stays float. */
#include "trace.h"
#include "surface.h"

#include <float.h>
#include <math.h>
#include <string.h>

#include "maxmip.h"
#include "planes.h"
#include "simd.h"
#include "sunlit.h"

#if TD_PACKET_WIDE
#include <immintrin.h> /* the eight-lane packets' mask tests */
#endif

static const char *const td_method_names[] = {
#define TD_X_NAME(e, name) name,
    TD_METHOD_LIST(TD_X_NAME)
#undef TD_X_NAME
};

static const char *const td_surface_names[] = {
#define TD_X_NAME(e, name) name,
    TD_SURFACE_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_method_name(td_method m)
{
    return (unsigned)m < TD_METHOD_COUNT ? td_method_names[m] : "unknown";
}

const char *td_surface_name(td_surface s)
{
    return (unsigned)s < TD_SURFACE_COUNT ? td_surface_names[s] : "unknown";
}

td_status td_method_parse(const char *name, td_method *out)
{
    int i = td_name_index(td_method_names, TD_METHOD_COUNT, name);
    if (i >= 0)
        *out = (td_method)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

td_status td_surface_parse(const char *name, td_surface *out)
{
    int i = td_name_index(td_surface_names, TD_SURFACE_COUNT, name);
    if (i >= 0)
        *out = (td_surface)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

td_status td_ray_validate(const td_ray *r, td_err *err)
{
    static const char *const comp[] = {"ox", "oy", "oz", "dx", "dy", "dz"};
    td_status rc = TD_OK;
    for (int i = 0; i < 6 && rc == TD_OK; i++) {
        double v = i < 3 ? r->o[i] : r->d[i - 3];
        if (!isfinite(v))
            rc = td_err_set(err, TD_ERANGE, "ray component %s is %s", comp[i], isnan(v) ? "NaN" : "infinite");
    }
    if (rc == TD_OK && r->d[0] == 0.0 && r->d[1] == 0.0 && r->d[2] == 0.0)
        rc = td_err_set(err, TD_ERANGE, "ray direction is zero");
    /* t is in units of d: below this floor a hit distance of a few metres would not fit
     * a double (2^900 * 2^100 m), and td_trace's power-of-two rescaling stays finite. */
    if (rc == TD_OK && fabs(r->d[0]) < 0x1p-900 && fabs(r->d[1]) < 0x1p-900 && fabs(r->d[2]) < 0x1p-900)
        rc = td_err_set(err, TD_ERANGE, "ray direction is too small (all components below 2^-900): "
                                        "hit distances would overflow");
    if (rc == TD_OK && !(r->tmin >= 0.0 && isfinite(r->tmin)))
        rc = td_err_set(err, TD_ERANGE, "ray tmin must be finite and >= 0");
    if (rc == TD_OK && !(r->tmax >= r->tmin)) /* NaN fails too */
        rc = td_err_set(err, TD_ERANGE, "ray tmax must be >= tmin");
    return rc;
}

/* The walk's helpers are small and on the hot path of every step: always inlined. */
#define TD_HOT static inline __attribute__((always_inline))

/* ------------------------------------------------------------------------------------ */
/* The walk's invariant data for one ray, and where it stands.                          */

typedef struct surface_ops surface_ops;

typedef struct walk {
    const td_grid *g;
    td_corners cz;     /* g->cz: where a cell's corners are (grid.h) */
    const surface_ops *surf;
    double ou, ov, oz; /* origin: cell units (u = x/sx, v = y/sy), metres */
    double du, dv, dz; /* direction per unit of internal t */
    double iu, iv, iz; /* reciprocals (+inf where the component is zero) */
    int su, sv;        /* signs of du, dv: -1, 0, +1 */
    double hs;         /* horizontal metres per unit t (for cone steps) */
    double t_end;      /* end of the search, internal t */
    double zeps;       /* margin kept above every bound before skipping */
    int32_t cmax_i, cmax_j; /* last cell index: w-2, h-2 */
    const td_sunlit *lit;   /* occlusion toward the sun: where the ray is surely lit */
    ptrdiff_t lit_k;        /* the ray's strip of lit (td_sunlit_strip; -1: none) */
} walk;

/* How the walk entered its cell: at the ray's start, or across a sample column (u), a
 * sample row (v) or both at once (a sample point). */
enum { ENTRY_START, ENTRY_U, ENTRY_V, ENTRY_UV };

typedef struct walk_state {
    int32_t ci, cj;
    double t;
    double f;  /* z_ray - surface at t on the entry boundary; NaN: not computed yet */
    int entry; /* how the cell was entered */
    int level; /* max-mipmap level a hierarchical run starts at (-1: the tile's top) */
} walk_state;

typedef struct hit_rec {
    double t;
    int32_t ci, cj;
    int wall; /* plane surface: 0 top, ENTRY_U or ENTRY_V for a wall */
} hit_rec;

/* The ray over one cell: what a surface's intersection needs. */
typedef struct cell_seg {
    int32_t ci, cj;
    double c[4];     /* corners z00, z10, z01, z11 */
    double ta, tb;   /* the span, entry to exit (or to the end of the search) */
    int entry, exit; /* how the ray enters and leaves (ENTRY_START: it ends inside) */
    double fa, fb;   /* f at ta (NaN: not known) and at tb (set by the f surfaces) */
} cell_seg;

enum { STEP_CONTINUE, STEP_HIT, STEP_END };

static inline double ray_u(const walk *w, double t) { return w->ou + w->du * t; }
static inline double ray_v(const walk *w, double t) { return w->ov + w->dv * t; }
static inline double ray_z(const walk *w, double t) { return w->oz + w->dz * t; }

static inline double clamp01(double x) { return td_clamp01(x); }

/* A direction component below 1e-200 is zero (see Precision at the top). */
static inline double flush_tiny(double x) { return fabs(x) < 1e-200 ? 0.0 : x; }

/* min/max of non-NaN values as single instructions (libm's fmin/fmax are calls that
 * honour NaN rules we never need here: no NaN reaches them). */
static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

static inline void corners(const td_grid *g, int32_t ci, int32_t cj, double c[4])
{
    const float *s0 = td_grid_corner(&g->cz, ci, cj);
    c[0] = s0[0];
    c[1] = s0[1];
    c[2] = s0[g->cz.stride];
    c[3] = s0[g->cz.stride + 1];
}

/* Time the ray reaches the sample line u = k (or v = k). */
static inline double time_u(const walk *w, double k)
{
    return w->su ? (k - w->ou) * w->iu : INFINITY;
}

static inline double time_v(const walk *w, double k)
{
    return w->sv ? (k - w->ov) * w->iv : INFINITY;
}

/* Entry and exit times of cell column ci (row cj); -inf entry for a ray parallel to it. */
static inline double entry_u(const walk *w, int32_t ci)
{
    return w->su ? time_u(w, (double)(ci + (w->su < 0))) : -INFINITY;
}

static inline double entry_v(const walk *w, int32_t cj)
{
    return w->sv ? time_v(w, (double)(cj + (w->sv < 0))) : -INFINITY;
}

static inline double exit_u(const walk *w, int32_t ci)
{
    return time_u(w, (double)(ci + (w->su > 0)));
}

static inline double exit_v(const walk *w, int32_t cj)
{
    return time_v(w, (double)(cj + (w->sv > 0)));
}

/* The cell index along one axis that contains the ray just after time t (surface.h). */
static inline int32_t cell_along(double pos, int s, int32_t lo, int32_t hi)
{
    return td_cell_along(pos, s, lo, hi);
}

/* cell_along's cell c at time t, put where the walk is at t: back a cell (along the walk's
 * step s, within [lo, hi]) when the walk enters c only after t (entry te > t), on to the
 * next when it has left c by t (exit tx <= t; at a tie the walk has stepped on). The
 * position is rounded: a ray within an ulp of a grid line lands past the line long before
 * the walk crosses it (a nearly vertical ray: the line's ulp is crossed after metres of
 * descent), or short of it after, and a walk put there skips what is left of the cell it
 * is in, or walks a cell off its path (a ray through a sample point met the column beside
 * it, which it touches at that point only). fuzz_render found these (seeds
 * straight-down-on-line, straight-down-jump, diagonal-vertex). */
static inline int32_t time_cell(double te, double tx, double t, int32_t c, int s, int32_t lo, int32_t hi)
{
    return te > t && c - s >= lo && c - s <= hi ? c - s : (tx <= t && c + s >= lo && c + s <= hi ? c + s : c);
}

/* The column (row) the walk is in at time t, within [lo, hi]: from the ray's position,
 * then time_cell. Every place that finds a cell inside the walk takes it from here
 * (skip_to, cone_run's jump, leave_box_at's other axis; vstart_at lane by lane);
 * start_cell, at the walk's start, has no crossing before it to agree with. */
static inline int32_t walk_col(const walk *w, double t, int32_t lo, int32_t hi)
{
    int32_t c = cell_along(ray_u(w, t), w->su, lo, hi);
    return time_cell(entry_u(w, c), exit_u(w, c), t, c, w->su, lo, hi);
}

static inline int32_t walk_row(const walk *w, double t, int32_t lo, int32_t hi)
{
    int32_t c = cell_along(ray_v(w, t), w->sv, lo, hi);
    return time_cell(entry_v(w, c), exit_v(w, c), t, c, w->sv, lo, hi);
}

/* ------------------------------------------------------------------------------------ */
/* Cell boundaries: the heights every surface shares there.                             */

/* Height on the edge from sample height a to b, at the ray's v (a column's edge, from row
 * J) or u (a row's edge, from column I) at time t. */
static inline double edge_height(double a, double b, double pos, int32_t k)
{
    return a + (b - a) * clamp01(pos - (double)k);
}

/* The surface height where the ray crosses boundary `kind` of the segment's cell, on its
 * entry side (`side` 0) or its exit side (1), from the cell's corners the segment holds
 * (c: z00, z10, z01, z11). A crossing is one boundary seen from both cells: the entry side
 * of a cell is the exit side of the one before it, and both read the same two samples
 * (the same floats, whichever cell's corners they came with), so the two values are the
 * same bits. */
static inline double boundary_height(const walk *w, const cell_seg *s, int kind, int side, double t)
{
    const int eu = side ? w->su > 0 : w->su < 0, ev = side ? w->sv > 0 : w->sv < 0;
    const double *c = s->c;
    double h;
    if (kind == ENTRY_U) /* column ci + eu, rows cj .. cj + 1 */
        h = edge_height(c[eu], c[2 + eu], ray_v(w, t), s->cj);
    else if (kind == ENTRY_V) /* row cj + ev, columns ci .. ci + 1 */
        h = edge_height(c[2 * ev], c[2 * ev + 1], ray_u(w, t), s->ci);
    else
        h = c[2 * ev + eu];
    return h;
}

/* ------------------------------------------------------------------------------------ */
/* The surfaces, one row each in `surfaces` below.                                      */

/* A patch's height at local (a, b) in [0, 1]^2 of a cell with corners c[4]. */
/* The patches (surface.h), as the surfaces' table takes them */
static double plane_patch(const double c[4], double a, double b)
{
    (void)a;
    (void)b;
    return td_patch_plane(c);
}

static double triangle_patch(const double c[4], double a, double b) { return td_patch_triangle(c, a, b); }

static double bilinear_patch(const double c[4], double a, double b) { return td_patch_bilinear(c, a, b); }

/* Height under the ray at time t inside the cell, for the patch surfaces. */
static double patch_under(const walk *w, const cell_seg *s, double t);

/* The linear surface (Qu 3.1) under the ray at time t: linear along the ray between the
 * heights where the ray's line enters and leaves the cell's footprint. */
static double linear_under(const walk *w, const cell_seg *s, double t)
{
    double h;
    double tu0 = entry_u(w, s->ci), tv0 = entry_v(w, s->cj);
    double tu1 = exit_u(w, s->ci), tv1 = exit_v(w, s->cj);
    double tin = dmax(tu0, tv0), tout = dmin(tu1, tv1);
    if (!(tout > tin) || !isfinite(tin) || !isfinite(tout)) {
        /* vertical ray or a ray that only touches the cell: the surface under it */
        h = bilinear_patch(s->c, clamp01(ray_u(w, t) - s->ci), clamp01(ray_v(w, t) - s->cj));
    } else {
        double hin = boundary_height(w, s, tu0 >= tv0 ? ENTRY_U : ENTRY_V, 0, tin);
        double hout = boundary_height(w, s, tu1 <= tv1 ? ENTRY_U : ENTRY_V, 1, tout);
        h = hin + (hout - hin) * clamp01((t - tin) / (tout - tin));
    }
    return h;
}

/* f = z_ray - surface at both ends of the segment: on a boundary, the shared boundary
 * height (f carried from the cell before when known); inside the cell (the ray starts or
 * ends there), the surface's own height under the ray. */
typedef double (*under_fn)(const walk *w, const cell_seg *s, double t);

TD_HOT void seg_f(const walk *w, cell_seg *s, under_fn under)
{
    if (isnan(s->fa))
        s->fa = ray_z(w, s->ta) - (s->entry == ENTRY_START
                                       ? under(w, s, s->ta)
                                       : boundary_height(w, s, s->entry, 0, s->ta));
    s->fb = ray_z(w, s->tb) - (s->exit == ENTRY_START
                                   ? under(w, s, s->tb)
                                   : boundary_height(w, s, s->exit, 1, s->tb));
}

/* First t in [ta, tb] where the linear f goes from fa to fb through zero. */
static inline int seg_hit(double ta, double fa, double tb, double fb, double *t)
{
    return td_seg_hit(ta, fa, tb, fb, t);
}

/* Plane surface: a solid column under the cell's highest corner. */
static int plane_cross(const walk *w, cell_seg *s, hit_rec *h)
{
    int hit = 0;
    double top = plane_patch(s->c, 0.0, 0.0);
    double za = ray_z(w, s->ta), zb = ray_z(w, s->tb);
    h->wall = 0;
    if (za <= top) {
        h->t = s->ta;
        h->wall = za < top && (s->entry == ENTRY_U || s->entry == ENTRY_V) ? s->entry : 0;
        hit = 1;
    } else if (zb <= top) {
        /* descending (zb < za): the time the ray comes down to the top */
        double th = s->ta + (za - top) / -w->dz;
        h->t = th < s->ta ? s->ta : (th > s->tb ? s->tb : th);
        hit = 1;
    }
    return hit;
}

/* Linear surface: f is linear along the ray by construction. */
static int linear_cross(const walk *w, cell_seg *s, hit_rec *h)
{
    seg_f(w, s, linear_under);
    return seg_hit(s->ta, s->fa, s->tb, s->fb, &h->t);
}

/* Triangle surface: split the segment where it crosses the diagonal a + b = 1 (from
 * the south-east corner (i+1, j) to the north-west corner (i, j+1)); f is linear on
 * each part, and the value on the diagonal is shared by both. */
static int triangle_cross(const walk *w, cell_seg *s, hit_rec *h)
{
    int hit;
    const double *c = s->c;
    double sa, sb;
    seg_f(w, s, patch_under);
    sa = (ray_u(w, s->ta) - s->ci) + (ray_v(w, s->ta) - s->cj) - 1.0;
    sb = (ray_u(w, s->tb) - s->ci) + (ray_v(w, s->tb) - s->cj) - 1.0;
    if ((sa < 0.0 && sb > 0.0) || (sa > 0.0 && sb < 0.0)) {
        double td = s->ta + (s->tb - s->ta) * (sa / (sa - sb));
        double bd = clamp01(ray_v(w, td) - s->cj);
        double fd = ray_z(w, td) - (c[1] + (c[2] - c[1]) * bd);
        hit = seg_hit(s->ta, s->fa, td, fd, &h->t) || seg_hit(td, fd, s->tb, s->fb, &h->t);
    } else {
        hit = seg_hit(s->ta, s->fa, s->tb, s->fb, &h->t);
    }
    return hit;
}

/* Bilinear surface: the quadratic along the ray (surface.h, td_quad_hit), its
 * coefficient A from the patch's twist. */
static int bilinear_cross(const walk *w, cell_seg *sg, hit_rec *h)
{
    seg_f(w, sg, patch_under);
    const double k = sg->c[0] - sg->c[1] - sg->c[2] + sg->c[3];
    return td_quad_hit(sg->ta, sg->fa, sg->tb, sg->fb, -k * w->du * w->dv, &h->t);
}

/* Height gradients (surface.h), as the surfaces' table takes them */
static void triangle_gradient(const double c[4], double a, double b, double g[2])
{
    td_gradient_triangle(c, a, b, g);
}

static void bilinear_gradient(const double c[4], double a, double b, double g[2])
{
    td_gradient_bilinear(c, a, b, g);
}

/* One surface: its patch (also what td_surface_height reports), the height under a ray
 * inside a cell, the intersection over a cell's segment, the gradient of its normal
 * (NULL: the plane's top or wall), and whether it is a solid column (the plane: nothing
 * below its top is outside it, so no lower bound may clip or skip a ray). A new surface
 * is a row here and its functions. */
struct surface_ops {
    double (*patch)(const double c[4], double a, double b);
    double (*under)(const walk *w, const cell_seg *s, double t);
    int (*cross)(const walk *w, cell_seg *s, hit_rec *h);
    void (*gradient)(const double c[4], double a, double b, double g[2]);
    int solid;
};

static const surface_ops surfaces[TD_SURFACE_COUNT] = {
    [TD_SURFACE_PLANE] = {plane_patch, patch_under, plane_cross, NULL, 1},
    /* the linear surface has no patch of its own: as a height field it is bilinear */
    [TD_SURFACE_LINEAR] = {bilinear_patch, linear_under, linear_cross, bilinear_gradient, 0},
    [TD_SURFACE_TRIANGLE] = {triangle_patch, patch_under, triangle_cross, triangle_gradient, 0},
    [TD_SURFACE_BILINEAR] = {bilinear_patch, patch_under, bilinear_cross, bilinear_gradient, 0},
};

static double patch_under(const walk *w, const cell_seg *s, double t)
{
    return w->surf->patch(s->c, clamp01(ray_u(w, t) - s->ci), clamp01(ray_v(w, t) - s->cj));
}

/* ------------------------------------------------------------------------------------ */
/* The cell walk: the one place the walk moves from cell to cell.                       */

/* The tie rule watertightness depends on: leaving at tu == tv is crossing the sample
 * point itself (both indices move), never one line and then the other. */
static inline int crossing(double tu, double tv)
{
    return tu < tv ? ENTRY_U : (tv < tu ? ENTRY_V : ENTRY_UV);
}

/* Puts the walk in cell (ci, cj), entered at time t across `entry` with f (NaN: to be
 * recomputed by the same boundary function). The cell may be off the grid: every method
 * stops at its tile's edge, and td_trace ends the walk there. */
TD_HOT int enter_cell(walk_state *restrict st, int32_t ci, int32_t cj, double t, int entry,
                      double f)
{
    st->ci = ci;
    st->cj = cj;
    st->t = t;
    st->f = f;
    st->entry = entry;
    return STEP_CONTINUE;
}

/* Into the neighbour across the crossing `kind` at time t, carrying f. */
TD_HOT int advance(const walk *restrict w, walk_state *restrict st, int kind, double t, double f)
{
    return enter_cell(st, st->ci + (kind != ENTRY_V ? w->su : 0),
                      st->cj + (kind != ENTRY_U ? w->sv : 0), t, kind, f);
}

/* Intersects the current cell over [st->t, its exit] and either reports a hit or moves
 * the state to the next cell (carrying f across the shared boundary). */
static int cell_test(const walk *restrict w, walk_state *restrict st, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    double tu = exit_u(w, st->ci), tv = exit_v(w, st->cj);
    cell_seg s = {.ci = st->ci, .cj = st->cj, .ta = st->t, .tb = dmin(tu, tv), .entry = st->entry,
                  .exit = crossing(tu, tv), .fa = st->f, .fb = NAN};
    corners(w->g, s.ci, s.cj, s.c);
    if (s.tb >= w->t_end) {
        s.tb = w->t_end;
        s.exit = ENTRY_START; /* the ray ends inside the cell: interior value */
    }
    if (!isnan(s.c[0] + s.c[1] + s.c[2] + s.c[3]) && s.tb >= s.ta) {
        /* Quick rejection: the ray stays strictly above the highest corner (or, for the
         * two-sided surfaces, strictly below the lowest) over the whole segment. f is
         * then not carried; the next cell recomputes it with the same boundary function,
         * bit for bit. */
        double za = ray_z(w, s.ta), zb = ray_z(w, s.tb);
        double top = dmax(dmax(s.c[0], s.c[1]), dmax(s.c[2], s.c[3]));
        double bottom = dmin(dmin(s.c[0], s.c[1]), dmin(s.c[2], s.c[3]));
        int clear = dmin(za, zb) > top || (!w->surf->solid && dmax(za, zb) < bottom);
        if (!clear && w->surf->cross(w, &s, hit)) {
            hit->ci = s.ci;
            hit->cj = s.cj;
            rc = STEP_HIT;
        }
    }
    if (rc == STEP_CONTINUE) /* NaN f after a hole or a clear cell: recomputed */
        rc = s.exit == ENTRY_START ? STEP_END : advance(w, st, s.exit, s.tb, s.fb);
    return rc;
}

/* One step of the walk: a cell the ray passes strictly above costs two exit times, four
 * loads and a compare here (a hole's NaN corners either fail the compare or drop out of
 * the maximum, and a hole may be passed either way); every other cell goes through
 * cell_test, which reaches the same verdict on a clear cell. */
TD_HOT int walk_cell(const walk *restrict w, walk_state *restrict st, hit_rec *hit)
{
    int rc;
    double tu = exit_u(w, st->ci), tv = exit_v(w, st->cj);
    double tb = dmin(tu, tv);
    const size_t W = w->cz.stride;
    const float *s0 = td_grid_corner(&w->cz, st->ci, st->cj);
    if (tb < w->t_end &&
        dmin(ray_z(w, st->t), ray_z(w, tb)) >
            dmax(dmax((double)s0[0], (double)s0[1]), dmax((double)s0[W], (double)s0[W + 1])))
        rc = advance(w, st, crossing(tu, tv), tb, NAN);
    else
        rc = cell_test(w, st, hit);
    return rc;
}

/* ------------------------------------------------------------------------------------ */
/* Boxes of cells: tiles and max-mipmap blocks.                                         */

typedef struct box {
    int32_t ulo, uhi, vlo, vhi; /* cells [ulo, uhi) x [vlo, vhi) */
} box;

static inline box tile_box(const td_tile *t)
{
    box b = {t->i0, t->i0 + t->nx, t->j0, t->j0 + t->ny};
    return b;
}

static inline int in_box(const walk_state *st, const box *b)
{
    return (uint32_t)(st->ci - b->ulo) < (uint32_t)(b->uhi - b->ulo) &&
           (uint32_t)(st->cj - b->vlo) < (uint32_t)(b->vhi - b->vlo);
}

/* A shadow ray past everything that could shade it (sunlit.h): at its point, above the
 * bound of the block it is in. */
TD_HOT int lit_end(const walk *w, const walk_state *st)
{
    return w->lit && w->lit_k >= 0 && st->ci >= 0 && st->cj >= 0 && st->ci <= w->cmax_i &&
           st->cj <= w->cmax_j && ray_z(w, st->t) > td_sunlit_col(w->lit, w->lit_k, st->ci, st->cj) + w->zeps;
}

/* Exit times of the box along each axis. */
static inline double box_exit_u(const walk *w, const box *b)
{
    return time_u(w, (double)(w->su > 0 ? b->uhi : b->ulo));
}

static inline double box_exit_v(const walk *w, const box *b)
{
    return time_v(w, (double)(w->sv > 0 ? b->vhi : b->vlo));
}

/* Moves the walk to the cell after the box, which the ray leaves at min(tu, tv) (the
 * box's exit times). Every skip ends here. */
TD_HOT int leave_box_at(const walk *restrict w, walk_state *restrict st, const box *b, double tu,
                        double tv)
{
    int rc = STEP_END;
    double tx = dmin(tu, tv);
    if (tx < w->t_end) {
        int kind = crossing(tu, tv);
        /* the other axis's cell where the walk is at tx (walk_col, walk_row); entered
         * across both lines when the walk crosses that axis's line at tx too, from a cell
         * of the grid (the walk steps diagonally at a tie; a line it starts on is not
         * crossed) */
        int32_t ci = kind != ENTRY_V ? (w->su > 0 ? b->uhi : b->ulo - 1) : walk_col(w, tx, b->ulo, b->uhi - 1);
        int32_t cj = kind != ENTRY_U ? (w->sv > 0 ? b->vhi : b->vlo - 1) : walk_row(w, tx, b->vlo, b->vhi - 1);
        if (kind == ENTRY_V)
            kind = entry_u(w, ci) == tx && ci - w->su >= 0 && ci - w->su <= w->cmax_i ? ENTRY_UV : kind;
        else if (kind == ENTRY_U)
            kind = entry_v(w, cj) == tx && cj - w->sv >= 0 && cj - w->sv <= w->cmax_j ? ENTRY_UV : kind;
        rc = enter_cell(st, ci, cj, dmax(tx, st->t), kind, NAN);
    }
    return rc;
}

TD_HOT int leave_box(const walk *restrict w, walk_state *restrict st, const box *b)
{
    return leave_box_at(w, st, b, box_exit_u(w, b), box_exit_v(w, b));
}

/* ------------------------------------------------------------------------------------ */
/* The methods: how each crosses one tile. They return when the walk hits, ends, or      */
/* leaves the tile; each test is one step.                                               */

typedef int (*method_run)(const walk *restrict w, const td_tile *tile, const td_tile_accel *ta,
                          walk_state *restrict st, uint32_t *steps, hit_rec *hit);

/* Incremental: every cell. */
static int walk_run(const walk *restrict w, const td_tile *tile, const td_tile_accel *ta,
                    walk_state *restrict st, uint32_t *steps, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    const box tb = tile_box(tile);
    walk_state s = *st;
    uint32_t n = 0;
    (void)ta;
    while (rc == STEP_CONTINUE && in_box(&s, &tb)) {
        n++;
        rc = walk_cell(w, &s, hit);
        if (rc == STEP_CONTINUE && lit_end(w, &s))
            rc = STEP_END;
    }
    *st = s;
    *steps += n;
    return rc;
}

/* Hierarchical: test the block of the current level that holds the current cell; skip
 * it if the ray stays above its maximum up to the block's exit (and go up a level), else
 * descend a level; at level 0 walk the cell. */
TD_PACKET_CLONES static int hier_run(const walk *restrict w, const td_tile *tile, const td_tile_accel *ta,
                    walk_state *restrict st, uint32_t *steps, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    const td_maxmip *mm = ta->maxmip;
    const box tb = tile_box(tile);
    /* the tile test covered the top; a ray started near its hit (td_trace_from) climbs
       from the bottom instead */
    int L = st->level >= 0 ? st->level : (mm->levels > 1 ? mm->levels - 1 : mm->levels);
    /* td_maxmip_bound plus zeps, its scale held in registers across the cell tests' stores */
    const double base = mm->base + w->zeps, step = mm->step;
    uint32_t n = 0;
    while (rc == STEP_CONTINUE && in_box(st, &tb)) {
        n++;
        if (L == 0) {
            rc = cell_test(w, st, hit);
            L = 1;
        } else {
            int32_t bi = (st->ci - tb.ulo) >> L, bj = (st->cj - tb.vlo) >> L;
            double m = base + (double)td_maxmip_code(mm, L, bi, bj) * step;
            box b = {tb.ulo + (bi << L), 0, tb.vlo + (bj << L), 0};
            b.uhi = b.ulo + ((int32_t)1 << L) < tb.uhi ? b.ulo + ((int32_t)1 << L) : tb.uhi;
            b.vhi = b.vlo + ((int32_t)1 << L) < tb.vhi ? b.vlo + ((int32_t)1 << L) : tb.vhi;
            double tu = box_exit_u(w, &b), tv = box_exit_v(w, &b);
            double tx = dmin(dmin(tu, tv), w->t_end);
            if (dmin(ray_z(w, st->t), ray_z(w, tx)) > m) {
                rc = leave_box_at(w, st, &b, tu, tv);
                L = L < mm->levels ? L + 1 : L;
                if (rc == STEP_CONTINUE && lit_end(w, st))
                    rc = STEP_END;
            } else {
                L--;
            }
        }
    }
    *steps += n;
    return rc;
}

/* Parametric: if the ray is above the current cell's cone, jump to the entry boundary
 * of the cell where it would meet the cone (or out of the tile); else walk the cell
 * (Paglieroni's incremental jump-start). */
static int cone_run(const walk *restrict w, const td_tile *tile, const td_tile_accel *ta,
                    walk_state *restrict st, uint32_t *steps, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    const td_planes *pl = ta->planes;
    const box tb = tile_box(tile);
    const double txu = box_exit_u(w, &tb), txv = box_exit_v(w, &tb);
    const double tx = dmin(dmin(txu, txv), w->t_end);
    uint32_t n = 0;
    while (rc == STEP_CONTINUE && in_box(st, &tb)) {
        const td_cone cone = td_planes_cone(pl, st->ci - tb.ulo, st->cj - tb.vlo);
        double zp = td_cone_apex(pl, cone), sp = td_cone_slope(pl, cone);
        double above = ray_z(w, st->t) - zp - w->zeps;
        int jumped = 0;
        n++;
        if (above > 0.0) {
            /* how fast the ray nears the cone, per unit t (a vertical ray meets the apex;
               the test keeps an infinite slope from making 0 * inf) */
            double closing = (w->hs > 0.0 ? sp * w->hs : 0.0) - w->dz;
            double tl = closing > 0.0 ? st->t + above / closing : INFINITY;
            if (tl >= tx) {
                rc = leave_box_at(w, st, &tb, txu, txv);
                jumped = 1;
                if (rc == STEP_CONTINUE && lit_end(w, st))
                    rc = STEP_END;
            } else {
                int32_t ci = walk_col(w, tl, tb.ulo, tb.uhi - 1), cj = walk_row(w, tl, tb.vlo, tb.vhi - 1);
                double teu = entry_u(w, ci), tev = entry_v(w, cj);
                double te = dmax(teu, tev);
                if ((ci != st->ci || cj != st->cj) && te > st->t) {
                    /* the later of the two entry times is the crossing into the cell */
                    rc = enter_cell(st, ci, cj, te, crossing(tev, teu), NAN);
                    jumped = 1;
                }
            }
        }
        if (!jumped)
            rc = cell_test(w, st, hit);
    }
    *steps += n;
    return rc;
}

static const method_run method_runs[TD_METHOD_COUNT] = {
    [TD_METHOD_INCREMENTAL] = walk_run,
    [TD_METHOD_HIERARCHICAL] = hier_run,
    [TD_METHOD_PARAMETRIC] = cone_run,
    [TD_METHOD_SILHOUETTE] = walk_run, /* choose_method never leaves it: for completeness */
};

/* `auto`, per tile and ray: a tile crossed by fewer cells than this is walked
 * incrementally (the skips' bookkeeping costs more than the cells it would save);
 * otherwise the max-mipmap when it is resident, else the parameter planes, else the
 * walk. Measured on oblique views of trinidad (make bench, one thread): parametric takes
 * about half the steps of hierarchical, but a jump costs about three block tests (42 vs
 * 15 ns: its bookkeeping, and a cone and then the cells it lands on far from the last
 * ones, out of cache), so hierarchical traces about 1.4 times as many rays per second;
 * planes are used where they are all that is resident. */
#define TD_AUTO_MIN_CELLS 6.0

static td_method choose_method(td_method m, const td_tile_accel *ta, double cells_crossed)
{
    td_method used = m;
    if (m == TD_METHOD_AUTO) {
        if (cells_crossed < TD_AUTO_MIN_CELLS)
            used = TD_METHOD_INCREMENTAL;
        else if (ta && ta->maxmip)
            used = TD_METHOD_HIERARCHICAL;
        else if (ta && ta->planes)
            used = TD_METHOD_PARAMETRIC;
        else
            used = TD_METHOD_INCREMENTAL;
    } else if (m == TD_METHOD_HIERARCHICAL && !(ta && ta->maxmip)) {
        used = TD_METHOD_INCREMENTAL;
    } else if ((m == TD_METHOD_PARAMETRIC && !(ta && ta->planes)) || m == TD_METHOD_SILHOUETTE) {
        used = TD_METHOD_INCREMENTAL;
    }
    return used;
}

/* ------------------------------------------------------------------------------------ */
/* td_trace: ray setup, the walk over tiles, the hit.                                   */

/* Clips [t0, t1] to the slab lo <= o + d t <= hi (inv = 1/d when d is not 0). */
static void clip_slab(double o, double d, double inv, double lo, double hi, double *t0, double *t1)
{
    if (d == 0.0) {
        if (!(o >= lo && o <= hi))
            *t1 = -INFINITY;
    } else {
        double a = (lo - o) * inv, b = (hi - o) * inv;
        if (a > b) {
            double s = a;
            a = b;
            b = s;
        }
        *t0 = a > *t0 ? a : *t0;
        *t1 = b < *t1 ? b : *t1;
    }
}

/* The walk's setup (see Precision at the top) in the parts rays share: the grid and
 * surface (every ray), the origin (a fan of camera rays), the direction (the shadow rays
 * of a render), then each ray's clip to the grid's box. */
TD_HOT void walk_grid(walk *w, const td_grid *g, td_surface s)
{
    w->g = g;
    w->cz = g->cz;
    w->surf = &surfaces[s];
    w->lit = NULL;
    w->lit_k = -1;
    w->cmax_i = g->w - 2;
    w->cmax_j = g->h - 2;
    w->zeps = 1e-6 * (1.0 + dmax(fabs((double)g->zmin), fabs((double)g->zmax)));
}

TD_HOT void walk_origin(walk *w, const double o[3])
{
    w->ou = o[0] / w->g->sx;
    w->ov = o[1] / w->g->sy;
    w->oz = o[2];
}

/* The direction, rescaled by a power of two when extreme (*scale: t's factor back to the
 * caller's units). Returns 0 for a zero direction. */
TD_HOT int walk_dir(walk *w, const double dir[3], double *scale)
{
    int exp2 = 0;
    double dlen = dmax(fabs(dir[0]), dmax(fabs(dir[1]), fabs(dir[2])));
    double d[3];

    *scale = 1.0;
    if (!(dlen > 0.0))
        return 0;
    if (dlen < 0x1p-20 || dlen > 0x1p20) { /* only extreme directions need rescaling */
        frexp(dlen, &exp2);
        *scale = ldexp(1.0, -exp2); /* exact power of two: d*scale and t/scale are exact */
    }
    /* three scalars, not a loop over an array: the divisions below would wait for the
       array's two stores to reach one 16-byte load (measured: a store-forwarding stall) */
    d[0] = flush_tiny(dir[0] * *scale);
    d[1] = flush_tiny(dir[1] * *scale);
    d[2] = flush_tiny(dir[2] * *scale);
    w->du = d[0] / w->g->sx;
    w->dv = d[1] / w->g->sy;
    w->dz = d[2];
    w->su = w->du > 0.0 ? 1 : (w->du < 0.0 ? -1 : 0);
    w->sv = w->dv > 0.0 ? 1 : (w->dv < 0.0 ? -1 : 0);
    w->iu = w->su ? 1.0 / w->du : INFINITY;
    w->iv = w->sv ? 1.0 / w->dv : INFINITY;
    w->iz = 1.0 / w->dz; /* clip_slab's, unused where dz is 0 */
    w->hs = sqrt(d[0] * d[0] + d[1] * d[1]); /* no overflow: |d| <= 2^21 after scaling */
    return 1;
}

/* Clips [tmin, tmax] (caller's units) to the grid's box (the plane surface's columns
 * reach down forever) and puts the walk at its start, the cell left to start_cell or
 * skip_to. Returns 0 if nothing is left. */
TD_HOT int walk_clip(walk *w, walk_state *st, double tmin, double tmax, double scale)
{
    const td_grid *g = w->g;
    double t0 = tmin / scale, t1 = tmax / scale;
    clip_slab(w->ou, w->du, w->iu, 0.0, (double)(g->w - 1), &t0, &t1);
    clip_slab(w->ov, w->dv, w->iv, 0.0, (double)(g->h - 1), &t0, &t1);
    clip_slab(w->oz, w->dz, w->iz, w->surf->solid ? -INFINITY : (double)g->zmin - w->zeps,
              (double)g->zmax + w->zeps, &t0, &t1);
    w->t_end = t1;
    st->t = t0;
    st->f = NAN;
    st->entry = ENTRY_START;
    st->level = -1;
    return t0 <= t1;
}

/* The cell the walk starts in, at its clipped start st->t. */
TD_HOT void start_cell(const walk *w, walk_state *st)
{
    /* by the crossing times, as inside the walk (walk_col, walk_row): a start after the
       origin (the clip to the grid's heights) may round onto a line the ray crosses only
       later (test_trace's test_from_after_clip: 107 m along, a line crossed at 180 m) */
    st->ci = walk_col(w, st->t, 0, w->cmax_i);
    st->cj = walk_row(w, st->t, 0, w->cmax_j);
}

/* The walk enters a new tile (one step): skips it whole if the ray passes above it (or
 * below it, for the two-sided surfaces) or it holds no sample; else says which method
 * crosses it. Returns STEP_CONTINUE with *tile set, or what leaving the tile gave. */
static int tile_enter(const walk *w, const td_view *v, td_method m, walk_state *st,
                      const td_tile **tile, const td_tile_accel **ta, td_method *used)
{
    int rc = STEP_CONTINUE;
    const td_tile *now = td_grid_tile_of_cell(w->g, st->ci, st->cj);
    const box b = tile_box(now);
    double tx = dmin(dmin(box_exit_u(w, &b), box_exit_v(w, &b)), w->t_end);
    double za = ray_z(w, st->t), zb = ray_z(w, tx);
    *tile = now;
    if (dmin(za, zb) > (double)now->zmax + w->zeps || now->zmax < now->zmin ||
        (!w->surf->solid && dmax(za, zb) < (double)now->zmin - w->zeps)) {
        rc = leave_box(w, st, &b);
    } else {
        *ta = v->accel ? &v->accel[now - w->g->tiles] : NULL;
        double cells = fabs(ray_u(w, tx) - ray_u(w, st->t)) + fabs(ray_v(w, tx) - ray_v(w, st->t));
        *used = choose_method(m, *ta, cells);
    }
    return rc;
}

/* The normal of the surface that was hit, facing up, not normalised (unit_normal). */
static void surface_normal(const walk *w, const hit_rec *h, double nv[3])
{
    const td_grid *g = w->g;
    if (!w->surf->gradient) { /* the plane's top, or the wall the ray came through */
        nv[0] = h->wall == ENTRY_U ? -(double)w->su : 0.0;
        nv[1] = h->wall == ENTRY_V ? -(double)w->sv : 0.0;
        nv[2] = h->wall ? 0.0 : 1.0;
    } else {
        double c[4], gr[2];
        corners(g, h->ci, h->cj, c);
        w->surf->gradient(c, clamp01(ray_u(w, h->t) - h->ci), clamp01(ray_v(w, h->t) - h->cj), gr);
        nv[0] = -gr[0] / g->sx;
        nv[1] = -gr[1] / g->sy;
        nv[2] = 1.0;
    }
}

/* The unit normal of surface_normal's vector. A fan normalises its hits' after all its
 * walks (a loop of independent square roots and divisions, which overlap; after each
 * walk they stalled it: measured 17% of trace_one's cycles). */
static inline void unit_normal(const double nv[3], float n[3]) { td_unit_normal(nv, n); }

/* Cells a ray started from a bound walks plainly before its method takes over (a fan's
 * packet walks them four rays at a time). Measured first (callgrind, primary stage,
 * triangle, M instructions, 8 -> 16 -> 32 cells): trinidad level 168.6 -> 167.2 -> 167.7,
 * rolled 260.3 -> 254.4 -> 255.6, straight down 313.9 -> 310.0 -> 309.6; picos grazing 279.0
 * -> 263.1 -> 255.5, rolled 431.4 -> 429.5 -> 442.7: 16 then. Once the packets had their
 * records as arrays, -O3 and an AVX-512 clone, their cells cost less than the max-mipmap
 * walk's steps that take over: primary stage, ms (median of 5, chrt), 16 -> 32 -> 64:
 * picos rolled 37.2 -> 36.3 -> 38.5, picos grazing 19.5 -> 18.2 -> 21.9, trinidad level
 * 11.8 -> 11.4 -> 11.9, rolled 19.0 -> 18.5 -> 19.6, straight down 21.9 (32) -> 22.4. */
#define TD_NEAR_CELLS 32

static inline int on_grid(const walk *w, const walk_state *st)
{
    return st->ci >= 0 && st->cj >= 0 && st->ci <= w->cmax_i && st->cj <= w->cmax_j;
}

/* Moves the walk's start (walk_clip's) to the entry boundary of the cell the ray is in at
 * internal time tc, which the caller knows no hit precedes, or else puts it in the cell it
 * starts in. From a cell's entry boundary the walk is the walk from the ray's start, bit
 * for bit: the boundary's f is recomputed by the function the cell before would have
 * carried it with. Returns 0 when tc is past the end (no hit). */
TD_HOT int skip_to(const walk *w, walk_state *st, double tc)
{
    int go = 1, moved = 0;
    if (tc > w->t_end) {
        go = 0;
    } else if (tc > st->t) {
        int32_t ci = walk_col(w, tc, 0, w->cmax_i), cj = walk_row(w, tc, 0, w->cmax_j);
        double teu = entry_u(w, ci), tev = entry_v(w, cj), te = dmax(teu, tev);
        if (te > st->t) {
            enter_cell(st, ci, cj, te, crossing(tev, teu), NAN);
        } else { /* the ray is in that cell from before its clip's start on, to tc: that
                    cell, not the one its rounded position at the start names (a ray a
                    rounding off a row line, its clip's start 107 m and tc 110 m out,
                    started a row too low: fuzz_render, seed row-line-clip) */
            st->ci = ci;
            st->cj = cj;
        }
        moved = 1;
        st->level = 0; /* near the hit: no use testing the tile's big blocks first */
    }
    if (go && !moved)
        start_cell(w, st);
    return go;
}

void td_trace(const td_view *v, td_method m, td_surface s, const td_ray *r, td_hit *hit)
{
    td_trace_from(v, m, s, r, 0.0, hit);
}

/* The walk over tiles from where st stands (run_walk's second part, and a packet's rays
 * that its near walk did not finish), adding its steps to *steps. */
static int tile_walk(const td_view *v, td_method m, const walk *w, walk_state *st, hit_rec *hr,
                     uint32_t *steps, td_method *used)
{
    int rc = STEP_CONTINUE;
    const td_tile *tile = NULL;
    const td_tile_accel *ta = NULL;
    box tb = {0, 0, 0, 0};
    uint32_t n = 0;
    while (rc == STEP_CONTINUE) {
        if (tile && in_box(st, &tb)) {
            rc = method_runs[*used](w, tile, ta, st, &n, hr);
            st->level = -1; /* only the tile a near start lands in starts low */
        } else if (!on_grid(w, st) || lit_end(w, st)) {
            rc = STEP_END; /* off the grid, or surely lit */
        } else { /* a new tile: one step */
            n++;
            rc = tile_enter(w, v, m, st, &tile, &ta, used);
            tb = tile_box(tile);
        }
    }
    *steps += n;
    return rc;
}

/* The walk from where st stands to a hit (STEP_HIT, in *hr) or the end: a start near the
 * surface (st->level 0) first walks its cells plainly, then every tile is entered (one
 * step) and crossed by its method. */
/* The near walk (run_walk's first part) from its k-th cell on: while the start is near
 * the surface (st->level 0), up to TD_NEAR_CELLS cells plainly, adding them to *n. */
TD_HOT int near_walk(const walk *w, walk_state *st, hit_rec *hr, int k, uint32_t *n)
{
    int rc = STEP_CONTINUE;
    for (; k < TD_NEAR_CELLS && st->level == 0 && rc == STEP_CONTINUE && on_grid(w, st); k++) {
        (*n)++;
        rc = walk_cell(w, st, hr);
    }
    return rc;
}

static int run_walk(const td_view *v, td_method m, const walk *w, walk_state *st, hit_rec *hr,
                    uint32_t *steps, td_method *used)
{
    uint32_t n = 0;
    int rc = near_walk(w, st, hr, 0, &n);
    if (rc == STEP_CONTINUE)
        rc = tile_walk(v, m, w, st, hr, &n, used);
    *steps += n;
    return rc;
}

/* The method a walk starts with: auto and silhouette walk incrementally until a tile
 * says otherwise (auto) or always (silhouette). */
static inline td_method walk_method(td_method m)
{
    return m == TD_METHOD_AUTO || m == TD_METHOD_SILHOUETTE ? TD_METHOD_INCREMENTAL : m;
}

static int valid_call(const td_grid *g, td_method m, td_surface s)
{
    return !isnan(g->zmin) && (unsigned)m < TD_METHOD_COUNT && (unsigned)s < TD_SURFACE_COUNT;
}

/* A hit into *hit as td_trace reports it: t in the caller's units, the point and the cell;
 * the normal's vector (not normalised: unit_normal makes hit->n of it) in nv. */
static void keep_hit(const walk *w, const hit_rec *hr, const double o[3], const double d[3],
                     double scale, double tmin, td_hit *hit, double nv[3])
{
    hit->t = hr->t * scale;
    for (int i = 0; i < 3; i++)
        hit->p[i] = o[i] + hit->t * d[i];
    hit->ci = hr->ci;
    hit->cj = hr->cj;
    surface_normal(w, hr, nv);
    /* never report a hit before tmin through rounding */
    if (hit->t < tmin)
        hit->t = tmin;
}

/* One ray from where w's grid and origin are set: direction, clip, the start at t_clear,
 * the walk and the hit (see td_trace_from), its normal in nv (not normalised: unit_normal
 * makes hit->n of it). */
static void trace_one(const td_view *v, td_method m, walk *w, const double o[3], const double d[3],
                      double tmin, double tmax, double t_clear, td_hit *hit, double nv[3])
{
    walk_state st;
    hit_rec hr = {.t = INFINITY};
    uint32_t steps = 0;
    td_method used = walk_method(m);
    double scale = 1.0;

    hit->t = INFINITY;
    hit->ci = hit->cj = -1;
    if (t_clear < INFINITY && walk_dir(w, d, &scale) && walk_clip(w, &st, tmin, tmax, scale) &&
        skip_to(w, &st, t_clear / scale) &&
        run_walk(v, m, w, &st, &hr, &steps, &used) == STEP_HIT)
        keep_hit(w, &hr, o, d, scale, tmin, hit, nv);
    hit->steps = steps;
    hit->method = used;
}

void td_trace_from(const td_view *v, td_method m, td_surface s, const td_ray *r, double t_clear,
                   td_hit *hit)
{
    walk w;
    double nv[3];
    int ok = valid_call(v->grid, m, s);
    memset(hit, 0, sizeof *hit);
    if (ok) {
        walk_grid(&w, v->grid, s);
        walk_origin(&w, r->o);
    }
    /* an invalid call is a miss (+inf: trace_one then reads nothing of w) */
    trace_one(v, m, &w, r->o, r->d, r->tmin, r->tmax, ok ? t_clear : INFINITY, hit, nv);
    if (hit->t < INFINITY)
        unit_normal(nv, hit->n);
}

/* ------------------------------------------------------------------------------------ */
/* Packets: the near walk of four camera or shadow rays at once.                        */
/*
 * A render's camera rays come in fans with a start each (t_clear, from the horizon or the
 * beam), and almost all of them hit inside the near walk that start sets off (run_walk's
 * first TD_NEAR_CELLS cells, incremental): 97% of the traced rays of the trinidad level
 * view. For them td_trace is ray setup, a cell or two and the hit, the same arithmetic for
 * every ray. A packet does it for four rays in one pass of four-lane double vectors (GCC's
 * vector extensions: one AVX2 register in the AVX2 clone, two SSE2 registers in the
 * baseline's), each branch of the scalar code a select between its two sides. Each lane
 * runs the scalar code's operations in its order on its operands, so its values are the
 * scalar walk's bit for bit (IEEE arithmetic is the same in a lane as in a scalar
 * register; no FMA, and C11 mode contracts nothing). A ray the near walk leaves on the
 * grid goes on over the tiles from the lane's state (packet_rest, tile_walk), and one that
 * starts behind its clip (no near walk) is trace_one's. Every surface has its packet form (vcross: vplane_cross .. vbilinear_cross,
 * each its scalar twin's expressions in the same order). test_trace's test_batches_same
 * holds the packets to td_trace_from, memory for memory.
 *
 * Shadow rays (occ_packets) share a direction and differ in origin, and nearly all of a
 * render's end lit within a few cells (trinidad's bench views: 99.96% of the level view's
 * 139,558, 99.8% of the straight-down view's 261,489, 84% of the grazing sunset's): a
 * packet walks their cells from their starts and checks the sun bound after each, where
 * the scalar any-hit walk enters a tile and climbs the max-mipmap from 2 x 2 blocks. The
 * answer is the same (every method's answer is the exact walk's; the bound only proves
 * lit); test_occluded_packets holds them to td_occluded. */

/* td_trace_fan's zb for a hit traced one ray at a time */
static double hit_bilinear(const td_grid *g, const td_hit *h)
{
    double z = NAN;
    if (!(h->t < INFINITY) || !td_grid_bilinear_cell(g, h->ci, h->cj, h->p[0], h->p[1], &z, NULL))
        z = NAN;
    return z;
}

/* A fan ray whose near walk a packet began and did not finish: the rest of trace_one's
 * walk (the near cells left of near_done, then the tiles) from the cell, time, f and entry
 * the lane stood at (the same bits as the scalar near walk's), after its n steps. */
static void packet_rest(const td_view *v, td_method m, walk *w, const double o[3], const double d[3],
                        const walk_state *at, uint32_t n, int near_done, td_hit *hit, double nv[3])
{
    walk_state st;
    hit_rec hr = {.t = INFINITY};
    td_method used = walk_method(m);
    double scale = 1.0;
    walk_dir(w, d, &scale); /* scale 1: fan_packet's lanes */
    walk_clip(w, &st, 0.0, INFINITY, scale);
    st = *at;
    hit->t = INFINITY;
    hit->ci = hit->cj = -1;
    int rc = near_walk(w, &st, &hr, near_done, &n); /* st.level 0: the rest of it */
    if (rc == STEP_CONTINUE)
        rc = tile_walk(v, m, w, &st, &hr, &n, &used);
    if (rc == STEP_HIT)
        keep_hit(w, &hr, o, d, scale, 0.0, hit, nv);
    hit->steps = n;
    hit->method = used;
}

/* Ray k's record in a fan's hits: x as td_trace_from leaves it, and its zb */
static void fan_store(td_fan_hits *h, int k, const td_hit *x, double zb)
{
    h->t[k] = x->t;
    h->px[k] = x->p[0], h->py[k] = x->p[1], h->pz[k] = x->p[2];
    h->nx[k] = x->n[0], h->ny[k] = x->n[1], h->nz[k] = x->n[2];
    h->ci[k] = x->ci, h->cj[k] = x->cj;
    h->steps[k] = x->steps;
    h->method[k] = (int32_t)x->method;
    h->zb[k] = zb;
}

void td_fan_hit(const td_fan_hits *h, int k, td_hit *out)
{
    memset(out, 0, sizeof *out);
    out->t = h->t[k];
    out->p[0] = h->px[k], out->p[1] = h->py[k], out->p[2] = h->pz[k];
    out->n[0] = h->nx[k], out->n[1] = h->ny[k], out->n[2] = h->nz[k];
    out->ci = h->ci[k], out->cj = h->cj[k];
    out->steps = h->steps[k];
    out->method = (td_method)h->method[k];
}

/* A fan ray's hit record finished as td_trace_from finishes it (its unit normal), into
 * slot k with its zb */
static void fan_keep(const td_grid *g, td_hit *x, const double nv[3], td_fan_hits *h, int k)
{
    if (x->t < INFINITY)
        unit_normal(nv, x->n);
    fan_store(h, k, x, hit_bilinear(g, x));
}

/* Fan ray k traced alone (trace_one; an invalid call, ok 0, is a miss) */
static void fan_one(const td_view *v, td_method m, walk *w, const double o[3], const td_fan *f, int k,
                    int ok, td_fan_hits *h)
{
    double nv[3], d[3] = {f->dx[k], f->dy[k], f->dz[k]};
    td_hit x;
    memset(&x, 0, sizeof x);
    trace_one(v, m, w, o, d, 0.0, INFINITY, ok ? f->t_clear[k] : INFINITY, &x, nv);
    if (ok)
        fan_keep(v->grid, &x, nv, h, k);
    else
        fan_store(h, k, &x, NAN);
}

/* Cells a packet of shadow rays walks together before a lane still walking goes on alone.
 * Measured (callgrind, trinidad's bench views, shadows stage, M instructions, level /
 * grazing / rolled / down): 4 cells 64.3 / 168.8 / 79.1 / 202.3; 8: 63.1 / 152.4 / 77.9 /
 * 186.9; 16: 62.4 / 137.8 / 77.7 / 183.7; 32: 62.0 / 142.5 / 77.2 / 182.5; 64: 62.1 /
 * 151.9 / 77.3 / 182.3. Handing a lone lane to the scalar walk at once costs more
 * (16 cells: 64.1 / 139.8 / 79.8 / 191.6): a vector step for one lane is still cheaper
 * than the scalar walk's tile entry and block climb. */
#define TD_OCC_NEAR_CELLS 16


/* What a lane of occ_packets left: the rest of occluded_one's walk (the tiles, from blocks
 * of 2 x 2 cells up) from the cell, time, f and entry the lane stood at, after n steps. */
static int occ_rest(const td_view *v, td_method m, walk *w, const double o[3],
                    const walk_state *at, uint32_t *steps)
{
    walk_state st;
    hit_rec hr = {.t = INFINITY};
    td_method used = walk_method(m);
    walk_origin(w, o);
    w->lit_k = w->lit ? td_sunlit_strip(w->lit, w->ou, w->ov) : -1;
    walk_clip(w, &st, 0.0, INFINITY, 1.0); /* the lane's t_end, the bits vstart clipped to */
    st = *at;
    return tile_walk(v, m, w, &st, &hr, steps, &used) == STEP_HIT;
}

/* The packets, four lanes wide and (TD_PACKET_WIDE) eight (trace_lanes.inc). Their helpers
 * are always inlined into the entry points (fan_packet, occ_packets, occ_packets_lo), so
 * no vector crosses a call: the warning that a wide vector's calling convention differs
 * without AVX does not apply. (Not popped: GCC gives it at the end of the file.) */
#pragma GCC diagnostic ignored "-Wpsabi"
#define TD_LANES 4
#define TD_LANES_FN TD_PACKET_CLONES
#include "trace_lanes.inc"
#undef TD_LANES
#undef TD_LANES_FN
#if TD_PACKET_WIDE
#pragma GCC push_options
#pragma GCC target("arch=x86-64-v4")
#define TD_LANES 8
#define TD_LANES_FN
#include "trace_lanes.inc"
#undef TD_LANES
#undef TD_LANES_FN
#pragma GCC pop_options
#endif

/* 0: the processor's choice; 4 or 8: td_trace_set_lanes' (atomic: read by every render's
 * threads) */
static _Atomic int lanes_set;

static int lanes_wide(void)
{
#if TD_PACKET_WIDE
    return __builtin_cpu_supports("x86-64-v4") > 0;
#else
    return 0;
#endif
}

int td_trace_lanes(void)
{
    const int set = lanes_set;
    return set == 4 || !lanes_wide() ? 4 : 8;
}

int td_trace_set_lanes(int lanes)
{
    lanes_set = lanes == 4 || lanes == 8 ? lanes : 0;
    return td_trace_lanes();
}

/* fan_packet of the width in use */
static int fan_packet_of(int lanes, const td_view *v, td_method m, walk *w, const double o[3],
                         const td_fan *f, int k0, int nl, td_fan_hits *h)
{
    int fin;
#if TD_PACKET_WIDE
    if (lanes == 8)
        fin = fan_packet8(v, m, w, o, f, k0, nl, h);
    else
#endif
        fin = fan_packet(v, m, w, o, f, k0, nl, h);
    (void)lanes;
    return fin;
}

void td_trace_fan(const td_view *v, td_method m, td_surface s, const double o[3], int n, td_fan *f,
                  td_fan_hits *h)
{
    walk w;
    int ok = valid_call(v->grid, m, s);
    const int lanes = td_trace_lanes();
    n = n < TD_FAN_MAX ? n : TD_FAN_MAX;
    if (ok) {
        walk_grid(&w, v->grid, s);
        walk_origin(&w, o);
    }
    for (int k0 = 0; k0 < n; k0 += lanes) {
        const int nl = n - k0 < lanes ? n - k0 : lanes;
        for (int l = nl; l < lanes; l++) { /* a packet short of rays repeats its first */
            f->dx[k0 + l] = f->dx[k0], f->dy[k0 + l] = f->dy[k0], f->dz[k0 + l] = f->dz[k0];
            f->t_clear[k0 + l] = f->t_clear[k0];
        }
        int fin = ok ? fan_packet_of(lanes, v, m, &w, o, f, k0, nl, h) : 0;
        for (int l = 0; l < nl; l++) /* what the packet left */
            if (!(fin >> l & 1))
                fan_one(v, m, &w, o, f, k0 + l, ok, h);
    }
}

/* One any-hit query from where w's grid and direction are set (see td_occluded). */
static int occluded_one(const td_view *v, td_method m, walk *w, const double o[3], double tmin,
                        double tmax, double scale, uint32_t *steps)
{
    walk_state st;
    hit_rec hr = {.t = INFINITY};
    td_method used = walk_method(m);
    int hit = 0;
    walk_origin(w, o);
    w->lit_k = w->lit ? td_sunlit_strip(w->lit, w->ou, w->ov) : -1;
    if (walk_clip(w, &st, tmin, tmax, scale)) {
        start_cell(w, &st);
        /* from the surface: blocks of 2 x 2 cells first, then up (measured on the
           baseline's shadow rays: 4 x 4 took 20% fewer steps than the tile's top, 30%
           fewer than cell by cell; with the sun bound and batches, 2 x 2 takes 2-6% fewer
           instructions than 4 x 4 on the bench views, 8 x 8 3-7% more) */
        st.level = 1;
        hit = run_walk(v, m, w, &st, &hr, steps, &used) == STEP_HIT;
    }
    return hit;
}

/* Whether the shadow ray from o along the sun (w's direction and lit, the sun's bound
 * with its shadow side) is surely shadowed (sunlit.h): o on the grid, above the surface
 * under it (the surface's `under` at t = 0, as the walk's first cell takes it: the linear
 * surface's depends on the ray) and below its strip's L, by zeps each. A solid surface
 * (the plane's cells): below L is enough. The cell is the walk's first: before
 * 2026-11-30 it was the one east (north) of a line the origin lies on, and a shadow ray
 * from a plane column's wall facing the sun, beside a void, was called shadowed from the
 * column behind the wall, where the walk, leaving the wall into the void, found it lit
 * (fuzz_render, seed wall-beside-void). */
static int surely_shadowed(walk *w, const td_sunlit *lit, const double o[3])
{
    const td_grid *g = w->g;
    const double u = o[0] / g->sx, v = o[1] / g->sy;
    int yes = 0;
    if (lit && lit->lo && u >= 0.0 && v >= 0.0 && u <= (double)(g->w - 1) && v <= (double)(g->h - 1)) {
        ptrdiff_t k = td_sunlit_strip(lit, u, v);
        /* the cell the walk starts in (start_cell's, ties toward the sun): an origin on a
         * column's line, on the wall of the column behind it, is in the cell before */
        cell_seg sg = {.ci = cell_along(u, w->su, 0, w->cmax_i), .cj = cell_along(v, w->sv, 0, w->cmax_j)};
        if (k >= 0 && o[2] < td_sunlit_lo(lit, k, sg.ci, sg.cj) - w->zeps) {
            corners(g, sg.ci, sg.cj, sg.c);
            walk_origin(w, o);
            yes = w->surf->solid || o[2] > w->surf->under(w, &sg, 0.0) + w->zeps;
        }
    }
    return yes;
}

int td_occluded(const td_view *v, td_method m, td_surface s, const td_ray *r,
                const td_sunlit *lit, uint32_t *steps)
{
    walk w;
    double scale = 1.0;
    int hit = 0;
    if (valid_call(v->grid, m, s)) {
        walk_grid(&w, v->grid, s);
        if (walk_dir(&w, r->d, &scale)) {
            w.lit = lit;
            hit = (r->tmin == 0.0 && r->tmax == INFINITY && surely_shadowed(&w, lit, r->o)) ||
                  occluded_one(v, m, &w, r->o, r->tmin, r->tmax, scale, steps);
        }
    }
    return hit;
}

int td_sunlit_clear(const td_grid *g, const td_sunlit *lit, const double p[3])
{
    walk w;
    int clear = 0;
    if (lit) {
        const double u = p[0] / g->sx, v = p[1] / g->sy;
        walk_grid(&w, g, TD_SURFACE_PLANE); /* its margin, zeps */
        clear = u >= 0.0 && v >= 0.0 && u <= (double)(g->w - 1) && v <= (double)(g->h - 1) &&
                p[2] > td_sunlit_at(lit, u, v) + w.zeps;
    }
    return clear;
}

/* occ_packets or occ_packets_lo (lo: the bound has a shadow side) of the width in use */
static int occ_packets_of_width(int lanes, int lo, const td_view *v, td_method m, walk *w,
                                const double d[3], const double (*o)[3], int n, uint8_t *hit,
                                uint32_t *steps)
{
    int k;
#if TD_PACKET_WIDE
    if (lanes == 8)
        k = lo ? occ_packets_lo8(v, m, w, d, o, n, hit, steps) : occ_packets8(v, m, w, d, o, n, hit, steps);
    else
#endif
        k = lo ? occ_packets_lo(v, m, w, d, o, n, hit, steps) : occ_packets(v, m, w, d, o, n, hit, steps);
    (void)lanes;
    return k;
}

void td_occluded_par(const td_view *v, td_method m, td_surface s, const double d[3], int n,
                     const double (*o)[3], const td_sunlit *lit, uint8_t *hit, uint32_t *steps)
{
    walk w;
    double scale = 1.0;
    int ok = valid_call(v->grid, m, s), k = 0;
    if (ok) {
        walk_grid(&w, v->grid, s);
        ok = walk_dir(&w, d, &scale);
        w.lit = lit;
    }
    /* packets of two rays or more, with a sun bound to end them lit (without one, a lane
       ends only on a hit or past the grid, and the max-mipmap's climb is the faster walk:
       measured 2.3x the packets' rate on trinidad's views with the bound off) */
    if (ok && scale == 1.0 && lit)
        k = occ_packets_of_width(td_trace_lanes(), lit->lo != NULL, v, m, &w, d, o, n, hit, steps);
    for (; k < n; k++)
        hit[k] = ok && occluded_one(v, m, &w, o[k], 0.0, INFINITY, scale, steps);
}

/* ------------------------------------------------------------------------------------ */
/* Bounds over boxes of cells, from whatever is resident.                               */

/* max that drops a NaN (a void) in v */
static inline float fmax_nan(float m, float v) { return v > m ? v : m; }

/* Highest sample over the cells [i0, i1] x [j0, j1] (their corners; fmaxf drops a void's
 * NaN, and a hole's other corners only loosen the bound). */
static float samples_max(const td_grid *g, int32_t i0, int32_t i1, int32_t j0, int32_t j1)
{
    float m = -INFINITY;
    for (int32_t j = j0; j <= j1 + 1; j++)
        for (int32_t i = i0, n; i <= i1 + 1; i += n) { /* runs inside a block (grid.h) */
            const float *row = td_grid_corner(&g->cz, i, j);
            n = td_grid_run(&g->cz, i, i1 + 2 - i);
            for (int32_t k = 0; k < n; k++)
                m = fmax_nan(m, row[k]);
        }
    return m;
}

/* Highest corner over the cells [i0, i1] x [j0, j1] of one tile (clipped to it): the
 * samples themselves for a box of up to 3 x 3 cells, else the max-mipmap blocks of the
 * finest level at which at most 4 x 4 of them cover it, else the tile's zmax. */
static double tile_box_max(const td_view *v, const td_tile *t, size_t ti, int32_t i0, int32_t i1,
                           int32_t j0, int32_t j1)
{
    const td_grid *g = v->grid;
    const td_maxmip *mm = v->accel ? v->accel[ti].maxmip : NULL;
    int32_t ci0 = i0 > t->i0 ? i0 : t->i0, ci1 = i1 < t->i0 + t->nx - 1 ? i1 : t->i0 + t->nx - 1;
    int32_t cj0 = j0 > t->j0 ? j0 : t->j0, cj1 = j1 < t->j0 + t->ny - 1 ? j1 : t->j0 + t->ny - 1;
    double m = (double)t->zmax;
    if (ci1 - ci0 < 3 && cj1 - cj0 < 3) {
        m = samples_max(g, ci0, ci1, cj0, cj1);
    } else if (mm) {
        int32_t li0 = ci0 - t->i0, li1 = ci1 - t->i0, lj0 = cj0 - t->j0, lj1 = cj1 - t->j0;
        int L = 1;
        while (L <= mm->levels && ((li1 >> L) - (li0 >> L) > 3 || (lj1 >> L) - (lj0 >> L) > 3))
            L++;
        if (L <= mm->levels) {
            double b = -INFINITY;
            for (int32_t bj = lj0 >> L; bj <= lj1 >> L; bj++)
                for (int32_t bi = li0 >> L; bi <= li1 >> L; bi++)
                    b = dmax(b, td_maxmip_bound(mm, L, bi, bj));
            m = b < m ? b : m; /* the tile's own bound, when lower */
        }
    } else if ((int64_t)(ci1 - ci0 + 1) * (cj1 - cj0 + 1) <= 64) {
        m = samples_max(g, ci0, ci1, cj0, cj1);
    }
    return m;
}

double td_view_max(const td_view *v, int32_t i0, int32_t i1, int32_t j0, int32_t j1)
{
    const td_grid *g = v->grid;
    const int tl = g->tile_log2;
    double m = -INFINITY;
    i0 = i0 < 0 ? 0 : i0;
    j0 = j0 < 0 ? 0 : j0;
    i1 = i1 > g->w - 2 ? g->w - 2 : i1;
    j1 = j1 > g->h - 2 ? g->h - 2 : j1;
    for (int32_t tj = j0 >> tl; i0 <= i1 && tj <= j1 >> tl; tj++) {
        for (int32_t ti = i0 >> tl; ti <= i1 >> tl; ti++) {
            size_t k = (size_t)tj * (size_t)g->tiles_x + (size_t)ti;
            m = dmax(m, tile_box_max(v, &g->tiles[k], k, i0, i1, j0, j1));
        }
    }
    return m;
}

double td_surface_height(const td_grid *g, td_surface s, int32_t ci, int32_t cj, double x, double y)
{
    double h = NAN;
    if ((unsigned)s < TD_SURFACE_COUNT && ci >= 0 && cj >= 0 && ci < g->w - 1 && cj < g->h - 1) {
        double c[4];
        corners(g, ci, cj, c);
        if (!(isnan(c[0]) || isnan(c[1]) || isnan(c[2]) || isnan(c[3])))
            h = surfaces[s].patch(c, clamp01(x / g->sx - ci), clamp01(y / g->sy - cj));
    }
    return h;
}
