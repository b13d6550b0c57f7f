/* surface.h: the four surfaces' arithmetic inside one cell, for the two walks that decide
 * where a ray meets them: the cell walk (trace.c, one ray) and the column walk (colwalk.c,
 * the rays of one vertical plane). Both take their heights, crossings and normals from
 * these expressions, so a ray's hit is decided by the same rules either way, and enter
 * cells by the same rule (td_cell_along).
 *
 * A cell's corners are c[0] = (i, j), c[1] = (i+1, j), c[2] = (i, j+1), c[3] = (i+1, j+1);
 * (a, b) in [0, 1]^2 is a point's place in it. f is a ray's height over the surface along
 * the ray's parameter t (trace.c: per unit of the walk's direction; colwalk.c: the
 * horizontal distance). */
#ifndef TD_SURFACE_H
#define TD_SURFACE_H

#include <math.h>
#include <stdint.h>

static inline double td_clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* The cell index along one axis that contains a ray just after it is at position pos (in
 * cells), walking in direction s, within [lo, hi]: a point on a line belongs to the cell
 * the ray goes on into (going west or south, the cell before the line). */
static inline int32_t td_cell_along(double pos, int s, int32_t lo, int32_t hi)
{
    int32_t c;
    if (!(pos >= (double)lo)) { /* below the range (or NaN): clamp before converting */
        c = lo;
    } else if (pos >= (double)hi + 1.0) {
        c = hi;
    } else {
        c = (int32_t)pos; /* floor, pos >= lo >= 0 */
        if (s < 0 && (double)c == pos && c > lo)
            c--;
    }
    return c;
}

/* Height plane: the cell's highest corner. */
static inline double td_patch_plane(const double c[4])
{
    const double a = c[0] > c[1] ? c[0] : c[1], b = c[2] > c[3] ? c[2] : c[3];
    return a > b ? a : b;
}

/* Triangles split by the diagonal a + b = 1, from (i+1, j) to (i, j+1). */
static inline double td_patch_triangle(const double c[4], double a, double b)
{
    double h;
    if (a + b <= 1.0)
        h = c[0] + (c[1] - c[0]) * a + (c[2] - c[0]) * b;
    else
        h = c[3] + (c[2] - c[3]) * (1.0 - a) + (c[1] - c[3]) * (1.0 - b);
    return h;
}

static inline double td_patch_bilinear(const double c[4], double a, double b)
{
    return c[0] + (c[1] - c[0]) * a + (c[2] - c[0]) * b + (c[0] - c[1] - c[2] + c[3]) * a * b;
}

/* Height gradients (dz/da, dz/db per cell) at (a, b). */
static inline void td_gradient_triangle(const double c[4], double a, double b, double g[2])
{
    if (a + b <= 1.0) {
        g[0] = c[1] - c[0];
        g[1] = c[2] - c[0];
    } else {
        g[0] = c[3] - c[2];
        g[1] = c[3] - c[1];
    }
}

static inline void td_gradient_bilinear(const double c[4], double a, double b, double g[2])
{
    double k = c[0] - c[1] - c[2] + c[3];
    g[0] = (c[1] - c[0]) + k * b;
    g[1] = (c[2] - c[0]) + k * a;
}

/* The first t in [ta, tb] where the linear f goes from fa to fb through zero (a touch
 * counts). */
static inline int td_seg_hit(double ta, double fa, double tb, double fb, double *t)
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

/* The bilinear patch along a ray: f(s) = fa + B s + A s^2 on s = t - ta in [0, tb - ta],
 * with A from the patch's twist (A = -twist du dv, du and dv the ray's steps in cells per
 * unit t) and B fixed by the shared end values, so the quadratic agrees with both boundary
 * values exactly. Roots in the cancellation-free form q = -(B + sign(B) sqrt)/2, r1 = q/A,
 * r2 = fa/q. No iteration, no sampling. f(s) is the chord between fa and fb plus
 * A s (s - L), which takes back at most A L^2 / 4 (A > 0; nothing for A < 0): with both
 * ends above that (and 1e-12 of the magnitudes, far over the rounding of fext), there is
 * no root and no division is needed. Same answers as the full test (whose fext is then
 * above zero), measured 3-9% of the primary stage on bilinear level views (the column walk). */
static inline int td_quad_hit(double ta, double fa, double tb, double fb, double A, double *t)
{
    int hit = 0;
    const double L = tb - ta;
    if (fa == 0.0) {
        *t = ta;
        hit = 1;
    } else if (!(L > 0.0)) {
        hit = 0;
    } else if (A == 0.0 || fabs(A) * L * L <= 1e-12 * (fabs(fa) + fabs(fb))) {
        hit = td_seg_hit(ta, fa, tb, fb, t);
    } else if (fa > 0.0 && fb > 0.0 &&
               (fa < fb ? fa : fb) > (A > 0.0 ? 0.25 * A * L * L : 0.0) + 1e-12 * (fa + fb + fabs(A) * L * L)) {
        hit = 0; /* above the chord by more than the sag can take back */
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
            double lo = r1 < r2 ? r1 : r2, hi = r1 > r2 ? r1 : r2;
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

/* The unit normal of a surface's normal vector nv (facing up), as a hit records it. */
static inline void td_unit_normal(const double nv[3], float n[3])
{
    double len = sqrt(nv[0] * nv[0] + nv[1] * nv[1] + nv[2] * nv[2]);
    n[0] = (float)(nv[0] / len);
    n[1] = (float)(nv[1] / len);
    n[2] = (float)(nv[2] / len);
}

#endif
