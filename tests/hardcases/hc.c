/* hc.c: the hard-cases harness: degenerate terrains, ray generators and the judge (see
 * hc.h for the rules it enforces).
 *
 * The judge never trusts td_trace's own arithmetic: the reference (tests/oracle,
 * reference.c) clips the ray against every cell's closed footprint and solves each
 * surface in closed form in double. Verdicts, as in the oracle tests:
 *   agree  within 1 mm + float32 rounding of the exact first hit (or both miss);
 *   tie    not the exact hit, but inside the exact band: the ray comes within 1e-9 of the
 *          scene's size of the surface there and has not definitely crossed it before
 *          (touches at ridge heights, rays through vertices, grazing rays);
 *   float  the same inside the float32 band (1 mm + float32 rounding, times 1 + the
 *          steepest slope): allowed, counted and printed in the table;
 *   wrong  anything else: a missed hit, a hit the surface does not have, a hit behind
 *          the origin. The suite requires 0.
 * Rays with huge or tiny directions are judged on a copy scaled by a power of two
 * (exact), because the reference's |d| would overflow; t is scaled back.
 *
 * Rejected: judging by agreement between methods only (all methods share the walk, so a
 * shared bug would agree with itself); a tolerance that grows with the case (a case
 * that needs more than the float32 band is a finding, not a tolerance). */
#include "hc.h"
#include "sunlit.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "terrain.h"

/* ---- random numbers ------------------------------------------------------------------ */
uint64_t hc_rng_next(uint64_t *s)
{
    uint64_t x = (*s += 0x9e3779b97f4a7c15ull);
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

double hc_rng_u(uint64_t *s) { return (double)(hc_rng_next(s) >> 11) * (1.0 / 9007199254740992.0); }
double hc_rng_range(uint64_t *s, double a, double b) { return a + (b - a) * hc_rng_u(s); }
int32_t hc_rng_int(uint64_t *s, int32_t n) { return n > 0 ? (int32_t)(hc_rng_next(s) % (uint64_t)n) : 0; }

/* ---- names ---------------------------------------------------------------------------- */
static const char *const terrain_names[] = {
#define HC_X_NAME(e, name) name,
    HC_TERRAIN_LIST(HC_X_NAME)
#undef HC_X_NAME
};
static const char *const voids_names[] = {
#define HC_X_NAME(e, name) name,
    HC_VOIDS_LIST(HC_X_NAME)
#undef HC_X_NAME
};
static const char *const ray_names[] = {
#define HC_X_NAME(e, name) name,
    HC_RAY_LIST(HC_X_NAME)
#undef HC_X_NAME
};

const char *hc_terrain_name(hc_terrain t) { return (unsigned)t < HC_T_COUNT ? terrain_names[t] : "?"; }
const char *hc_voids_name(hc_voids v) { return (unsigned)v < HC_V_COUNT ? voids_names[v] : "?"; }
const char *hc_ray_kind_name(hc_ray_kind k) { return (unsigned)k < HC_R_COUNT ? ray_names[k] : "?"; }

/* ---- terrains --------------------------------------------------------------------------- */
void hc_terrain_defaults(hc_terrain_params *p, hc_terrain kind)
{
    memset(p, 0, sizeof *p);
    p->kind = kind;
    p->w = 41;
    p->h = 37;
    p->sx = 10.0;
    p->sy = 10.0;
    p->tile_log2 = 3;
    p->base = 100.0;
    p->relief = 150.0;
    p->plateau = 175.0;
    p->k = TD_PLANES_K_DEFAULT;
    p->voids = HC_V_NONE;
    p->seed = 1;
}

td_grid *hc_grid_from(int32_t w, int32_t h, double sx, double sy, int tile_log2, const float *z)
{
    td_grid *g = NULL;
    td_err err = {0};
    if (td_grid_create(w, h, sx, sy, tile_log2, NULL, &g, &err) == TD_OK) {
        memcpy(g->z, z, (size_t)w * (size_t)h * sizeof(float));
        if (td_grid_finish(g, &err) != TD_OK) {
            td_grid_free(g);
            g = NULL;
        }
    }
    if (!g)
        fprintf(stderr, "hardcases: grid %d x %d: %s\n", (int)w, (int)h, err.msg);
    return g;
}

/* fBm heights in [0, 1] from td_terrain (its spacing only sets the feature size). */
static int procedural01(int32_t w, int32_t h, uint64_t seed, float *out)
{
    td_terrain_params tp;
    td_grid *t = NULL;
    int ok;
    td_terrain_params_default(&tp);
    tp.width = w;
    tp.height = h;
    tp.spacing = 10.0;
    tp.seed = seed;
    tp.feature_m = 10.0 * (w > h ? w : h) / 2.0;
    tp.relief_m = 1000.0;
    tp.base_m = 0.0;
    ok = td_terrain_generate(&tp, 4, &t, NULL) == TD_OK;
    if (ok) {
        double lo = t->zmin, hi = t->zmax, span = hi > lo ? hi - lo : 1.0;
        for (size_t k = 0; k < (size_t)w * (size_t)h; k++)
            out[k] = (float)(((double)t->z[k] - lo) / span);
    }
    td_grid_free(t);
    return ok;
}

static void apply_voids(const hc_terrain_params *p, float *z)
{
    const int32_t w = p->w, h = p->h, T = (int32_t)1 << p->tile_log2;
    uint64_t s = p->seed * 7919u + 17u;
    for (int32_t j = 0; j < h; j++) {
        for (int32_t i = 0; i < w; i++) {
            int v = 0;
            switch (p->voids) {
            case HC_V_SINGLE:
                v = hc_rng_u(&s) < 0.03;
                break;
            case HC_V_ROWS:
                v = j == h / 3 || i == w / 2 || i == w / 2 + 1 || j == h - 1;
                break;
            case HC_V_TILES: { /* tiles (0,0), (1,1) and (2,0), edges included */
                int32_t tx = i / T, ty = j / T;
                int in00 = i <= T && j <= T;
                int in11 = i >= T && i <= 2 * T && j >= T && j <= 2 * T;
                int in20 = i >= 2 * T && i <= 3 * T && j <= T;
                (void)tx;
                (void)ty;
                v = in00 || in11 || in20;
                break;
            }
            case HC_V_SEAMS:
                v = (i == T && j < h / 2) || (j == 2 * T) || (i == 3 * T && j > h / 3);
                break;
            case HC_V_ALL:
                v = 1;
                break;
            default:
                break;
            }
            if (v)
                z[(size_t)j * (size_t)w + (size_t)i] = NAN;
        }
    }
}

td_grid *hc_terrain_make(const hc_terrain_params *p)
{
    const int32_t w = p->w, h = p->h;
    const size_t n = (size_t)w * (size_t)h;
    float *z = malloc(n * sizeof *z), *f = malloc(n * sizeof *f);
    td_grid *g = NULL;
    uint64_t s = p->seed;
    int ok = z && f && procedural01(w, h, p->seed, f);

    for (int32_t j = 0; ok && j < h; j++) {
        for (int32_t i = 0; i < w; i++) {
            size_t k = (size_t)j * (size_t)w + (size_t)i;
            double v = p->base;
            switch (p->kind) {
            case HC_T_FLAT:
                v = p->base;
                break;
            case HC_T_PROCEDURAL:
                v = p->base + p->relief * f[k];
                break;
            case HC_T_RIDGE: { /* a crest on the sample column w/2, one along i + j = c */
                double r1 = 1.0 - 2.0 * fabs((double)(i - w / 2)) / w;
                double r2 = 0.8 - 2.0 * fabs((double)(i + j - (w + h) / 3)) / w;
                v = p->base + p->relief * fmax(0.0, fmax(r1, r2)) + 0.02 * p->relief * f[k];
                break;
            }
            case HC_T_NEEDLE:
                v = p->base;
                if ((i == w / 2 && j == h / 2) || (i == 2 * (1 << p->tile_log2) && j == (1 << p->tile_log2)))
                    v = p->base + p->relief;
                break;
            case HC_T_WALL: /* a jump between columns w/2-1 and w/2, and between two rows */
                v = p->base + (i >= w / 2 ? p->relief : 0.0) + (j >= 2 * h / 3 ? 0.5 * p->relief : 0.0);
                break;
            case HC_T_PLATEAU:
                v = fmin(p->base + p->relief * f[k], p->plateau);
                break;
            case HC_T_TERRACES: { /* exactly on the heights of p->k slices over [base, base+relief] */
                int kk = p->k > 1 ? p->k : 2;
                double step = p->relief / (kk - 1);
                v = p->base + step * floor(f[k] * (kk - 1) + 0.5);
                break;
            }
            case HC_T_SADDLES:
                v = p->base + (((i + j) & 1) ? p->relief * (0.5 + 0.5 * hc_rng_u(&s)) : 0.1 * p->relief * hc_rng_u(&s));
                break;
            case HC_T_STEPS:
                v = p->base + 0.25 * p->relief * (double)hc_rng_int(&s, 5);
                break;
            default:
                break;
            }
            z[k] = (float)v;
        }
    }
    if (ok) {
        apply_voids(p, z);
        g = hc_grid_from(w, h, p->sx, p->sy, p->tile_log2, z);
    }
    free(z);
    free(f);
    return g;
}

/* ---- rays --------------------------------------------------------------------------- */
void hc_ray_set(td_ray *r, double ox, double oy, double oz, double dx, double dy, double dz)
{
    r->o[0] = ox, r->o[1] = oy, r->o[2] = oz;
    r->d[0] = dx, r->d[1] = dy, r->d[2] = dz;
    r->tmin = 0.0;
    r->tmax = INFINITY;
}

double hc_ground(const td_grid *g, double x, double y)
{
    int32_t ci = (int32_t)fmin(fmax(floor(x / g->sx), 0.0), (double)(g->w - 2));
    int32_t cj = (int32_t)fmin(fmax(floor(y / g->sy), 0.0), (double)(g->h - 2));
    double h = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, x, y);
    return isnan(h) ? (isnan(g->zmax) ? 0.0 : (double)g->zmax) : h;
}

/* A valid sample if there is one within 64 tries. */
static void pick_sample(const td_grid *g, uint64_t *s, int32_t *i, int32_t *j, double *z)
{
    *z = NAN;
    for (int tries = 0; tries < 64 && isnan(*z); tries++) {
        *i = hc_rng_int(s, g->w);
        *j = hc_rng_int(s, g->h);
        *z = td_grid_at(g, *i, *j);
    }
    if (isnan(*z))
        *z = isnan(g->zmax) ? 0.0 : g->zmax;
}

static double zlo(const td_grid *g) { return isnan(g->zmin) ? 0.0 : g->zmin; }
static double zhi(const td_grid *g) { return isnan(g->zmax) ? 0.0 : g->zmax; }

void hc_ray_make(const td_grid *g, hc_ray_kind kind, uint64_t *s, td_ray *r)
{
    const double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
    const double R = fmax(zhi(g) - zlo(g), 1e-3 * (g->sx + g->sy));
    const int32_t T = td_grid_tile_size(g);
    double x = hc_rng_range(s, 0.0, X), y = hc_rng_range(s, 0.0, Y), z;
    double hd = hc_rng_range(s, 0.0, 2.0 * M_PI);
    int32_t i, j;

    switch (kind) {
    case HC_R_OBLIQUE: {
        double pitch = hc_rng_range(s, -1.2, -0.1);
        hc_ray_set(r, x, y, zhi(g) + hc_rng_range(s, 0.05, 1.0) * R, cos(hd) * cos(pitch), sin(hd) * cos(pitch),
                   sin(pitch));
        break;
    }
    case HC_R_GRAZING: {
        /* skim a point P of the surface at 1e-3 .. 1e-9 rad, P a sample (a crest on the
         * ridge terrain) or an interior point, the ray a hair above, on or below it */
        static const double offs[] = {0.0, 0.0, 1e-9, -1e-9, 1e-6, -1e-6, 1e-3, -1e-3};
        double a = pow(10.0, -(double)(3 + hc_rng_int(s, 7)));
        double dir = hc_rng_u(s) < 0.75 ? -1.0 : 1.0;
        double L = hc_rng_range(s, 0.05, 1.2) * (X + Y);
        double p[3];
        if (hc_rng_u(s) < 0.5) {
            pick_sample(g, s, &i, &j, &z);
            p[0] = i * g->sx, p[1] = j * g->sy, p[2] = z;
        } else {
            p[0] = x, p[1] = y, p[2] = hc_ground(g, x, y);
        }
        p[2] += offs[hc_rng_int(s, 8)] * (1.0 + fabs(p[2]));
        double d[3] = {cos(hd) * cos(a), sin(hd) * cos(a), dir * sin(a)};
        hc_ray_set(r, p[0] - L * d[0], p[1] - L * d[1], p[2] - L * d[2], d[0], d[1], d[2]);
        break;
    }
    case HC_R_GRIDLINE: {
        double sg = hc_rng_u(s) < 0.5 ? -1.0 : 1.0, dz = -hc_rng_range(s, 0.0, 0.5);
        pick_sample(g, s, &i, &j, &z);
        if (hc_rng_u(s) < 0.2)
            dz = 0.0;
        if (hc_rng_u(s) < 0.3)
            dz = -dz; /* going up along the line */
        double zo = hc_rng_u(s) < 0.3 ? z : zlo(g) + hc_rng_range(s, -0.2, 1.3) * R;
        if (hc_rng_u(s) < 0.5)
            hc_ray_set(r, i * g->sx, y, zo, 0.0, sg, dz);
        else
            hc_ray_set(r, x, j * g->sy, zo, sg, 0.0, dz);
        break;
    }
    case HC_R_DIAGONAL: {
        double sg = hc_rng_u(s) < 0.5 ? -1.0 : 1.0, dz = -hc_rng_range(s, 0.0, 0.5);
        pick_sample(g, s, &i, &j, &z);
        if (hc_rng_u(s) < 0.2)
            dz = 0.0;
        double zo = hc_rng_u(s) < 0.3 ? z : zlo(g) + hc_rng_range(s, -0.2, 1.3) * R;
        if (hc_rng_u(s) < 0.5) /* the triangles' diagonal (i+1, j)-(i, j+1) */
            hc_ray_set(r, i * g->sx, j * g->sy, zo, sg * g->sx, -sg * g->sy, dz * g->sx);
        else
            hc_ray_set(r, i * g->sx, j * g->sy, zo, sg * g->sx, sg * g->sy, dz * g->sx);
        break;
    }
    case HC_R_SAMPLE: {
        pick_sample(g, s, &i, &j, &z);
        double o[3] = {x, y, zhi(g) + hc_rng_range(s, -0.3, 1.0) * R};
        if (hc_rng_u(s) < 0.3) { /* from beyond the box */
            o[0] = hc_rng_range(s, -0.5, 1.5) * X;
            o[1] = hc_rng_range(s, -0.5, 1.5) * Y;
        }
        if (o[0] == i * g->sx && o[1] == j * g->sy)
            o[2] = z + R;
        hc_ray_set(r, o[0], o[1], o[2], i * g->sx - o[0], j * g->sy - o[1], z - o[2]);
        break;
    }
    case HC_R_SEAM: {
        int32_t ti = T * hc_rng_int(s, g->tiles_x + 1), tj = T * hc_rng_int(s, g->tiles_y + 1);
        double sg = hc_rng_u(s) < 0.5 ? -1.0 : 1.0, dz = -hc_rng_range(s, 0.0, 0.4);
        ti = ti < g->w ? ti : g->w - 1;
        tj = tj < g->h ? tj : g->h - 1;
        z = td_grid_at(g, ti, tj);
        if (isnan(z))
            z = zhi(g);
        double zo = hc_rng_u(s) < 0.3 ? z : zlo(g) + hc_rng_range(s, -0.1, 1.2) * R;
        switch (hc_rng_int(s, 4)) {
        case 0: /* along a vertical seam */
            hc_ray_set(r, ti * g->sx, y, zo, 0.0, sg, dz);
            break;
        case 1: /* along a horizontal seam */
            hc_ray_set(r, x, tj * g->sy, zo, sg, 0.0, dz);
            break;
        case 2: { /* aimed through a tile corner */
            double o[3] = {x, y, zhi(g) + hc_rng_range(s, 0.0, 1.0) * R};
            hc_ray_set(r, o[0], o[1], o[2], ti * g->sx - o[0], tj * g->sy - o[1], z - o[2]);
            break;
        }
        default: /* a diagonal through a tile corner */
            hc_ray_set(r, ti * g->sx, tj * g->sy, zo, sg * g->sx, (hc_rng_u(s) < 0.5 ? -sg : sg) * g->sy, dz * g->sx);
            break;
        }
        break;
    }
    case HC_R_VERTICAL: {
        int where = hc_rng_int(s, 4);
        pick_sample(g, s, &i, &j, &z);
        if (where == 1)
            x = i * g->sx; /* on a grid line */
        else if (where == 2)
            x = i * g->sx, y = j * g->sy; /* on a sample */
        else if (where == 3)
            x = fmin(T * hc_rng_int(s, g->tiles_x + 1), g->w - 1) * g->sx; /* on a seam */
        double gz = hc_ground(g, x, y);
        if (hc_rng_u(s) < 0.6)
            hc_ray_set(r, x, y, zhi(g) + hc_rng_range(s, 0.0, 1.0) * R, 0.0, 0.0, -hc_rng_range(s, 0.01, 100.0));
        else /* straight up from below the surface or from above it */
            hc_ray_set(r, x, y, gz + hc_rng_range(s, -1.0, 0.5) * R, 0.0, 0.0, hc_rng_range(s, 0.01, 100.0));
        break;
    }
    case HC_R_HORIZONTAL: {
        double L = hc_rng_range(s, 0.5, 20.0) * (g->sx + g->sy);
        double dx = cos(hd), dy = sin(hd);
        int axis = hc_rng_int(s, 3);
        pick_sample(g, s, &i, &j, &z);
        if (axis)
            dx = axis == 1 ? 0.0 : (dx < 0 ? -1.0 : 1.0), dy = axis == 2 ? 0.0 : (dy < 0 ? -1.0 : 1.0);
        if (hc_rng_u(s) < 0.7) /* through the sample */
            hc_ray_set(r, i * g->sx - L * dx, j * g->sy - L * dy, z, dx, dy, 0.0);
        else
            hc_ray_set(r, x - L * dx, y - L * dy, z, dx, dy, 0.0);
        break;
    }
    case HC_R_OUTSIDE: {
        double t[3] = {hc_rng_range(s, 0, X), hc_rng_range(s, 0, Y), hc_rng_range(s, zlo(g), zhi(g))};
        double o[3];
        int where = hc_rng_int(s, 4);
        if (where == 0) { /* around the box */
            double a = hc_rng_range(s, 0, 2 * M_PI), rad = 0.75 * fmax(X, Y) + hc_rng_range(s, 0, X + Y);
            o[0] = 0.5 * X + rad * cos(a), o[1] = 0.5 * Y + rad * sin(a);
            o[2] = hc_rng_range(s, zlo(g) - R, zhi(g) + 2 * R);
        } else if (where == 1) { /* exactly on a face of the box */
            int face = hc_rng_int(s, 6);
            o[0] = face == 0 ? 0.0 : (face == 1 ? X : hc_rng_range(s, 0, X));
            o[1] = face == 2 ? 0.0 : (face == 3 ? Y : hc_rng_range(s, 0, Y));
            o[2] = face == 4 ? zhi(g) : (face == 5 ? zlo(g) : hc_rng_range(s, zlo(g), zhi(g) + R));
            if (hc_rng_u(s) < 0.3) { /* leaving the box through that face */
                t[0] = 2.0 * o[0] - t[0];
                t[1] = 2.0 * o[1] - t[1];
                t[2] = 2.0 * o[2] - t[2];
            }
        } else if (where == 2) { /* far away: 1e7 m */
            double a = hc_rng_range(s, 0, 2 * M_PI);
            o[0] = 0.5 * X + 1e7 * cos(a), o[1] = 0.5 * Y + 1e7 * sin(a);
            o[2] = zhi(g) + hc_rng_range(s, 0.0, 1e5);
        } else { /* far above */
            o[0] = x, o[1] = y, o[2] = zhi(g) + 1e7;
        }
        if (t[0] == o[0] && t[1] == o[1] && t[2] == o[2])
            t[2] -= 1.0;
        hc_ray_set(r, o[0], o[1], o[2], t[0] - o[0], t[1] - o[1], t[2] - o[2]);
        break;
    }
    case HC_R_ONSURFACE: {
        double pitch = hc_rng_range(s, -1.5, 1.5);
        pick_sample(g, s, &i, &j, &z);
        if (hc_rng_u(s) < 0.2)
            pitch = 0.0;
        hc_ray_set(r, i * g->sx, j * g->sy, z, cos(hd) * cos(pitch), sin(hd) * cos(pitch), sin(pitch));
        break;
    }
    case HC_R_BELOW: {
        double pitch = hc_rng_range(s, -1.5, 1.5);
        double dz = pow(10.0, hc_rng_range(s, -6.0, 0.0)) * R;
        hc_ray_set(r, x, y, hc_ground(g, x, y) - dz, cos(hd) * cos(pitch), sin(hd) * cos(pitch), sin(pitch));
        break;
    }
    default: { /* HC_R_SCALED: another kind, its direction scaled or given a denormal */
        /* the largest component becomes l; 2^-899 stays above 2^-900, the floor below
         * which td_ray_validate refuses a direction (t would overflow) */
        static const double lam[] = {0x1p-899, 1e-250, 1e-7, 3.7, -0.0, 1e7, 1e250, 0x1p+900};
        hc_ray_kind base = (hc_ray_kind)hc_rng_int(s, HC_R_SCALED);
        double l = lam[hc_rng_int(s, 8)];
        hc_ray_make(g, base, s, r);
        if (l == 0.0) { /* a denormal in place of a small component */
            static const double den[] = {0x1p-1074, -0x1p-1074, 1e-310, -3e-320};
            int big = fabs(r->d[0]) >= fabs(r->d[1]) ? 0 : 1;
            big = fabs(r->d[big]) >= fabs(r->d[2]) ? big : 2;
            int c = (big + 1 + hc_rng_int(s, 2)) % 3; /* never the largest component */
            r->d[c] = den[hc_rng_int(s, 4)];
        } else {
            /* scale so the largest component is l (>= 2^-900 in magnitude) */
            double m = fmax(fabs(r->d[0]), fmax(fabs(r->d[1]), fabs(r->d[2])));
            double k = m > 0.0 ? fabs(l) / m : 1.0;
            for (int c = 0; c < 3; c++)
                r->d[c] *= k;
        }
        break;
    }
    }
}

/* ---- scenes ---------------------------------------------------------------------------- */
int hc_scene_init(hc_scene *sc, const char *label, td_grid *g, int k)
{
    int rc = g ? 0 : 1;
    td_accel_opts o;
    td_err err = {0};
    memset(sc, 0, sizeof *sc);
    snprintf(sc->label, sizeof sc->label, "%s", label);
    sc->g = g;
    if (g && k > 0) { /* k <= 0: a judge only, no acceleration, no Embree */
        td_accel_opts_default(&o);
        o.planes_k = k;
        o.threads = 1;
        if (td_accel_build(g, &o, &sc->acc, NULL, &err) != TD_OK) {
            fprintf(stderr, "hardcases: %s: acceleration: %s\n", label, err.msg);
            rc = 1;
        }
        if (rc == 0 && !isnan(g->zmin) && td_embree_build(g, 1, &sc->emb, &err) != TD_OK) {
            fprintf(stderr, "hardcases: %s: embree: %s\n", label, err.msg);
            sc->emb = NULL; /* informational only */
        }
    }
    if (g) {
        double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
        double zl = isnan(g->zmin) ? 0.0 : fabs(g->zmin), zh = isnan(g->zmax) ? 0.0 : fabs(g->zmax);
        double scale = fmax(fmax(X, Y), fmax(zl, zh));
        sc->view.grid = g;
        sc->view.accel = sc->acc ? sc->acc->tiles : NULL;
        sc->eps_x = 1e-9 * scale;
        sc->eps_f = (1e-3 + 2.0 * FLT_EPSILON * scale) * (1.0 + td_ref_max_slope(g));
    }
    return rc;
}

void hc_scene_free(hc_scene *sc)
{
    td_accel_free(sc->acc);
    td_embree_free(sc->emb);
    td_grid_free(sc->g);
    memset(sc, 0, sizeof *sc);
}

/* ---- the judge -------------------------------------------------------------------------- */
void hc_stats_init(hc_stats *st, const char *name)
{
    memset(st, 0, sizeof *st);
    st->name = name;
}

void hc_print_ray(FILE *f, const td_ray *r)
{
    fprintf(f, "  ray o=(%a, %a, %a) d=(%a, %a, %a) tmin=%a tmax=%a\n", r->o[0], r->o[1], r->o[2],
            r->d[0], r->d[1], r->d[2], r->tmin, r->tmax);
}

int hc_check(hc_stats *st, int ok, const char *fmt, ...)
{
    st->checks++;
    if (!ok) {
        va_list ap;
        st->check_fail++;
        if (st->printed++ < 40) {
            printf("CHECK FAILED: ");
            va_start(ap, fmt);
            vprintf(fmt, ap);
            va_end(ap);
            printf("\n");
        }
    }
    return ok;
}

/* The ray with its direction scaled by 2^-e to a largest component in [0.5, 1). */
static double normalised(const td_ray *r, td_ray *n)
{
    double m = fmax(fabs(r->d[0]), fmax(fabs(r->d[1]), fabs(r->d[2])));
    int e = 0;
    double f;
    frexp(m, &e);
    f = ldexp(1.0, -e);
    *n = *r;
    for (int c = 0; c < 3; c++)
        n->d[c] = r->d[c] * f;
    n->tmin = r->tmin / f;
    n->tmax = r->tmax / f;
    return f;
}

/* Clips the (normalised) ray's interval to the slab of heights where a surface can be,
 * with a margin of the bands: [zmin, zmax] for the two-sided surfaces, below zmax for the
 * plane surface's columns. The reference itself clips only to the footprint, and its
 * root slack (1e-12 of a piece's length in t) becomes metres on a ray whose horizontal
 * component is tiny but not zero: such a ray stays in one cell for an astronomically
 * long t (reported to the oracle tests' owner). Returns 0 if nothing remains. */
static int clip_to_heights(const hc_scene *sc, td_surface s, td_ray *n)
{
    int ok = 1;
    const td_grid *g = sc->g;
    if (!isnan(g->zmin)) {
        double m = 2.0 * sc->eps_f + sc->eps_x;
        double lo = s == TD_SURFACE_PLANE ? -INFINITY : (double)g->zmin - m, hi = (double)g->zmax + m;
        if (n->d[2] == 0.0) {
            ok = n->o[2] >= lo && n->o[2] <= hi;
        } else {
            double a = (lo - n->o[2]) / n->d[2], b = (hi - n->o[2]) / n->d[2];
            if (a > b) {
                double x = a;
                a = b;
                b = x;
            }
            n->tmin = a > n->tmin ? a : n->tmin;
            n->tmax = b < n->tmax ? b : n->tmax;
            ok = n->tmin <= n->tmax && isfinite(n->tmin);
        }
    }
    return ok;
}

int hc_judge(const hc_scene *sc, td_surface s, const td_ray *r, double t, double *ref_t,
             double *near_t, double *strict_t)
{
    td_ray n;
    td_ref_hit ref;
    int v;
    double f = normalised(r, &n), tn = t / f; /* t in the normalised ray's units */
    td_ref_verdict jv;
    if (!clip_to_heights(sc, s, &n)) { /* never within the heights: only a miss is right */
        ref.t = ref.t_near = ref.t_strict = INFINITY;
        jv = tn < INFINITY ? TD_REF_WRONG : TD_REF_AGREE;
    } else {
        td_ref_trace(sc->g, s, &n, sc->eps_f, &ref);
        jv = td_ref_judge(sc->g, s, &n, &ref, tn, sc->eps_f);
    }
    if (jv == TD_REF_AGREE) {
        v = HC_AGREE;
    } else if (jv == TD_REF_TIE) {
        td_ref_hit tight;
        td_ref_trace(sc->g, s, &n, sc->eps_x, &tight);
        v = td_ref_judge(sc->g, s, &n, &tight, tn, sc->eps_x) != TD_REF_WRONG ? HC_TIE : HC_FLOAT;
    } else {
        v = HC_WRONG;
    }
    if (ref_t)
        *ref_t = ref.t * f;
    if (near_t)
        *near_t = ref.t_near * f;
    if (strict_t)
        *strict_t = ref.t_strict * f;
    return v;
}

static int same_hit(const td_ray *r, double a, double b)
{
    int same;
    if (!(a < INFINITY) || !(b < INFINITY)) {
        same = !(a < INFINITY) && !(b < INFINITY);
    } else {
        td_ray n;
        double f = normalised(r, &n), p[3];
        for (int k = 0; k < 3; k++)
            p[k] = r->o[k] + a * r->d[k];
        same = td_ref_dist(&n, a / f, b / f) <= td_ref_tol(p);
    }
    return same;
}

/* The rules every answer obeys whatever the reference says; returns a reason or NULL. */
static const char *rule_violation(const td_grid *g, const td_ray *r, const td_hit *h)
{
    const char *why = NULL;
    if (isnan(h->t) || h->t == -INFINITY) {
        why = "t is NaN or -inf";
    } else if (h->t < INFINITY) {
        double tol[2];
        for (int c = 0; c < 2; c++)
            tol[c] = 1e-9 * (c ? g->sy : g->sx) +
                     64.0 * DBL_EPSILON * (fabs(r->o[c]) + fabs(h->t * r->d[c]));
        if (h->t < r->tmin)
            why = "hit before tmin (behind the origin)";
        else if (h->t > r->tmax)
            why = "hit after tmax";
        else if (!isfinite(h->p[0]) || !isfinite(h->p[1]) || !isfinite(h->p[2]))
            why = "hit point not finite";
        else if (!isfinite(h->n[0]) || !isfinite(h->n[1]) || !isfinite(h->n[2]) || h->n[2] < 0.0f ||
                 fabs(sqrt((double)h->n[0] * h->n[0] + (double)h->n[1] * h->n[1] + (double)h->n[2] * h->n[2]) - 1.0) > 1e-5)
            why = "normal not a finite unit vector facing up";
        else if (h->ci < 0 || h->cj < 0 || h->ci > g->w - 2 || h->cj > g->h - 2)
            why = "hit names a cell outside the grid";
        else if (isnan(td_surface_height(g, TD_SURFACE_BILINEAR, h->ci, h->cj, h->ci * g->sx, h->cj * g->sy)))
            why = "hit names a hole";
        else if (h->p[0] < h->ci * g->sx - tol[0] || h->p[0] > (h->ci + 1) * g->sx + tol[0] ||
                 h->p[1] < h->cj * g->sy - tol[1] || h->p[1] > (h->cj + 1) * g->sy + tol[1])
            why = "hit point outside the cell it names";
        else {
            for (int c = 0; c < 3 && !why; c++) {
                double q = r->o[c] + h->t * r->d[c];
                if (fabs(q - h->p[c]) > 1e-9 * (1.0 + fabs(q)))
                    why = "hit point is not o + t*d";
            }
        }
    }
    return why;
}

/* HC_SHOW_FLOAT=1 prints the answers that only the float32 band explains. */
static int show_float(void)
{
    static int show = -1;
    if (show < 0)
        show = getenv("HC_SHOW_FLOAT") != NULL;
    return show;
}

/* For every 4th ray going up, the sun bound (sunlit.h) of its direction as if it were
 * the sun's: td_occluded must answer the same with it. NULL for the others. */
static td_sunlit *ray_sunlit(const hc_scene *sc, const td_ray *r, uint64_t k)
{
    td_sunlit *lit = NULL;
    double n = sqrt(r->d[0] * r->d[0] + r->d[1] * r->d[1] + r->d[2] * r->d[2]);
    if (k % 4 == 0 && r->d[2] > 0.0 && n > 0.0 && isfinite(n)) {
        double sun[3] = {r->d[0] / n, r->d[1] / n, r->d[2] / n};
        td_sunlit_build(&sc->view, sun, 0, &lit, NULL);
    }
    return lit;
}

/* Whether td_occluded_par (a render's shadow rays: a direction's rays in packets of four
 * lanes) fails to answer `want` for ray r taken three times (one packet, three lanes), with
 * the sun bound lit (NULL: none). Only for r's search [0, +inf), the one it asks. */
static int par_differs(const hc_scene *sc, td_method m, td_surface s, const td_ray *r,
                       const td_sunlit *lit, int want)
{
    const double o[3][3] = {{r->o[0], r->o[1], r->o[2]}, {r->o[0], r->o[1], r->o[2]},
                            {r->o[0], r->o[1], r->o[2]}};
    uint8_t hit[3] = {2, 2, 2};
    uint32_t steps = 0;
    int differs = 0;
    if (r->tmin == 0.0 && r->tmax == INFINITY) {
        td_occluded_par(&sc->view, m, s, r->d, 3, o, lit, hit, &steps);
        differs = hit[0] != want || hit[1] != want || hit[2] != want;
    }
    return differs;
}

int hc_run_ray(hc_stats *st, const hc_scene *sc, const td_ray *r,
               td_hit out[TD_SURFACE_COUNT][TD_METHOD_COUNT])
{
    int fails = 0;
    td_sunlit *lit = ray_sunlit(sc, r, st->rays);
    st->rays++;
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        double t_inc = INFINITY, ref_t = INFINITY, near_t = INFINITY, strict_t = INFINITY;
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            hc_cell *c = &st->c[s][m];
            td_hit h;
            const char *why;
            int v;
            td_trace(&sc->view, (td_method)m, (td_surface)s, r, &h);
            if (out)
                out[s][m] = h;
            c->rays++;
            c->steps += h.steps;
            c->hits += h.t < INFINITY;
            if (m == 0)
                t_inc = h.t;
            else if (!same_hit(r, h.t, t_inc))
                c->vs_incremental++;
            why = rule_violation(sc->g, r, &h);
            if (!why) { /* the any-hit query of shadow rays answers as the trace does */
                uint32_t osteps = 0;
                if (td_occluded(&sc->view, (td_method)m, (td_surface)s, r, NULL, &osteps) != (h.t < INFINITY))
                    why = "td_occluded disagrees with td_trace";
                else if (lit && td_occluded(&sc->view, (td_method)m, (td_surface)s, r, lit, &osteps) != (h.t < INFINITY))
                    why = "td_occluded with the sun bound of the ray's direction disagrees with td_trace";
                else if (par_differs(sc, (td_method)m, (td_surface)s, r, lit, h.t < INFINITY))
                    why = "td_occluded_par (shadow rays in packets) disagrees with td_trace";
            }
            v = why ? HC_WRONG : hc_judge(sc, (td_surface)s, r, h.t, &ref_t, &near_t, &strict_t);
            if (why)
                c->rule++;
            else
                c->v[v]++;
            if (v == HC_AGREE && h.t < INFINITY && ref_t < INFINITY) {
                td_ray n;
                double f = normalised(r, &n);
                double dt = td_ref_dist(&n, h.t / f, ref_t / f);
                c->max_dt = fmax(c->max_dt, dt);
                if (getenv("HC_SHOW_DT") && dt > atof(getenv("HC_SHOW_DT")) && st->printed++ < 40) {
                    printf("%s: (shown) agreeing hit %.3g m from the exact one: surface=%s method=%s t=%.17g "
                           "exact t=%.17g p=(%.9g, %.9g, %.9g)\n",
                           sc->label, dt, td_surface_name((td_surface)s), td_method_name((td_method)m), h.t,
                           ref_t, h.p[0], h.p[1], h.p[2]);
                    hc_print_ray(stdout, r);
                }
            }
            if (why || v == HC_WRONG || (v == HC_FLOAT && show_float())) {
                fails += why || v == HC_WRONG;
                if (st->printed++ < 40) {
                    printf("%s: %s surface=%s method=%s got t=%.17g cell (%d,%d) want t=%.17g "
                           "(near %.17g strict %.17g) steps %u\n",
                           sc->label, why ? why : (v == HC_FLOAT ? "(shown) float-band tie" : "DISAGREES with the reference"),
                           td_surface_name((td_surface)s), td_method_name((td_method)m), h.t,
                           (int)h.ci, (int)h.cj, ref_t, near_t, strict_t, (unsigned)h.steps);
                    hc_print_ray(stdout, r);
                }
            }
        }
        if (s == TD_SURFACE_TRIANGLE && sc->emb) {
            td_ray n;
            double f = normalised(r, &n);
            double te = td_embree_trace(sc->emb, &n) * f;
            int v = hc_judge(sc, TD_SURFACE_TRIANGLE, r, te, &ref_t, &near_t, &strict_t);
            st->embree_rays++;
            if (v == HC_AGREE) {
                st->embree_agree++;
            } else if (v != HC_WRONG) {
                st->embree_tie++;
            } else {
                if (te > strict_t)
                    st->embree_wrong_miss++;
                else
                    st->embree_wrong_hit++;
                if (!st->quiet_embree && st->printed++ < 40) {
                    printf("%s: (info) Embree wrong: t=%.17g, reference t=%.17g (near %.17g strict %.17g)\n",
                           sc->label, te, ref_t, near_t, strict_t);
                    hc_print_ray(stdout, r);
                }
            }
        }
    }
    td_sunlit_free(lit);
    return fails;
}

uint64_t hc_report(const hc_stats *st)
{
    uint64_t wrong = 0, rule = 0, traces = 0, ties = 0, flt = 0;
    printf("case %s: %llu scenes, %llu rays\n", st->name, (unsigned long long)st->scenes,
           (unsigned long long)st->rays);
    printf("  %-9s %-13s %8s %7s %8s %6s %6s %6s %5s %10s %7s %8s\n", "surface", "method", "rays",
           "hits", "agree", "ties", "float", "wrong", "rule", "max|dt|m", "vs-inc", "steps/r");
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            const hc_cell *c = &st->c[s][m];
            printf("  %-9s %-13s %8llu %7llu %8llu %6llu %6llu %6llu %5llu %10.3g %7llu %8.1f\n",
                   td_surface_name((td_surface)s), td_method_name((td_method)m),
                   (unsigned long long)c->rays, (unsigned long long)c->hits,
                   (unsigned long long)c->v[HC_AGREE], (unsigned long long)c->v[HC_TIE],
                   (unsigned long long)c->v[HC_FLOAT], (unsigned long long)c->v[HC_WRONG],
                   (unsigned long long)c->rule, c->max_dt, (unsigned long long)c->vs_incremental,
                   c->rays ? (double)c->steps / (double)c->rays : 0.0);
            wrong += c->v[HC_WRONG];
            rule += c->rule;
            traces += c->rays;
            ties += c->v[HC_TIE];
            flt += c->v[HC_FLOAT];
        }
    }
    if (st->embree_rays)
        printf("  embree (triangle, info): %llu rays, %llu agree, %llu ties, wrong: %llu missed hits, "
               "%llu wrong hits\n",
               (unsigned long long)st->embree_rays, (unsigned long long)st->embree_agree,
               (unsigned long long)st->embree_tie, (unsigned long long)st->embree_wrong_miss,
               (unsigned long long)st->embree_wrong_hit);
    printf("case %s: rays tried %llu (%llu traces), disagreements %llu, rule violations %llu, "
           "ties %llu, float-band %llu, checks %llu failed %llu -> %s\n",
           st->name, (unsigned long long)st->rays, (unsigned long long)traces,
           (unsigned long long)wrong, (unsigned long long)rule, (unsigned long long)ties,
           (unsigned long long)flt, (unsigned long long)st->checks,
           (unsigned long long)st->check_fail, wrong + rule + st->check_fail ? "FAIL" : "PASS");
    return wrong + rule + st->check_fail;
}
