/* trace.c: one ray against the height field, by three methods over four surfaces.
 *
 * Every method is the same cell walk (Amanatides & Woo) with a different way of
 * skipping cells the ray cannot hit:
 *
 *   incremental   skips nothing: every cell the ray crosses is intersected;
 *   hierarchical  skips whole blocks of a tile's max-mipmap the ray passes above;
 *   parametric    skips the span over which the ray stays above the current cell's cone
 *                 of empty space (planes.c explains why that is safe);
 *   auto          picks one of these per tile from what is resident and how many cells
 *                 the ray crosses there.
 *
 * Each iteration of the walk is one step: a tile test, a block test, a cone step or a
 * cell intersection. Counters live in locals and are written once at the end.
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

#include <float.h>
#include <math.h>
#include <string.h>

#include "maxmip.h"
#include "planes.h"

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

/* ------------------------------------------------------------------------------------ */
/* The walk's invariant data for one ray.                                              */

typedef struct walk {
    const td_grid *g;
    const td_tile_accel *accel;
    td_surface surf;
    double ou, ov, oz; /* origin: cell units (u = x/sx, v = y/sy), metres */
    double du, dv, dz; /* direction per unit of internal t */
    double iu, iv;     /* reciprocals (+inf where the component is zero) */
    int su, sv;        /* signs of du, dv: -1, 0, +1 */
    double hs;         /* horizontal metres per unit t (for cone steps) */
    double t_end;      /* end of the search, internal t */
    double zeps;       /* margin kept above every bound before skipping */
    int32_t cmax_i, cmax_j; /* last cell index: w-2, h-2 */
} walk;

/* Where the walk stands: a cell, the time it entered it, and f there if known. */
enum { ENTRY_START, ENTRY_U, ENTRY_V, ENTRY_UV };

typedef struct walk_state {
    int32_t ci, cj;
    double t;
    double f;  /* z_ray - surface at t on the entry boundary; NaN: not computed yet */
    int entry; /* how the cell was entered */
} walk_state;

typedef struct hit_rec {
    double t;
    int32_t ci, cj;
    int wall; /* plane surface: 0 top, ENTRY_U or ENTRY_V for a wall */
} hit_rec;

enum { STEP_CONTINUE, STEP_HIT, STEP_END };

static inline double ray_u(const walk *w, double t) { return w->ou + w->du * t; }
static inline double ray_v(const walk *w, double t) { return w->ov + w->dv * t; }
static inline double ray_z(const walk *w, double t) { return w->oz + w->dz * t; }

static inline double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* min/max of non-NaN values as single instructions (libm's fmin/fmax are calls that
 * honour NaN rules we never need here: no NaN reaches them). */
static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

static inline double sample(const td_grid *g, int32_t i, int32_t j)
{
    return (double)g->z[(size_t)j * (size_t)g->w + (size_t)i];
}

/* Time the ray reaches the sample line u = k (or v = k). */
static inline double time_u(const walk *w, double k) { return w->su ? (k - w->ou) * w->iu : INFINITY; }
static inline double time_v(const walk *w, double k) { return w->sv ? (k - w->ov) * w->iv : INFINITY; }

/* Exit times of cell (ci, cj). */
static inline double exit_u(const walk *w, int32_t ci) { return time_u(w, (double)(ci + (w->su > 0))); }
static inline double exit_v(const walk *w, int32_t cj) { return time_v(w, (double)(cj + (w->sv > 0))); }

/* The cell index along one axis that contains the ray just after time t. */
static inline int32_t cell_along(double pos, int s, int32_t lo, int32_t hi)
{
    int32_t c;
    if (!(pos >= (double)lo)) { /* below the range (or NaN): clamp before converting */
        c = lo;
    } else if (pos >= (double)hi + 1.0) {
        c = hi;
    } else {
        c = (int32_t)pos; /* floor, pos >= lo >= 0 */
        if (s < 0 && (double)c == pos && c > lo)
            c--; /* going west/south, a point on the line belongs to the cell before it */
    }
    return c;
}

/* Height on the sample column I between rows J and J+1 (param from the ray's v). */
static inline double edge_u_height(const walk *w, int32_t I, int32_t J, double t)
{
    double a = sample(w->g, I, J), b = sample(w->g, I, J + 1);
    return a + (b - a) * clamp01(ray_v(w, t) - (double)J);
}

/* Height on the sample row J between columns I and I+1 (param from the ray's u). */
static inline double edge_v_height(const walk *w, int32_t I, int32_t J, double t)
{
    double a = sample(w->g, I, J), b = sample(w->g, I + 1, J);
    return a + (b - a) * clamp01(ray_u(w, t) - (double)I);
}

/* Interior height of a surface at local (a, b) of a cell with corners c[4] = z00, z10,
 * z01, z11. The linear surface is handled by its caller. */
static inline double interior_height(td_surface s, const double c[4], double a, double b)
{
    double h;
    if (s == TD_SURFACE_TRIANGLE) {
        if (a + b <= 1.0)
            h = c[0] + (c[1] - c[0]) * a + (c[2] - c[0]) * b;
        else
            h = c[3] + (c[2] - c[3]) * (1.0 - a) + (c[1] - c[3]) * (1.0 - b);
    } else if (s == TD_SURFACE_PLANE) {
        h = dmax(dmax(c[0], c[1]), dmax(c[2], c[3]));
    } else {
        h = c[0] + (c[1] - c[0]) * a + (c[2] - c[0]) * b + (c[0] - c[1] - c[2] + c[3]) * a * b;
    }
    return h;
}

/* The linear surface (Qu 3.1) of cell (ci, cj) at time t: linear along the ray between
 * the heights where the ray's line enters and leaves the cell's footprint. */
static double linear_height(const walk *w, int32_t ci, int32_t cj, const double c[4], double t)
{
    double h;
    double tu0 = w->su ? time_u(w, (double)(ci + (w->su < 0))) : -INFINITY;
    double tv0 = w->sv ? time_v(w, (double)(cj + (w->sv < 0))) : -INFINITY;
    double tu1 = exit_u(w, ci), tv1 = exit_v(w, cj);
    double tin = dmax(tu0, tv0), tout = dmin(tu1, tv1);
    if (!(tout > tin) || !isfinite(tin) || !isfinite(tout)) {
        /* vertical ray or a ray that only touches the cell: the surface under it */
        h = interior_height(TD_SURFACE_BILINEAR, c, clamp01(ray_u(w, t) - ci), clamp01(ray_v(w, t) - cj));
    } else {
        double hin = tu0 >= tv0 ? edge_u_height(w, ci + (w->su < 0), cj, tin)
                                : edge_v_height(w, ci, cj + (w->sv < 0), tin);
        double hout = tu1 <= tv1 ? edge_u_height(w, ci + (w->su > 0), cj, tout)
                                 : edge_v_height(w, ci, cj + (w->sv > 0), tout);
        h = hin + (hout - hin) * clamp01((t - tin) / (tout - tin));
    }
    return h;
}

/* f = z_ray - surface at time t where the walk entered cell (ci, cj) by `entry`. The
 * boundary cases are the functions that the neighbour's exit uses. */
static double entry_f(const walk *w, int32_t ci, int32_t cj, const double c[4], double t, int entry)
{
    double h;
    if (entry == ENTRY_U) {
        h = edge_u_height(w, ci + (w->su < 0), cj, t);
    } else if (entry == ENTRY_V) {
        h = edge_v_height(w, ci, cj + (w->sv < 0), t);
    } else if (entry == ENTRY_UV) {
        h = sample(w->g, ci + (w->su < 0), cj + (w->sv < 0));
    } else if (w->surf == TD_SURFACE_LINEAR) {
        h = linear_height(w, ci, cj, c, t);
    } else {
        h = interior_height(w->surf, c, clamp01(ray_u(w, t) - ci), clamp01(ray_v(w, t) - cj));
    }
    return ray_z(w, t) - h;
}

/* First t in [ta, tb] where the linear f goes from fa to fb through zero. */
static inline int seg_hit(double ta, double fa, double tb, double fb, double *t)
{
    int hit = 0;
    if (fa == 0.0) {
        *t = ta;
        hit = 1;
    } else if ((fa > 0.0) != (fb > 0.0) || fb == 0.0) {
        *t = ta + (tb - ta) * (fa / (fa - fb));
        hit = 1;
    }
    return hit;
}

/* Triangle surface: split the segment where it crosses the diagonal a + b = 1 (from
 * the south-east corner (i+1, j) to the north-west corner (i, j+1)); f is linear on
 * each part, and the value on the diagonal is shared by both. */
static int triangle_hit(const walk *w, int32_t ci, int32_t cj, const double c[4], double ta,
                        double fa, double tb, double fb, double *t)
{
    int hit;
    double sa = (ray_u(w, ta) - ci) + (ray_v(w, ta) - cj) - 1.0;
    double sb = (ray_u(w, tb) - ci) + (ray_v(w, tb) - cj) - 1.0;
    if ((sa < 0.0 && sb > 0.0) || (sa > 0.0 && sb < 0.0)) {
        double td = ta + (tb - ta) * (sa / (sa - sb));
        double bd = clamp01(ray_v(w, td) - cj);
        double fd = ray_z(w, td) - (c[1] + (c[2] - c[1]) * bd);
        hit = seg_hit(ta, fa, td, fd, t) || seg_hit(td, fd, tb, fb, t);
    } else {
        hit = seg_hit(ta, fa, tb, fb, t);
    }
    return hit;
}

/* Bilinear surface: f(s) = fa + B s + A s^2 on s = t - ta in [0, L], with A from the
 * patch's twist and B fixed by the shared end values, so the quadratic agrees with both
 * boundary values exactly. Roots in the cancellation-free form q = -(B + sign(B) sqrt)/2,
 * r1 = q/A, r2 = fa/q. No iteration, no sampling. */
static int bilinear_hit(const walk *w, const double c[4], double ta, double fa, double tb,
                        double fb, double *t)
{
    int hit = 0;
    double L = tb - ta;
    double k = c[0] - c[1] - c[2] + c[3];
    double A = -k * w->du * w->dv;
    if (fa == 0.0) {
        *t = ta;
        hit = 1;
    } else if (!(L > 0.0)) {
        hit = 0;
    } else if (A == 0.0 || fabs(A) * L * L <= 1e-12 * (fabs(fa) + fabs(fb))) {
        hit = seg_hit(ta, fa, tb, fb, t);
    } else {
        double B = (fb - fa - A * L * L) / L;
        int change = (fa > 0.0) != (fb > 0.0) || fb == 0.0;
        double smin = -B / (2.0 * A);
        double fext = fa + 0.5 * B * smin; /* f at the extremum */
        if (change || (smin > 0.0 && smin < L && (fext == 0.0 || (fext > 0.0) != (fa > 0.0)))) {
            double disc = B * B - 4.0 * A * fa;
            double sq = sqrt(disc > 0.0 ? disc : 0.0);
            double q = -0.5 * (B + copysign(sq, B));
            double r1 = q / A, r2 = q != 0.0 ? fa / q : r1;
            double lo = dmin(r1, r2), hi = dmax(r1, r2);
            double hiend = change ? L : smin;
            double s = lo >= 0.0 ? lo : hi;
            if (!(s >= 0.0 && s <= hiend)) {
                /* rounding put the root just outside: take the nearest admissible one */
                s = change ? L * (fa / (fa - fb)) : smin;
            }
            *t = ta + s;
            hit = 1;
        }
    }
    return hit;
}

/* Plane surface: a solid column under the cell's highest corner. */
static int plane_hit(const walk *w, const double c[4], double ta, double tb, int entry, double *t,
                     int *wall)
{
    int hit = 0;
    double top = dmax(dmax(c[0], c[1]), dmax(c[2], c[3]));
    double za = ray_z(w, ta), zb = ray_z(w, tb);
    if (za <= top) {
        *t = ta;
        *wall = za < top && (entry == ENTRY_U || entry == ENTRY_V) ? entry : 0;
        hit = 1;
    } else if (zb <= top) {
        /* descending (zb < za): the time the ray comes down to the top */
        double th = ta + (za - top) / -w->dz;
        *t = th < ta ? ta : (th > tb ? tb : th);
        *wall = 0;
        hit = 1;
    }
    return hit;
}

/* Intersects the current cell over [st->t, its exit] and either reports a hit or moves
 * the state to the next cell (carrying f across the shared boundary). */
static int step_cell(const walk *w, walk_state *st, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    const int32_t ci = st->ci, cj = st->cj;
    double tu = exit_u(w, ci), tv = exit_v(w, cj);
    double tb = dmin(tu, tv);
    int exit_kind = tu < tv ? ENTRY_U : (tv < tu ? ENTRY_V : ENTRY_UV);
    double c[4] = {sample(w->g, ci, cj), sample(w->g, ci + 1, cj), sample(w->g, ci, cj + 1),
                   sample(w->g, ci + 1, cj + 1)};
    int hole = isnan(c[0] + c[1] + c[2] + c[3]);
    double fb = NAN;

    if (tb >= w->t_end) {
        tb = w->t_end;
        exit_kind = ENTRY_START; /* the ray ends inside the cell: interior value */
    }
    if (!hole && tb >= st->t) {
        /* Quick rejection: the ray stays strictly above the highest corner (or, for the
         * two-sided surfaces, strictly below the lowest) over the whole segment. f is
         * then not carried; the next cell recomputes it with the same edge function,
         * bit for bit. */
        double za = ray_z(w, st->t), zb = ray_z(w, tb);
        double top = dmax(dmax(c[0], c[1]), dmax(c[2], c[3]));
        double bottom = dmin(dmin(c[0], c[1]), dmin(c[2], c[3]));
        int clear = dmin(za, zb) > top || (w->surf != TD_SURFACE_PLANE && dmax(za, zb) < bottom);
        double t = 0.0;
        int found = 0;
        if (clear) {
            found = 0;
        } else if (w->surf == TD_SURFACE_PLANE) {
            int wall = 0;
            found = plane_hit(w, c, st->t, tb, st->entry, &t, &wall);
            hit->wall = wall;
        } else {
            double fa = isnan(st->f) ? entry_f(w, ci, cj, c, st->t, st->entry) : st->f;
            if (exit_kind == ENTRY_U)
                fb = zb - edge_u_height(w, ci + (w->su > 0), cj, tb);
            else if (exit_kind == ENTRY_V)
                fb = zb - edge_v_height(w, ci, cj + (w->sv > 0), tb);
            else if (exit_kind == ENTRY_UV)
                fb = zb - sample(w->g, ci + (w->su > 0), cj + (w->sv > 0));
            else
                fb = entry_f(w, ci, cj, c, tb, ENTRY_START);
            if (w->surf == TD_SURFACE_BILINEAR)
                found = bilinear_hit(w, c, st->t, fa, tb, fb, &t);
            else if (w->surf == TD_SURFACE_TRIANGLE)
                found = triangle_hit(w, ci, cj, c, st->t, fa, tb, fb, &t);
            else
                found = seg_hit(st->t, fa, tb, fb, &t);
        }
        if (found) {
            hit->t = t;
            hit->ci = ci;
            hit->cj = cj;
            rc = STEP_HIT;
        }
    }
    if (rc == STEP_CONTINUE) {
        if (exit_kind == ENTRY_START) {
            rc = STEP_END;
        } else {
            st->ci += (exit_kind != ENTRY_V) ? w->su : 0;
            st->cj += (exit_kind != ENTRY_U) ? w->sv : 0;
            st->t = tb;
            st->f = fb; /* NaN after a hole: recomputed by the same edge function */
            st->entry = exit_kind;
            if (st->ci < 0 || st->cj < 0 || st->ci > w->cmax_i || st->cj > w->cmax_j)
                rc = STEP_END;
        }
    }
    return rc;
}

/* The incremental walk through one tile. A cell the ray passes strictly above costs two
 * exit times, four loads and a compare here (a hole's NaN corners either fail the
 * compare or drop out of the maximum, and a hole may be passed either way); every other
 * cell goes through step_cell. Returns when the walk hits, ends, or leaves the tile. */
static int walk_run(const walk *w, walk_state *st, const td_tile *tile, uint32_t *steps,
                    hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    const int32_t ilo = tile->i0, ihi = tile->i0 + tile->nx, jlo = tile->j0, jhi = tile->j0 + tile->ny;
    const size_t W = (size_t)w->g->w;
    uint32_t n = 0;
    while (rc == STEP_CONTINUE && st->ci >= ilo && st->ci < ihi && st->cj >= jlo && st->cj < jhi) {
        const int32_t ci = st->ci, cj = st->cj;
        double tu = exit_u(w, ci), tv = exit_v(w, cj);
        double tb = dmin(tu, tv);
        n++;
        if (tb < w->t_end) {
            const float *s0 = w->g->z + (size_t)cj * W + (size_t)ci;
            double top = dmax(dmax((double)s0[0], (double)s0[1]), dmax((double)s0[W], (double)s0[W + 1]));
            if (dmin(ray_z(w, st->t), ray_z(w, tb)) > top) {
                int kind = tu < tv ? ENTRY_U : (tv < tu ? ENTRY_V : ENTRY_UV);
                st->ci += kind != ENTRY_V ? w->su : 0;
                st->cj += kind != ENTRY_U ? w->sv : 0;
                st->t = tb;
                st->f = NAN;
                st->entry = kind;
                if (st->ci < 0 || st->cj < 0 || st->ci > w->cmax_i || st->cj > w->cmax_j)
                    rc = STEP_END;
                continue;
            }
        }
        rc = step_cell(w, st, hit);
    }
    *steps += n;
    return rc;
}

/* Moves the walk to the cell after the box of cells [ulo, uhi) x [vlo, vhi) that the
 * ray leaves at time `tx` (computed from the same box). Used by every skip. */
static inline int leave_box_at(const walk *w, walk_state *st, int32_t ulo, int32_t uhi,
                               int32_t vlo, int32_t vhi, double tu, double tv)
{
    int rc = STEP_CONTINUE;
    double tx = dmin(tu, tv);
    if (!(tx < w->t_end)) {
        rc = STEP_END;
    } else {
        int kind = tu < tv ? ENTRY_U : (tv < tu ? ENTRY_V : ENTRY_UV);
        st->ci = kind != ENTRY_V ? (w->su > 0 ? uhi : ulo - 1)
                                 : cell_along(ray_u(w, tx), w->su, ulo, uhi - 1);
        st->cj = kind != ENTRY_U ? (w->sv > 0 ? vhi : vlo - 1)
                                 : cell_along(ray_v(w, tx), w->sv, vlo, vhi - 1);
        st->t = tx > st->t ? tx : st->t;
        st->f = NAN;
        st->entry = kind;
        if (st->ci < 0 || st->cj < 0 || st->ci > w->cmax_i || st->cj > w->cmax_j)
            rc = STEP_END;
    }
    return rc;
}

/* Exit times of the box [ulo, uhi) x [vlo, vhi) along each axis. */
static inline double box_exit_u(const walk *w, int32_t ulo, int32_t uhi)
{
    return w->su > 0 ? time_u(w, (double)uhi) : time_u(w, (double)ulo);
}

static inline double box_exit_v(const walk *w, int32_t vlo, int32_t vhi)
{
    return w->sv > 0 ? time_v(w, (double)vhi) : time_v(w, (double)vlo);
}

static int leave_box(const walk *w, walk_state *st, int32_t ulo, int32_t uhi, int32_t vlo,
                     int32_t vhi)
{
    return leave_box_at(w, st, ulo, uhi, vlo, vhi, box_exit_u(w, ulo, uhi), box_exit_v(w, vlo, vhi));
}

static inline int in_tile(const walk_state *st, const td_tile *t)
{
    return st->ci >= t->i0 && st->cj >= t->j0 && st->ci < t->i0 + t->nx && st->cj < t->j0 + t->ny;
}

/* ------------------------------------------------------------------------------------ */
/* The methods' skips.                                                                  */

/* Hierarchical, through one tile: test the block of the current level that holds the
 * current cell; skip it if the ray stays above its maximum up to the block's exit (and go
 * up a level), else descend a level; at level 0 intersect the cell. Every test is one
 * step. Returns when the walk hits, ends, or leaves the tile. */
static int hier_run(const walk *w, const td_tile *tile, const td_maxmip *mm, walk_state *st,
                    uint32_t *steps, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    int L = mm->levels > 1 ? mm->levels - 1 : mm->levels; /* the tile test covered the top */
    const int32_t ti1 = tile->i0 + tile->nx, tj1 = tile->j0 + tile->ny;
    uint32_t n = 0;
    while (rc == STEP_CONTINUE && in_tile(st, tile)) {
        n++;
        if (L == 0) {
            rc = step_cell(w, st, hit);
            L = 1;
        } else {
            int32_t bi = (st->ci - tile->i0) >> L, bj = (st->cj - tile->j0) >> L;
            float m = mm->max[mm->offset[L] + (size_t)bj * (size_t)mm->dim[L] + (size_t)bi];
            int32_t ulo = tile->i0 + (bi << L), vlo = tile->j0 + (bj << L);
            int32_t uhi = ulo + ((int32_t)1 << L), vhi = vlo + ((int32_t)1 << L);
            uhi = uhi < ti1 ? uhi : ti1;
            vhi = vhi < tj1 ? vhi : tj1;
            double tu = box_exit_u(w, ulo, uhi), tv = box_exit_v(w, vlo, vhi);
            double tx = dmin(dmin(tu, tv), w->t_end);
            if (dmin(ray_z(w, st->t), ray_z(w, tx)) > (double)m + w->zeps) {
                rc = leave_box_at(w, st, ulo, uhi, vlo, vhi, tu, tv);
                L = L < mm->levels ? L + 1 : L;
            } else {
                L--;
            }
        }
    }
    *steps += n;
    return rc;
}

/* Parametric, through one tile: if the ray is above the current cell's cone, jump to the
 * entry boundary of the cell where it would meet the cone (or out of the tile); else
 * intersect the cell (Paglieroni's incremental jump-start). Every jump or cell is one
 * step. Returns when the walk hits, ends, or leaves the tile. */
static int cone_run(const walk *w, const td_tile *tile, const td_planes *pl, walk_state *st,
                    uint32_t *steps, hit_rec *hit)
{
    int rc = STEP_CONTINUE;
    const int32_t ulo = tile->i0, uhi = tile->i0 + tile->nx, vlo = tile->j0, vhi = tile->j0 + tile->ny;
    const double txu = box_exit_u(w, ulo, uhi), txv = box_exit_v(w, vlo, vhi);
    const double tx = dmin(dmin(txu, txv), w->t_end);
    uint32_t n = 0;
    while (rc == STEP_CONTINUE && in_tile(st, tile)) {
        size_t idx = (size_t)(st->cj - vlo) * (size_t)pl->nx + (size_t)(st->ci - ulo);
        const td_cone cone = pl->cone[idx];
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
                rc = leave_box_at(w, st, ulo, uhi, vlo, vhi, txu, txv);
                jumped = 1;
            } else {
                int32_t ci = cell_along(ray_u(w, tl), w->su, ulo, uhi - 1);
                int32_t cj = cell_along(ray_v(w, tl), w->sv, vlo, vhi - 1);
                double teu = w->su ? time_u(w, (double)(ci + (w->su < 0))) : -INFINITY;
                double tev = w->sv ? time_v(w, (double)(cj + (w->sv < 0))) : -INFINITY;
                double te = dmax(teu, tev);
                if ((ci != st->ci || cj != st->cj) && te > st->t) {
                    st->ci = ci;
                    st->cj = cj;
                    st->t = te;
                    st->f = NAN;
                    st->entry = teu > tev ? ENTRY_U : (tev > teu ? ENTRY_V : ENTRY_UV);
                    jumped = 1;
                }
            }
        }
        if (!jumped)
            rc = step_cell(w, st, hit);
    }
    *steps += n;
    return rc;
}

/* `auto`, per tile and ray: a tile crossed by fewer cells than this is walked
 * incrementally (the skips' bookkeeping costs more than the cells it would save);
 * otherwise the max-mipmap when it is resident, else the parameter planes, else the
 * walk. Measured on oblique views of trinidad (make bench, one thread): parametric takes
 * about half the steps of hierarchical, but a jump costs about three block tests (42 vs
 * 15 ns: its bookkeeping, and a cone and then the cells it lands on far from the last
 * ones, out of cache), so hierarchical traces about 1.4 times as many rays per second;
 * planes are used where they are all that is resident. */
#define TD_AUTO_MIN_CELLS 6.0

static td_method choose_method(const walk *w, td_method m, const td_tile_accel *ta,
                               double cells_crossed)
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
    } else if (m == TD_METHOD_PARAMETRIC && !(ta && ta->planes)) {
        used = TD_METHOD_INCREMENTAL;
    }
    (void)w;
    return used;
}

/* ------------------------------------------------------------------------------------ */

/* Clips [t0, t1] to the slab lo <= o + d t <= hi. */
static void clip_slab(double o, double d, double lo, double hi, double *t0, double *t1)
{
    if (d == 0.0) {
        if (!(o >= lo && o <= hi))
            *t1 = -INFINITY;
    } else {
        double inv = 1.0 / d;
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

static void surface_normal(const walk *w, const hit_rec *h, float n[3])
{
    const td_grid *g = w->g;
    double c[4] = {sample(g, h->ci, h->cj), sample(g, h->ci + 1, h->cj), sample(g, h->ci, h->cj + 1),
                   sample(g, h->ci + 1, h->cj + 1)};
    double a = clamp01(ray_u(w, h->t) - h->ci), b = clamp01(ray_v(w, h->t) - h->cj);
    double ga, gb, nx, ny, nz = 1.0, len;
    if (w->surf == TD_SURFACE_PLANE) {
        nx = h->wall == ENTRY_U ? -(double)w->su : 0.0;
        ny = h->wall == ENTRY_V ? -(double)w->sv : 0.0;
        nz = h->wall ? 0.0 : 1.0;
    } else {
        if (w->surf == TD_SURFACE_TRIANGLE) {
            if (a + b <= 1.0) {
                ga = c[1] - c[0];
                gb = c[2] - c[0];
            } else {
                ga = c[3] - c[2];
                gb = c[3] - c[1];
            }
        } else {
            double k = c[0] - c[1] - c[2] + c[3];
            ga = (c[1] - c[0]) + k * b;
            gb = (c[2] - c[0]) + k * a;
        }
        nx = -ga / g->sx;
        ny = -gb / g->sy;
    }
    len = sqrt(nx * nx + ny * ny + nz * nz);
    n[0] = (float)(nx / len);
    n[1] = (float)(ny / len);
    n[2] = (float)(nz / len);
}

void td_trace(const td_view *v, td_method m, td_surface s, const td_ray *r, td_hit *hit)
{
    const td_grid *g = v->grid;
    walk w;
    walk_state st;
    hit_rec hr = {.t = INFINITY};
    uint32_t steps = 0;
    int rc = STEP_END;
    td_method used = m == TD_METHOD_AUTO ? TD_METHOD_INCREMENTAL : m;
    int exp2 = 0;
    double scale = 1.0;
    double dlen = dmax(fabs(r->d[0]), dmax(fabs(r->d[1]), fabs(r->d[2])));
    double d[3], t0, t1;

    memset(hit, 0, sizeof *hit);
    hit->t = INFINITY;
    hit->ci = hit->cj = -1;
    if (isnan(g->zmin) || !(dlen > 0.0))
        goto out;

    /* Scale the direction by a power of two (exact) so its largest component is ~1. */
    if (dlen < 0x1p-20 || dlen > 0x1p20) { /* only extreme directions need rescaling */
        frexp(dlen, &exp2);
        scale = ldexp(1.0, -exp2); /* exact power of two: d*scale and t/scale are exact */
    }
    for (int i = 0; i < 3; i++) {
        d[i] = r->d[i] * scale;
        if (fabs(d[i]) < 1e-200)
            d[i] = 0.0;
    }
    w.g = g;
    w.accel = v->accel;
    w.surf = s;
    w.ou = r->o[0] / g->sx;
    w.ov = r->o[1] / g->sy;
    w.oz = r->o[2];
    w.du = d[0] / g->sx;
    w.dv = d[1] / g->sy;
    w.dz = d[2];
    w.su = w.du > 0.0 ? 1 : (w.du < 0.0 ? -1 : 0);
    w.sv = w.dv > 0.0 ? 1 : (w.dv < 0.0 ? -1 : 0);
    w.iu = w.su ? 1.0 / w.du : INFINITY;
    w.iv = w.sv ? 1.0 / w.dv : INFINITY;
    w.hs = sqrt(d[0] * d[0] + d[1] * d[1]); /* no overflow: |d| <= 2^21 after scaling */
    w.cmax_i = g->w - 2;
    w.cmax_j = g->h - 2;
    w.zeps = 1e-6 * (1.0 + dmax(fabs((double)g->zmin), fabs((double)g->zmax)));

    /* Clip to the grid's box (the plane surface's columns reach down forever). */
    t0 = r->tmin / scale;
    t1 = r->tmax / scale;
    clip_slab(w.ou, w.du, 0.0, (double)(g->w - 1), &t0, &t1);
    clip_slab(w.ov, w.dv, 0.0, (double)(g->h - 1), &t0, &t1);
    clip_slab(w.oz, w.dz, s == TD_SURFACE_PLANE ? -INFINITY : (double)g->zmin - w.zeps,
              (double)g->zmax + w.zeps, &t0, &t1);
    if (!(t0 <= t1))
        goto out;
    w.t_end = t1;

    st.t = t0;
    st.ci = cell_along(ray_u(&w, t0), w.su, 0, w.cmax_i);
    st.cj = cell_along(ray_v(&w, t0), w.sv, 0, w.cmax_j);
    st.f = NAN;
    st.entry = ENTRY_START;

    {
        const td_tile *tile = NULL;
        const td_tile_accel *ta = NULL;
        rc = STEP_CONTINUE;
        while (rc == STEP_CONTINUE) {
            if (!tile || st.ci < tile->i0 || st.cj < tile->j0 || st.ci >= tile->i0 + tile->nx ||
                st.cj >= tile->j0 + tile->ny) {
                const td_tile *now = td_grid_tile_of_cell(g, st.ci, st.cj);
                /* A new tile: skip it whole if the ray passes above or below it. */
                int32_t ulo = now->i0, uhi = now->i0 + now->nx, vlo = now->j0, vhi = now->j0 + now->ny;
                double tx = dmin(dmin(w.su > 0 ? time_u(&w, uhi) : time_u(&w, ulo),
                                      w.sv > 0 ? time_v(&w, vhi) : time_v(&w, vlo)),
                                 w.t_end);
                double za = ray_z(&w, st.t), zb = ray_z(&w, tx);
                tile = now;
                steps++;
                if (dmin(za, zb) > (double)now->zmax + w.zeps || now->zmax < now->zmin ||
                    (s != TD_SURFACE_PLANE && dmax(za, zb) < (double)now->zmin - w.zeps)) {
                    rc = leave_box(&w, &st, ulo, uhi, vlo, vhi);
                    continue;
                }
                ta = v->accel ? &v->accel[now - g->tiles] : NULL;
                used = choose_method(&w, m, ta,
                                     fabs(ray_u(&w, tx) - ray_u(&w, st.t)) + fabs(ray_v(&w, tx) - ray_v(&w, st.t)));
            }
            if (used == TD_METHOD_HIERARCHICAL) {
                rc = hier_run(&w, tile, ta->maxmip, &st, &steps, &hr);
            } else if (used == TD_METHOD_PARAMETRIC) {
                rc = cone_run(&w, tile, ta->planes, &st, &steps, &hr);
            } else {
                rc = walk_run(&w, &st, tile, &steps, &hr);
            }
        }
    }
    if (rc == STEP_HIT) {
        hit->t = hr.t * scale;
        for (int i = 0; i < 3; i++)
            hit->p[i] = r->o[i] + hit->t * r->d[i];
        hit->ci = hr.ci;
        hit->cj = hr.cj;
        surface_normal(&w, &hr, hit->n);
        /* never report a hit before tmin through rounding */
        if (hit->t < r->tmin)
            hit->t = r->tmin;
    }
out:
    hit->steps = steps;
    hit->method = used;
}

double td_surface_height(const td_grid *g, td_surface s, int32_t ci, int32_t cj, double x, double y)
{
    double h = NAN;
    if (ci >= 0 && cj >= 0 && ci < g->w - 1 && cj < g->h - 1) {
        double c[4] = {sample(g, ci, cj), sample(g, ci + 1, cj), sample(g, ci, cj + 1),
                       sample(g, ci + 1, cj + 1)};
        if (!(isnan(c[0]) || isnan(c[1]) || isnan(c[2]) || isnan(c[3])))
            h = interior_height(s == TD_SURFACE_LINEAR ? TD_SURFACE_BILINEAR : s, c,
                                clamp01(x / g->sx - ci), clamp01(y / g->sy - cj));
    }
    return h;
}
