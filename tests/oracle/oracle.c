/* oracle.c: every method and surface of td_trace held to the references.
 *
 *   oracle_trace DATASET [--rays N] [--seed S] [--threads T]
 *   oracle_trace DATASET --cameras     (rendered views: camera and shadow rays with the
 *                                       coherence devices, bit for bit and vs the references)
 *   oracle_trace DATASET --ray OX OY OZ DX DY DZ      (replay one ray; %a hex accepted)
 *
 *   oracle_trace DATASET|--dem FILE --write-rays FILE        (a ray set for terrad trace)
 *   oracle_trace --dem FILE --surface S --check RAYS HITS     (judge terrad trace output)
 *
 * DATASET is volcano, levi, picos (voids), trinidad (a crop of the fixtures' N37W105.hgt),
 * trinidad-crop, procedural, or a made-up terrain (flat, single, strip, needle, wall,
 * terraces, voids); all use 32 x 32-cell tiles so rays cross seams often. ORACLE_SHOW_TIES
 * in the environment prints the first ties too.
 * Per dataset one ray set mixes camera fans (oblique, grazing, looking up, straight
 * down), rays from outside the box, rays along grid lines and diagonals, rays through
 * sample points and horizontal rays at sample heights (see make_rays).
 *
 * triangle: each method against Embree (robust, same diagonal, voids left out); a
 *   disagreement is settled by the exact double reference (reference.c): terrad within
 *   tolerance of the exact hit = "embree wrong"; terrad inside the exact band (1e-9 of
 *   the grid's size) = "tie"; inside the float32 band (1 mm + float32 rounding of the
 *   coordinates, times 1 + the steepest slope) = "float"; else an unexplained error.
 * bilinear, linear, plane: each method against the double reference, same verdicts;
 *   bilinear also against Embree on a refined mesh (small grids), within its bound.
 * All methods against each other: differences beyond tolerance are counted (each is
 *   also judged against the reference above, so none can hide an error).
 * Exit status 1 on any unexplained disagreement; the ray is printed as hex doubles. */
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "cam_view.h"
#include "dem.h"
#include "embree_ref.h"
#include "reference.h"
#include "render.h"
#include "sunlit.h"
#include "terrain.h"
#include "trace.h"

#ifndef TERRAD_TEST_DATA
#define TERRAD_TEST_DATA "tests/data"
#endif

#define MAX_PRINT 8

enum { V_AGREE, V_EMBREE_WRONG, V_TIE, V_FLOAT, V_ERROR, V_COUNT };
static const char *const v_names[V_COUNT] = {"agree", "embree-wrong", "tie", "float", "ERROR"};

typedef struct cell_stats {
    uint64_t rays, hits, disagree, v[V_COUNT], steps, vs_incremental;
    double max_dt; /* metres, over agreeing hits */
} cell_stats;

typedef struct stats {
    cell_stats c[TD_SURFACE_COUNT][TD_METHOD_COUNT];
    uint64_t refined_rays, refined_disagree, refined_within, refined_embree_miss, refined_error;
    uint64_t printed;
} stats;

typedef struct ctx {
    const td_grid *g;
    td_view view;
    const td_embree *emb, *emb_fine;
    double eps_f, eps_x; /* float32 band and exact band, metres */
    const td_ray *rays;
    size_t n0, n1;
    stats st;
} ctx;

static pthread_mutex_t print_lock = PTHREAD_MUTEX_INITIALIZER;
static int reference_only, show_ties;

static void ctx_init(ctx *c, const td_grid *g, const td_view *view, const td_embree *emb, double eps_f,
                     double eps_x)
{
    memset(c, 0, sizeof *c);
    c->g = g;
    c->view = *view;
    c->emb = emb;
    c->eps_f = eps_f;
    c->eps_x = eps_x;
}

/* ---- random numbers (splitmix64) ---------------------------------------------------- */
static uint64_t rng_next(uint64_t *s)
{
    uint64_t x = (*s += 0x9e3779b97f4a7c15ull);
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}
static double rng_u(uint64_t *s) { return (double)(rng_next(s) >> 11) * (1.0 / 9007199254740992.0); }
static double rng_range(uint64_t *s, double a, double b) { return a + (b - a) * rng_u(s); }
static int32_t rng_int(uint64_t *s, int32_t n) { return (int32_t)(rng_next(s) % (uint64_t)n); }

/* ---- datasets ------------------------------------------------------------------------ */
static td_status crop(const td_grid *src, int32_t i0, int32_t j0, int32_t w, int32_t h,
                      td_grid **out, td_err *err)
{
    td_status rc = td_grid_create(w, h, src->sx, src->sy, src->tile_log2, NULL, out, err);
    if (rc == TD_OK) {
        for (int32_t j = 0; j < h; j++)
            memcpy((*out)->z + (size_t)j * w, src->z + (size_t)(j0 + j) * src->w + i0,
                   (size_t)w * sizeof(float));
        rc = td_grid_finish(*out, err);
    }
    return rc;
}

/* Small made-up terrains that break tracers: flat, one cell, a 2 x N strip, a needle,
 * a 1e4 m wall, terraces at round heights, and voids in rows, blocks and a whole tile. */
static td_status synthetic(const char *name, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    int32_t w = 65, h = 65;
    double sp = 10.0;
    td_grid *g = NULL;
    int kind = -1;
    const char *names[] = {"flat", "single", "strip", "needle", "wall", "terraces", "voids"};
    for (int k = 0; k < 7; k++)
        if (!strcmp(name, names[k]))
            kind = k;
    if (kind < 0) {
        rc = td_err_set(err, TD_EINVAL, "unknown dataset '%s'", name);
        goto out;
    }
    if (kind == 1)
        w = h = 2;
    if (kind == 2)
        w = 2, h = 70;
    if (kind == 5 || kind == 6) {
        td_terrain_params p;
        td_terrain_params_default(&p);
        p.width = 130;
        p.height = 100;
        p.spacing = 20.0;
        p.seed = 11;
        p.feature_m = 1500.0;
        p.relief_m = 600.0;
        rc = td_terrain_generate(&p, 5, &g, err);
        if (rc != TD_OK)
            goto out;
        for (int32_t j = 0; j < g->h; j++) {
            for (int32_t i = 0; i < g->w; i++) {
                float *z = &g->z[(size_t)j * g->w + i];
                if (kind == 5)
                    *z = 50.0f * floorf(*z / 50.0f);
                else if (j == 40 || (i >= 70 && i < 75 && j < 60) || (i < 33 && j >= 64) ||
                         ((i * 7 + j * 13) % 97 == 0))
                    *z = NAN; /* a row, a block, a whole tile (cells 0..31 x 64..95), specks */
            }
        }
    } else {
        rc = td_grid_create(w, h, sp, sp, 5, NULL, &g, err);
        if (rc != TD_OK)
            goto out;
        for (int32_t j = 0; j < h; j++) {
            for (int32_t i = 0; i < w; i++) {
                float z = 100.0f;
                if (kind == 1)
                    z = (float[]){100.0f, 105.0f, 103.0f, 110.0f}[j * 2 + i];
                else if (kind == 2)
                    z = 100.0f + 30.0f * (float)sin(0.3 * j) + 5.0f * (float)i;
                else if (kind == 3 && i == 32 && j == 32)
                    z = 2000.0f;
                else if (kind == 4)
                    z = i < 30 ? 0.0f : 10000.0f;
                g->z[(size_t)j * w + i] = z;
            }
        }
    }
    rc = td_grid_finish(g, err);
out:
    if (rc != TD_OK) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}

static td_status load_dataset(const char *name, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    td_dem_opts o;
    td_grid *full = NULL;
    td_dem_opts_default(&o);
    o.tile_log2 = 5;
    *out = NULL;
    if (!strcmp(name, "volcano")) {
        rc = td_dem_load(TERRAD_TEST_DATA "/volcano.asc", &o, out, err);
    } else if (!strcmp(name, "levi")) {
        o.encoding = TD_ENC_RGB_DIV;
        o.spacing[0] = o.spacing[1] = 20.0;
        rc = td_dem_load(TERRAD_TEST_DATA "/levi-topography.png", &o, out, err);
    } else if (!strcmp(name, "picos")) {
        rc = td_dem_load(TERRAD_TEST_DATA "/picos-dtm.asc", &o, out, err);
    } else if (!strcmp(name, "trinidad-crop")) {
        rc = td_dem_load(TERRAD_TEST_DATA "/trinidad-crop.f32", &o, out, err);
    } else if (!strcmp(name, "trinidad")) {
        /* Spanish Peaks corner of the east half: 321 x 321 samples */
        rc = td_dem_load(TERRAD_TEST_DATA "/N37W105.hgt", &o, &full, err);
        if (rc == TD_OK)
            rc = crop(full, 0, 320, 321, 321, out, err);
    } else if (!strcmp(name, "procedural")) {
        td_terrain_params p;
        td_terrain_params_default(&p);
        p.width = 300;
        p.height = 260;
        p.spacing = 25.0;
        p.seed = 7;
        p.feature_m = 3000.0;
        p.relief_m = 1200.0;
        rc = td_terrain_generate(&p, 5, out, err);
    } else {
        rc = synthetic(name, out, err);
    }
    td_grid_free(full);
    return rc;
}

/* ---- ray sets ------------------------------------------------------------------------ */
static double ground(const td_grid *g, double x, double y)
{
    double h = td_surface_height(g, TD_SURFACE_BILINEAR,
                                 (int32_t)fmin(fmax(floor(x / g->sx), 0), g->w - 2),
                                 (int32_t)fmin(fmax(floor(y / g->sy), 0), g->h - 2), x, y);
    return isnan(h) ? (double)g->zmax : h;
}

static void set_ray(td_ray *r, double ox, double oy, double oz, double dx, double dy, double dz)
{
    r->o[0] = ox, r->o[1] = oy, r->o[2] = oz;
    r->d[0] = dx, r->d[1] = dy, r->d[2] = dz;
    r->tmin = 0.0;
    r->tmax = INFINITY;
}

/* A pixel of a camera at p with heading/pitch (degrees) and horizontal fov. */
static void camera_ray(td_ray *r, const double p[3], double heading, double pitch, double fov,
                       uint64_t *s)
{
    double h = heading * M_PI / 180.0, q = pitch * M_PI / 180.0, k = tan(fov * M_PI / 360.0);
    double f[3] = {sin(h) * cos(q), cos(h) * cos(q), sin(q)};
    double rt[3] = {cos(h), -sin(h), 0.0};
    double up[3] = {-sin(q) * sin(h), -sin(q) * cos(h), cos(q)};
    double a = rng_range(s, -k, k), b = rng_range(s, -0.75 * k, 0.75 * k);
    set_ray(r, p[0], p[1], p[2], f[0] + a * rt[0] + b * up[0], f[1] + a * rt[1] + b * up[1],
            f[2] + a * rt[2] + b * up[2]);
}

#define RAY_KINDS(X)                                                           \
    X(K_OBLIQUE, "oblique fan")                                                \
    X(K_GRAZING, "grazing fan")                                                \
    X(K_UP, "looking up")                                                      \
    X(K_DOWN, "straight down")                                                 \
    X(K_OUTSIDE, "from outside the box")                                       \
    X(K_GRIDLINE, "along grid lines / diagonals")                              \
    X(K_SAMPLE, "through sample points")                                       \
    X(K_HORIZONTAL, "horizontal at sample heights")                            \
    X(K_SCALED, "far origins, huge/tiny direction lengths")

enum {
#define X_ENUM(e, n) e,
    RAY_KINDS(X_ENUM)
#undef X_ENUM
    K_COUNT
};
static const char *const kind_names[K_COUNT] = {
#define X_NAME(e, n) n,
    RAY_KINDS(X_NAME)
#undef X_NAME
};

static void random_sample(const td_grid *g, uint64_t *s, int32_t *i, int32_t *j, double *z)
{
    for (int tries = 0; tries < 64; tries++) {
        *i = rng_int(s, g->w);
        *j = rng_int(s, g->h);
        *z = td_grid_at(g, *i, *j);
        if (!isnan(*z))
            break;
    }
    if (isnan(*z))
        *z = g->zmax;
}

static void make_ray(const td_grid *g, int kind, uint64_t *s, td_ray *r)
{
    double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
    double zmin = g->zmin, zmax = g->zmax, R = fmax(zmax - zmin, 1.0);
    double p[3];
    int32_t i, j;
    double z;
    p[0] = rng_range(s, 0.0, X);
    p[1] = rng_range(s, 0.0, Y);
    switch (kind) {
    case K_OBLIQUE:
        p[2] = zmax + rng_range(s, 0.1, 1.0) * R;
        camera_ray(r, p, rng_range(s, 0, 360), rng_range(s, -40, -10), 60, s);
        break;
    case K_GRAZING:
        p[2] = ground(g, p[0], p[1]) + rng_range(s, 1.0, 40.0);
        camera_ray(r, p, rng_range(s, 0, 360), rng_range(s, -3, 1), 40, s);
        break;
    case K_UP:
        p[2] = ground(g, p[0], p[1]) + rng_range(s, 0.5, 10.0);
        camera_ray(r, p, rng_range(s, 0, 360), rng_range(s, 2, 45), 50, s);
        break;
    case K_DOWN:
        if (rng_u(s) < 0.5) { /* exactly vertical, half of them over grid lines or samples */
            if (rng_u(s) < 0.3)
                p[0] = rng_int(s, g->w) * g->sx;
            if (rng_u(s) < 0.3)
                p[1] = rng_int(s, g->h) * g->sy;
            set_ray(r, p[0], p[1], zmax + rng_range(s, 0.0, R), 0.0, 0.0, -rng_range(s, 0.1, 10));
        } else {
            p[2] = zmax + rng_range(s, 0.2, 2.0) * R;
            camera_ray(r, p, rng_range(s, 0, 360), -90, 30, s);
        }
        break;
    case K_OUTSIDE: {
        double a = rng_range(s, 0, 2 * M_PI), rad = 0.75 * fmax(X, Y) + rng_range(s, 0, X + Y);
        double o[3] = {0.5 * X + rad * cos(a), 0.5 * Y + rad * sin(a),
                       rng_range(s, zmin - R, zmax + 2 * R)};
        double t[3] = {rng_range(s, 0, X), rng_range(s, 0, Y), rng_range(s, zmin, zmax)};
        set_ray(r, o[0], o[1], o[2], t[0] - o[0], t[1] - o[1], t[2] - o[2]);
        break;
    }
    case K_GRIDLINE: {
        double dz = -rng_range(s, 0.0, 0.3) * (rng_u(s) < 0.2 ? 0.0 : 1.0);
        double sg = rng_u(s) < 0.5 ? -1.0 : 1.0, zo = zmax + rng_range(s, -0.8, 0.3) * R;
        int mode = rng_int(s, 4);
        random_sample(g, s, &i, &j, &z);
        if (rng_u(s) < 0.25)
            zo = z; /* at a sample's height */
        if (mode == 0)
            set_ray(r, i * g->sx, p[1], zo, 0.0, sg, dz);
        else if (mode == 1)
            set_ray(r, p[0], j * g->sy, zo, sg, 0.0, dz);
        else if (mode == 2) /* along the cell diagonal (i+1,j)-(i,j+1) */
            set_ray(r, i * g->sx, j * g->sy, zo, sg * g->sx, -sg * g->sy, dz * g->sx);
        else /* along the other diagonal */
            set_ray(r, i * g->sx, j * g->sy, zo, sg * g->sx, sg * g->sy, dz * g->sx);
        break;
    }
    case K_SAMPLE: {
        random_sample(g, s, &i, &j, &z);
        double t[3] = {i * g->sx, j * g->sy, z};
        double o[3] = {p[0], p[1], zmax + rng_range(s, -0.2, 1.0) * R};
        set_ray(r, o[0], o[1], o[2], t[0] - o[0], t[1] - o[1], t[2] - o[2]);
        break;
    }
    case K_SCALED: { /* an oblique ray moved back up to 1e7 m, its direction scaled */
        double sc = pow(10.0, rng_range(s, -150.0, 150.0)), back = pow(10.0, rng_range(s, 0.0, 7.0));
        p[2] = zmax + rng_range(s, 0.1, 1.0) * R;
        camera_ray(r, p, rng_range(s, 0, 360), rng_range(s, -40, -5), 60, s);
        double n = sqrt(r->d[0] * r->d[0] + r->d[1] * r->d[1] + r->d[2] * r->d[2]);
        for (int a = 0; a < 3; a++) {
            r->o[a] -= back * r->d[a] / n;
            r->d[a] *= sc;
        }
        break;
    }
    default: { /* K_HORIZONTAL: dz = 0 at exactly a sample's height, through the sample */
        random_sample(g, s, &i, &j, &z);
        double a = rng_range(s, 0, 2 * M_PI), L = rng_range(s, 0.5, 20.0) * (g->sx + g->sy);
        int axis = rng_int(s, 3);
        double dx = axis == 1 ? 0.0 : cos(a), dy = axis == 2 ? 0.0 : sin(a);
        if (axis)
            dx = axis == 1 ? 0.0 : (cos(a) < 0 ? -1.0 : 1.0), dy = axis == 2 ? 0.0 : (sin(a) < 0 ? -1.0 : 1.0);
        set_ray(r, i * g->sx - L * dx, j * g->sy - L * dy, z, dx, dy, 0.0);
        break;
    }
    }
    if (rng_u(s) < 0.05) /* some finite intervals */
        r->tmax = rng_range(s, 0.0, 2.0) * (X + Y) / sqrt(r->d[0] * r->d[0] + r->d[1] * r->d[1] + r->d[2] * r->d[2] + 1e-300);
}

/* ---- judging ------------------------------------------------------------------------- */
static void print_ray(const char *what, td_method m, td_surface sf, const td_ray *r, double got,
                      double want, const td_ref_hit *ref)
{
    pthread_mutex_lock(&print_lock);
    printf("%s %s method=%s surface=%s got t=%.17g want t=%.17g (near %.17g strict %.17g)\n"
           "  replay: --ray %a %a %a %a %a %a   (tmin %a tmax %a)\n",
           strcmp(what, v_names[V_TIE]) && strcmp(what, v_names[V_FLOAT]) ? "UNEXPLAINED" : "SHOW",
           what, td_method_name(m), td_surface_name(sf), got, want, ref ? ref->t_near : NAN,
           ref ? ref->t_strict : NAN, r->o[0], r->o[1], r->o[2], r->d[0], r->d[1], r->d[2],
           r->tmin, r->tmax);
    fflush(stdout);
    pthread_mutex_unlock(&print_lock);
}

/* Settles terrad's answer t against the double reference (computed on demand). */
static int settle(ctx *c, td_surface sf, const td_ray *r, double t, td_ref_hit *ref, int *have_ref)
{
    int v;
    if (!*have_ref) {
        td_ref_trace(c->g, sf, r, c->eps_f, ref);
        *have_ref = 1;
    }
    td_ref_verdict jv = td_ref_judge(c->g, sf, r, ref, t, c->eps_f);
    if (jv == TD_REF_AGREE) {
        v = V_AGREE;
    } else if (jv == TD_REF_TIE) {
        td_ref_hit tight;
        td_ref_trace(c->g, sf, r, c->eps_x, &tight);
        v = td_ref_judge(c->g, sf, r, &tight, t, c->eps_x) != TD_REF_WRONG ? V_TIE : V_FLOAT;
    } else {
        v = V_ERROR;
    }
    return v;
}

static int same_hit(const td_ray *r, double a, double b)
{
    int same;
    if (!(a < INFINITY) || !(b < INFINITY)) {
        same = !(a < INFINITY) && !(b < INFINITY);
    } else {
        double p[3];
        for (int k = 0; k < 3; k++)
            p[k] = r->o[k] + a * r->d[k];
        same = td_ref_dist(r, a, b) <= td_ref_tol(p);
    }
    return same;
}

static void one_ray(ctx *c, const td_ray *r)
{
    stats *st = &c->st;
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        td_ref_hit ref;
        int have_ref = 0;
        double te = INFINITY, tinc = INFINITY;
        if (sf == TD_SURFACE_TRIANGLE) {
            te = td_embree_trace(c->emb, r);
        } else {
            td_ref_trace(c->g, (td_surface)sf, r, c->eps_f, &ref);
            have_ref = 1;
        }
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            cell_stats *cs = &st->c[sf][m];
            td_hit h;
            int v;
            td_trace(&c->view, (td_method)m, (td_surface)sf, r, &h);
            cs->rays++;
            cs->steps += h.steps;
            cs->hits += h.t < INFINITY;
            if (m == 0)
                tinc = h.t;
            else if (!same_hit(r, h.t, tinc))
                cs->vs_incremental++;
            if (sf == TD_SURFACE_TRIANGLE) {
                if (same_hit(r, h.t, te)) {
                    v = V_AGREE;
                } else {
                    cs->disagree++;
                    v = settle(c, (td_surface)sf, r, h.t, &ref, &have_ref);
                    if (v == V_AGREE)
                        v = V_EMBREE_WRONG;
                }
                if (v == V_AGREE && h.t < INFINITY && te < INFINITY)
                    cs->max_dt = fmax(cs->max_dt, td_ref_dist(r, h.t, te));
            } else {
                v = settle(c, (td_surface)sf, r, h.t, &ref, &have_ref);
                if (v != V_AGREE)
                    cs->disagree++;
                if (v == V_AGREE && h.t < INFINITY && ref.t < INFINITY)
                    cs->max_dt = fmax(cs->max_dt, td_ref_dist(r, h.t, ref.t));
            }
            cs->v[v]++;
            if (show_ties && (v == V_TIE || v == V_FLOAT) && st->printed++ < MAX_PRINT)
                print_ray(v_names[v], (td_method)m, (td_surface)sf, r, h.t,
                          have_ref ? ref.t : te, have_ref ? &ref : NULL);
            if (v == V_ERROR && st->printed++ < MAX_PRINT)
                print_ray(sf == TD_SURFACE_TRIANGLE ? "vs embree" : "vs reference", (td_method)m,
                          (td_surface)sf, r, h.t, have_ref ? ref.t : te, have_ref ? &ref : NULL);
        }
        if (sf == TD_SURFACE_BILINEAR && c->emb_fine) {
            /* Embree on the refined mesh must be consistent with the reference up to the
             * refinement's bound. */
            double tf = td_embree_trace(c->emb_fine, r), band = td_embree_refine_bound(c->emb_fine) + c->eps_f;
            st->refined_rays++;
            /* Embree loses rays through vertices and along the mesh's outer edges; a
             * hit later than the band (or a miss) is that, not a terrad error. */
            if (!same_hit(r, tf, tinc)) {
                td_ref_hit wide;
                st->refined_disagree++;
                td_ref_trace(c->g, TD_SURFACE_BILINEAR, r, band, &wide);
                if (td_ref_judge(c->g, TD_SURFACE_BILINEAR, r, &wide, tf, band) != TD_REF_WRONG) {
                    st->refined_within++;
                } else if (tf > wide.t_strict) {
                    st->refined_embree_miss++;
                } else {
                    st->refined_error++;
                    if (st->printed++ < MAX_PRINT)
                        print_ray("refined embree vs bilinear reference", TD_METHOD_INCREMENTAL,
                                  TD_SURFACE_BILINEAR, r, tf, wide.t, &wide);
                }
            }
        }
    }
}

/* ---- --cameras: rendered camera views (the coherence devices of render.c) ------------ */

/* Views placed in the grid's own frame (fx, fy: fraction of its extent; agl over the
 * highest sample; a negative agl puts the camera below the crests, at the lowest sample
 * plus a quarter of the relief). */
static const cam_view cam_views[] = {
    {"level", 0.3, 0.3, 150, 40, 0, 0, 70, 300, 30},
    {"grazing sunset", 0.2, 0.5, 60, 95, -3, 0, 70, 270, 3},
    {"rolled 35", 0.7, 0.6, 300, 200, -10, 35, 70, 120, 40},
    {"roll 90", 0.5, 0.2, 200, 10, -15, 90, 60, 60, 25},
    {"straight down", 0.5, 0.5, 2000, 0, -90, 0, 70, 150, 35},
    {"vanishing point inside", 0.4, 0.4, 800, 30, -60, 0, 100, 200, 20},
    {"fov 170", 0.5, 0.1, 100, 0, -5, 0, 170, 90, 10},
    {"below the crests", 0.5, 0.5, -1, 70, 5, 0, 80, 320, 45},
};

/* Panoramas (issue 19): the cylindrical camera, every column an azimuth, the seam at
 * heading +- 180; placed as the views above. */
static const cam_view pano_views[] = {
    {"panorama 360", 0.5, 0.5, 40, 17, 0, 0, 360, 200, 15},
    {"panorama 140 low", 0.3, 0.6, -1, 250, -4, 0, 140, 80, 30},
};

/* One batch of par_shadows: at[0 .. np) index sh, o holds their origins, d their direction. */
static uint64_t par_batch(ctx *c, td_surface sf, const td_ray *sh, const double *d, const double (*o)[3],
                          const int *at, int np, const td_sunlit *lit)
{
    uint8_t occ[64];
    uint32_t steps = 0;
    uint64_t errors = 0;
    td_occluded_par(&c->view, TD_METHOD_AUTO, sf, d, np, o, lit, occ, &steps);
    for (int q = 0; q < np; q++) {
        td_hit h;
        td_trace(&c->view, TD_METHOD_AUTO, sf, &sh[at[q]], &h);
        if (occ[q] != (h.t < INFINITY) && errors++ < MAX_PRINT) /* got 0: occluded, inf: lit */
            print_ray("shadow ray in a packet (td_occluded_par, got) vs td_trace (want)", TD_METHOD_AUTO, sf,
                      &sh[at[q]], occ[q] ? 0.0 : INFINITY, h.t, NULL);
    }
    return errors;
}

/* The render's own query for its shadow rays: td_occluded_par with the sun bound (packets
 * of four walking their first cells), in batches of 64 along the sun as the render sends
 * them, answers as td_trace for each of the n slots of sh that holds a straight ray. */
static uint64_t par_shadows(ctx *c, td_surface sf, const td_ray *sh, int n, const td_sunlit *lit)
{
    double o[64][3];
    int at[64], np = 0;
    const double *d = NULL;
    uint64_t errors = 0;
    for (int k = 0; k < n; k++) {
        if (!(sh[k].tmax >= 0.0))
            continue;
        d = d ? d : sh[k].d;
        if (memcmp(sh[k].d, d, sizeof sh[k].d)) /* bent by the curvature: not along the sun */
            continue;
        memcpy(o[np], sh[k].o, sizeof o[np]);
        at[np++] = k;
        if (np == 64) {
            errors += par_batch(c, sf, sh, d, (const double(*)[3])o, at, np, lit);
            np = 0;
        }
    }
    if (np > 0)
        errors += par_batch(c, sf, sh, d, (const double(*)[3])o, at, np, lit);
    return errors;
}

/* The shadow rays of a colour render of the view (png, shadows on): td_occluded with the
 * render's sun bound answers as td_trace, whose hit is judged against the reference, and
 * so does the render's batched query (par_shadows); the same again with the finer bound a
 * server keeps across renders (td_sunlit_build's `kept`) where the grid's blocks differ
 * (td_sunlit_kept_finer: every test DEM but the largest). */
static uint64_t camera_shadows(ctx *c, td_scene *sc, td_surface sf, td_ray *sh, uint64_t *count)
{
    td_render_opts o;
    td_render_result res;
    td_err err = {0};
    td_sunlit *lit = NULL;
    double sun[3], a = sc->effects.sun_azimuth * M_PI / 180.0, e = sc->effects.sun_elevation * M_PI / 180.0;
    uint64_t errors = 0;
    sun[0] = sin(a) * cos(e), sun[1] = cos(a) * cos(e), sun[2] = sin(e);
    sc->image.format = TD_FORMAT_PNG;
    sc->effects.shadows = 1;
    td_render_opts_default(&o);
    o.threads = 1;
    o.shadow_rays = sh;
    memset(&res, 0, sizeof res);
    if (td_render(&c->view, sc, &o, &res, &err)) {
        printf("ERROR shadows: %s\n", err.msg);
        errors++;
    }
    for (int kept = 0; kept < 1 + td_sunlit_kept_finer(c->g) && !errors; kept++) {
        if (td_sunlit_build(&c->view, sun, kept, &lit, &err)) {
            printf("ERROR shadows: %s\n", err.msg);
            errors++;
        }
        for (int k = 0; !errors && k < sc->image.width * sc->image.height; k++) {
            td_hit h;
            td_ref_hit ref;
            uint32_t steps = 0;
            int have = 0;
            if (!(sh[k].tmax >= 0.0))
                continue;
            *count += !kept;
            td_trace(&c->view, TD_METHOD_AUTO, sf, &sh[k], &h);
            if (td_occluded(&c->view, TD_METHOD_AUTO, sf, &sh[k], lit, &steps) != (h.t < INFINITY) ||
                settle(c, sf, &sh[k], h.t, &ref, &have) == V_ERROR) {
                if (errors++ < MAX_PRINT)
                    print_ray(kept ? "shadow ray vs reference (kept bound)" : "shadow ray vs reference",
                              TD_METHOD_AUTO, sf, &sh[k], h.t, have ? ref.t : NAN, have ? &ref : NULL);
            }
        }
        errors += errors ? 0 : par_shadows(c, sf, sh, sc->image.width * sc->image.height, lit);
        td_sunlit_free(lit);
        lit = NULL;
    }
    td_render_result_free(&res);
    return errors;
}

/* One view, one method and surface: the depths with the devices on and off are the same
 * bit for bit; each pixel's depth (auto only: all methods must equal it) is judged
 * against the references like any ray; the render's shadow rays answer td_occluded with
 * the sun bound as td_trace does, and that is judged too. Returns unexplained errors. */
static uint64_t camera_check(ctx *c, const cam_view *cv, td_projection proj, td_method m, td_surface sf,
                             float *auto_depth,
                             uint64_t *pixels, uint64_t *shadow_rays)
{
    enum { W = 96, H = 72 };
    const td_grid *g = c->g;
    td_scene sc;
    td_render_opts o;
    td_render_result on = {0}, off = {0};
    td_err err = {0};
    td_camera cam;
    uint64_t errors = 0;
    td_ray *sh = calloc((size_t)W * H, sizeof *sh);
    cam_view_scene(cv, g, W, H, m, sf, &sc);
    sc.camera.projection = proj;
    td_render_opts_default(&o);
    o.threads = 1;
    if (!sh || cam_view_render(&c->view, &sc, &o, &on, &off, &cam, &err)) {
        printf("ERROR %s %s/%s: %s\n", cv->name, td_method_name(m), td_surface_name(sf), err.msg);
        errors++;
        goto out;
    }
    for (int k = 0; k < W * H; k++) {
        if (!cam_view_same(&on, &off, auto_depth, m, k)) {
            if (errors++ < MAX_PRINT)
                printf("ERROR %s %s/%s pixel %d: horizon %.9g plain %.9g auto %.9g\n", cv->name,
                       td_method_name(m), td_surface_name(sf), k, on.depth[k], off.depth[k], auto_depth[k]);
        }
        if (m == TD_METHOD_AUTO) {
            td_ray r;
            td_hit h;
            td_ref_hit ref;
            int have = 0;
            auto_depth[k] = on.depth[k];
            td_camera_ray(&cam, k % W, k / W, &r);
            td_trace(&c->view, m, sf, &r, &h); /* the pixel's t in double; its float is the depth */
            if ((float)h.t != on.depth[k] || settle(c, sf, &r, h.t, &ref, &have) == V_ERROR) {
                if (errors++ < MAX_PRINT)
                    print_ray("camera pixel vs reference", m, sf, &r, h.t, have ? ref.t : NAN, have ? &ref : NULL);
            }
            (*pixels)++;
        }
    }
    if (m == TD_METHOD_AUTO)
        errors += camera_shadows(c, &sc, sf, sh, shadow_rays);
out:
    td_render_result_free(&on);
    td_render_result_free(&off);
    free(sh);
    return errors;
}

/* One view with every method and surface; prints its line. */
static uint64_t run_view(ctx *c, const cam_view *cv, td_projection proj, float *auto_depth, uint64_t *pixels,
                         uint64_t *shadow_rays)
{
    uint64_t errors = 0;
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        errors += camera_check(c, cv, proj, TD_METHOD_AUTO, (td_surface)sf, auto_depth, pixels, shadow_rays);
        for (int m = 0; m < TD_METHOD_AUTO; m++)
            errors += camera_check(c, cv, proj, (td_method)m, (td_surface)sf, auto_depth, pixels, shadow_rays);
    }
    printf("camera %-24s every method and surface: %s\n", cv->name, errors ? "ERRORS" : "ok");
    return errors;
}

/* --cameras: every view (perspective, then the panoramas), method and surface. */
static uint64_t run_cameras(ctx *c)
{
    uint64_t errors = 0, pixels = 0, shadow_rays = 0;
    float *auto_depth = calloc(96 * 72, sizeof *auto_depth);
    for (size_t v = 0; auto_depth && v < sizeof cam_views / sizeof cam_views[0]; v++)
        errors += run_view(c, &cam_views[v], TD_PROJ_PERSPECTIVE, auto_depth, &pixels, &shadow_rays);
    for (size_t v = 0; auto_depth && v < sizeof pano_views / sizeof pano_views[0]; v++)
        errors += run_view(c, &pano_views[v], TD_PROJ_CYLINDRICAL, auto_depth, &pixels, &shadow_rays);
    printf("cameras: %" PRIu64 " pixels judged against the references, %" PRIu64
           " shadow rays; horizon-started and plain depths compared bit for bit\n", pixels, shadow_rays);
    free(auto_depth);
    return auto_depth ? errors : errors + 1;
}

/* --reference-only: the double reference against Embree, without terrad. Embree may miss
 * (robust mode still loses some rays through vertices and edges) but every hit it reports
 * must be consistent with the reference; counted in the triangle/incremental row. */
static void one_ray_reference(ctx *c, const td_ray *r)
{
    cell_stats *cs = &c->st.c[TD_SURFACE_TRIANGLE][0];
    td_ref_hit ref;
    int have_ref = 1, v;
    double te = td_embree_trace(c->emb, r);
    td_ref_trace(c->g, TD_SURFACE_TRIANGLE, r, c->eps_f, &ref);
    cs->rays++;
    cs->hits += ref.t < INFINITY;
    cs->steps += ref.cells;
    if (same_hit(r, te, ref.t)) {
        v = V_AGREE;
        if (te < INFINITY)
            cs->max_dt = fmax(cs->max_dt, td_ref_dist(r, te, ref.t));
    } else {
        cs->disagree++;
        v = settle(c, TD_SURFACE_TRIANGLE, r, te, &ref, &have_ref);
        if (v == V_ERROR && te > ref.t_strict)
            v = V_EMBREE_WRONG; /* Embree missed the first crossing (and maybe hit later) */
    }
    cs->v[v]++;
    if (v == V_ERROR && c->st.printed++ < MAX_PRINT)
        print_ray("embree hit vs reference", TD_METHOD_INCREMENTAL, TD_SURFACE_TRIANGLE, r, te,
                  ref.t, &ref);
}


static void *worker(void *arg)
{
    ctx *c = arg;
    for (size_t k = c->n0; k < c->n1; k++) {
        if (reference_only)
            one_ray_reference(c, &c->rays[k]);
        else
            one_ray(c, &c->rays[k]);
    }
    return NULL;
}

static void merge(stats *a, const stats *b)
{
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            cell_stats *x = &a->c[sf][m];
            const cell_stats *y = &b->c[sf][m];
            x->rays += y->rays, x->hits += y->hits, x->disagree += y->disagree;
            x->steps += y->steps, x->vs_incremental += y->vs_incremental;
            for (int v = 0; v < V_COUNT; v++)
                x->v[v] += y->v[v];
            x->max_dt = fmax(x->max_dt, y->max_dt);
        }
    }
    a->refined_rays += b->refined_rays, a->refined_disagree += b->refined_disagree;
    a->refined_within += b->refined_within, a->refined_error += b->refined_error;
    a->refined_embree_miss += b->refined_embree_miss;
}

/* Little-endian float64 files of `terrad trace`. */
static int write_rays(const char *path, const td_ray *r, size_t n)
{
    FILE *f = fopen(path, "wb");
    int ok = f != NULL;
    for (size_t k = 0; k < n && ok; k++) {
        unsigned char b[48];
        for (int c = 0; c < 6; c++) {
            double v = c < 3 ? r[k].o[c] : r[k].d[c - 3];
            uint64_t u;
            memcpy(&u, &v, 8);
            for (int q = 0; q < 8; q++, u >>= 8)
                b[8 * c + q] = (unsigned char)(u & 0xff);
        }
        ok = fwrite(b, 1, 48, f) == 48;
    }
    if (f && fclose(f) != 0)
        ok = 0;
    return ok;
}

static double *read_doubles(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    double *v = NULL;
    size_t cap = 0, len = 0;
    unsigned char b[8];
    while (f && fread(b, 1, 8, f) == 8) {
        uint64_t u = 0;
        if (len == cap) {
            double *nv = realloc(v, (cap = cap ? 2 * cap : 4096) * sizeof *v);
            if (!nv)
                break;
            v = nv;
        }
        for (int q = 7; q >= 0; q--)
            u = (u << 8) | b[q];
        memcpy(&v[len++], &u, 8);
    }
    if (f)
        fclose(f);
    *n = len;
    return v;
}

/* --check RAYS HITS: judges the output of `terrad trace` (any method) for one surface:
 * triangle against Embree with the same settling, the others against the reference. */
static uint64_t check_file(ctx *c, td_surface sf, const char *rays_path, const char *hits_path)
{
    size_t nr = 0, nh = 0;
    double *rv = read_doubles(rays_path, &nr), *hv = read_doubles(hits_path, &nh);
    uint64_t v[V_COUNT] = {0}, hits = 0;
    nr /= 6;
    if (!rv || !hv || nr != nh) {
        fprintf(stderr, "oracle: %s holds %zu rays but %s %zu hits\n", rays_path, nr, hits_path, nh);
        v[V_ERROR] = 1;
    } else {
        for (size_t k = 0; k < nr; k++) {
            td_ray r;
            td_ref_hit ref;
            int have_ref = 0, vv;
            set_ray(&r, rv[6 * k], rv[6 * k + 1], rv[6 * k + 2], rv[6 * k + 3], rv[6 * k + 4],
                    rv[6 * k + 5]);
            hits += hv[k] < INFINITY;
            if (sf == TD_SURFACE_TRIANGLE && same_hit(&r, hv[k], td_embree_trace(c->emb, &r)))
                vv = V_AGREE;
            else
                vv = settle(c, sf, &r, hv[k], &ref, &have_ref);
            if (vv == V_AGREE && sf == TD_SURFACE_TRIANGLE && have_ref)
                vv = V_EMBREE_WRONG;
            v[vv]++;
            if (vv == V_ERROR && c->st.printed++ < MAX_PRINT)
                print_ray("terrad trace output", TD_METHOD_AUTO, sf, &r, hv[k], ref.t, &ref);
        }
        printf("check %s surface %s: %zu rays, %" PRIu64 " hits: %" PRIu64 " agree, %" PRIu64
               " embree wrong, %" PRIu64 " ties, %" PRIu64 " float, %" PRIu64 " unexplained\n",
               hits_path, td_surface_name(sf), nr, hits, v[V_AGREE], v[V_EMBREE_WRONG], v[V_TIE],
               v[V_FLOAT], v[V_ERROR]);
    }
    free(rv);
    free(hv);
    return v[V_ERROR];
}

static double parse_double(const char *s)
{
    char *end;
    double v = strtod(s, &end);
    if (*end) {
        fprintf(stderr, "not a number: %s\n", s);
        exit(2);
    }
    return v;
}

static void replay(const td_grid *g, const td_view *view, const td_embree *emb, double eps_f,
                   const td_ray *r)
{
    printf("ray %a %a %a  %a %a %a\n", r->o[0], r->o[1], r->o[2], r->d[0], r->d[1], r->d[2]);
    printf("embree triangle t=%.17g\n", td_embree_trace(emb, r));
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        td_ref_hit ref;
        td_ref_trace(g, (td_surface)sf, r, eps_f, &ref);
        printf("%-8s reference t=%.17g cell (%d,%d) near=%.17g strict=%.17g\n",
               td_surface_name((td_surface)sf), ref.t, (int)ref.ci, (int)ref.cj, ref.t_near,
               ref.t_strict);
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            td_hit h;
            td_trace(view, (td_method)m, (td_surface)sf, r, &h);
            printf("    %-12s t=%.17g cell (%d,%d) steps=%u verdict=%d\n",
                   td_method_name((td_method)m), h.t, (int)h.ci, (int)h.cj, (unsigned)h.steps,
                   (int)td_ref_judge(g, (td_surface)sf, r, &ref, h.t, eps_f));
        }
    }
}

int main(int argc, char **argv)
{
    int rc = 1, threads = 2, do_replay = 0, running = 0, cameras = 0;
    size_t nrays = 200000;
    uint64_t seed = 12345;
    const char *name = argc > 1 && argv[1][0] != '-' ? argv[1] : "procedural";
    const char *dem = NULL, *out_rays = NULL, *check_rays = NULL, *check_hits = NULL;
    td_surface check_sf = TD_SURFACE_TRIANGLE;
    td_err err = {0};
    td_grid *g = NULL;
    td_accel *acc = NULL;
    td_accel_opts ao;
    td_accel_stats as;
    td_embree *emb = NULL, *fine = NULL;
    td_ray *rays = NULL, one;
    ctx *cx = NULL;
    pthread_t *th = NULL;
    stats total;

    memset(&total, 0, sizeof total);
    for (int k = argc > 1 && argv[1][0] != '-' ? 2 : 1; k < argc; k++) {
        if (!strcmp(argv[k], "--dem") && k + 1 < argc) {
            dem = argv[++k];
        } else if (!strcmp(argv[k], "--write-rays") && k + 1 < argc) {
            out_rays = argv[++k];
        } else if (!strcmp(argv[k], "--surface") && k + 1 < argc &&
                   td_surface_parse(argv[k + 1], &check_sf) == TD_OK) {
            k++;
        } else if (!strcmp(argv[k], "--check") && k + 2 < argc) {
            check_rays = argv[k + 1];
            check_hits = argv[k + 2];
            k += 2;
        } else if (!strcmp(argv[k], "--rays") && k + 1 < argc) {
            nrays = (size_t)parse_double(argv[++k]);
        } else if (!strcmp(argv[k], "--seed") && k + 1 < argc) {
            seed = (uint64_t)parse_double(argv[++k]);
        } else if (!strcmp(argv[k], "--threads") && k + 1 < argc) {
            threads = (int)parse_double(argv[++k]);
        } else if (!strcmp(argv[k], "--reference-only")) {
            reference_only = 1;
        } else if (!strcmp(argv[k], "--cameras")) {
            cameras = 1;
        } else if (!strcmp(argv[k], "--ray") && k + 6 < argc) {
            set_ray(&one, parse_double(argv[k + 1]), parse_double(argv[k + 2]),
                    parse_double(argv[k + 3]), parse_double(argv[k + 4]),
                    parse_double(argv[k + 5]), parse_double(argv[k + 6]));
            k += 6;
            do_replay = 1;
        } else {
            fprintf(stderr,
                    "usage: %s DATASET|--dem FILE [--rays N] [--seed S] [--threads T] [--reference-only]\n"
                    "       [--ray OX OY OZ DX DY DZ] [--write-rays FILE] [--surface S --check RAYS HITS]\n"
                    "       [--cameras]\n",
                    argv[0]);
            return 2;
        }
    }
    if (threads < 1)
        threads = 1;
    show_ties = getenv("ORACLE_SHOW_TIES") != NULL;
    if (dem) {
        td_dem_opts o;
        td_dem_opts_default(&o);
        name = dem;
        if (td_dem_load(dem, &o, &g, &err) != TD_OK) {
            fprintf(stderr, "oracle: %s\n", err.msg);
            goto out;
        }
    } else if (load_dataset(name, &g, &err) != TD_OK) {
        fprintf(stderr, "oracle: %s\n", err.msg);
        goto out;
    }
    td_accel_opts_default(&ao);
    ao.maxmip = 1;
    ao.planes = 1;
    ao.threads = threads;
    if (td_accel_build(g, &ao, &acc, &as, &err) != TD_OK ||
        td_embree_build(g, 1, &emb, &err) != TD_OK) {
        fprintf(stderr, "oracle: %s\n", err.msg);
        goto out;
    }
    if ((int64_t)(g->w - 1) * (g->h - 1) <= 80000 && !reference_only && td_embree_build(g, 4, &fine, &err) != TD_OK) {
        fprintf(stderr, "oracle: %s\n", err.msg);
        goto out;
    }
    double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
    double scale = fmax(fmax(X, Y), fmax(fabs(g->zmin), fabs(g->zmax)));
    double slope = td_ref_max_slope(g);
    double tolg = 1e-3 + 2.0 * FLT_EPSILON * scale;
    double eps_f = tolg * (1.0 + slope), eps_x = 1e-9 * scale;
    td_view view = {g, acc->tiles};
    printf("dataset %s: %d x %d samples, spacing %.3f x %.3f m, heights %.1f .. %.1f m, %" PRId64
           " voids, %d x %d tiles of %d cells; max slope %.2f; bands: float %.3g m, exact %.3g m\n",
           name, (int)g->w, (int)g->h, g->sx, g->sy, g->zmin, g->zmax, g->voids, (int)g->tiles_x,
           (int)g->tiles_y, td_grid_tile_size(g), slope, eps_f, eps_x);
    if (do_replay) {
        replay(g, &view, emb, eps_f, &one);
        rc = 0;
        goto out;
    }
    if (cameras) {
        ctx c1;
        ctx_init(&c1, g, &view, emb, eps_f, eps_x);
        uint64_t errors = run_cameras(&c1);
        printf("%s: %" PRIu64 " unexplained disagreements\n", errors ? "FAIL" : "PASS", errors);
        rc = errors ? 1 : 0;
        goto out;
    }
    if (check_rays) {
        ctx c1;
        ctx_init(&c1, g, &view, emb, eps_f, eps_x);
        rc = check_file(&c1, check_sf, check_rays, check_hits) ? 1 : 0;
        printf("%s\n", rc ? "FAIL" : "PASS");
        goto out;
    }
    rays = calloc(nrays, sizeof *rays);
    cx = calloc((size_t)threads, sizeof *cx);
    th = calloc((size_t)threads, sizeof *th);
    if (!rays || !cx || !th)
        goto out;
    uint64_t s = seed;
    for (size_t k = 0; k < nrays; k++)
        make_ray(g, (int)(k % K_COUNT), &s, &rays[k]);
    if (out_rays) { /* for `terrad trace`, whose rays all have tmin = 0 and tmax = +inf */
        for (size_t k = 0; k < nrays; k++)
            rays[k].tmax = INFINITY;
        rc = write_rays(out_rays, rays, nrays) ? 0 : 1;
        if (rc)
            fprintf(stderr, "oracle: cannot write %s\n", out_rays);
        goto out;
    }
    printf("rays: %zu, seed %" PRIu64 ", kinds:", nrays, seed);
    for (int k = 0; k < K_COUNT; k++)
        printf(" %s%s", kind_names[k], k + 1 < K_COUNT ? "," : "\n");
    for (int t = 0; t < threads; t++) {
        ctx_init(&cx[t], g, &view, emb, eps_f, eps_x);
        cx[t].emb_fine = fine;
        cx[t].rays = rays;
        cx[t].n0 = nrays * (size_t)t / (size_t)threads;
        cx[t].n1 = nrays * (size_t)(t + 1) / (size_t)threads;
        if (pthread_create(&th[t], NULL, worker, &cx[t]) != 0)
            goto out;
        running = t + 1;
    }
    for (int t = 0; t < threads; t++)
        pthread_join(th[t], NULL);
    running = 0;
    for (int t = 0; t < threads; t++)
        merge(&total, &cx[t].st);

    uint64_t errors = total.refined_error;
    printf("%-9s %-12s %8s %8s %7s %8s %8s %6s %6s %6s %10s %10s %8s\n", "surface", "method",
           "rays", "hits", "disagr", v_names[V_EMBREE_WRONG], v_names[V_TIE], v_names[V_FLOAT],
           v_names[V_ERROR], "!=inc", "max|dt| m", "mean steps", "oracle");
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            const cell_stats *q = &total.c[sf][m];
            if (reference_only && (sf != TD_SURFACE_TRIANGLE || m != 0))
                continue;
            printf("%-9s %-12s %8" PRIu64 " %8" PRIu64 " %7" PRIu64 " %8" PRIu64 " %8" PRIu64
                   " %6" PRIu64 " %6" PRIu64 " %6" PRIu64 " %10.3g %10.2f %8s\n",
                   td_surface_name((td_surface)sf), td_method_name((td_method)m), q->rays, q->hits,
                   q->disagree, q->v[V_EMBREE_WRONG], q->v[V_TIE], q->v[V_FLOAT], q->v[V_ERROR],
                   q->vs_incremental, q->max_dt, q->rays ? (double)q->steps / q->rays : 0.0,
                   reference_only ? "ref/emb" : sf == TD_SURFACE_TRIANGLE ? "embree" : "double");
            errors += q->v[V_ERROR];
        }
    }
    if (fine)
        printf("bilinear vs embree refined 4x4 (bound %.3g m): %" PRIu64 " rays, %" PRIu64
               " differ from terrad beyond tolerance: %" PRIu64 " within the bound, %" PRIu64
               " embree missed (later than the band), %" PRIu64 " unexplained\n",
               td_embree_refine_bound(fine), total.refined_rays, total.refined_disagree,
               total.refined_within, total.refined_embree_miss, total.refined_error);
    printf("%s: %" PRIu64 " unexplained disagreements\n", errors ? "FAIL" : "PASS", errors);
    rc = errors ? 1 : 0;
out:
    for (int t = 0; t < running; t++)
        pthread_join(th[t], NULL);
    free(th);
    free(cx);
    free(rays);
    td_embree_free(fine);
    td_embree_free(emb);
    td_accel_free(acc);
    td_grid_free(g);
    return rc;
}
