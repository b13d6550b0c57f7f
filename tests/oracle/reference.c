/* reference.c: brute-force double-precision references for the four surfaces (see
 * reference.h for what they report and why).
 *
 * Walk: the ray is clipped to the grid's footprint, then cut into strips of cells along
 * its major ground axis; in each strip every cell whose closed footprint (plus a margin)
 * meets the ground track is visited, in ray order. The walk is deliberately dumb: it
 * visits a superset of the cells the ray crosses and lets each cell clip the ray exactly,
 * so there is no DDA state that could skip a cell on a grid line or through a corner.
 *
 * Per cell the surface along the ray is a polynomial in t of degree <= 2:
 *   f(t) = z_ray(t) - h(t) = C + B (t - a) + A (t - a)^2  on a piece [a, b]
 * triangle: two linear pieces split where the ray crosses the diagonal u + v = 1;
 * bilinear: one quadratic; linear (Qu): one linear piece between the heights where the
 * ray's LINE enters and exits the footprint. A hit is a zero of f; roots are found in
 * closed form (the stable quadratic formula), never by stepping. The plane surface is a
 * closed box per cell, solved directly.
 *
 * Rejected: a classic DDA (its decisions at exact grid lines are what we want to test,
 * not to depend on), and sampling the ray (misses touches by construction). */
#include "reference.h"

#include <float.h>
#include <math.h>

typedef struct ref_walk {
    const td_grid *g;
    td_surface s;
    const td_ray *r;
    double eps;
    td_ref_hit *out;
    double t_cov;  /* the ray is covered by valid pieces up to here */
    int started;   /* a valid piece was seen */
    int side;      /* -1 definitely below, +1 definitely above, 0 not yet known */
    double t_stop; /* strips that start after this cannot improve the answer */
} ref_walk;

static double at(const td_grid *g, int32_t i, int32_t j) { return (double)td_grid_at(g, i, j); }

static int corners(const td_grid *g, int32_t i, int32_t j, double z[4])
{
    z[0] = at(g, i, j);         /* z00 */
    z[1] = at(g, i + 1, j);     /* z10 */
    z[2] = at(g, i, j + 1);     /* z01 */
    z[3] = at(g, i + 1, j + 1); /* z11 */
    return !(isnan(z[0]) || isnan(z[1]) || isnan(z[2]) || isnan(z[3]));
}

/* Parametric interval of the ray's LINE inside cell (i, j)'s footprint grown by mw, me,
 * ms, mn on its west, east, south and north sides (negative: shrunk). */
static int clip_cell4(const td_grid *g, const td_ray *r, int32_t i, int32_t j, double mw,
                      double me, double ms, double mn, double *t0, double *t1)
{
    double lo = -INFINITY, hi = INFINITY;
    double b0[2] = {i * g->sx - mw, j * g->sy - ms};
    double b1[2] = {(i + 1) * g->sx + me, (j + 1) * g->sy + mn};
    int ok = 1;
    for (int a = 0; a < 2 && ok; a++) {
        if (b0[a] > b1[a]) {
            ok = 0;
        } else if (r->d[a] == 0.0) {
            ok = r->o[a] >= b0[a] && r->o[a] <= b1[a];
        } else {
            double ta = (b0[a] - r->o[a]) / r->d[a], tb = (b1[a] - r->o[a]) / r->d[a];
            if (ta > tb) {
                double x = ta;
                ta = tb;
                tb = x;
            }
            lo = ta > lo ? ta : lo;
            hi = tb < hi ? tb : hi;
        }
    }
    ok = ok && lo <= hi;
    *t0 = lo;
    *t1 = hi;
    return ok;
}

static int clip_cell(const td_grid *g, const td_ray *r, int32_t i, int32_t j, double m,
                     double *t0, double *t1)
{
    return clip_cell4(g, r, i, j, m, m, m, m, t0, t1);
}

/* Non-zero if cell (i, j) exists and has no void corner. */
static int cell_ok(const td_grid *g, int32_t i, int32_t j)
{
    double z[4];
    return i >= 0 && j >= 0 && i <= g->w - 2 && j <= g->h - 2 && corners(g, i, j, z);
}

static double bilin(const double z[4], double u, double v)
{
    return z[0] + (z[1] - z[0]) * u + (z[2] - z[0]) * v + (z[0] - z[1] - z[2] + z[3]) * u * v;
}

static double tri_height(const double z[4], double u, double v)
{
    double h;
    if (u + v <= 1.0)
        h = z[0] + (z[1] - z[0]) * u + (z[2] - z[0]) * v;
    else
        h = z[3] + (z[3] - z[2]) * (u - 1.0) + (z[3] - z[1]) * (v - 1.0);
    return h;
}

/* First s in [s0 - slack, L + slack] with A s^2 + B s + C = 0 (clamped to [s0, L]),
 * +inf if none. */
static double first_root(double A, double B, double C, double s0, double L)
{
    double res = INFINITY;
    double slack = 1e-12 * (isfinite(L) ? fabs(L) : 1.0) + 1e-12 * fabs(s0);
    double r1 = INFINITY, r2 = INFINITY;
    if (A == 0.0) {
        if (B != 0.0)
            r1 = -C / B;
        else if (C == 0.0)
            r1 = s0;
    } else {
        double disc = B * B - 4.0 * A * C;
        if (disc < 0.0 && disc > -1e-12 * B * B)
            disc = 0.0; /* tangent within rounding: a double root */
        if (disc >= 0.0) {
            double q = -0.5 * (B + copysign(sqrt(disc), B));
            r1 = q / A;
            r2 = q != 0.0 ? C / q : r1;
            if (r2 < r1) {
                double x = r1;
                r1 = r2;
                r2 = x;
            }
        }
    }
    if (r1 >= s0 - slack && r1 <= L + slack)
        res = r1;
    else if (r2 >= s0 - slack && r2 <= L + slack)
        res = r2;
    if (res < s0)
        res = s0;
    if (res < INFINITY && res > L)
        res = L;
    return res;
}

static double poly(double A, double B, double C, double s) { return C + s * (B + s * A); }

/* Exact hit and near point of one piece f(t) = C + B (t-a) + A (t-a)^2 on [a, b] of
 * cell (i, j). */
static void piece_hit(ref_walk *w, int32_t i, int32_t j, double a, double b, double A, double B,
                      double C)
{
    td_ref_hit *o = w->out;
    double eps = w->eps, L = b - a, s, cand;

    if (a > b)
        return;
    s = first_root(A, B, C, 0.0, L);
    cand = a + s;
    if (s < INFINITY && cand < o->t) {
        o->t = cand;
        o->ci = i;
        o->cj = j;
    }
    if (fabs(C) <= eps)
        s = 0.0;
    else
        s = first_root(A, B, C - (C > 0.0 ? eps : -eps), 0.0, L);
    cand = a + s;
    if (s < INFINITY && cand < o->t_near)
        o->t_near = cand;
}

/* The definite-crossing state machine over one piece [a, b] (pieces come in ray order;
 * the part of the ray within eps of a hole's or the grid's border is left out, so the
 * state restarts after it). */
static void piece_strict(ref_walk *w, double a, double b, double A, double B, double C)
{
    td_ref_hit *o = w->out;
    double eps = w->eps, L, s, cand;

    if (b < w->t_cov || a > b)
        return;
    if (a < w->t_cov) { /* overlap (ray along a shared edge): continue from t_cov */
        double sh = w->t_cov - a;
        C = poly(A, B, C, sh);
        B = B + 2.0 * A * sh;
        a = w->t_cov;
    }
    L = b - a;
    if (!w->started || a - w->t_cov > 1e-9 * (fabs(a) + (isfinite(L) ? L : 0.0) + 1e-300)) {
        /* first piece, or after a gap: no crossing can have happened before */
        w->side = C > eps ? 1 : (C < -eps ? -1 : 0);
        w->started = 1;
    }
    s = 0.0;
    if (w->side == 1 && C <= -eps) {
        cand = a;
    } else if (w->side == -1 && C >= eps) {
        cand = a;
    } else {
        if (w->side == 0) {
            double sp = first_root(A, B, C - eps, 0.0, L), sm = first_root(A, B, C + eps, 0.0, L);
            s = sp < sm ? sp : sm;
            if (s < INFINITY) {
                double slope = B + 2.0 * A * s;
                w->side = slope > 0.0 ? 1 : (slope < 0.0 ? -1 : (A > 0.0 ? 1 : -1));
                if (eps > 0.0)
                    w->side = sp < sm ? 1 : -1;
            }
        }
        cand = INFINITY;
        if (s < INFINITY && w->side != 0) {
            double c = w->side == 1 ? -eps : eps;
            double s2 = first_root(A, B, C - c, s, L);
            if (eps == 0.0 && s2 == s)
                s2 = INFINITY; /* the exit point itself is no crossing */
            if (s2 < INFINITY)
                cand = a + s2;
        }
    }
    if (cand < o->t_strict) {
        o->t_strict = cand;
        if (cand < w->t_stop)
            w->t_stop = cand;
    }
    if (b > w->t_cov)
        w->t_cov = b;
}

/* Up to 5 disjoint sorted intervals of the ray away from holes and the grid's border. */
typedef struct ref_ivs {
    int n;
    double lo[5], hi[5];
} ref_ivs;

/* Removes [c0, c1] from the set. */
static void ivs_cut(ref_ivs *v, double c0, double c1)
{
    ref_ivs o;
    o.n = 0;
    for (int k = 0; k < v->n; k++) {
        if (c1 < v->lo[k] || c0 > v->hi[k]) {
            o.lo[o.n] = v->lo[k], o.hi[o.n++] = v->hi[k];
            continue;
        }
        if (c0 > v->lo[k] && o.n < 5)
            o.lo[o.n] = v->lo[k], o.hi[o.n++] = c0;
        if (c1 < v->hi[k] && o.n < 5)
            o.lo[o.n] = c1, o.hi[o.n++] = v->hi[k];
    }
    *v = o;
}

/* Both of the above; iv is the part of the ray away from holes and the border. */
static void run_piece(ref_walk *w, int32_t i, int32_t j, double a, double b, double A, double B,
                      double C, const ref_ivs *iv)
{
    piece_hit(w, i, j, a, b, A, B, C);
    for (int k = 0; k < iv->n; k++) {
        double sa = iv->lo[k] > a ? iv->lo[k] : a, sb = iv->hi[k] < b ? iv->hi[k] : b;
        if (sa <= sb) {
            double sh = sa - a;
            piece_strict(w, sa, sb, A, B + 2.0 * A * sh, poly(A, B, C, sh));
        }
    }
}

static void box_hit(const td_ray *r, double l0, double l1, double H, double *best)
{
    double a = l0 > r->tmin ? l0 : r->tmin, b = l1 < r->tmax ? l1 : r->tmax, t = INFINITY;
    if (a <= b) {
        if (r->d[2] == 0.0) {
            t = r->o[2] <= H ? a : INFINITY;
        } else {
            double tz = (H - r->o[2]) / r->d[2];
            if (r->d[2] < 0.0)
                t = (tz > a ? tz : a) <= b ? (tz > a ? tz : a) : INFINITY;
            else
                t = a <= tz ? a : INFINITY;
        }
    }
    if (t < *best)
        *best = t;
}

static void visit_plane(ref_walk *w, int32_t i, int32_t j, const double z[4])
{
    const td_grid *g = w->g;
    const td_ray *r = w->r;
    double H = fmax(fmax(z[0], z[1]), fmax(z[2], z[3]));
    double l0, l1, t = INFINITY;
    if (clip_cell(g, r, i, j, 1e-9 * (g->sx + g->sy), &l0, &l1)) { /* see visit() */
        box_hit(r, l0, l1, H, &t);
        if (t < w->out->t) {
            w->out->t = t;
            w->out->ci = i;
            w->out->cj = j;
        }
    }
    if (clip_cell(g, r, i, j, w->eps, &l0, &l1))
        box_hit(r, l0, l1, H + w->eps, &w->out->t_near);
    if (clip_cell(g, r, i, j, -w->eps, &l0, &l1))
        box_hit(r, l0, l1, H - w->eps, &w->out->t_strict);
    if (w->out->t_strict < w->t_stop)
        w->t_stop = w->out->t_strict;
}

/* Coefficients at t = a of the piece of cell (i, j) for triangle (tri = 0 SW, 1 NE),
 * bilinear or linear. */
static void coefs(const ref_walk *w, int32_t i, int32_t j, const double z[4], int tri, double a,
                  double l0, double l1, double *A, double *B, double *C)
{
    const td_grid *g = w->g;
    const td_ray *r = w->r;
    double du = r->d[0] / g->sx, dv = r->d[1] / g->sy;
    double ua = (r->o[0] + a * r->d[0] - i * g->sx) / g->sx;
    double va = (r->o[1] + a * r->d[1] - j * g->sy) / g->sy;
    double za = r->o[2] + a * r->d[2];
    double bb = z[1] - z[0], cc = z[2] - z[0], dd = z[0] - z[1] - z[2] + z[3];

    *A = 0.0;
    switch (w->s) {
    case TD_SURFACE_TRIANGLE:
        if (tri == 0) {
            *C = za - (z[0] + bb * ua + cc * va);
            *B = r->d[2] - (bb * du + cc * dv);
        } else {
            double gu = z[3] - z[2], gv = z[3] - z[1];
            *C = za - (z[3] + gu * (ua - 1.0) + gv * (va - 1.0));
            *B = r->d[2] - (gu * du + gv * dv);
        }
        break;
    case TD_SURFACE_BILINEAR:
        *C = za - bilin(z, ua, va);
        *B = r->d[2] - (bb * du + cc * dv + dd * (ua * dv + va * du));
        *A = -dd * du * dv;
        break;
    default: /* linear */
        if (isfinite(l0) && isfinite(l1) && l1 > l0) {
            double u0 = (r->o[0] + l0 * r->d[0] - i * g->sx) / g->sx;
            double v0 = (r->o[1] + l0 * r->d[1] - j * g->sy) / g->sy;
            double u1 = (r->o[0] + l1 * r->d[0] - i * g->sx) / g->sx;
            double v1 = (r->o[1] + l1 * r->d[1] - j * g->sy) / g->sy;
            double h0 = bilin(z, u0, v0), h1 = bilin(z, u1, v1);
            double k = (h1 - h0) / (l1 - l0);
            *C = za - (h0 + k * (a - l0));
            *B = r->d[2] - k;
        } else {
            *C = za - bilin(z, ua, va);
            *B = r->d[2];
        }
        break;
    }
}

static void visit(ref_walk *w, int32_t i, int32_t j)
{
    const td_grid *g = w->g;
    const td_ray *r = w->r;
    double z[4], l0, l1, a, b, A, B, C;
    ref_ivs iv;

    w->out->cells++;
    if (!corners(g, i, j, z))
        return;
    if (w->s == TD_SURFACE_PLANE) {
        visit_plane(w, i, j, z);
        return;
    }
    /* a hair of margin so that a ray touching only a corner (a degenerate interval that
     * rounding may turn inside out) still sees it; the formulas extrapolate by 1e-9 */
    if (!clip_cell(g, r, i, j, 1e-9 * (g->sx + g->sy), &l0, &l1))
        return;
    a = l0 > r->tmin ? l0 : r->tmin;
    b = l1 < r->tmax ? l1 : r->tmax;
    if (a > b)
        return;
    {
        /* strict crossings only count eps away from holes and the border: shrink the
         * sides that face a hole, and cut out the corners whose diagonal cell is one */
        double e = w->eps, sl0, sl1;
        iv.n = 0;
        if (clip_cell4(g, r, i, j, cell_ok(g, i - 1, j) ? 0.0 : -e, cell_ok(g, i + 1, j) ? 0.0 : -e,
                       cell_ok(g, i, j - 1) ? 0.0 : -e, cell_ok(g, i, j + 1) ? 0.0 : -e, &sl0, &sl1)) {
            iv.n = 1;
            iv.lo[0] = sl0;
            iv.hi[0] = sl1;
        }
        for (int c = 0; c < 4 && e > 0.0; c++) {
            int di = c & 1, dj = c >> 1; /* corner (i+di, j+dj) */
            if (!cell_ok(g, di ? i + 1 : i - 1, dj ? j + 1 : j - 1)) {
                int32_t ci = i + di, cj = j + dj;
                /* the eps-square around the corner is cell (ci-1, cj-1) grown by e-1 cell */
                double c0, c1;
                if (clip_cell4(g, r, ci - 1, cj - 1, e - g->sx, e, e - g->sy, e, &c0, &c1))
                    ivs_cut(&iv, c0, c1);
            }
        }
    }
    if (w->s == TD_SURFACE_TRIANGLE) {
        double du = r->d[0] / g->sx, dv = r->d[1] / g->sy;
        double ua = (r->o[0] + a * r->d[0] - i * g->sx) / g->sx;
        double va = (r->o[1] + a * r->d[1] - j * g->sy) / g->sy;
        double sg = ua + va - 1.0, ds = du + dv;
        double td = ds != 0.0 ? a - sg / ds : INFINITY;
        if (td > a && td < b) {
            int first = sg < 0.0 ? 0 : 1;
            coefs(w, i, j, z, first, a, l0, l1, &A, &B, &C);
            run_piece(w, i, j, a, td, A, B, C, &iv);
            coefs(w, i, j, z, 1 - first, td, l0, l1, &A, &B, &C);
            run_piece(w, i, j, td, b, A, B, C, &iv);
        } else {
            double smid = ds == 0.0 ? sg : (isfinite(b) ? sg + 0.5 * (b - a) * ds : ds);
            coefs(w, i, j, z, smid <= 0.0 ? 0 : 1, a, l0, l1, &A, &B, &C);
            run_piece(w, i, j, a, b, A, B, C, &iv);
        }
    } else {
        coefs(w, i, j, z, 0, a, l0, l1, &A, &B, &C);
        run_piece(w, i, j, a, b, A, B, C, &iv);
    }
}

static int32_t cell_index(double c, double s, int32_t n)
{
    double k = floor(c / s);
    if (!(k >= 0.0))
        k = 0.0;
    if (k > (double)(n - 2))
        k = (double)(n - 2);
    return (int32_t)k;
}

static void walk(ref_walk *w, double m)
{
    const td_grid *g = w->g;
    const td_ray *r = w->r;
    const double sp[2] = {g->sx, g->sy};
    const int32_t n[2] = {g->w, g->h};
    double lo = r->tmin, hi = r->tmax;
    int ok = 1;

    for (int a = 0; a < 2 && ok; a++) {
        double b0 = -m, b1 = (n[a] - 1) * sp[a] + m;
        if (r->d[a] == 0.0) {
            ok = r->o[a] >= b0 && r->o[a] <= b1;
        } else {
            double ta = (b0 - r->o[a]) / r->d[a], tb = (b1 - r->o[a]) / r->d[a];
            if (ta > tb) {
                double x = ta;
                ta = tb;
                tb = x;
            }
            lo = ta > lo ? ta : lo;
            hi = tb < hi ? tb : hi;
        }
    }
    if (!ok || lo > hi)
        return;
    if (r->d[0] == 0.0 && r->d[1] == 0.0) {
        int32_t i0 = cell_index(r->o[0] - m, g->sx, g->w), i1 = cell_index(r->o[0] + m, g->sx, g->w);
        int32_t j0 = cell_index(r->o[1] - m, g->sy, g->h), j1 = cell_index(r->o[1] + m, g->sy, g->h);
        for (int32_t j = j0; j <= j1; j++)
            for (int32_t i = i0; i <= i1; i++)
                visit(w, i, j);
        return;
    }
    int ax = fabs(r->d[0]) / g->sx >= fabs(r->d[1]) / g->sy ? 0 : 1, bx = 1 - ax;
    double c0 = r->o[ax] + lo * r->d[ax], c1 = r->o[ax] + hi * r->d[ax];
    int32_t k0 = cell_index(fmin(c0, c1) - m, sp[ax], n[ax]);
    int32_t k1 = cell_index(fmax(c0, c1) + m, sp[ax], n[ax]);
    int step = r->d[ax] > 0.0 ? 1 : -1;
    int32_t kfirst = step > 0 ? k0 : k1, klast = step > 0 ? k1 : k0;
    for (int32_t k = kfirst;; k += step) {
        double ta = (k * sp[ax] - m - r->o[ax]) / r->d[ax];
        double tb = ((k + 1) * sp[ax] + m - r->o[ax]) / r->d[ax];
        if (ta > tb) {
            double x = ta;
            ta = tb;
            tb = x;
        }
        ta = ta > lo ? ta : lo;
        tb = tb < hi ? tb : hi;
        if (ta > w->t_stop)
            break;
        if (ta <= tb) {
            double y0 = r->o[bx] + ta * r->d[bx], y1 = r->o[bx] + tb * r->d[bx];
            int32_t m0 = cell_index(fmin(y0, y1) - m, sp[bx], n[bx]);
            int32_t m1 = cell_index(fmax(y0, y1) + m, sp[bx], n[bx]);
            int mstep = r->d[bx] >= 0.0 ? 1 : -1;
            int32_t mfirst = mstep > 0 ? m0 : m1, mlast = mstep > 0 ? m1 : m0;
            for (int32_t q = mfirst;; q += mstep) {
                if (ax == 0)
                    visit(w, k, q);
                else
                    visit(w, q, k);
                if (q == mlast)
                    break;
            }
        }
        if (k == klast)
            break;
    }
}

void td_ref_trace(const td_grid *g, td_surface s, const td_ray *r, double eps, td_ref_hit *out)
{
    ref_walk w;
    out->t = out->t_near = out->t_strict = INFINITY;
    out->ci = out->cj = -1;
    out->cells = 0;
    w.g = g;
    w.s = s;
    w.r = r;
    w.eps = eps;
    w.out = out;
    w.t_cov = -INFINITY;
    w.started = 0;
    w.side = 0;
    w.t_stop = INFINITY;
    walk(&w, (s == TD_SURFACE_PLANE ? eps : 0.0) + 1e-9 * (g->sx + g->sy));
}

int td_ref_point_near(const td_grid *g, td_surface s, const td_ray *r, double t, double eps)
{
    double p[3];
    int near = 0;
    for (int a = 0; a < 3; a++)
        p[a] = r->o[a] + t * r->d[a];
    int32_t ci = cell_index(p[0], g->sx, g->w), cj = cell_index(p[1], g->sy, g->h);
    double mxy = eps + 1e-9 * (g->sx + g->sy);
    for (int32_t j = cj - 1; j <= cj + 1 && !near; j++) {
        for (int32_t i = ci - 1; i <= ci + 1 && !near; i++) {
            double z[4];
            if (i < 0 || j < 0 || i > g->w - 2 || j > g->h - 2 || !corners(g, i, j, z))
                continue;
            double x0 = i * g->sx, y0 = j * g->sy;
            if (p[0] < x0 - mxy || p[0] > x0 + g->sx + mxy || p[1] < y0 - mxy ||
                p[1] > y0 + g->sy + mxy)
                continue;
            double u = fmin(fmax((p[0] - x0) / g->sx, 0.0), 1.0);
            double v = fmin(fmax((p[1] - y0) / g->sy, 0.0), 1.0);
            if (s == TD_SURFACE_TRIANGLE) {
                near = fabs(p[2] - tri_height(z, u, v)) <= eps;
            } else if (s == TD_SURFACE_BILINEAR) {
                near = fabs(p[2] - bilin(z, u, v)) <= eps;
            } else if (s == TD_SURFACE_PLANE) {
                double H = fmax(fmax(z[0], z[1]), fmax(z[2], z[3]));
                int inner = p[0] > x0 + eps && p[0] < x0 + g->sx - eps && p[1] > y0 + eps &&
                            p[1] < y0 + g->sy - eps && p[2] < H - eps;
                near = p[2] <= H + eps && !inner;
            } else {
                double l0, l1, A, B, C;
                ref_walk w;
                w.g = g;
                w.s = s;
                w.r = r;
                if (clip_cell(g, r, i, j, 0.0, &l0, &l1)) {
                    coefs(&w, i, j, z, 0, t, l0, l1, &A, &B, &C);
                    near = fabs(C) <= eps;
                } else {
                    near = fabs(p[2] - bilin(z, u, v)) <= eps; /* corner graze */
                }
            }
        }
    }
    return near;
}

double td_ref_gap(const td_grid *g, td_surface s, const td_ray *r, double t)
{
    double p[3], z[4], gap = NAN;
    for (int a = 0; a < 3; a++)
        p[a] = r->o[a] + t * r->d[a];
    int32_t i = cell_index(p[0], g->sx, g->w), j = cell_index(p[1], g->sy, g->h);
    if (s != TD_SURFACE_PLANE && corners(g, i, j, z)) {
        double u = (p[0] - i * g->sx) / g->sx, v = (p[1] - j * g->sy) / g->sy, l0, l1, A, B, C;
        ref_walk w = {.g = g, .s = s, .r = r};
        if (s == TD_SURFACE_TRIANGLE) {
            gap = p[2] - tri_height(z, u, v);
        } else if (s == TD_SURFACE_BILINEAR || !clip_cell(g, r, i, j, 0.0, &l0, &l1)) {
            gap = p[2] - bilin(z, u, v);
        } else { /* linear: the chord of the ray's line through the cell, as coefs */
            coefs(&w, i, j, z, 0, t, l0, l1, &A, &B, &C);
            gap = C;
        }
    }
    return gap;
}

double td_ref_tol(const double p[3])
{
    double m = fmax(fabs(p[0]), fmax(fabs(p[1]), fabs(p[2])));
    return 1e-3 + 2.0 * FLT_EPSILON * m;
}

double td_ref_max_slope(const td_grid *g)
{
    double mx = 0.0, my = 0.0;
    for (int32_t j = 0; j < g->h; j++) {
        for (int32_t i = 0; i < g->w; i++) {
            double z = at(g, i, j);
            if (i + 1 < g->w) {
                double d = fabs(at(g, i + 1, j) - z) / g->sx;
                if (d > mx) /* false for NaN */
                    mx = d;
            }
            if (j + 1 < g->h) {
                double d = fabs(at(g, i, j + 1) - z) / g->sy;
                if (d > my)
                    my = d;
            }
        }
    }
    return mx + my;
}

static double dir_norm(const td_ray *r)
{
    double m = fmax(fabs(r->d[0]), fmax(fabs(r->d[1]), fabs(r->d[2])));
    double q[3] = {r->d[0] / m, r->d[1] / m, r->d[2] / m};
    return m * sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
}

double td_ref_dist(const td_ray *r, double t1, double t2)
{
    return t1 == t2 ? 0.0 : fabs(t1 - t2) * dir_norm(r);
}

td_ref_verdict td_ref_judge(const td_grid *g, td_surface s, const td_ray *r,
                            const td_ref_hit *ref, double t, double eps)
{
    td_ref_verdict v = TD_REF_WRONG;
    if (!(t < INFINITY)) {
        if (!(ref->t < INFINITY))
            v = TD_REF_AGREE;
        else if (!(ref->t_strict < INFINITY))
            v = TD_REF_TIE;
    } else if (isfinite(t)) {
        double p[3], n = dir_norm(r);
        for (int a = 0; a < 3; a++)
            p[a] = r->o[a] + t * r->d[a];
        double tol = td_ref_tol(p), tol_t = tol / n;
        if (ref->t < INFINITY && td_ref_dist(r, t, ref->t) <= tol)
            v = TD_REF_AGREE;
        else if (t >= r->tmin - tol_t && t <= r->tmax + tol_t && t >= ref->t_near - tol_t &&
                 t <= ref->t_strict + tol_t && td_ref_point_near(g, s, r, t, eps))
            v = TD_REF_TIE;
    }
    return v;
}
