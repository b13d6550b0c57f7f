/* isogrid.c: the isometric lattice of isogrid.h: building it from a function or a grid,
 * locating and evaluating its triangles, the ray walk over them, and the two-byte vertex
 * packing.
 *
 * The walk: along the ray, A(t) = y/b, B(t) = x/a - y/2b and C(t) = x/a + y/2b are linear
 * in t; the triangle the ray is in is (floor A, floor B + floor C + 1) (isogrid.h), so
 * the walk keeps the three floors and the t at which each one next changes, and steps
 * the family whose line comes first, as Amanatides-Woo do with two families of lines on
 * the square grid. In each triangle the ray's height above the triangle's plane is
 * linear in t; the hit is its first zero (surfaces are two-sided, as trace.h's). The
 * height where one triangle's segment ends is carried to the next: if the sign changed
 * across their shared edge, that is a crossing there, so a crack between two planes that
 * disagree by a rounding cannot let a ray through (watertight across triangles and tiles,
 * which share their samples). Rejected: testing the candidate triangles of each row strip
 * with a ray-triangle test (needs a margin of neighbours to be watertight; it is what the
 * oracle's reference does instead, tests/oracle/iso_reference.c).
 *
 * Hierarchy: a pyramid of block maxima (8 x 8 rows and columns, then doubling); where the
 * ray stays above a block's maximum over the block's box the walk jumps to the box's exit
 * and starts its three families again there (the "hierarchical" method on the lattice).
 * Rejected: Paglieroni-Petersen cones on the lattice. Measured (docs/isometric.md,
 * "Trace cost"): on the levels of detail cones save 5-9% of a max pyramid's steps where far
 * rays land (trinidad's levels 1-2), each cone step costs more, and this pyramid already
 * takes fewer steps than the square level's cones. Measured there too: the walk's rays
 * per second against the square grid's methods on the same samples. */
#include "isogrid.h"

#include <math.h>
#include <stdlib.h>

static const char *const rows_names[] = {
#define TD_X_NAME(e, name) name,
    TD_ISO_ROWS_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_iso_rows_name(td_iso_rows r)
{
    return (unsigned)r < TD_ISO_ROWS_COUNT ? rows_names[r] : "?";
}

double td_iso_x(const td_iso *l, int32_t r, int32_t c)
{
    double x;
    if (!(r & 1))
        x = c * l->a;
    else if (c == 0)
        x = 0.0;
    else if (c >= l->nx)
        x = (l->nx - 1) * l->a;
    else
        x = (c - 0.5) * l->a;
    return x;
}

/* A lattice's record and block pyramid, with float samples (NaN) if `floats`; a packed
 * lattice (td_iso_pack_lattice) has none. */
static td_status iso_alloc(int32_t nx, int32_t ny, double a, double b, int floats, td_iso **out,
                           td_err *err)
{
    td_status rc = TD_OK;
    td_iso *l = NULL;
    size_t n;

    *out = NULL;
    if (nx < 2 || ny < 2 || nx > (1 << 24) || ny > (1 << 24) || !(a > 0.0) || !(b > 0.0) ||
        !isfinite(a) || !isfinite(b)) {
        rc = td_err_set(err, TD_EINVAL, "isometric lattice %d x %d, spacing %g x %g: out of range",
                        (int)nx, (int)ny, a, b);
        goto out;
    }
    if (!td_mul_size((size_t)nx, (size_t)ny, &n) || !td_add_size(n, (size_t)ny / 2, &n) ||
        !td_mul_size(n, sizeof(float), &n)) {
        rc = td_err_set(err, TD_ETOOBIG, "isometric lattice %d x %d: size overflows", (int)nx,
                        (int)ny);
        goto out;
    }
    l = calloc(1, sizeof *l);
    if (l) {
        size_t nb = 0;
        int32_t bw = ((nx - 2) >> TD_ISO_BLOCK_LOG2) + 1, bh = ((ny - 2) >> TD_ISO_BLOCK_LOG2) + 1;
        for (int k = 0; k < TD_ISO_BLEVELS; k++) { /* 2^24 samples: at most 22 levels */
            l->bw[k] = bw;
            l->bh[k] = bh;
            nb += (size_t)bw * (size_t)bh;
            l->blevels = k + 1;
            if (bw == 1 && bh == 1)
                break;
            bw = (bw + 1) / 2;
            bh = (bh + 1) / 2;
        }
        l->z = floats ? malloc(n) : NULL;
        l->bmax[0] = malloc(nb * sizeof(float));
        for (int k = 1; l->bmax[0] && k < l->blevels; k++)
            l->bmax[k] = l->bmax[k - 1] + (size_t)l->bw[k - 1] * (size_t)l->bh[k - 1];
    }
    if (!l || (floats && !l->z) || !l->bmax[0]) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a %d x %d isometric lattice", (int)nx,
                        (int)ny);
        goto out;
    }
    l->nx = nx;
    l->ny = ny;
    l->a = a;
    l->b = b;
    for (size_t i = 0; floats && i < n / sizeof(float); i++)
        l->z[i] = NAN;
    l->zmin = l->zmax = NAN;
out:
    if (rc) {
        td_iso_free(l);
        l = NULL;
    }
    *out = l;
    return rc;
}

td_status td_iso_create(int32_t nx, int32_t ny, double a, double b, td_iso **out, td_err *err)
{
    return iso_alloc(nx, ny, a, b, 1, out, err);
}

void td_iso_sample(td_iso *l, td_iso_fn f, void *ctx)
{
    for (int32_t r = 0; r < l->ny; r++) {
        float *row = l->z + td_iso_row_offset(l->nx, r);
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++)
            row[c] = (float)f(ctx, td_iso_x(l, r, c), r * l->b);
    }
    td_iso_finish(l);
}

void td_iso_finish(td_iso *l)
{
    float lo = INFINITY, hi = -INFINITY;
    const int32_t S = (int32_t)1 << TD_ISO_BLOCK_LOG2;
    for (int32_t r = 0; r < l->ny; r++) {
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            float z = td_iso_at(l, r, c);
            lo = z < lo ? z : lo; /* NaN compares false */
            hi = z > hi ? z : hi;
        }
    }
    l->zmin = lo <= hi ? lo : NAN;
    l->zmax = lo <= hi ? hi : NAN;
    /* a triangle over block (i, j) lies in strips j S .. j S + S - 1 and has its corners
     * within a of the box in x: columns i S - 1 .. i S + S + 2 of either row bound it */
    for (int32_t j = 0; j < l->bh[0]; j++) {
        for (int32_t i = 0; i < l->bw[0]; i++) {
            float m = -INFINITY;
            for (int32_t r = j * S; r <= j * S + S && r < l->ny; r++) {
                int32_t last = td_iso_row_len(l, r) - 1;
                int32_t c1 = i * S + S + 2 < last ? i * S + S + 2 : last;
                for (int32_t c = i * S - 1 > 0 ? i * S - 1 : 0; c <= c1; c++) {
                    float z = td_iso_at(l, r, c);
                    m = z > m ? z : m;
                }
            }
            l->bmax[0][(size_t)j * (size_t)l->bw[0] + (size_t)i] = m;
        }
    }
    for (int k = 1; k < l->blevels; k++) { /* a block's box is its four children's */
        for (int32_t j = 0; j < l->bh[k]; j++) {
            for (int32_t i = 0; i < l->bw[k]; i++) {
                float m = -INFINITY;
                for (int32_t y = 2 * j; y <= 2 * j + 1 && y < l->bh[k - 1]; y++)
                    for (int32_t x = 2 * i; x <= 2 * i + 1 && x < l->bw[k - 1]; x++) {
                        float v = l->bmax[k - 1][(size_t)y * (size_t)l->bw[k - 1] + (size_t)x];
                        m = v > m ? v : m;
                    }
                l->bmax[k][(size_t)j * (size_t)l->bw[k] + (size_t)i] = m;
            }
        }
    }
}

/* The grid's surface at (x, y): its sample on a node, else the bilinear patch of the cell
 * (the corners whose weight is 0 do not count, so a point on an edge next to a void is
 * still defined). */
static double grid_fn(void *ctx, double x, double y)
{
    const td_grid *g = ctx;
    double fi = x / g->sx, fj = y / g->sy;
    int32_t i = (int32_t)floor(fi), j = (int32_t)floor(fj);
    double u, v, z = 0.0;

    i = i < 0 ? 0 : (i > g->w - 2 ? g->w - 2 : i);
    j = j < 0 ? 0 : (j > g->h - 2 ? g->h - 2 : j);
    u = fi - i;
    v = fj - j;
    if (fabs(u) < 1e-9 || fabs(u - 1.0) < 1e-9) {
        i += u > 0.5;
        u = 0.0;
    }
    if (fabs(v) < 1e-9 || fabs(v - 1.0) < 1e-9) {
        j += v > 0.5;
        v = 0.0;
    }
    for (int dj = 0; dj < 2; dj++) {
        for (int di = 0; di < 2; di++) {
            double wt = (di ? u : 1.0 - u) * (dj ? v : 1.0 - v);
            if (wt != 0.0)
                z += wt * (double)td_grid_at(g, i + di, j + dj);
        }
    }
    return z;
}

td_status td_iso_from_grid(const td_grid *g, int32_t step, td_iso_rows rows, td_iso **out,
                           td_err *err)
{
    td_status rc;
    double a, b, X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
    int32_t nx, ny;

    *out = NULL;
    if (step < 1 || step > (1 << 20)) {
        rc = td_err_set(err, TD_EINVAL, "isometric lattice: step %d out of range", (int)step);
        goto out;
    }
    if (rows == TD_ISO_ROWS_SQUARE) {
        a = step * g->sx;
        b = step * g->sy;
        nx = (g->w - 1) / step + 1;
        ny = (g->h - 1) / step + 1;
    } else {
        a = step * sqrt(2.0 * g->sx * g->sy / sqrt(3.0));
        b = a * sqrt(3.0) / 2.0;
        nx = (int32_t)floor(X / a * (1.0 + 1e-12)) + 1;
        ny = (int32_t)floor(Y / b * (1.0 + 1e-12)) + 1;
    }
    rc = td_iso_create(nx, ny, a, b, out, err);
    if (rc)
        goto out;
    td_iso_sample(*out, grid_fn, (void *)g);
out:
    return rc;
}

void td_iso_free(td_iso *l)
{
    if (l) {
        free(l->bmax[0]);
        free(l->z);
        td_iso_packed_free(l->packed);
        free(l);
    }
}

static int32_t clamp32(int32_t v, int32_t lo, int32_t hi) { return v < lo ? lo : (v > hi ? hi : v); }

void td_iso_locate(const td_iso *l, double x, double y, int32_t *r, int32_t *q)
{
    double u = x / l->a, Y = y / l->b;
    u = u < 0.0 ? 0.0 : (u > l->nx - 1 ? l->nx - 1 : u);
    Y = Y < 0.0 ? 0.0 : (Y > l->ny - 1 ? l->ny - 1 : Y);
    *r = clamp32((int32_t)floor(Y), 0, l->ny - 2);
    *q = clamp32((int32_t)(floor(u - 0.5 * Y) + floor(u + 0.5 * Y)) + 1, 0, 2 * l->nx - 2);
}

/* Rows and columns of triangle (r, q)'s corners. */
static void tri_index(int32_t r, int32_t q, int32_t rr[3], int32_t cc[3])
{
    int32_t re = (r & 1) ? r + 1 : r, ro = (r & 1) ? r : r + 1, c = q / 2;
    if (!(q & 1)) { /* O-based: O_c, O_c+1, E_c */
        rr[0] = ro, cc[0] = c;
        rr[1] = ro, cc[1] = c + 1;
        rr[2] = re, cc[2] = c;
    } else { /* E-based: E_k, E_k+1, O_k+1 */
        rr[0] = re, cc[0] = c;
        rr[1] = re, cc[1] = c + 1;
        rr[2] = ro, cc[2] = c + 1;
    }
}

int td_iso_triangle(const td_iso *l, int32_t r, int32_t q, double v[3][3])
{
    int32_t rr[3], cc[3];
    int ok = 1;

    tri_index(r, q, rr, cc);
    for (int k = 0; k < 3; k++) {
        v[k][0] = td_iso_x(l, rr[k], cc[k]);
        v[k][1] = rr[k] * l->b;
        v[k][2] = (double)td_iso_at(l, rr[k], cc[k]);
        ok = ok && !isnan(v[k][2]);
    }
    return ok;
}

/* The plane of a triangle: z = v0z + gx (x - v0x) + gy (y - v0y). */
typedef struct iso_plane {
    double x0, y0, z0, gx, gy;
} iso_plane;

static int plane_of(const td_iso *l, int32_t r, int32_t q, iso_plane *p)
{
    double v[3][3];
    int ok = td_iso_triangle(l, r, q, v);
    if (ok) {
        double e1[3] = {v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]};
        double e2[3] = {v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]};
        double nx = e1[1] * e2[2] - e1[2] * e2[1], ny = e1[2] * e2[0] - e1[0] * e2[2];
        double nz = e1[0] * e2[1] - e1[1] * e2[0]; /* never 0: the footprint is a triangle */
        p->x0 = v[0][0];
        p->y0 = v[0][1];
        p->z0 = v[0][2];
        p->gx = -nx / nz;
        p->gy = -ny / nz;
    }
    return ok;
}

static void plane_normal(const iso_plane *p, double n[3])
{
    double s = 1.0 / sqrt(p->gx * p->gx + p->gy * p->gy + 1.0);
    n[0] = -p->gx * s;
    n[1] = -p->gy * s;
    n[2] = s;
}

int td_iso_eval(const td_iso *l, double x, double y, double *z, double n[3])
{
    int32_t r, q;
    iso_plane p;
    int ok;

    x = x < 0.0 ? 0.0 : (x > (l->nx - 1) * l->a ? (l->nx - 1) * l->a : x);
    y = y < 0.0 ? 0.0 : (y > (l->ny - 1) * l->b ? (l->ny - 1) * l->b : y);
    td_iso_locate(l, x, y, &r, &q);
    ok = plane_of(l, r, q, &p);
    if (ok) {
        *z = p.z0 + p.gx * (x - p.x0) + p.gy * (y - p.y0);
        if (n)
            plane_normal(&p, n);
    }
    return ok;
}

/* The ray's height above plane p at t. */
static double above(const td_ray *ray, const iso_plane *p, double t)
{
    double x = ray->o[0] + t * ray->d[0], y = ray->o[1] + t * ray->d[1];
    return ray->o[2] + t * ray->d[2] - (p->z0 + p->gx * (x - p->x0) + p->gy * (y - p->y0));
}

/* The first t in [t0, t1] where the ray meets triangle (r, q), or +inf. *fprev is the
 * ray's height above the surface where the previous triangle's segment ended (NaN after a
 * hole or at the start): a sign change between it and this triangle's entry is a crossing
 * on their shared edge, which the two planes' roundings could otherwise both miss. On
 * return *fprev is the height at t1. A hole forgets the sign (the ray may pass under its
 * edge), unless the ray only passes its corner: a segment shorter than 1e-9 cells on the
 * ground, which is how a ray through a vertex between two valid triangles and a hole
 * looks after rounding (the three families' lines cross there at t's a few ulps apart);
 * a sign change across that vertex is a crossing at it. */
static double segment_hit(const td_iso *l, const td_ray *ray, int32_t r, int32_t q, double t0,
                          double t1, iso_plane *p, double *fprev)
{
    double t = INFINITY, zr0 = ray->o[2] + t0 * ray->d[2], zr1 = ray->o[2] + t1 * ray->d[2];
    int32_t rr[3], cc[3];
    float m;
    tri_index(r, q, rr, cc);
    m = td_iso_at(l, rr[0], cc[0]);
    m = td_iso_at(l, rr[1], cc[1]) > m ? td_iso_at(l, rr[1], cc[1]) : m;
    m = td_iso_at(l, rr[2], cc[2]) > m ? td_iso_at(l, rr[2], cc[2]) : m;
    if (zr0 > m && zr1 > m) { /* above the highest corner at both ends: nothing to solve */
        *fprev = 1.0;
    } else if (!plane_of(l, r, q, p)) { /* a hole: see above */
        double run = (t1 - t0) * hypot(ray->d[0], ray->d[1]);
        *fprev = run > 1e-9 * (l->a < l->b ? l->a : l->b) ? NAN : *fprev;
    } else {
        double f0 = above(ray, p, t0), f1 = t1 > t0 ? above(ray, p, t1) : f0;
        if (f0 == 0.0 || (*fprev > 0.0 && f0 < 0.0) || (*fprev < 0.0 && f0 > 0.0)) {
            t = t0;
        } else if (f1 == 0.0 || (f0 < 0.0) != (f1 < 0.0)) {
            t = t0 + (t1 - t0) * (f0 / (f0 - f1));
            t = t < t0 ? t0 : (t > t1 ? t1 : t);
        }
        *fprev = f1;
    }
    return t;
}

/* Clips [*t0, *t1] to the ray's ground track over [lo, hi] on axis k; 0 if empty. */
static int clip_axis(const td_ray *ray, int k, double lo, double hi, double *t0, double *t1)
{
    int ok = 1;
    if (ray->d[k] == 0.0) {
        ok = ray->o[k] >= lo && ray->o[k] <= hi;
    } else {
        double ta = (lo - ray->o[k]) / ray->d[k], tb = (hi - ray->o[k]) / ray->d[k];
        if (ta > tb) {
            double s = ta;
            ta = tb;
            tb = s;
        }
        *t0 = ta > *t0 ? ta : *t0;
        *t1 = tb < *t1 ? tb : *t1;
    }
    return ok && *t0 <= *t1;
}

/* The cell [i, i+1) of the integer lines holding v, ties broken toward the direction of
 * travel: floor(v), or ceil(v) - 1 going down. By truncation (floor and ceil are library
 * calls without SSE4.1, and this runs at every step and block test): v is a lattice
 * coordinate, far inside int32 (clamped, so a cast is never undefined). */
static int32_t cell_toward(double v, int down)
{
    int32_t i;
    v = v >= -1e9 ? (v <= 1e9 ? v : 1e9) : -1e9;
    i = (int32_t)v;
    if (down)
        i += ((double)i < v) - 1;
    else
        i -= (double)i > v;
    return i;
}

/* One family of lines v(t) = v0 + t dv, v = integer: the floor of v along the ray (ties
 * broken toward the direction of travel) and the t of its next change. */
typedef struct iso_family {
    double v0, dv, tnext;
    int32_t idx, dir;
} iso_family;

static void family_init(iso_family *f, double v0, double dv, double t)
{
    double v = v0 + t * dv;
    f->v0 = v0;
    f->dv = dv;
    f->dir = dv > 0.0 ? 1 : (dv < 0.0 ? -1 : 0);
    f->idx = cell_toward(v, f->dir < 0);
    f->tnext = f->dir > 0 ? (f->idx + 1 - v0) / dv : (f->dir < 0 ? (f->idx - v0) / dv : INFINITY);
}

static void family_step(iso_family *f)
{
    f->idx += f->dir;
    f->tnext = f->dir > 0 ? (f->idx + 1 - f->v0) / f->dv : (f->idx - f->v0) / f->dv;
}

/* The three families of the walk at t: A = y/b, B = x/a - y/2b, C = x/a + y/2b. */
static void walk_init(iso_family f[3], const td_iso *l, const td_ray *ray, double t)
{
    double ia = 1.0 / l->a, ib = 1.0 / l->b;
    family_init(&f[0], ray->o[1] * ib, ray->d[1] * ib, t);
    family_init(&f[1], ray->o[0] * ia - 0.5 * ray->o[1] * ib, ray->d[0] * ia - 0.5 * ray->d[1] * ib, t);
    family_init(&f[2], ray->o[0] * ia + 0.5 * ray->o[1] * ib, ray->d[0] * ia + 0.5 * ray->d[1] * ib, t);
}

/* What the block tests need of a ray, computed once per trace: 1/d and 1/(a, b). */
typedef struct iso_inv {
    double d[2], s[2];
} iso_inv;

/* The ray from tc against the block of level k holding its point there (ties toward the
 * direction of travel; a point a rounding away from an edge may get the neighbour, whose
 * maximum also bounds the triangles along that edge): *te gets the t where it leaves the
 * block's box (at most t1); returns whether it stays above the block's maximum until then
 * (and leaves after tc). */
static int block_clear(const td_iso *l, int k, const td_ray *ray, const iso_inv *inv, double tc,
                       double t1, double *te)
{
    const double S = (double)(1u << (TD_ISO_BLOCK_LOG2 + k)), iS = 1.0 / S; /* powers of 2 */
    double w[2] = {S * l->a, S * l->b}, z0, z1;
    int32_t bi[2], n[2] = {l->bw[k], l->bh[k]};
    float m;
    *te = t1;
    for (int a = 0; a < 2; a++) {
        double v = (ray->o[a] + tc * ray->d[a]) * (inv->s[a] * iS);
        bi[a] = clamp32(cell_toward(v, ray->d[a] < 0.0), 0, n[a] - 1);
        if (ray->d[a] != 0.0) {
            double ta = ((ray->d[a] > 0.0 ? bi[a] + 1 : bi[a]) * w[a] - ray->o[a]) * inv->d[a];
            *te = ta < *te ? ta : *te;
        }
    }
    m = l->bmax[k][(size_t)bi[1] * (size_t)l->bw[k] + (size_t)bi[0]];
    z0 = ray->o[2] + tc * ray->d[2];
    z1 = ray->o[2] + *te * ray->d[2];
    return *te > tc && z0 > m && z1 > m;
}

/* Where the walk may jump from tc: the exit of the largest block the ray clears (returns
 * 1), or 0 and *te the exit of the level-0 block (no test again before it). The pyramid is
 * climbed from the level of the last clear block, so a ray above the terrain pays one or
 * two tests a jump, not one per level. */
static int block_skip(const td_iso *l, const td_ray *ray, const iso_inv *inv, double tc,
                      double t1, int *level, double *te)
{
    int k = *level, ok = block_clear(l, k, ray, inv, tc, t1, te);
    if (ok) {
        double t2;
        while (k + 1 < l->blevels && block_clear(l, k + 1, ray, inv, tc, t1, &t2)) {
            k++;
            *te = t2;
        }
    } else {
        while (k > 0 && !ok)
            ok = block_clear(l, --k, ray, inv, tc, t1, te);
    }
    *level = k;
    return ok;
}

void td_iso_trace(const td_iso *l, const td_ray *ray, td_hit *hit)
{
    double t0 = ray->tmin, t1 = ray->tmax, t = INFINITY;
    int32_t r = 0, q = 0;
    uint32_t steps = 0;
    iso_plane p = {0};

    hit->t = INFINITY;
    hit->ci = hit->cj = -1;
    hit->method = TD_METHOD_INCREMENTAL;
    if (!clip_axis(ray, 0, 0.0, (l->nx - 1) * l->a, &t0, &t1) ||
        !clip_axis(ray, 1, 0.0, (l->ny - 1) * l->b, &t0, &t1))
        goto out;
    if (ray->d[0] == 0.0 && ray->d[1] == 0.0) {
        td_iso_locate(l, ray->o[0], ray->o[1], &r, &q);
        steps = 1;
        if (plane_of(l, r, q, &p)) {
            double h = p.z0 + p.gx * (ray->o[0] - p.x0) + p.gy * (ray->o[1] - p.y0);
            double tz = ray->d[2] != 0.0 ? (h - ray->o[2]) / ray->d[2] : INFINITY;
            if (ray->o[2] + t0 * ray->d[2] == h)
                t = t0;
            else if (tz >= t0 && tz <= t1)
                t = tz;
        }
    } else {
        iso_family f[3];
        double tc = t0, tb = -INFINITY, fprev = NAN; /* blocks checked up to tb */
        int level = l->blevels - 1;
        uint32_t cap = 4u * (uint32_t)(l->nx + l->ny) + 16u;
        iso_inv inv = {{ray->d[0] != 0.0 ? 1.0 / ray->d[0] : 0.0,
                        ray->d[1] != 0.0 ? 1.0 / ray->d[1] : 0.0},
                       {1.0 / l->a, 1.0 / l->b}};
        walk_init(f, l, ray, t0);
        for (;;) {
            int k;
            double tn, te;
            if (tc >= tb) {
                if (block_skip(l, ray, &inv, tc, t1, &level, &te)) {
                    steps++;
                    if (te >= t1 || steps >= cap)
                        break;
                    tc = te;
                    fprev = 1.0; /* above the block's triangles, those at its edge included */
                    walk_init(f, l, ray, tc);
                    continue;
                }
                tb = te;
            }
            k = f[1].tnext < f[0].tnext ? 1 : 0;
            k = f[2].tnext < f[k].tnext ? 2 : k;
            tn = f[k].tnext < t1 ? f[k].tnext : t1;
            tn = tn < tc ? tc : tn;
            r = clamp32(f[0].idx, 0, l->ny - 2);
            q = clamp32(f[1].idx + f[2].idx + 1, 0, 2 * l->nx - 2);
            steps++;
            t = segment_hit(l, ray, r, q, tc, tn, &p, &fprev);
            if (t < INFINITY || tn >= t1 || steps >= cap)
                break;
            family_step(&f[k]);
            tc = tn;
        }
    }
out:
    hit->steps = steps;
    if (t < INFINITY) {
        double n[3];
        hit->t = t;
        for (int k = 0; k < 3; k++)
            hit->p[k] = ray->o[k] + t * ray->d[k];
        plane_normal(&p, n);
        for (int k = 0; k < 3; k++)
            hit->n[k] = (float)n[k];
        hit->ci = q;
        hit->cj = r;
    }
}

/* --- two-byte vertices ------------------------------------------------------------- */

/* Whether every valid sample of tile `ti` is offset + k * step exactly (k <= 65534). */
static int tile_exact(const td_iso *l, const td_iso_packed *p, size_t ti, double offset,
                      double step)
{
    int ok = 1;
    int32_t T = (int32_t)1 << p->tile_log2, ty = (int32_t)(ti / (size_t)p->tiles_x);
    int32_t tx = (int32_t)(ti % (size_t)p->tiles_x);
    for (int32_t r = ty * T; ok && r < l->ny && r < (ty + 1) * T; r++) {
        int32_t cend = tx == p->tiles_x - 1 ? td_iso_row_len(l, r) : (tx + 1) * T;
        for (int32_t c = tx * T; ok && c < cend; c++) {
            float z = td_iso_at(l, r, c);
            double k = nearbyint(((double)z - offset) / step);
            ok = isnan(z) || (k >= 0.0 && k <= 65534.0 && (float)(offset + k * step) == z);
        }
    }
    return ok;
}

/* Whether step s codes tile ti exactly, from an offset that is a whole number of steps
 * (so decimal data, 2339.84 = 233984 x 0.01, stay decimal: float32 heights are not). */
static int try_step(const td_iso *l, td_iso_packed *p, size_t ti, double lo, double hi, double s)
{
    double off = nearbyint(lo / s) * s;
    int ok = (hi - off) / s <= 65534.0 && tile_exact(l, p, ti, off, s); /* off within s/2 of lo */
    if (ok) {
        p->offset[ti] = off;
        p->step[ti] = s;
    }
    return ok;
}

/* Picks tile ti's offset and step (lossless if a candidate step is exact). */
static void tile_code(const td_iso *l, td_iso_packed *p, size_t ti, double lo, double hi)
{
    int ok = 0;
    for (int e = 4; e >= -16 && !ok; e--) { /* 16, 8, .. 1, 1/2, .. 2^-16 */
        ok = try_step(l, p, ti, lo, hi, ldexp(1.0, e));
        for (int d = 1; e == 0 && d <= 3 && !ok; d++) /* 1/10, 1/100, 1/1000 */
            ok = try_step(l, p, ti, lo, hi, pow(10.0, -d));
    }
    p->lossless += ok;
    if (!ok) {
        p->offset[ti] = lo;
        p->step[ti] = hi > lo ? (hi - lo) / 65534.0 : 1.0;
    }
}

td_status td_iso_pack(const td_iso *l, int tile_log2, td_iso_packed **out, td_err *err)
{
    td_status rc = TD_OK;
    td_iso_packed *p = NULL;
    size_t n = td_iso_row_offset(l->nx, l->ny), nt;
    double *lo = NULL, *hi = NULL;

    *out = NULL;
    if (tile_log2 < 1 || tile_log2 > 14) {
        rc = td_err_set(err, TD_EINVAL, "isometric packing: tile_log2 %d outside 1 .. 14", tile_log2);
        goto out;
    }
    p = calloc(1, sizeof *p);
    if (!p)
        goto nomem;
    p->nx = l->nx;
    p->ny = l->ny;
    p->a = l->a;
    p->b = l->b;
    p->tile_log2 = tile_log2;
    p->tiles_x = ((l->nx - 1) >> tile_log2) + 1;
    p->tiles_y = ((l->ny - 1) >> tile_log2) + 1;
    nt = (size_t)p->tiles_x * (size_t)p->tiles_y;
    p->offset = calloc(nt, sizeof *p->offset);
    p->step = calloc(nt, sizeof *p->step);
    p->k = malloc(n * sizeof *p->k);
    lo = malloc(nt * sizeof *lo);
    hi = malloc(nt * sizeof *hi);
    if (!p->offset || !p->step || !p->k || !lo || !hi)
        goto nomem;
    for (size_t i = 0; i < nt; i++) {
        lo[i] = INFINITY;
        hi[i] = -INFINITY;
    }
    for (int32_t r = 0; r < l->ny; r++) {
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            double z = td_iso_at(l, r, c);
            size_t ti = td_iso_packed_tile(p, r, c);
            lo[ti] = z < lo[ti] ? z : lo[ti]; /* NaN compares false */
            hi[ti] = z > hi[ti] ? z : hi[ti];
        }
    }
    for (size_t ti = 0; ti < nt; ti++)
        tile_code(l, p, ti, lo[ti] <= hi[ti] ? lo[ti] : 0.0, lo[ti] <= hi[ti] ? hi[ti] : 0.0);
    for (int32_t r = 0; r < l->ny; r++) {
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            float z = td_iso_at(l, r, c);
            size_t ti = td_iso_packed_tile(p, r, c), i = td_iso_row_offset(l->nx, r) + (size_t)c;
            double k = isnan(z) ? 65535.0 : nearbyint(((double)z - p->offset[ti]) / p->step[ti]);
            k = k < 0.0 ? 0.0 : (k > 65534.0 && !isnan(z) ? 65534.0 : k);
            p->k[i] = (uint16_t)k;
            if (!isnan(z)) {
                double e = fabs((double)td_iso_packed_at(p, r, c, i) - (double)z);
                p->max_err = e > p->max_err ? e : p->max_err;
            }
        }
    }
    p->bytes = n * sizeof *p->k + nt * (sizeof *p->offset + sizeof *p->step);
    goto out;
nomem:
    rc = td_err_set(err, TD_ENOMEM, "out of memory packing a %d x %d isometric lattice",
                    (int)l->nx, (int)l->ny);
out:
    free(lo);
    free(hi);
    if (rc) {
        td_iso_packed_free(p);
        p = NULL;
    }
    *out = p;
    return rc;
}

td_status td_iso_unpack(const td_iso_packed *p, td_iso **out, td_err *err)
{
    td_status rc = td_iso_create(p->nx, p->ny, p->a, p->b, out, err);
    if (rc)
        goto out;
    for (int32_t r = 0; r < p->ny; r++) {
        for (int32_t c = 0; c < p->nx + (r & 1); c++) {
            size_t i = td_iso_row_offset(p->nx, r) + (size_t)c;
            (*out)->z[i] = td_iso_packed_at(p, r, c, i);
        }
    }
    td_iso_finish(*out);
out:
    return rc;
}

td_status td_iso_pack_lattice(const td_iso *l, int tile_log2, td_iso **out, td_err *err)
{
    td_iso_packed *p = NULL;
    td_status rc = td_iso_pack(l, tile_log2, &p, err);
    if (rc)
        goto out;
    rc = iso_alloc(l->nx, l->ny, l->a, l->b, 0, out, err);
    if (rc)
        goto out;
    (*out)->packed = p; /* the lattice owns it from here */
    p = NULL;
    td_iso_finish(*out);
out:
    td_iso_packed_free(p);
    return rc;
}

uint64_t td_iso_bytes(const td_iso *l)
{
    uint64_t n = 0;
    for (int k = 0; k < l->blevels; k++)
        n += (uint64_t)l->bw[k] * (uint64_t)l->bh[k] * sizeof(float);
    return n + (l->packed ? l->packed->bytes
                          : (uint64_t)td_iso_row_offset(l->nx, l->ny) * sizeof(float));
}

void td_iso_packed_free(td_iso_packed *p)
{
    if (p) {
        free(p->offset);
        free(p->step);
        free(p->k);
        free(p);
    }
}
