/* iso_reference.c: the brute-force double-precision reference for rays against the
 * isometric lattice (see iso_reference.h for what it reports and why it is independent
 * of core/isogrid.c's walk). */
#include "iso_reference.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>

typedef struct vtx {
    double x, y, z;
} vtx;

/* Row r's vertices, west to east, from the paper's description; returns their number. */
static int32_t row_vertices(const td_iso *l, int32_t r, vtx *v)
{
    int32_t n = 0;
    const float *z = l->z + (size_t)r * (size_t)l->nx + (size_t)(r / 2);
    double y = r * l->b;
    if (r % 2 == 0) {
        for (int32_t c = 0; c < l->nx; c++)
            v[n++] = (vtx){c * l->a, y, z[c]};
    } else {
        v[n++] = (vtx){0.0, y, z[0]};
        for (int32_t c = 1; c < l->nx; c++)
            v[n++] = (vtx){(c - 0.5) * l->a, y, z[c]};
        v[n++] = (vtx){(l->nx - 1) * l->a, y, z[l->nx]};
    }
    return n;
}

typedef void (*tri_fn)(void *ctx, const vtx *a, const vtx *b, const vtx *c);

/* Triangulates the strip between rows r and r+1 by merging them west to east. */
static void strip(const td_iso *l, int32_t r, vtx *buf, tri_fn fn, void *ctx)
{
    vtx *L = buf, *U = buf + l->nx + 1;
    int32_t nl = row_vertices(l, r, L), nu = row_vertices(l, r + 1, U), i = 0, j = 0;
    int lower_even = r % 2 == 0;
    while (i < nl - 1 || j < nu - 1) {
        int low;
        if (i == nl - 1)
            low = 0;
        else if (j == nu - 1)
            low = 1;
        else
            low = L[i + 1].x < U[j + 1].x || (L[i + 1].x == U[j + 1].x && lower_even);
        if (low) {
            fn(ctx, &L[i], &L[i + 1], &U[j]);
            i++;
        } else {
            fn(ctx, &L[i], &U[j + 1], &U[j]);
            j++;
        }
    }
}

/* The ray's line against one triangle: the interval [lo, hi] where it is over the
 * (closed) footprint, and f(t) = f0 + f1 t, its height above the triangle's plane. */
typedef struct clip {
    double lo, hi, f0, f1;
} clip;

static int clip_tri(const td_ray *r, const vtx *p[3], double margin, clip *c)
{
    double area2 = (p[1]->x - p[0]->x) * (p[2]->y - p[0]->y) - (p[1]->y - p[0]->y) * (p[2]->x - p[0]->x);
    double s = area2 > 0 ? 1.0 : -1.0;
    int ok = 1;
    c->lo = -INFINITY;
    c->hi = INFINITY;
    c->f0 = r->o[2];
    c->f1 = r->d[2];
    for (int k = 0; k < 3; k++) { /* edge opposite vertex k: from p[k+1] to p[k+2] */
        const vtx *a = p[(k + 1) % 3], *b = p[(k + 2) % 3];
        double ex = b->x - a->x, ey = b->y - a->y;
        double al = s * (ex * (r->o[1] - a->y) - ey * (r->o[0] - a->x));
        double be = s * (ex * r->d[1] - ey * r->d[0]);
        double m = margin * sqrt(ex * ex + ey * ey);
        if (be == 0.0) {
            ok = ok && al >= -m;
        } else if (be > 0.0) {
            c->lo = fmax(c->lo, (-m - al) / be);
        } else {
            c->hi = fmin(c->hi, (-m - al) / be);
        }
        c->f0 -= al / fabs(area2) * p[k]->z; /* barycentric weight of vertex k */
        c->f1 -= be / fabs(area2) * p[k]->z;
    }
    return ok && c->lo <= c->hi;
}

/* The ray over one valid triangle: [lo, hi] and its height above it, f0 + f1 t; inner
 * when the ray's ground track enters the triangle's interior (not only its closed edge or
 * a corner, within the margin). */
typedef struct piece {
    double lo, hi, f0, f1;
    int inner;
} piece;

typedef struct ref_ctx {
    const td_ray *r;
    double eps, margin;
    td_iso_ref_hit *out;
    piece *pc;
    size_t n, cap;
} ref_ctx;

/* First t in [lo, hi] where f0 + f1 t = level, or +inf (lo itself when f(lo) = level). */
static double first_at(const piece *c, double level)
{
    double t = INFINITY, flo = c->f0 + c->f1 * c->lo;
    if (flo == level)
        t = c->lo;
    else if (c->f1 != 0.0) {
        double root = (level - c->f0) / c->f1;
        t = root > c->lo && root <= c->hi ? root : INFINITY;
    }
    return t;
}

static void on_tri(void *vctx, const vtx *a, const vtx *b, const vtx *c3)
{
    ref_ctx *x = vctx;
    const vtx *p[3] = {a, b, c3};
    clip c;
    if (isnan(a->z) || isnan(b->z) || isnan(c3->z))
        return;
    x->out->triangles++;
    if (!clip_tri(x->r, p, x->margin, &c))
        return;
    c.lo = fmax(c.lo, x->r->tmin);
    c.hi = fmin(c.hi, x->r->tmax);
    if (c.lo > c.hi)
        return;
    if (x->n == x->cap) {
        size_t nc = x->cap ? 2 * x->cap : 64;
        piece *np = realloc(x->pc, nc * sizeof *np);
        if (!np)
            return;
        x->pc = np;
        x->cap = nc;
    }
    clip in;
    int inner = clip_tri(x->r, p, -x->margin, &in) && fmax(in.lo, x->r->tmin) < fmin(in.hi, x->r->tmax);
    x->pc[x->n++] = (piece){c.lo, c.hi, c.f0, c.f1, inner};
}

static int by_lo(const void *a, const void *b)
{
    double x = ((const piece *)a)->lo, y = ((const piece *)b)->lo;
    return x < y ? -1 : x > y;
}

/* The answers from the pieces: the exact hit and t_near per piece; t_strict by a sweep in
 * ray order over the inner pieces that remembers which side the ray was definitely on
 * (forgotten at a gap: a hole, where the ray may pass under an edge without crossing
 * anything). A ray whose ground track runs along an edge, or through a corner, without
 * entering a valid triangle there (along a hole's border) only touches the surface: a
 * hit or a miss there is a tie, as the square grid's reference has it (reference.c). */
static void sweep(ref_ctx *x)
{
    double eps = x->eps, t_cov = -INFINITY;
    int side = 0;
    if (x->n > 1)
        qsort(x->pc, x->n, sizeof *x->pc, by_lo);
    for (size_t i = 0; i < x->n; i++) {
        const piece *c = &x->pc[i];
        double flo = c->f0 + c->f1 * c->lo, fhi = isfinite(c->hi) ? c->f0 + c->f1 * c->hi : NAN;
        x->out->t = fmin(x->out->t, first_at(c, 0.0));
        double tn = fabs(flo) <= eps ? c->lo : fmin(first_at(c, eps), first_at(c, -eps));
        x->out->t_near = fmin(x->out->t_near, tn);
        if (!c->inner)
            continue;
        if (c->lo > t_cov + 1e-9 * (1.0 + fabs(c->lo)))
            side = 0; /* a gap */
        if (side == 0)
            side = flo > eps ? 1 : (flo < -eps ? -1 : 0);
        if (side != 0) {
            double ts = first_at(c, side > 0 ? -eps : eps);
            if (side > 0 ? flo < -eps : flo > eps)
                ts = c->lo;
            x->out->t_strict = fmin(x->out->t_strict, ts);
        }
        if (isfinite(fhi) && fabs(fhi) > eps)
            side = fhi > 0 ? 1 : -1;
        else if (side == 0 && c->f1 != 0.0 && !isfinite(c->hi))
            side = c->f1 > 0 ? 1 : -1;
        t_cov = fmax(t_cov, c->hi);
    }
}

/* Rows of strips the ray's ground track may touch: [*r0, *r1]. */
static void strips_of(const td_iso *l, const td_ray *r, int32_t *r0, int32_t *r1)
{
    double t0 = r->tmin, t1 = r->tmax, X = (l->nx - 1) * l->a, Y = (l->ny - 1) * l->b;
    double ya, yb;
    for (int k = 0; k < 2; k++) {
        double hi = k ? Y : X;
        if (r->d[k] != 0.0) {
            double ta = (0.0 - r->o[k]) / r->d[k], tb = (hi - r->o[k]) / r->d[k];
            t0 = fmax(t0, fmin(ta, tb));
            t1 = fmin(t1, fmax(ta, tb));
        }
    }
    if (r->d[1] == 0.0 || !(t0 <= t1)) {
        ya = yb = r->o[1];
    } else {
        ya = fmin(r->o[1] + t0 * r->d[1], r->o[1] + t1 * r->d[1]);
        yb = fmax(r->o[1] + t0 * r->d[1], r->o[1] + t1 * r->d[1]);
    }
    *r0 = (int32_t)fmax(0.0, floor(ya / l->b) - 1.0);
    *r1 = (int32_t)fmin(l->ny - 2.0, floor(yb / l->b) + 1.0);
}

void td_iso_ref_trace(const td_iso *l, const td_ray *r, double eps, td_iso_ref_hit *out)
{
    vtx *buf = malloc(2 * ((size_t)l->nx + 1) * sizeof *buf);
    ref_ctx x = {r, eps, 1e-9 * fmin(l->a, l->b), out, NULL, 0, 0};
    int32_t r0, r1;
    out->t = out->t_near = out->t_strict = INFINITY;
    out->triangles = 0;
    strips_of(l, r, &r0, &r1);
    for (int32_t s = r0; buf && s <= r1; s++)
        strip(l, s, buf, on_tri, &x);
    sweep(&x);
    free(x.pc);
    free(buf);
}

typedef struct height_ctx {
    double x, y, z;
} height_ctx;

static void on_tri_height(void *vctx, const vtx *a, const vtx *b, const vtx *c3)
{
    height_ctx *h = vctx;
    const vtx *p[3] = {a, b, c3};
    td_ray down = {{h->x, h->y, 0.0}, {0.0, 0.0, 1.0}, -INFINITY, INFINITY};
    clip c;
    if (isnan(h->z) && clip_tri(&down, p, 1e-9, &c)) /* f = 0 - z + t: z = -f0 */
        h->z = -c.f0;
}

double td_iso_ref_height(const td_iso *l, double x, double y)
{
    double X = (l->nx - 1) * l->a, Y = (l->ny - 1) * l->b, m = 1e-9 * fmax(X, Y);
    height_ctx h;
    vtx *buf = malloc(2 * ((size_t)l->nx + 1) * sizeof *buf);
    int32_t r;
    /* a point a rounding outside the border (a hit where the ray enters) is on it */
    x = x < 0.0 && x >= -m ? 0.0 : (x > X && x <= X + m ? X : x);
    y = y < 0.0 && y >= -m ? 0.0 : (y > Y && y <= Y + m ? Y : y);
    h = (height_ctx){x, y, NAN};
    r = (int32_t)floor(y / l->b);
    r = r > l->ny - 2 ? l->ny - 2 : r;
    if (buf && r >= 0 && x >= 0.0 && x <= (l->nx - 1) * l->a && y <= (l->ny - 1) * l->b)
        strip(l, r, buf, on_tri_height, &h);
    free(buf);
    return h.z;
}

td_iso_ref_verdict td_iso_ref_judge(const td_iso *l, const td_ray *r, const td_iso_ref_hit *ref,
                                    double t, double eps)
{
    td_iso_ref_verdict v = TD_ISO_REF_WRONG;
    if (!(t < INFINITY)) {
        if (!(ref->t < INFINITY))
            v = TD_ISO_REF_AGREE;
        else if (!(ref->t_strict < INFINITY))
            v = TD_ISO_REF_TIE;
    } else if (isfinite(t)) {
        double p[3], q[3], m = 0.0, dist = 0.0, n = 0.0, tol, z;
        for (int k = 0; k < 3; k++) {
            p[k] = r->o[k] + t * r->d[k];
            q[k] = r->o[k] + ref->t * r->d[k];
            m = fmax(m, fabs(p[k]));
            dist += (p[k] - q[k]) * (p[k] - q[k]);
            n += r->d[k] * r->d[k];
        }
        tol = 1e-3 + 2.0 * FLT_EPSILON * m;
        z = td_iso_ref_height(l, p[0], p[1]);
        if (ref->t < INFINITY && sqrt(dist) <= tol)
            v = TD_ISO_REF_AGREE;
        else if (t >= ref->t_near - tol / sqrt(n) && t <= ref->t_strict + tol / sqrt(n) &&
                 fabs(p[2] - z) <= eps + tol)
            v = TD_ISO_REF_TIE;
    }
    return v;
}
