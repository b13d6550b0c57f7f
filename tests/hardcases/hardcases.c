/* hardcases.c: the hard-cases suite of issue 4: places where floating point breaks
 * terrain tracers, each a named case run for every method (incremental, hierarchical,
 * parametric, silhouette, auto) over every surface (plane, linear, triangle, bilinear) against the
 * double-precision references (tests/oracle/reference.c), with Embree's answers on the
 * triangle surface reported beside them (hc.c has the judge and the rules).
 *
 *   hardcases CASE      run one case (ctest runs each as hardcases_CASE, label hardcases)
 *   hardcases all       run every case
 *   hardcases --list    name them
 * TERRAD_SEED=S replays the property case with seed S (it prints its seed).
 *
 * Each case prints a table per surface and method: rays, hits, verdicts (agree, ties in
 * the exact band, float-band ties, wrong), rule violations, max |dt| of agreeing hits,
 * differences from the incremental walk and mean steps; then one line "rays tried N,
 * disagreements D". Exit status 1 if anything was wrong. Cases that reproduce a known
 * tracer bug say so in their description (see /work/notes/tracer-bugs.md) and keep
 * failing until the tracer is fixed; none is weakened to pass.
 *
 * Documented behaviours checked here beyond the reference (trace.h): an origin exactly
 * on a sample of the surface hits at tmin on every surface; an origin inside the plane
 * surface's solid column hits at tmin; below a two-sided surface the first crossing is
 * the hit; georeferencing never changes a hit; NaN or inf anywhere in a ray is refused
 * by td_ray_validate; every ray's occlusion query (td_occluded, shadow and AO rays, and
 * td_occluded_par, a render's shadow rays in packets) says hit exactly when the trace
 * does (hc.c); camera rays started from their horizons
 * (horizon.h) render the depths of the rays traced from their starts, bit for bit. */
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "camera.h"
#include "dem.h"
#include "hc.h"
#include "render.h"
#include "scene.h"

#define ALL_KINDS 0xffffffffu
#define KIND(k) (1u << (k))

/* ---- helpers ------------------------------------------------------------------------ */

/* Builds the scene, traces n rays of each kind in mask (seeded), frees it. */
static int run_terrain(hc_stats *st, const hc_terrain_params *p, int k, unsigned mask, int n,
                       const char *what)
{
    hc_scene sc;
    char label[160];
    uint64_t seed = p->seed * 1000003u + (uint64_t)k;
    int rc;
    snprintf(label, sizeof label, "%s[%s %dx%d s=%gx%g T=2^%d base=%g relief=%g voids=%s K=%d seed=%llu]",
             what, hc_terrain_name(p->kind), (int)p->w, (int)p->h, p->sx, p->sy, p->tile_log2,
             p->base, p->relief, hc_voids_name(p->voids), k, (unsigned long long)p->seed);
    rc = hc_scene_init(&sc, label, hc_terrain_make(p), k);
    if (rc == 0) {
        st->scenes++;
        for (int kind = 0; kind < HC_R_COUNT; kind++) {
            if (!(mask & KIND(kind)))
                continue;
            for (int q = 0; q < n; q++) {
                td_ray r;
                hc_ray_make(sc.g, (hc_ray_kind)kind, &seed, &r);
                hc_run_ray(st, &sc, &r, NULL);
            }
        }
    } else {
        hc_check(st, 0, "%s: scene could not be built", label);
    }
    hc_scene_free(&sc);
    return rc;
}

/* One scene from explicit heights, kept by the caller. */
static int scene_from(hc_stats *st, hc_scene *sc, const char *label, int32_t w, int32_t h, double sx,
                      double sy, int tile_log2, const float *z, int k)
{
    int rc = hc_scene_init(sc, label, hc_grid_from(w, h, sx, sy, tile_log2, z), k);
    if (rc == 0)
        st->scenes++;
    else
        hc_check(st, 0, "%s: scene could not be built", label);
    return rc;
}

/* ---- grazing ------------------------------------------------------------------------- */

/* Sharp crests on a sample column and along the triangles' diagonal; rays cross them at
 * 1e-3 .. 1e-9 rad, a hair above, on and below the crest, from both sides. */
static int case_grazing_ridge(hc_stats *st)
{
    static const double offs[] = {-1e-3, -1e-6, -1e-9, 0.0, 1e-9, 1e-6, 1e-3};
    hc_terrain_params p;
    hc_scene sc;
    hc_terrain_defaults(&p, HC_T_RIDGE);
    p.tile_log2 = 2;
    if (hc_scene_init(&sc, "ridge 41x37 s=10", hc_terrain_make(&p), 16) == 0) {
        const td_grid *g = sc.g;
        int32_t ic = g->w / 2;
        st->scenes++;
        for (int e = 3; e <= 9; e++) {
            double a = pow(10.0, -e);
            for (int o = 0; o < 7; o++) {
                for (int32_t j = 1; j < g->h - 1; j += 5) {
                    for (int side = -1; side <= 1; side += 2) {
                        for (int dir = -1; dir <= 1; dir += 2) {
                            /* crest point on the sample (ic, j) or between samples */
                            double y = (j + (side > 0 ? 0.0 : 0.37)) * g->sy;
                            double zc = hc_ground(g, ic * g->sx, y) + offs[o] * (1.0 + fabs(g->zmax));
                            double d[3] = {side * cos(a), side > 0 ? 0.0 : 0.013 * cos(a), dir * sin(a)};
                            double L = 0.6 * (g->w - 1) * g->sx;
                            td_ray r;
                            hc_ray_set(&r, ic * g->sx - L * d[0], y - L * d[1], zc - L * d[2], d[0], d[1], d[2]);
                            hc_run_ray(st, &sc, &r, NULL);
                        }
                    }
                }
            }
        }
    }
    hc_scene_free(&sc);
    /* random grazing rays over ridges, procedural relief and twisted cells */
    for (int t = 0; t < 3; t++) {
        hc_terrain kinds[] = {HC_T_RIDGE, HC_T_PROCEDURAL, HC_T_SADDLES};
        hc_terrain_defaults(&p, kinds[t]);
        p.seed = 11 + t;
        p.sy = t == 1 ? 7.5 : 10.0;
        run_terrain(st, &p, 16, KIND(HC_R_GRAZING), 300, "grazing");
    }
    return 0;
}

/* Flat and gently tilted ground; rays come down at 1e-3 .. 1e-9 rad from a height that
 * puts the hit inside the grid (down to 1e-7 m above the ground), and leave the ground
 * at those angles from exactly on it (tmin) or a hair above it (a miss or a tie). */
static int case_grazing_flat(hc_stats *st)
{
    for (int variant = 0; variant < 2; variant++) {
        int32_t w = 65, h = 49;
        float *z = malloc(sizeof(float) * (size_t)w * (size_t)h);
        hc_scene sc;
        uint64_t s = 99 + (uint64_t)variant;
        for (int32_t j = 0; j < h; j++)
            for (int32_t i = 0; i < w; i++)
                z[(size_t)j * w + i] = variant == 0 ? 100.0f : (float)(100.0 + 0.5 * i); /* exact in float */
        if (scene_from(st, &sc, variant ? "tilted plane 65x49 s=8" : "flat z=100 65x49 s=8", w, h, 8.0, 8.0, 3, z, 16) == 0) {
            const td_grid *g = sc.g;
            double X = (w - 1) * g->sx, Y = (h - 1) * g->sy;
            for (int e = 3; e <= 9; e++) {
                double a = pow(10.0, -e);
                for (int q = 0; q < 30; q++) {
                    double hd = hc_rng_range(&s, 0.0, 2.0 * M_PI);
                    double tx = hc_rng_range(&s, 0.1, 0.9) * X, ty = hc_rng_range(&s, 0.1, 0.9) * Y;
                    double D = hc_rng_range(&s, 0.05, 0.4) * X;
                    double d[3] = {cos(hd) * cos(a), sin(hd) * cos(a), -sin(a)};
                    double gz = hc_ground(g, tx, ty);
                    td_ray r;
                    td_hit hits[TD_SURFACE_COUNT][TD_METHOD_COUNT];
                    if (q % 3 == 1) { /* axis-aligned headings along grid lines */
                        d[0] = (q & 4) ? 0.0 : cos(a) * (q & 8 ? -1 : 1);
                        d[1] = (q & 4) ? cos(a) * (q & 8 ? -1 : 1) : 0.0;
                        tx = floor(tx / g->sx) * g->sx;
                    }
                    hc_ray_set(&r, tx - D * d[0], ty - D * d[1], gz - D * d[2], d[0], d[1], d[2]);
                    hc_run_ray(st, &sc, &r, NULL);
                    /* leaving the ground from exactly on it: a sample point */
                    {
                        int32_t i = (int32_t)hc_rng_int(&s, w), j = (int32_t)hc_rng_int(&s, h);
                        hc_ray_set(&r, i * g->sx, j * g->sy, td_grid_at(g, i, j), d[0], d[1], sin(a));
                        hc_run_ray(st, &sc, &r, hits);
                        for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
                            for (int m = 0; m < TD_METHOD_COUNT; m++)
                                hc_check(st, hits[sf][m].t == 0.0,
                                         "%s: origin on sample (%d,%d) rising at %g rad: %s/%s t=%.17g, want tmin 0",
                                         sc.label, (int)i, (int)j, a, td_surface_name((td_surface)sf),
                                         td_method_name((td_method)m), hits[sf][m].t);
                    }
                    /* a hair above the ground, rising */
                    hc_ray_set(&r, tx, ty, gz + 1e-7, d[0], d[1], sin(a));
                    hc_run_ray(st, &sc, &r, NULL);
                }
            }
        }
        hc_scene_free(&sc);
        free(z);
    }
    return 0;
}

/* Rays tangent to a bilinear patch: f(s) = -k du dv s^2 has a double root at the
 * tangent point; shifted down by delta it has two roots (the first must be found),
 * up by delta none. */
static int case_bilinear_tangent(hc_stats *st)
{
    static const double deltas[] = {0.0, 0.0, 1e-12, -1e-12, 1e-9, -1e-9, 1e-6, -1e-6, 1e-3, -1e-3};
    for (int variant = 0; variant < 3; variant++) {
        hc_scene sc;
        hc_terrain_params p;
        uint64_t s = 4242 + (uint64_t)variant;
        int ok;
        if (variant == 0) {
            float z[4] = {0.0f, 0.0f, 0.0f, 50.0f}; /* z = 50 u v */
            ok = scene_from(st, &sc, "single cell z=50uv s=10", 2, 2, 10.0, 10.0, 1, z, 16) == 0;
        } else if (variant == 1) {
            float z[4] = {10.0f, 40.0f, 35.0f, 5.0f}; /* k = -60 */
            ok = scene_from(st, &sc, "single cell saddle s=3x7", 2, 2, 3.0, 7.0, 1, z, 16) == 0;
        } else {
            hc_terrain_defaults(&p, HC_T_SADDLES);
            p.tile_log2 = 2;
            ok = hc_scene_init(&sc, "saddles 41x37", hc_terrain_make(&p), 16) == 0;
            st->scenes += ok;
        }
        for (int q = 0; ok && q < 400; q++) {
            const td_grid *g = sc.g;
            int32_t ci = hc_rng_int(&s, g->w - 1), cj = hc_rng_int(&s, g->h - 1);
            double c[4] = {td_grid_at(g, ci, cj), td_grid_at(g, ci + 1, cj), td_grid_at(g, ci, cj + 1),
                           td_grid_at(g, ci + 1, cj + 1)};
            double K = c[0] - c[1] - c[2] + c[3];
            double u0 = hc_rng_range(&s, 0.05, 0.95), v0 = hc_rng_range(&s, 0.05, 0.95);
            double hd = hc_rng_range(&s, 0.0, 2.0 * M_PI), du = cos(hd), dv = sin(hd);
            if (K == 0.0)
                continue;
            if (K * du * dv > 0.0) /* the patch must curve away below the ray */
                dv = -dv;
            double hu = (c[1] - c[0]) + K * v0, hv = (c[2] - c[0]) + K * u0;
            double dz = hu * du + hv * dv; /* per unit s in cell units */
            double h0 = c[0] + (c[1] - c[0]) * u0 + (c[2] - c[0]) * v0 + K * u0 * v0;
            double delta = deltas[q % 10] * (1.0 + fabs(h0));
            double d[3] = {du * g->sx, dv * g->sy, dz};
            double L = hc_rng_range(&s, 0.3, 3.0);
            td_ray r;
            hc_ray_set(&r, (ci + u0 - L * du) * g->sx, (cj + v0 - L * dv) * g->sy, h0 + delta - L * dz, d[0],
                       d[1], d[2]);
            hc_run_ray(st, &sc, &r, NULL);
        }
        hc_scene_free(&sc);
    }
    return 0;
}

/* ---- lines, diagonals, samples, seams ------------------------------------------------ */
static int case_terrain_kinds(hc_stats *st, unsigned mask, int n, int tile_log2)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_STEPS, HC_T_SADDLES, HC_T_RIDGE};
    for (int t = 0; t < 4; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, kinds[t]);
        p.tile_log2 = tile_log2;
        p.seed = 31 + t;
        if (t == 2)
            p.sx = 4.0, p.sy = 12.5; /* anisotropic cells */
        run_terrain(st, &p, 16, mask, n, "lines");
    }
    return 0;
}

static int case_grid_lines(hc_stats *st) { return case_terrain_kinds(st, KIND(HC_R_GRIDLINE), 250, 2); }
static int case_diagonals(hc_stats *st) { return case_terrain_kinds(st, KIND(HC_R_DIAGONAL), 250, 2); }
static int case_sample_points(hc_stats *st) { return case_terrain_kinds(st, KIND(HC_R_SAMPLE), 250, 3); }

static int case_tile_seams(hc_stats *st)
{
    case_terrain_kinds(st, KIND(HC_R_SEAM), 150, 2);
    case_terrain_kinds(st, KIND(HC_R_SEAM), 100, 3);
    return case_terrain_kinds(st, KIND(HC_R_SEAM), 100, 1);
}

/* dx = 0, dy = 0 (at random positions, on grid lines and seams), straight down and up. */
static int case_axis_aligned(hc_stats *st)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_STEPS, HC_T_PLATEAU};
    for (int t = 0; t < 3; t++) {
        hc_terrain_params p;
        hc_scene sc;
        uint64_t s = 77 + (uint64_t)t;
        hc_terrain_defaults(&p, kinds[t]);
        p.tile_log2 = 2;
        p.seed = 5 + t;
        if (hc_scene_init(&sc, hc_terrain_name(kinds[t]), hc_terrain_make(&p), 16) != 0) {
            hc_check(st, 0, "scene %s", hc_terrain_name(kinds[t]));
            hc_scene_free(&sc);
            continue;
        }
        st->scenes++;
        for (int q = 0; q < 300; q++) {
            const td_grid *g = sc.g;
            double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy, R = g->zmax - g->zmin;
            double x = hc_rng_range(&s, -0.1, 1.1) * X, y = hc_rng_range(&s, -0.1, 1.1) * Y;
            double z = g->zmin + hc_rng_range(&s, -0.2, 1.3) * R;
            double a = hc_rng_range(&s, -1.0, 1.0), sg = hc_rng_u(&s) < 0.5 ? -1.0 : 1.0;
            td_ray r;
            if (q % 4 == 1)
                x = floor(x / g->sx) * g->sx;
            if (q % 4 == 2)
                y = floor(y / g->sy) * g->sy;
            if (q % 8 == 3)
                a = 0.0;
            if (q % 2 == 0)
                hc_ray_set(&r, x, y, z, 0.0, sg, a); /* dx = 0 */
            else
                hc_ray_set(&r, x, y, z, sg, 0.0, a); /* dy = 0 */
            hc_run_ray(st, &sc, &r, NULL);
        }
        hc_scene_free(&sc);
        run_terrain(st, &p, 16, KIND(HC_R_VERTICAL), 300, "vertical");
    }
    return 0;
}

/* dz = 0 at exactly a sample's height (through the sample and elsewhere). */
static int case_horizontal_sample_height(hc_stats *st)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_STEPS, HC_T_TERRACES, HC_T_SADDLES};
    for (int t = 0; t < 4; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, kinds[t]);
        p.tile_log2 = 2 + (t & 1);
        p.seed = 50 + t;
        run_terrain(st, &p, 16, KIND(HC_R_HORIZONTAL), 300, "horizontal");
    }
    return 0;
}

/* dz = 0 at exactly a plateau's height, over the plateau and along its edges; and at
 * exactly zmin and zmax of the grid. */
static int case_horizontal_plateau(hc_stats *st)
{
    for (int t = 0; t < 2; t++) {
        hc_terrain_params p;
        hc_scene sc;
        uint64_t s = 313 + (uint64_t)t;
        hc_terrain_defaults(&p, HC_T_PLATEAU);
        p.tile_log2 = 2 + t;
        p.seed = 60 + t;
        p.plateau = t ? 160.0 : 175.0;
        if (hc_scene_init(&sc, t ? "plateau z=160" : "plateau z=175", hc_terrain_make(&p), 16) != 0) {
            hc_check(st, 0, "plateau scene");
            hc_scene_free(&sc);
            continue;
        }
        st->scenes++;
        for (int q = 0; q < 500; q++) {
            const td_grid *g = sc.g;
            double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
            double x = hc_rng_range(&s, 0.0, X), y = hc_rng_range(&s, 0.0, Y);
            double hd = hc_rng_range(&s, 0.0, 2.0 * M_PI), dx = cos(hd), dy = sin(hd);
            double z = q % 10 == 8 ? (double)g->zmax : (q % 10 == 9 ? (double)g->zmin : p.plateau);
            double L = hc_rng_range(&s, 0.0, 1.0) * X;
            td_ray r;
            if (q % 3 == 1)
                dx = dx < 0 ? -1.0 : 1.0, dy = 0.0, y = floor(y / g->sy) * g->sy;
            if (q % 3 == 2)
                dx = dx < 0 ? -g->sx : g->sx, dy = dy < 0 ? -g->sy : g->sy;
            hc_ray_set(&r, x - L * dx, y - L * dy, z, dx, dy, 0.0);
            hc_run_ray(st, &sc, &r, NULL);
        }
        hc_scene_free(&sc);
    }
    return 0;
}

/* ---- origins ------------------------------------------------------------------------ */

/* Outside the box, exactly on its faces (going in and out), far away (1e7 m). */
static int case_origins_outside(hc_stats *st)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_FLAT, HC_T_WALL};
    for (int t = 0; t < 3; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, kinds[t]);
        p.seed = 70 + t;
        run_terrain(st, &p, 16, KIND(HC_R_OUTSIDE), 400, "outside");
    }
    return 0;
}

/* Exactly on a sample of the surface: every surface and method hits at tmin (trace.h). */
static int case_origin_on_surface(hc_stats *st)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_SADDLES, HC_T_STEPS, HC_T_FLAT};
    for (int t = 0; t < 4; t++) {
        hc_terrain_params p;
        hc_scene sc;
        uint64_t s = 900 + (uint64_t)t;
        hc_terrain_defaults(&p, kinds[t]);
        p.seed = 80 + t;
        p.tile_log2 = 2;
        if (t == 1)
            p.sx = 4.0, p.sy = 12.0;
        if (hc_scene_init(&sc, hc_terrain_name(kinds[t]), hc_terrain_make(&p), 16) != 0) {
            hc_check(st, 0, "scene");
            hc_scene_free(&sc);
            continue;
        }
        st->scenes++;
        for (int q = 0; q < 300; q++) {
            td_ray r;
            td_hit hits[TD_SURFACE_COUNT][TD_METHOD_COUNT];
            hc_ray_make(sc.g, HC_R_ONSURFACE, &s, &r);
            if (q % 5 == 0) { /* with tmin > 0 and the origin moved back along the ray */
                r.tmin = 2.0;
                for (int c = 0; c < 3; c++)
                    r.o[c] -= 2.0 * r.d[c];
            }
            hc_run_ray(st, &sc, &r, hits);
            if (r.tmin > 0.0)
                continue; /* o + tmin*d is only near the sample after rounding */
            for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
                for (int m = 0; m < TD_METHOD_COUNT; m++)
                    hc_check(st, hits[sf][m].t == r.tmin,
                             "%s: origin on a sample: %s/%s t=%.17g, want tmin exactly "
                             "(o=(%a,%a,%a) d=(%a,%a,%a))",
                             sc.label, td_surface_name((td_surface)sf), td_method_name((td_method)m),
                             hits[sf][m].t, r.o[0], r.o[1], r.o[2], r.d[0], r.d[1], r.d[2]);
        }
        hc_scene_free(&sc);
    }
    return 0;
}

/* Below the surface: the plane surface is a solid column (hit at tmin); the two-sided
 * surfaces report the first crossing (a ray that stays below misses). */
static int case_origin_below(hc_stats *st)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_SADDLES, HC_T_FLAT};
    for (int t = 0; t < 3; t++) {
        hc_terrain_params p;
        hc_scene sc;
        uint64_t s = 1900 + (uint64_t)t;
        hc_terrain_defaults(&p, kinds[t]);
        p.seed = 90 + t;
        if (hc_scene_init(&sc, hc_terrain_name(kinds[t]), hc_terrain_make(&p), 16) != 0) {
            hc_check(st, 0, "scene");
            hc_scene_free(&sc);
            continue;
        }
        st->scenes++;
        for (int q = 0; q < 300; q++) {
            td_ray r;
            td_hit hits[TD_SURFACE_COUNT][TD_METHOD_COUNT];
            hc_ray_make(sc.g, HC_R_BELOW, &s, &r);
            if (q % 4 == 0) /* straight up from below: must cross */
                r.d[0] = r.d[1] = 0.0, r.d[2] = 1.0;
            hc_run_ray(st, &sc, &r, hits);
            for (int m = 0; m < TD_METHOD_COUNT; m++) {
                hc_check(st, hits[TD_SURFACE_PLANE][m].t == 0.0,
                         "%s: origin below the surface: plane/%s t=%.17g, want tmin 0", sc.label,
                         td_method_name((td_method)m), hits[TD_SURFACE_PLANE][m].t);
                for (int sf = TD_SURFACE_LINEAR; sf < TD_SURFACE_COUNT && q % 4 == 0; sf++) {
                    /* below this surface (the origin is below the bilinear one) */
                    int32_t ci = (int32_t)fmin(r.o[0] / sc.g->sx, sc.g->w - 2), cj = (int32_t)fmin(r.o[1] / sc.g->sy, sc.g->h - 2);
                    if (r.o[2] < td_surface_height(sc.g, (td_surface)sf, ci, cj, r.o[0], r.o[1]))
                        hc_check(st, hits[sf][m].t < INFINITY,
                                 "%s: straight up from below: %s/%s missed", sc.label,
                                 td_surface_name((td_surface)sf), td_method_name((td_method)m));
                }
            }
        }
        hc_scene_free(&sc);
    }
    return 0;
}

/* ---- georeference --------------------------------------------------------------------- */
static int write_f32(const char *dir, const char *name, int32_t w, int32_t h, const float *z,
                     const char *origin_json, char *path, size_t pathlen)
{
    char json[512];
    FILE *f;
    int ok;
    snprintf(path, pathlen, "%s/%s.f32", dir, name);
    f = fopen(path, "wb");
    ok = f && fwrite(z, sizeof(float), (size_t)w * (size_t)h, f) == (size_t)w * (size_t)h;
    if (f)
        ok = (fclose(f) == 0) && ok;
    snprintf(json, sizeof json, "%s/%s.json", dir, name);
    f = fopen(json, "w");
    ok = ok && f;
    if (f) {
        fprintf(f, "{\"width\": %d, \"height\": %d, \"nodata\": \"nan\"%s%s}\n", (int)w, (int)h,
                origin_json ? ", " : "", origin_json ? origin_json : "");
        ok = (fclose(f) == 0) && ok;
    }
    return ok;
}

/* The frame is local: a georeference (projected 500000/4e6, lon/lat at the antimeridian
 * and the poles) changes no hit; lon/lat spacing stays positive and finite up to the
 * poles; loading such sidecars gives a usable grid or a clear refusal. */
static int case_georef(hc_stats *st)
{
    hc_terrain_params p;
    hc_scene base;
    td_georef geos[5];
    memset(geos, 0, sizeof geos);
    geos[0].kind = TD_GEO_PROJECTED, geos[0].x0 = 500000.0, geos[0].y0 = 4e6, geos[0].dx = geos[0].dy = 10.0;
    geos[1].kind = TD_GEO_LONLAT, geos[1].x0 = 179.99, geos[1].y0 = 10.0, geos[1].dx = geos[1].dy = 1.0 / 3600;
    geos[2].kind = TD_GEO_LONLAT, geos[2].x0 = -180.0, geos[2].y0 = 89.99, geos[2].dx = geos[2].dy = 1.0 / 3600;
    geos[3].kind = TD_GEO_LONLAT, geos[3].x0 = 179.999, geos[3].y0 = -90.0, geos[3].dx = geos[3].dy = 1.0 / 3600;
    geos[4].kind = TD_GEO_PROJECTED, geos[4].x0 = -2e7, geos[4].y0 = 1e7, geos[4].dx = geos[4].dy = 10.0;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.tile_log2 = 2;
    if (hc_scene_init(&base, "procedural (no georeference)", hc_terrain_make(&p), 16) == 0) {
        uint64_t s = 5150;
        st->scenes++;
        for (int q = 0; q < 400; q++) {
            td_ray r;
            td_hit h0[TD_SURFACE_COUNT][TD_METHOD_COUNT];
            hc_ray_make(base.g, (hc_ray_kind)(q % HC_R_COUNT), &s, &r);
            hc_run_ray(st, &base, &r, h0);
            for (int k = 0; k < 5; k++) {
                td_georef keep = base.g->geo;
                base.g->geo = geos[k];
                for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                    for (int m = 0; m < TD_METHOD_COUNT; m++) {
                        td_hit h;
                        td_trace(&base.view, (td_method)m, (td_surface)sf, &r, &h);
                        hc_check(st, memcmp(&h.t, &h0[sf][m].t, sizeof h.t) == 0 && h.ci == h0[sf][m].ci &&
                                         h.cj == h0[sf][m].cj && h.steps == h0[sf][m].steps,
                                 "georeference %d changes %s/%s: t %.17g vs %.17g", k,
                                 td_surface_name((td_surface)sf), td_method_name((td_method)m), h.t,
                                 h0[sf][m].t);
                    }
                }
                base.g->geo = keep;
            }
        }
    }
    hc_scene_free(&base);

    /* lon/lat spacing on the ellipsoid, equator to the poles */
    for (int k = 0; k <= 2000; k++) {
        double lat = -90.0 + 0.09 * k, sx, sy;
        if (k == 1)
            lat = -89.9999999;
        if (k == 1999)
            lat = 89.9999999;
        td_grid_lonlat_spacing(lat, 1.0 / 3600, 1.0 / 3600, &sx, &sy);
        hc_check(st, sx > 0.0 && isfinite(sx) && sy > 0.0 && isfinite(sy),
                 "lon/lat spacing at lat %.9f: %g x %g m", lat, sx, sy);
    }

    /* sidecars with origins at the antimeridian and the poles: loaded with a positive,
     * finite spacing, or refused with a message; a loaded grid traces like any other */
    {
        char dir[] = "/tmp/terrad-hc-XXXXXX", path[600];
        static const char *const origins[] = {
            "\"origin\": {\"lon_west\": 179.99, \"lat_north\": 0.5, \"dlon_deg\": 0.0002777777777777778, \"dlat_deg\": 0.0002777777777777778}",
            "\"origin\": {\"lon_west\": -180, \"lat_north\": 90, \"dlon_deg\": 0.0002777777777777778, \"dlat_deg\": 0.0002777777777777778}",
            "\"origin\": {\"lon_west\": 179.999, \"lat_north\": -89.99, \"dlon_deg\": 0.0002777777777777778, \"dlat_deg\": 0.0002777777777777778}",
            "\"origin\": {\"lon_west\": 10, \"lat_north\": -89.995, \"dlon_deg\": 0.001, \"dlat_deg\": 0.001}",
            "\"origin\": {\"x_ul\": 500000, \"y_ul\": 4000000}, \"spacing_m\": 10",
        };
        int32_t w = 33, h = 29;
        float *z = malloc(sizeof(float) * (size_t)w * (size_t)h);
        for (int32_t k = 0; k < w * h; k++)
            z[k] = (float)(100.0 + 30.0 * sin(0.3 * (k % w)) * cos(0.2 * (k / w)));
        if (!hc_check(st, mkdtemp(dir) != NULL, "mkdtemp: %s", strerror(errno)))
            goto out;
        for (int k = 0; k < 5; k++) {
            char name[32];
            td_dem_opts o;
            td_grid *g = NULL;
            td_err err = {0};
            td_status rc;
            snprintf(name, sizeof name, "geo%d", k);
            if (!hc_check(st, write_f32(dir, name, w, h, z, origins[k], path, sizeof path), "write %s", path))
                continue;
            td_dem_opts_default(&o);
            o.tile_log2 = 2;
            rc = td_dem_load(path, &o, &g, &err);
            printf("  sidecar %s: %s", origins[k], rc == TD_OK ? "loaded" : "refused: ");
            if (rc == TD_OK)
                printf(" spacing %.9g x %.9g m, georef %.9f %.9f\n", g->sx, g->sy, g->geo.x0, g->geo.y0);
            else
                printf("%s\n", err.msg);
            hc_check(st, rc != TD_OK ? err.msg[0] != '\0' : (g->sx > 0.0 && isfinite(g->sx) && g->sy > 0.0 && isfinite(g->sy)),
                     "sidecar %d: spacing %g x %g", k, g ? g->sx : 0.0, g ? g->sy : 0.0);
            if (rc == TD_OK) {
                hc_scene sc;
                char label[64];
                uint64_t s = 6000 + (uint64_t)k;
                snprintf(label, sizeof label, "loaded %s", name);
                if (hc_scene_init(&sc, label, g, 16) == 0) {
                    st->scenes++;
                    for (int q = 0; q < 60; q++) {
                        td_ray r;
                        hc_ray_make(sc.g, (hc_ray_kind)(q % HC_R_COUNT), &s, &r);
                        hc_run_ray(st, &sc, &r, NULL);
                    }
                }
                hc_scene_free(&sc);
            }
            unlink(path);
            snprintf(path, sizeof path, "%s/%s.json", dir, name);
            unlink(path);
        }
        rmdir(dir);
    out:
        free(z);
    }
    return 0;
}

/* ---- terrains --------------------------------------------------------------------------- */
static int case_flat(hc_stats *st)
{
    static const double zs[] = {0.0, 100.0, -50.5, 1e4};
    static const int ks[] = {1, 2, 16, 255};
    for (int t = 0; t < 4; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, HC_T_FLAT);
        p.base = zs[t];
        p.tile_log2 = 2 + (t & 1);
        run_terrain(st, &p, ks[t], ALL_KINDS, 40, "flat");
    }
    return 0;
}

static int case_single_cell(hc_stats *st)
{
    static const float cells[][4] = {
        {5, 5, 5, 5}, {0, 10, 0, 10}, {0, 0, 0, 50}, {10, 40, 35, 5}, {100, -100, -100, 100}, {1, NAN, 2, 3},
    };
    for (int t = 0; t < 6; t++) {
        hc_scene sc;
        char label[96];
        uint64_t s = 111 + (uint64_t)t;
        snprintf(label, sizeof label, "single cell %g %g %g %g", cells[t][0], cells[t][1], cells[t][2], cells[t][3]);
        if (scene_from(st, &sc, label, 2, 2, t == 3 ? 3.0 : 10.0, t == 3 ? 7.0 : 10.0, 1, cells[t], t == 2 ? 1 : 16) == 0) {
            for (int kind = 0; kind < HC_R_COUNT; kind++) {
                for (int q = 0; q < 40; q++) {
                    td_ray r;
                    hc_ray_make(sc.g, (hc_ray_kind)kind, &s, &r);
                    hc_run_ray(st, &sc, &r, NULL);
                }
            }
        }
        hc_scene_free(&sc);
    }
    return 0;
}

static int case_strips(hc_stats *st)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_STEPS};
    for (int t = 0; t < 4; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, kinds[t & 1]);
        p.w = t < 2 ? 2 : 57;
        p.h = t < 2 ? 57 : 2;
        p.tile_log2 = 2;
        p.seed = 140 + t;
        run_terrain(st, &p, 16, ALL_KINDS, 40, "strip");
    }
    return 0;
}

/* One sample 1000 m above flat ground; rays aimed at its tip and grazing it. */
static int case_needle(hc_stats *st)
{
    hc_terrain_params p;
    hc_scene sc;
    hc_terrain_defaults(&p, HC_T_NEEDLE);
    p.relief = 1000.0;
    p.tile_log2 = 3;
    run_terrain(st, &p, 16, ALL_KINDS, 40, "needle");
    if (hc_scene_init(&sc, "needle tip", hc_terrain_make(&p), 16) == 0) {
        const td_grid *g = sc.g;
        double tip[3] = {(g->w / 2) * g->sx, (g->h / 2) * g->sy, td_grid_at(g, g->w / 2, g->h / 2)};
        uint64_t s = 151;
        st->scenes++;
        for (int q = 0; q < 400; q++) {
            double hd = hc_rng_range(&s, 0.0, 2.0 * M_PI), pitch = hc_rng_range(&s, -1.4, 0.3);
            double off = (q % 5 - 2) * pow(10.0, -hc_rng_range(&s, 1.0, 9.0));
            double d[3] = {cos(hd) * cos(pitch), sin(hd) * cos(pitch), sin(pitch)};
            double L = hc_rng_range(&s, 1.0, 500.0);
            td_ray r;
            if (q % 4 == 0)
                d[0] = d[0] < 0 ? -1.0 : 1.0, d[1] = 0.0, d[2] = 0.0; /* horizontal at the tip */
            hc_ray_set(&r, tip[0] - L * d[0], tip[1] - L * d[1], tip[2] + off - L * d[2], d[0], d[1], d[2]);
            hc_run_ray(st, &sc, &r, NULL);
        }
    }
    hc_scene_free(&sc);
    return 0;
}

/* 1e4 m between neighbouring samples; plus horizontal rays at the wall's top. */
static int case_wall(hc_stats *st)
{
    hc_terrain_params p;
    hc_terrain_defaults(&p, HC_T_WALL);
    p.relief = 1e4;
    p.tile_log2 = 2;
    run_terrain(st, &p, 16, ALL_KINDS, 40, "wall");
    p.sx = 1.0, p.sy = 2.0, p.base = -5000.0;
    run_terrain(st, &p, 255, ALL_KINDS, 30, "wall");
    return 0;
}

static int case_plateau(hc_stats *st)
{
    hc_terrain_params p;
    hc_terrain_defaults(&p, HC_T_PLATEAU);
    p.tile_log2 = 2;
    run_terrain(st, &p, 16, ALL_KINDS, 40, "plateau");
    p.plateau = 120.0;
    p.tile_log2 = 4;
    run_terrain(st, &p, 3, ALL_KINDS, 30, "plateau");
    return 0;
}

/* Terraces exactly on the parameter planes' slice heights z_k = zlo + k (zhi-zlo)/(K-1):
 * one tile (so the tile's range is the grid's) and small tiles. */
static int case_terraces(hc_stats *st)
{
    static const int ks[] = {16, 4, 255, 2};
    static const double relief[] = {150.0, 30.0, 127.5, 10.0};
    for (int t = 0; t < 4; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, HC_T_TERRACES);
        p.k = ks[t];
        p.relief = relief[t];
        p.base = 0.0;
        p.tile_log2 = t < 2 ? 6 : 2;
        p.seed = 170 + t;
        run_terrain(st, &p, ks[t], ALL_KINDS, 40, "terraces");
    }
    return 0;
}

static int case_spacing_small(hc_stats *st)
{
    hc_terrain_params p;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.sx = p.sy = 0.01;
    p.base = 3.0;
    p.relief = 0.5;
    p.tile_log2 = 2;
    run_terrain(st, &p, 16, ALL_KINDS, 40, "0.01m");
    p.kind = HC_T_SADDLES;
    p.sy = 0.03;
    run_terrain(st, &p, 16, ALL_KINDS, 30, "0.01m");
    return 0;
}

static int case_spacing_large(hc_stats *st)
{
    hc_terrain_params p;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.sx = p.sy = 1e4;
    p.base = -200.0;
    p.relief = 6000.0;
    p.tile_log2 = 2;
    run_terrain(st, &p, 16, ALL_KINDS, 40, "10km");
    p.kind = HC_T_RIDGE;
    p.sx = 1e4, p.sy = 2.5e3;
    run_terrain(st, &p, 16, ALL_KINDS, 30, "10km");
    return 0;
}

static int case_heights_extreme(hc_stats *st)
{
    static const double base[] = {9990.0, -10000.0, -10000.0};
    static const double relief[] = {10.0, 10.0, 20000.0};
    for (int t = 0; t < 3; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, t == 1 ? HC_T_SADDLES : HC_T_PROCEDURAL);
        p.base = base[t];
        p.relief = relief[t];
        p.tile_log2 = 2;
        run_terrain(st, &p, 16, ALL_KINDS, 35, "heights");
    }
    return 0;
}

static int case_voids(hc_stats *st, hc_voids v)
{
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_STEPS};
    for (int t = 0; t < 2; t++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, kinds[t]);
        p.voids = v;
        p.tile_log2 = 2 + t;
        p.seed = 200 + t;
        run_terrain(st, &p, 16, ALL_KINDS, 35, "voids");
    }
    return 0;
}

static int case_voids_single(hc_stats *st) { return case_voids(st, HC_V_SINGLE); }
static int case_voids_rows(hc_stats *st) { return case_voids(st, HC_V_ROWS); }
static int case_voids_tiles(hc_stats *st) { return case_voids(st, HC_V_TILES); }
static int case_voids_seams(hc_stats *st) { return case_voids(st, HC_V_SEAMS); }

/* Every sample void: every ray misses (the reference agrees), nothing is NaN. */
static int case_voids_all(hc_stats *st)
{
    hc_terrain_params p;
    hc_scene sc;
    uint64_t s = 222;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.voids = HC_V_ALL;
    p.tile_log2 = 2;
    if (hc_scene_init(&sc, "all void", hc_terrain_make(&p), 16) == 0) {
        st->scenes++;
        hc_check(st, isnan(sc.g->zmin) && isnan(sc.g->zmax), "all-void grid: zmin/zmax %g %g", sc.g->zmin,
                 sc.g->zmax);
        for (int kind = 0; kind < HC_R_COUNT; kind++) {
            for (int q = 0; q < 40; q++) {
                td_ray r;
                td_hit hits[TD_SURFACE_COUNT][TD_METHOD_COUNT];
                hc_ray_make(sc.g, (hc_ray_kind)kind, &s, &r);
                hc_run_ray(st, &sc, &r, hits);
                for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
                    for (int m = 0; m < TD_METHOD_COUNT; m++)
                        hc_check(st, hits[sf][m].t == INFINITY, "all void: %s/%s hit at %g",
                                 td_surface_name((td_surface)sf), td_method_name((td_method)m), hits[sf][m].t);
            }
        }
    } else {
        hc_check(st, 0, "all-void scene could not be built");
    }
    hc_scene_free(&sc);
    return 0;
}

/* Parameter planes with K = 1, 2, 3 and 255 slices (the most). */
static int case_planes_k(hc_stats *st)
{
    static const int ks[] = {1, 2, 3, 255};
    hc_terrain kinds[] = {HC_T_PROCEDURAL, HC_T_RIDGE, HC_T_NEEDLE, HC_T_TERRACES};
    for (int t = 0; t < 4; t++) {
        for (int k = 0; k < 4; k++) {
            hc_terrain_params p;
            hc_terrain_defaults(&p, kinds[t]);
            p.tile_log2 = 3;
            p.k = ks[k];
            p.base = 0.0;
            p.relief = 127.5;
            p.seed = 300 + t;
            run_terrain(st, &p, ks[k], KIND(HC_R_OBLIQUE) | KIND(HC_R_GRAZING) | KIND(HC_R_HORIZONTAL) |
                                          KIND(HC_R_OUTSIDE) | KIND(HC_R_SAMPLE),
                        25, "planes");
        }
    }
    return 0;
}

/* ---- directions -------------------------------------------------------------------------- */

/* A ray from 20 m above the grid's top along d, which reaches the ground inside the
 * grid: refused by td_ray_validate (with a message), or it hits on every surface. */
static void aim_down(hc_stats *st, const hc_scene *sc, const double d[3])
{
    const td_grid *g = sc->g;
    td_ray r;
    td_hit hits[TD_SURFACE_COUNT][TD_METHOD_COUNT];
    td_err err = {0};
    hc_ray_set(&r, 0.4 * (g->w - 1) * g->sx, 0.55 * (g->h - 1) * g->sy, g->zmax + 20.0, d[0], d[1], d[2]);
    if (td_ray_validate(&r, &err) != TD_OK) {
        hc_check(st, err.msg[0] != '\0', "direction (%a, %a, %a) refused without a message", d[0], d[1], d[2]);
        printf("  direction (%a, %a, %a) refused: %s\n", d[0], d[1], d[2], err.msg);
        return;
    }
    hc_run_ray(st, sc, &r, hits);
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
        for (int m = 0; m < TD_METHOD_COUNT; m++)
            hc_check(st, hits[sf][m].t < INFINITY,
                     "direction (%a, %a, %a) straight at the ground: %s/%s reports a miss (t %g)", r.d[0],
                     r.d[1], r.d[2], td_surface_name((td_surface)sf), td_method_name((td_method)m),
                     hits[sf][m].t);
}

/* Unnormalised, huge, tiny and denormal direction components: the same ray scaled by
 * any factor has the same hit point. */
static int case_directions(hc_stats *st)
{
    static const double lam[] = {0x1p-900, 1e-250, 1e-7, 0.3, 3.7, 1e7, 1e250, 0x1p+900};
    hc_terrain_params p;
    hc_scene sc;
    uint64_t s = 4040;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.tile_log2 = 2;
    run_terrain(st, &p, 16, KIND(HC_R_SCALED), 400, "scaled");
    if (hc_scene_init(&sc, "procedural (scaling)", hc_terrain_make(&p), 16) == 0) {
        st->scenes++;
        for (int q = 0; q < 200; q++) {
            td_ray r, rs;
            td_hit h0[TD_SURFACE_COUNT][TD_METHOD_COUNT], h1[TD_SURFACE_COUNT][TD_METHOD_COUNT];
            hc_ray_make(sc.g, (hc_ray_kind)(q % HC_R_SCALED), &s, &r);
            hc_run_ray(st, &sc, &r, h0);
            rs = r;
            double l = lam[q % 8];
            for (int c = 0; c < 3; c++)
                rs.d[c] *= l;
            hc_run_ray(st, &sc, &rs, h1);
            for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                for (int m = 0; m < TD_METHOD_COUNT; m++) {
                    const td_hit *a = &h0[sf][m], *b = &h1[sf][m];
                    int same = (a->t == INFINITY) == (b->t == INFINITY);
                    for (int c = 0; c < 3 && same && a->t < INFINITY; c++)
                        same = fabs(a->p[c] - b->p[c]) <= td_ref_tol(a->p);
                    hc_check(st, same, "direction scaled by %g moves the %s/%s hit: t %.17g -> %.17g (x %.17g -> %.17g)",
                             l, td_surface_name((td_surface)sf), td_method_name((td_method)m), a->t,
                             b->t, a->p[0], b->p[0]);
                }
            }
        }
        /* subnormal components beside normal ones */
        {
            static const double den[][3] = {
                {0x1p-1074, 0.0, -1.0}, {0.0, -0x1p-1074, -1.0}, {1.0, 0x1p-1074, -0.25},
                {1e-310, 1.0, -0.5},    {-3e-320, -3e-320, -1.0}, {0x1p-1000, 0.0, -0x1p-1001},
                {0.0, 0.0, -0x1p-1000}, {0x1p-960, -0x1p-1074, -0x1p-959},
            };
            for (int q = 0; q < 8; q++)
                aim_down(st, &sc, den[q]);
        }
    }
    hc_scene_free(&sc);
    return 0;
}

/* Directions with every component subnormal, or so small (about DBL_MIN) that the hit's
 * t = distance/|d| would exceed DBL_MAX: td_ray_validate refuses them (no component
 * reaches 2^-900), so they are never answered with a miss (tracer-bugs.md 3, fixed). */
static int case_directions_tiny(hc_stats *st)
{
    static const double den[][3] = {
        {0x1p-1074, 0x1p-1074, -0x1p-1074}, {1e-310, -2e-310, -1e-310},
        {0.0, 0.0, -0x1p-1074},             {0x1p-1060, 0.0, -0x1p-1062},
        {0x1p-1022, 0x1p-1022, -0x1p-1021},
    };
    hc_terrain_params p;
    hc_scene sc;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.tile_log2 = 2;
    if (hc_scene_init(&sc, "procedural (tiny directions)", hc_terrain_make(&p), 16) == 0) {
        st->scenes++;
        for (int q = 0; q < 5; q++)
            aim_down(st, &sc, den[q]);
    }
    hc_scene_free(&sc);
    return 0;
}

/* NaN or inf anywhere in a ray is refused before tracing, with the component named. */
static int case_validate(hc_stats *st)
{
    static const char *const comp[] = {"ox", "oy", "oz", "dx", "dy", "dz"};
    const double bad[] = {NAN, -NAN, INFINITY, -INFINITY};
    td_ray ok;
    td_err err;
    hc_ray_set(&ok, 1.0, 2.0, 3.0, 0.5, -0.25, -1.0);
    hc_check(st, td_ray_validate(&ok, &err) == TD_OK, "a plain ray is refused: %s", err.msg);
    for (int c = 0; c < 6; c++) {
        for (int b = 0; b < 4; b++) {
            td_ray r = ok;
            td_status rc;
            if (c < 3)
                r.o[c] = bad[b];
            else
                r.d[c - 3] = bad[b];
            err.msg[0] = '\0';
            rc = td_ray_validate(&r, &err);
            hc_check(st, rc != TD_OK && strstr(err.msg, comp[c]) != NULL,
                     "ray with %s = %g: status %d, message '%s'", comp[c], bad[b], (int)rc, err.msg);
        }
    }
    {
        const double tb[][2] = {{NAN, INFINITY}, {0.0, NAN}, {-1.0, 1.0}, {INFINITY, INFINITY},
                                {2.0, 1.0}, {-INFINITY, 0.0}};
        for (int k = 0; k < 6; k++) {
            td_ray r = ok;
            r.tmin = tb[k][0], r.tmax = tb[k][1];
            hc_check(st, td_ray_validate(&r, &err) != TD_OK, "interval [%g, %g] accepted", r.tmin, r.tmax);
        }
    }
    {
        td_ray r = ok;
        r.d[0] = r.d[1] = r.d[2] = 0.0;
        hc_check(st, td_ray_validate(&r, &err) != TD_OK, "zero direction accepted");
        r.d[0] = -0.0, r.d[1] = 0.0, r.d[2] = -0.0;
        hc_check(st, td_ray_validate(&r, &err) != TD_OK, "negative zero direction accepted");
        r.d[0] = 0x1p-1074; /* all components below 2^-900: t would overflow */
        hc_check(st, td_ray_validate(&r, &err) != TD_OK, "denormal-only direction accepted");
        r.d[0] = 0x1p-900, r.d[1] = 0x1p-1074;
        hc_check(st, td_ray_validate(&r, &err) == TD_OK, "direction of 2^-900 refused: %s", err.msg);
        r.d[0] = DBL_MAX, r.d[1] = -DBL_MAX, r.d[2] = DBL_MAX;
        hc_check(st, td_ray_validate(&r, &err) == TD_OK, "huge direction refused: %s", err.msg);
        r.o[0] = -DBL_MAX, r.o[1] = DBL_MAX;
        hc_check(st, td_ray_validate(&r, &err) == TD_OK, "huge origin refused: %s", err.msg);
    }
    /* the largest finite values trace without NaN (the rules) */
    {
        hc_terrain_params p;
        hc_scene sc;
        hc_terrain_defaults(&p, HC_T_PROCEDURAL);
        if (hc_scene_init(&sc, "procedural (extreme values)", hc_terrain_make(&p), 16) == 0) {
            const double big[] = {DBL_MAX, -DBL_MAX, 1e300, -1e300, 0x1p-1074, 0.0};
            st->scenes++;
            for (int a = 0; a < 6; a++) {
                for (int b = 0; b < 6; b++) {
                    td_ray r;
                    hc_ray_set(&r, big[a], 150.0, 300.0, 1.0, big[b] == 0.0 ? 0.5 : big[b], -0.5);
                    if (td_ray_validate(&r, &err) == TD_OK)
                        hc_run_ray(st, &sc, &r, NULL);
                    hc_ray_set(&r, 200.0, 150.0, big[a], big[b] == 0.0 ? 1.0 : big[b], 0.25, -1.0);
                    if (td_ray_validate(&r, &err) == TD_OK)
                        hc_run_ray(st, &sc, &r, NULL);
                }
            }
        }
        hc_scene_free(&sc);
    }
    return 0;
}

/* ---- cameras ---------------------------------------------------------------------------- */

typedef struct hc_cam {
    double fov, pitch, roll;
    int32_t w, h;
    int expect_refusal;
    int below; /* the camera a quarter of the relief above the lowest sample */
} hc_cam;

/* One render of the camera with method m and surface sf: no NaN, negative or -inf depth;
 * and the camera rays started from their horizons (horizon.h, the default) give the depths
 * of the rays traced from their starts, bit for bit, every pixel. */
static void camera_render(hc_stats *st, const hc_scene *sc, const hc_cam *c, td_scene *scene,
                          td_method m, td_surface sf)
{
    td_render_opts ro;
    td_render_result res, plain;
    td_err err = {0};
    int64_t npx = (int64_t)c->w * c->h, bad = 0, differ = 0;
    td_render_opts_default(&ro);
    ro.threads = 1;
    scene->quality.method = m;
    scene->quality.surface = sf;
    scene->image.format = (m == 0 && sf == 3) ? TD_FORMAT_PNG : TD_FORMAT_DEPTH32F;
    memset(&res, 0, sizeof res);
    memset(&plain, 0, sizeof plain);
    if (!hc_check(st, td_render(&sc->view, scene, &ro, &res, &err) == TD_OK,
                  "camera fov %g: render %s/%s failed: %s", c->fov, td_method_name(m),
                  td_surface_name(sf), err.msg))
        return;
    for (int64_t q = 0; res.depth && q < npx; q++)
        bad += !(res.depth[q] == INFINITY || (isfinite(res.depth[q]) && res.depth[q] >= 0.0f));
    hc_check(st, bad == 0 && (res.depth || res.rgba), "camera fov %g: %s/%s render has %lld NaN/negative/-inf depths",
             c->fov, td_method_name(m), td_surface_name(sf), (long long)bad);
    ro.off = TD_RENDER_OFF_CAMERA;
    if (res.depth && hc_check(st, td_render(&sc->view, scene, &ro, &plain, &err) == TD_OK,
                              "camera fov %g: plain render %s/%s failed: %s", c->fov, td_method_name(m),
                              td_surface_name(sf), err.msg)) {
        for (int64_t q = 0; q < npx; q++)
            differ += memcmp(&res.depth[q], &plain.depth[q], sizeof(float)) != 0;
        hc_check(st, differ == 0,
                 "camera fov %g pitch %g roll %g: %s/%s: %lld pixels differ between the horizon-started "
                 "and the plain camera rays (%llu of %llu rays started from a horizon)",
                 c->fov, c->pitch, c->roll, td_method_name(m), td_surface_name(sf), (long long)differ,
                 (unsigned long long)res.stats.coherent_rays, (unsigned long long)res.stats.rays[TD_RAY_PRIMARY]);
    }
    td_render_result_free(&plain);
    td_render_result_free(&res);
}

/* One camera over the scene: setup refuses (with a message) or every ray of the image
 * (a subsample of large ones) is valid, unit length and judged like any other ray; its
 * renders (depth for every method and surface, colour once) hold no NaN, and a depth is
 * +inf for nothing or finite and >= 0. */
static void camera_one(hc_stats *st, const hc_scene *sc, const hc_cam *c, td_projection proj, double fov_v)
{
    td_scene scene;
    td_camera cam;
    td_err err = {0};
    td_status rc;
    int64_t npx = (int64_t)c->w * c->h, stride = npx > 512 ? npx / 512 : 1;
    td_scene_defaults(&scene);
    snprintf(scene.dataset, sizeof scene.dataset, "hardcases");
    scene.camera.x = 0.3 * (sc->g->w - 1) * sc->g->sx;
    scene.camera.y = 0.2 * (sc->g->h - 1) * sc->g->sy;
    scene.camera.z = c->below ? sc->g->zmin + 0.25 * (sc->g->zmax - sc->g->zmin) : sc->g->zmax + 80.0;
    scene.camera.heading = 35.0;
    scene.camera.pitch = c->pitch;
    scene.camera.roll = c->roll;
    scene.camera.fov = c->fov;
    scene.camera.projection = proj;
    scene.camera.fov_v = fov_v;
    scene.image.width = c->w;
    scene.image.height = c->h;
    rc = td_camera_setup(&scene.camera, c->w, c->h, sc->g, &cam, &err);
    printf("  camera fov %g pitch %g roll %g %dx%d: %s%s\n", c->fov, c->pitch, c->roll, (int)c->w, (int)c->h,
           rc == TD_OK ? "accepted" : "refused: ", rc == TD_OK ? "" : err.msg);
    if (c->expect_refusal) {
        hc_check(st, rc != TD_OK && err.msg[0], "camera fov %g %dx%d should be refused", c->fov, (int)c->w, (int)c->h);
        return;
    }
    if (rc != TD_OK) {
        hc_check(st, err.msg[0] != '\0', "camera fov %g refused without a message", c->fov);
        return;
    }
    for (int64_t q = 0; q < npx; q += stride) {
        td_ray r;
        td_err rerr = {0};
        double px = (double)(q % c->w), py = (double)(q / c->w), n;
        td_camera_ray(&cam, px, py, &r);
        n = sqrt(r.d[0] * r.d[0] + r.d[1] * r.d[1] + r.d[2] * r.d[2]);
        if (!hc_check(st, td_ray_validate(&r, &rerr) == TD_OK && fabs(n - 1.0) < 1e-9,
                      "camera fov %g pitch %g roll %g pixel (%g,%g): ray invalid (%s) or |d| = %.17g", c->fov,
                      c->pitch, c->roll, px, py, rerr.msg, n))
            continue;
        hc_run_ray(st, sc, &r, NULL);
    }
    for (int m = 0; m < TD_METHOD_COUNT; m++)
        for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
            camera_render(st, sc, c, &scene, (td_method)m, (td_surface)sf);
}

/* The cameras over a procedural 65 x 65 scene; a panorama's (proj cylindrical) each with
 * its fov_v (0: from the aspect). */
static void camera_set_proj(hc_stats *st, const hc_cam *cams, size_t n, td_projection proj, const double *fov_v)
{
    hc_terrain_params p;
    hc_scene sc;
    hc_terrain_defaults(&p, HC_T_PROCEDURAL);
    p.w = 65, p.h = 65;
    p.tile_log2 = 3;
    if (hc_scene_init(&sc, "procedural 65x65 (cameras)", hc_terrain_make(&p), 16) == 0) {
        st->scenes++;
        for (size_t k = 0; k < n; k++)
            camera_one(st, &sc, &cams[k], proj, fov_v ? fov_v[k] : 0.0);
    } else {
        hc_check(st, 0, "camera scene could not be built");
    }
    hc_scene_free(&sc);
}

static void camera_set(hc_stats *st, const hc_cam *cams, size_t n)
{
    camera_set_proj(st, cams, n, TD_PROJ_PERSPECTIVE, NULL);
}

/* fov near 0 and 180, pitch +-90, roll +-180, 1x1, 1x4096 and 4096x1 images. */
static int case_camera(hc_stats *st)
{
    static const hc_cam cams[] = {
        {60, -30, 0, 1, 1, 0, 0},          {60, -30, 0, 1, 4096, 0, 0},        {60, -30, 0, 4096, 1, 0, 0},
        {1e-6, -20, 0, 64, 48, 0, 0},      {1e-3, -20, 0, 1, 4096, 0, 0},      {179.999999, -10, 0, 64, 48, 0, 0},
        {179.9, -10, 0, 4096, 1, 0, 0},    {90, -90, 0, 64, 48, 0, 0},         {90, 90, 0, 64, 48, 0, 0},
        {60, -90, 180, 32, 32, 0, 0},      {60, 90, -180, 32, 32, 0, 0},       {60, -5, 180, 64, 48, 0, 0},
        {60, -5, -180, 1, 4096, 0, 0},     {0.0, -20, 0, 8, 8, 1, 0},          {180.0, -20, 0, 8, 8, 1, 0},
        {-5.0, -20, 0, 8, 8, 1, 0},        {NAN, -20, 0, 8, 8, 1, 0},          {60, -20, 0, 0, 8, 1, 0},
        {60, 1e6, -1e6, 16, 16, 0, 0},     {1e-20, -20, 0, 16, 16, 0, 0},
    };
    camera_set(st, cams, sizeof cams / sizeof cams[0]);
    return 0;
}

/* The cameras of the coherence devices (issue 12): level, straight down, the vanishing
 * point of verticals inside the image (looking steeply down: every azimuth), roll 90,
 * rolled 20-135 degrees, fov 170, and a camera below the terrain's crests (looking up at
 * slopes, level and down). Each renders the same depths from horizons as from the rays'
 * starts. */
static int case_camera_coherence(hc_stats *st)
{
    static const hc_cam cams[] = {
        {60, 0, 0, 64, 48, 0, 0},    {60, -90, 0, 48, 48, 0, 0},  {90, -60, 0, 64, 64, 0, 0},
        {60, -20, 90, 64, 48, 0, 0}, {60, -20, -90, 48, 64, 0, 0}, {170, -10, 0, 96, 48, 0, 0},
        {170, -89, 30, 64, 64, 0, 0}, {70, 15, 0, 64, 48, 0, 1},   {70, 0, 0, 64, 48, 0, 1},
        {70, -30, 45, 64, 48, 0, 1},  {5, -2, 0, 64, 48, 0, 0},   {120, 60, 0, 64, 48, 0, 0},
        /* upright cameras over several of render.c's tall blocks (64 and 32 rows) */
        {70, -3, 0, 40, 150, 0, 0},   {60, -6.5, 0, 40, 150, 0, 0},
        /* rolled cameras, their blocks cut into bands along the verticals (render.c's
           trace_band), partial blocks at the image's edges included */
        {70, -10, 35, 64, 48, 0, 0},  {70, -10, -35, 61, 45, 0, 0}, {60, -20, 135, 64, 48, 0, 0},
        {70, -5, 20, 45, 61, 0, 1},
    };
    camera_set(st, cams, sizeof cams / sizeof cams[0]);
    return 0;
}

/* The cylindrical camera (issue 19): 360 degrees on 1x1, 4096x1 and 1x4096 images, pitch
 * +-90 without fov_v (the centre row's tangent 1.6e16: every ray near vertical), fov_v
 * near 0 and at its limit, a fov of 1e-6; refused: fov 0, 361, NaN, fov_v past the
 * zenith, any roll, a NaN pitch. Every accepted one's
 * rays are unit and judged, and it renders the same depths with the devices off (they do
 * not run for it: the plain walk). */
static int case_camera_panorama(hc_stats *st)
{
    static const hc_cam cams[] = {
        {360, 0, 0, 1, 1, 0, 0},     {360, 0, 0, 4096, 1, 0, 0},   {360, -30, 0, 1, 4096, 0, 0},
        {360, -90, 0, 64, 48, 0, 0}, {360, 90, 0, 64, 48, 0, 0},   {360, 5, 0, 96, 32, 0, 1},
        {90, -10, 0, 64, 48, 0, 0},  {1e-6, -20, 0, 16, 16, 0, 0}, {360, 0, 0, 64, 48, 0, 0},
        {360, 10, 0, 64, 48, 0, 0},  {0.0, 0, 0, 8, 8, 1, 0},      {361, 0, 0, 8, 8, 1, 0},
        {NAN, 0, 0, 8, 8, 1, 0},     {360, 10, 0, 8, 8, 1, 0},     {360, 0, 3, 8, 8, 1, 0},
        {360, NAN, 0, 8, 8, 1, 0},
    };
    static const double fov_v[] = {0, 0, 0, 0, 0, 0, 30, 0, 1e-6, 157.9, 0, 0, 0, 160, 0, 0};
    camera_set_proj(st, cams, sizeof cams / sizeof cams[0], TD_PROJ_CYLINDRICAL, fov_v);
    return 0;
}

/* A fov below ~1e-150 degrees once made focal_px overflow when squared, and every ray a
 * zero direction (tracer-bugs.md 4, fixed in td_camera_ray: fwd + (right*a - up*b)/f).
 * Such a camera's rays must be valid. */
static int case_camera_tiny_fov(hc_stats *st)
{
    static const hc_cam cams[] = {{1e-300, -20, 0, 8, 8, 0, 0}, {1e-160, -20, 0, 1, 1, 0, 0}};
    camera_set(st, cams, sizeof cams / sizeof cams[0]);
    return 0;
}

/* ---- property ----------------------------------------------------------------------------- */

/* Random scenes mixing every terrain, void pattern, spacing, height range, tile size and
 * K with every ray kind. Prints its seed; TERRAD_SEED replays it. */
static int case_property(hc_stats *st)
{
    static const int ks[] = {1, 2, 3, 7, 16, 255};
    uint64_t seed = 20240917, s;
    const char *env = getenv("TERRAD_SEED");
    uint64_t before;
    if (env && *env)
        seed = strtoull(env, NULL, 0);
    printf("property: seed %llu (TERRAD_SEED=%llu replays it)\n", (unsigned long long)seed,
           (unsigned long long)seed);
    s = seed;
    before = 0;
    for (int n = 0; n < 24; n++) {
        hc_terrain_params p;
        hc_terrain_defaults(&p, (hc_terrain)hc_rng_int(&s, HC_T_COUNT));
        p.w = 2 + hc_rng_int(&s, 44);
        p.h = 2 + hc_rng_int(&s, 44);
        p.sx = pow(10.0, hc_rng_range(&s, -2.0, 4.0));
        p.sy = hc_rng_u(&s) < 0.5 ? p.sx : p.sx * pow(10.0, hc_rng_range(&s, -0.7, 0.7));
        p.tile_log2 = 1 + hc_rng_int(&s, 4);
        p.base = hc_rng_range(&s, -1e4, 1e4);
        p.relief = hc_rng_u(&s) < 0.1 ? 0.0 : pow(10.0, hc_rng_range(&s, -2.0, 4.0));
        if (p.base + p.relief > 1.2e4)
            p.base = 1.2e4 - p.relief;
        p.plateau = p.base + 0.6 * p.relief;
        p.k = ks[hc_rng_int(&s, 6)];
        p.voids = hc_rng_u(&s) < 0.3 ? (hc_voids)hc_rng_int(&s, HC_V_COUNT) : HC_V_NONE;
        p.seed = hc_rng_next(&s) % 100000;
        {
            uint64_t fails_before = 0;
            for (int a = 0; a < TD_SURFACE_COUNT; a++)
                for (int b = 0; b < TD_METHOD_COUNT; b++)
                    fails_before += st->c[a][b].v[HC_WRONG] + st->c[a][b].rule;
            run_terrain(st, &p, p.k, ALL_KINDS, 10, "property");
            uint64_t fails_after = 0;
            for (int a = 0; a < TD_SURFACE_COUNT; a++)
                for (int b = 0; b < TD_METHOD_COUNT; b++)
                    fails_after += st->c[a][b].v[HC_WRONG] + st->c[a][b].rule;
            if (fails_after != fails_before)
                printf("property: scene %d failed; replay with TERRAD_SEED=%llu\n", n, (unsigned long long)seed);
            before += fails_after - fails_before;
        }
    }
    if (before)
        printf("property: FAILED with seed %llu (TERRAD_SEED=%llu)\n", (unsigned long long)seed,
               (unsigned long long)seed);
    return 0;
}

/* ---- the table of cases -------------------------------------------------------------------- */
#define CASE_LIST(X)                                                                       \
    X(grazing_ridge, "rays at 1e-3 .. 1e-9 rad over sharp crests, above/on/below them")    \
    X(grazing_flat, "rays at 1e-3 .. 1e-9 rad onto flat and tilted ground, leaving it")     \
    X(bilinear_tangent, "rays tangent to bilinear patches (double roots), shifted by +-delta") \
    X(grid_lines, "rays exactly along x = i*sx and y = j*sy")                             \
    X(diagonals, "rays along either cell diagonal")                                        \
    X(sample_points, "rays aimed exactly at sample points")                               \
    X(tile_seams, "rays along tile seams and through tile corners (tiles of 2, 4, 8 cells)") \
    X(axis_aligned, "dx = 0, dy = 0, straight down and straight up")                       \
    X(horizontal_sample_height, "dz = 0 at exactly a sample's height")                    \
    X(horizontal_plateau, "dz = 0 at exactly a plateau's height, zmin and zmax")          \
    X(origins_outside, "origins outside the box, on its faces, 1e7 m away")               \
    X(origin_on_surface, "origins exactly on a sample: hit at tmin")                      \
    X(origin_below, "origins below the surface: plane at tmin, others the first crossing") \
    X(georef, "projected and lon/lat origins (antimeridian, poles) change no hit")         \
    X(flat, "perfectly flat terrain (zmin == zmax), K = 1, 2, 16, 255")                   \
    X(single_cell, "2 x 2 samples: flat, tilted, twisted, one void corner")                \
    X(strips, "2 x N and N x 2 grids")                                                     \
    X(needle, "one sample 1000 m above flat ground")                                       \
    X(wall, "a 1e4 m jump between neighbouring samples")                                   \
    X(plateau, "plateaus (flat tops over many cells)")                                     \
    X(terraces, "terraces on the parameter planes' slice heights")                         \
    X(spacing_small, "0.01 m spacing")                                                     \
    X(spacing_large, "10 km spacing")                                                      \
    X(heights_extreme, "heights near +-1e4 m")                                             \
    X(voids_single, "isolated voids")                                                      \
    X(voids_rows, "rows and columns of voids")                                             \
    X(voids_tiles, "whole tiles void")                                                     \
    X(voids_seams, "voids along tile seams")                                               \
    X(voids_all, "an entirely void grid")                                                  \
    X(planes_k, "parameter planes with K = 1, 2, 3, 255")                                  \
    X(directions, "unnormalised, huge, tiny and denormal direction components")             \
    X(directions_tiny, "|d| so small that t would overflow: refused, never a miss")       \
    X(validate, "NaN or inf anywhere in a ray is refused")                                 \
    X(camera, "fov near 0/180, pitch +-90, roll +-180, 1x1 and 1x4096 images")             \
    X(camera_tiny_fov, "fov below 1e-150 degrees: valid rays")                                \
    X(camera_coherence, "level, straight down, vanishing point inside, roll 90, fov 170, below crests: horizons change no depth") \
    X(camera_panorama, "cylindrical: 360 degrees on 1x1 and 1x4096 images, pitch +-90, fov_v near 0 and 89: valid rays, the plain walk") \
    X(property, "seeded mix of everything (TERRAD_SEED replays)")

typedef struct hc_case {
    const char *name, *what;
    int (*fn)(hc_stats *);
} hc_case;

static const hc_case cases[] = {
#define X_CASE(n, w) {#n, w, case_##n},
    CASE_LIST(X_CASE)
#undef X_CASE
};

static uint64_t run_case(const hc_case *c)
{
    hc_stats st;
    uint64_t fails;
    hc_stats_init(&st, c->name);
    printf("== %s: %s\n", c->name, c->what);
    c->fn(&st);
    fails = hc_report(&st);
    fflush(stdout);
    return fails;
}

int main(int argc, char **argv)
{
    int rc = 2;
    uint64_t fails = 0;
    size_t n = sizeof cases / sizeof cases[0];
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (argc == 2 && !strcmp(argv[1], "--list")) {
        for (size_t k = 0; k < n; k++)
            printf("%s\t%s\n", cases[k].name, cases[k].what);
        rc = 0;
    } else if (argc == 2 && !strcmp(argv[1], "all")) {
        for (size_t k = 0; k < n; k++)
            fails += run_case(&cases[k]);
        rc = fails ? 1 : 0;
    } else if (argc == 2) {
        for (size_t k = 0; k < n; k++) {
            if (!strcmp(argv[1], cases[k].name)) {
                fails = run_case(&cases[k]);
                rc = fails ? 1 : 0;
            }
        }
        if (rc == 2)
            fprintf(stderr, "hardcases: no case '%s' (--list names them)\n", argv[1]);
    } else {
        fprintf(stderr, "usage: %s CASE | all | --list\n", argv[0]);
    }
    return rc;
}
