/* test_colwalk.c: the column walk (core/colwalk.c) that renders an upright, level camera's
 * and a panorama's image columns, against the plain walk (td_trace, which the render's other paths give bit
 * for bit), on every surface.
 *
 * - Random level cameras over procedural terrain (unequal spacing; heights as they come,
 *   rounded to whole metres with a flat plateau, or with voids; the max-mipmaps resident,
 *   and not, where the silhouette partition takes the rays instead): eyes anywhere, on
 *   grid lines and on samples, headings along the axes and the diagonals or anywhere,
 *   fields of view from 20 to 170 degrees, images taller than a block (so upper blocks
 *   start from their wedge's horizon). Every pixel's depth is the plain walk's, or the
 *   pixel's ray only touches the surface: the plain walk with the ray lowered by the
 *   walk's margin hits at or before it, and raised by it, at or after (a tie, which the
 *   oracle tests judge the same way); and those ties are rare.
 * - Shaded renders (normals, shadows) give the same picture as the plain walk's.
 * - The height plane's walls at a sample point the line runs through, and a line a
 *   rounding off a row line (findings of fuzz_render): the plain walk's pixels.
 * - Panoramas (cylindrical: every column one azimuth, whatever the pitch) among the
 *   random cameras, judged the same way; with curvature the rays that bend are the
 *   curvature stage's and the others the columns'.
 * - The device applies only where it is exact (column_rays): a level camera or a panorama
 *   with the method auto and the eye above the surface around it; not pitched or rolled
 *   perspective cameras, other methods, an eye at or below the surface, orthographic
 *   views; one thread or three give the same bits; supersampled images too. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "accel.h"
#include "camera.h"
#include "colwalk.h"
#include "render.h"
#include "terrain.h"
#include "trace.h"
#include "terrain_fixture.h"

static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

enum { PLAIN, INTEGER, VOIDS, KINDS };
static int cur_kind, cur_res; /* the grid and residency being judged (judge's report) */

/* 97 x 61 samples, 30 x 45 m: as generated, rounded to whole metres with a flat plateau
 * (ties: rays along and through equal heights), or with voids. */
static td_grid *make_grid(uint64_t seed, int kind)
{
    td_grid *g = terrain_seeded(97, 61, 30.0, seed, 5);
    uint64_t s = seed;
    g->sy = 45.0;
    for (size_t k = 0; k < (size_t)g->w * (size_t)g->h && kind == INTEGER; k++)
        g->z[k] = roundf(g->z[k]);
    if (kind == INTEGER)
        for (int32_t j = 20; j < 35; j++)
            for (int32_t i = 30; i < 60; i++)
                g->z[(size_t)j * g->w + i] = 1200.0f;
    for (int k = 0; k < 150 && kind == VOIDS; k++)
        g->z[(size_t)(rnd(&s) * (double)g->w * (double)g->h)] = NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    return g;
}

/* The highest (lowest: sign -1) sample of the r x r cells around (x, y), skipping voids. */
static double local_ext(const td_grid *g, double x, double y, int r, double sign)
{
    int32_t i0 = (int32_t)(x / g->sx), j0 = (int32_t)(y / g->sy);
    double m = -INFINITY;
    for (int32_t j = j0 - r + 1; j <= j0 + r; j++)
        for (int32_t i = i0 - r + 1; i <= i0 + r; i++)
            if (i >= 0 && j >= 0 && i < g->w && j < g->h && !isnan(td_grid_at(g, i, j)))
                m = fmax(m, sign * td_grid_at(g, i, j));
    return sign * m;
}

static double local_max(const td_grid *g, double x, double y) { return local_ext(g, x, y, 3, 1.0); }

static void level_scene(td_scene *s, const td_grid *g, uint64_t *seed, td_surface sf, int32_t w, int32_t h)
{
    static const double axes[8] = {0, 45, 90, 135, 180, 225, 270, 315};
    td_scene_defaults(s);
    snprintf(s->dataset, sizeof s->dataset, "procedural");
    double x = (0.02 + 0.96 * rnd(seed)) * (g->w - 1) * g->sx, y = (0.02 + 0.96 * rnd(seed)) * (g->h - 1) * g->sy;
    double r = rnd(seed);
    if (r < 0.3) /* on a column line, a row line, or a sample */
        x = round(x / g->sx) * g->sx;
    if (r > 0.2 && r < 0.5)
        y = round(y / g->sy) * g->sy;
    s->camera.x = x;
    s->camera.y = y;
    s->camera.z = local_max(g, x, y) + (rnd(seed) < 0.3 ? 0.05 : 1.0 + 300.0 * rnd(seed));
    s->camera.heading = rnd(seed) < 0.3 ? axes[(int)(rnd(seed) * 8)] : 360.0 * rnd(seed);
    s->camera.pitch = 0.0;
    s->camera.roll = 0.0;
    s->camera.fov = 20.0 + 150.0 * rnd(seed);
    s->image.width = w;
    s->image.height = h;
    s->image.format = TD_FORMAT_DEPTH32F;
    s->quality.method = TD_METHOD_AUTO;
    s->quality.surface = sf;
}

/* A panorama (every column one azimuth, whatever the pitch) from level_scene's eye: pitch
 * -30 .. 30, fov 20 .. 360, the rows' span from the image's aspect or fov_v 5 .. 60. */
static void pano_scene(td_scene *s, const td_grid *g, uint64_t *seed, td_surface sf, int32_t w, int32_t h)
{
    level_scene(s, g, seed, sf, w, h);
    s->camera.projection = TD_PROJ_CYLINDRICAL;
    s->camera.pitch = 60.0 * rnd(seed) - 30.0;
    s->camera.fov = rnd(seed) < 0.3 ? 360.0 : 20.0 + 340.0 * rnd(seed);
    s->camera.fov_v = rnd(seed) < 0.5 ? 0.0 : 5.0 + 55.0 * rnd(seed);
}

static void render(const td_view *v, const td_scene *s, unsigned off, int threads, td_render_result *r)
{
    td_render_opts o;
    td_err err = {0};
    td_render_opts_default(&o);
    o.threads = threads;
    o.off = off;
    td_status st = td_render(v, s, &o, r, &err);
    if (st)
        print_error("render: %s\n", err.msg);
    assert_int_equal(st, TD_OK);
}

/* The plain walk's distance for ray r with its origin moved up by dz. */
static double walk_t(const td_view *v, td_surface sf, const td_ray *r, double dz)
{
    td_ray q = *r;
    td_hit h;
    q.o[2] += dz;
    td_trace(v, TD_METHOD_AUTO, sf, &q, &h);
    return h.t;
}

/* Pixel by pixel: the column walk's depth (on) is the plain walk's (off), or a tie (see
 * the top of the file). Returns the ties. */
static int judge(const td_view *v, const td_scene *s, const td_render_result *on, const td_render_result *off)
{
    td_camera cam;
    td_err err = {0};
    int ties = 0;
    const td_grid *g = v->grid;
    const double margin = 1e-6 * (1.0 + fmax(fabs((double)g->zmin), fabs((double)g->zmax)));
    assert_int_equal(td_camera_setup(&s->camera, s->image.width, s->image.height, g, &cam, &err), TD_OK);
    for (int32_t y = 0; y < s->image.height; y++)
        for (int32_t x = 0; x < s->image.width; x++) {
            const size_t i = (size_t)y * s->image.width + x;
            const float a = on->depth[i], b = off->depth[i];
            if (!memcmp(&a, &b, sizeof a))
                continue;
            td_ray r;
            td_camera_ray(&cam, x, y, &r);
            const double lo = walk_t(v, s->quality.surface, &r, -margin);
            const double hi = walk_t(v, s->quality.surface, &r, margin);
            int ok = (double)a >= (float)lo * (1.0 - 1e-6) && (double)a <= (float)hi * (1.0 + 1e-6);
            if (!ok)
                print_error("grid %d, resident %d, surface %d, eye (%.17g, %.17g, %.17g) heading %.17g fov %.17g, "
                            "pixel (%d, %d): column walk %.9g, plain walk %.9g, lowered %.9g, raised %.9g\n",
                            cur_kind, cur_res, (int)s->quality.surface, s->camera.x, s->camera.y, s->camera.z,
                            s->camera.heading, s->camera.fov, (int)x, (int)y, (double)a, (double)b, lo, hi);
            assert_true(ok);
            ties++;
        }
    return ties;
}

static void test_columns_match_walk(void **state)
{
    uint64_t seed = 2026;
    long pixels = 0, ties = 0, columns = 0, under = 0;
    (void)state;
    for (int kind = 0; kind < KINDS; kind++) {
        td_grid *g = make_grid(100 + kind, kind);
        td_accel *a = NULL;
        td_accel_opts ao;
        td_accel_opts_for(TD_METHOD_AUTO, &ao);
        assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
        for (int resident = 0; resident < 2; resident++) {
            const td_view v = {g, resident ? a->tiles : NULL};
            for (int k = 0; k < 12; k++) {
                for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                    static td_scene s;
                    td_render_result on, off;
                    uint64_t cam_seed = seed + (uint64_t)k * 7919u;
                    if (k % 4 == 3)
                        pano_scene(&s, g, &cam_seed, (td_surface)sf, 37, k % 3 ? 41 : 150);
                    else
                        level_scene(&s, g, &cam_seed, (td_surface)sf, 37, k % 3 ? 41 : 150);
                    render(&v, &s, 0, 1, &on);
                    render(&v, &s, TD_RENDER_OFF_COLUMNS, 1, &off);
                    /* a cold dataset (no max-mipmaps) takes the silhouette partition where it
                       has one for the view (then every ray is its), else the column walk */
                    const uint64_t all = (uint64_t)s.image.width * (uint64_t)s.image.height;
                    td_colwalk cw;
                    const double eye[3] = {s.camera.x, s.camera.y, s.camera.z};
                    const int applies = td_colwalk_init(&cw, &v, (td_surface)sf, eye); /* not beside a void */
                    /* with voids, the rays above one that went under the surface through a
                       hole are the plain walk's (colwalk.h) */
                    const uint64_t cols = on.stats.column_rays;
                    assert_true((applies && (cols == all || (kind == VOIDS && cols > 0 && cols < all))) ||
                                (!applies && cols == 0) ||
                                (!resident && cols == 0 && on.stats.silhouette_rays == all));
                    assert_int_equal(on.stats.rays[TD_RAY_PRIMARY], all);
                    columns += cols > 0;
                    under += kind == VOIDS && cols > 0 && cols < all;
                    assert_int_equal(off.stats.column_rays, 0);
                    cur_kind = kind, cur_res = resident;
                    ties += judge(&v, &s, &on, &off);
                    pixels += (long)s.image.width * s.image.height;
                    /* hits differ only by ties */
                    assert_true(llabs((long long)on.stats.hits - (long long)off.stats.hits) <= ties);
                    td_render_result_free(&on);
                    td_render_result_free(&off);
                }
            }
            seed += 104729u;
        }
        td_accel_free(a);
        td_grid_free(g);
    }
    print_message("%ld pixels, %ld ties with the plain walk; %ld renders of 288 by columns, %ld with rays "
                  "left to the plain walk\n", pixels, ties, columns, under);
    assert_true(under > 0); /* the voids' case is exercised */
    assert_true(columns > 100);
    assert_true(ties * 1000 < pixels); /* rare: under 0.1% */
}

/* Views with curvature from the lowest sample, toward the farthest corner. A panorama 60
 * degrees wide: no ray bends (each pixel's drop at the grid's far side is under a pixel,
 * render.c), and the columns take them all. 0.1 degree wide (rays whose run over the grid
 * is longer than about 1.3 km bend), a panorama and a pitched and a level perspective
 * camera, and a panorama looking up: every ray bends, and the curvature stage starts each
 * where its straight ray meets nothing before (the columns' hit or the block wedge's
 * horizon: the chords lie above that ray; a straight miss is a miss, counted as a known
 * miss is). Each the same depths as with the camera devices off (TD_RENDER_OFF_CAMERA). */
static void test_columns_curved(void **state)
{
    td_grid *g = make_grid(13, PLAIN);
    td_accel *a = NULL;
    td_accel_opts ao;
    uint64_t seed = 3;
    int32_t il = 0, jl = 0; /* the lowest sample off the edges: the eye sees the slopes around */
    (void)state;
    for (int32_t j = 3; j < g->h - 3; j++)
        for (int32_t i = 3; i < g->w - 3; i++)
            if (td_grid_at(g, i, j) < td_grid_at(g, il, jl) || il == 0)
                il = i, jl = j;
    td_accel_opts_for(TD_METHOD_AUTO, &ao);
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    const td_view v = {g, a->tiles};
    for (int k = 0; k < 5; k++) {
        static td_scene s;
        td_render_result on, off;
        const int across = k > 0;
        pano_scene(&s, g, &seed, TD_SURFACE_TRIANGLE, 40, 30);
        s.camera.x = il * g->sx;
        s.camera.y = jl * g->sy;
        s.camera.z = local_max(g, s.camera.x, s.camera.y) + 10.0;
        /* toward the farthest corner, or (wide: nothing bends) anywhere */
        const double cx = il < g->w / 2 ? (g->w - 1) * g->sx : 0.0, cy = jl < g->h / 2 ? (g->h - 1) * g->sy : 0.0;
        s.camera.heading = atan2(cx - s.camera.x, cy - s.camera.y) * 180.0 / M_PI;
        s.camera.pitch = k == 3 ? 0.0 : (k == 4 ? 60.0 : -1.0); /* 4: up, into the sky */
        s.camera.fov = across ? 0.1 : 60.0;
        s.camera.fov_v = 0.0;
        if (k >= 2)
            s.camera.projection = TD_PROJ_PERSPECTIVE;
        s.effects.curvature = 1;
        s.effects.curvature_k = 0.13;
        render(&v, &s, 0, 1, &on);
        render(&v, &s, TD_RENDER_OFF_CAMERA, 1, &off);
        const uint64_t all = 40 * 30;
        assert_int_equal(on.stats.column_rays, across ? 0 : all);
        assert_int_equal(on.stats.curved_rays, across ? all : 0);
        assert_int_equal(on.stats.coherent_rays, all); /* the columns', or the horizon's */
        assert_int_equal(off.stats.coherent_rays, 0);
        assert_int_equal(on.stats.rays[TD_RAY_PRIMARY], all);
        assert_int_equal(judge(&v, &s, &on, &off), 0);
        assert_int_equal(on.stats.hits, off.stats.hits);
        /* counted under the walks that ran, or auto's (incremental) where none had to */
        assert_int_equal(on.stats.method_rays[TD_METHOD_AUTO], 0);
        print_message("case %d: %d hits\n", k, (int)on.stats.hits);
        assert_true(k == 4 ? on.stats.hits < all / 2 : on.stats.hits > all / 2); /* the rays meet the terrain, or not */
        td_render_result_free(&on);
        td_render_result_free(&off);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* A shaded render with shadows: the same picture as the plain walk's, every surface. */
static void test_columns_shaded(void **state)
{
    td_grid *g = make_grid(7, PLAIN);
    td_accel *a = NULL;
    td_accel_opts ao;
    uint64_t seed = 99;
    (void)state;
    td_accel_opts_for(TD_METHOD_AUTO, &ao);
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    const td_view v = {g, a->tiles};
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        static td_scene s;
        td_render_result on, off;
        level_scene(&s, g, &seed, (td_surface)sf, 48, 80);
        s.camera.z = local_max(g, s.camera.x, s.camera.y) + 40.0;
        s.image.format = TD_FORMAT_PNG;
        s.effects.shadows = 1;
        s.effects.sun_azimuth = 120.0;
        s.effects.sun_elevation = 25.0;
        render(&v, &s, 0, 1, &on);
        render(&v, &s, TD_RENDER_OFF_COLUMNS, 1, &off);
        assert_true(on.stats.column_rays > 0);
        size_t n = (size_t)s.image.width * s.image.height * 4, differ = 0;
        for (size_t i = 0; i < n; i++)
            differ += abs((int)on.rgba[i] - (int)off.rgba[i]) > 1;
        assert_int_equal(differ, 0);
        assert_int_equal(on.stats.rays[TD_RAY_SHADOW], off.stats.rays[TD_RAY_SHADOW]);
        td_render_result_free(&on);
        td_render_result_free(&off);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* Where the device applies (column_rays), and that threads and samples keep its bits. */
static void test_columns_where(void **state)
{
    td_grid *g = make_grid(11, PLAIN);
    td_accel *a = NULL;
    td_accel_opts ao;
    uint64_t seed = 5;
    static td_scene s, t;
    td_render_result r, r3;
    (void)state;
    td_accel_opts_for(TD_METHOD_AUTO, &ao);
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    const td_view v = {g, a->tiles};
    level_scene(&s, g, &seed, TD_SURFACE_BILINEAR, 40, 70);
    s.camera.z = local_max(g, s.camera.x, s.camera.y) + 20.0;
    const uint64_t all = 40 * 70;
    render(&v, &s, 0, 1, &r);
    assert_int_equal(r.stats.column_rays, all);
    render(&v, &s, 0, 3, &r3); /* three threads: the same bits */
    assert_memory_equal(r.depth, r3.depth, sizeof(float) * all);
    td_render_result_free(&r3);
    td_render_result_free(&r);
    t = s;
    t.quality.samples = 2; /* four rays a pixel, each column of samples a plane */
    render(&v, &t, 0, 1, &r);
    render(&v, &t, TD_RENDER_OFF_COLUMNS, 1, &r3);
    assert_int_equal(r.stats.column_rays, 4 * all);
    assert_int_equal(r.stats.hits, r3.stats.hits);
    td_render_result_free(&r3);
    td_render_result_free(&r);
    /* not where the columns are not vertical planes, or another method is asked for, or
       the eye is not above the surface around it, or not a perspective camera */
    for (int k = 0; k < 7; k++) {
        t = s;
        if (k == 0)
            t.camera.pitch = -0.5;
        else if (k == 1)
            t.camera.roll = 3.0;
        else if (k == 2)
            t.quality.method = TD_METHOD_HIERARCHICAL;
        else if (k == 3) /* under the surface */
            t.camera.z = local_ext(g, s.camera.x, s.camera.y, 1, -1.0) - 1.0;
        else if (k == 4) /* as high as a corner of its cell */
            t.camera.z = local_ext(g, s.camera.x, s.camera.y, 1, 1.0);
        else if (k == 5) /* a panorama (which columns take) from under the surface */
            t.camera.projection = TD_PROJ_CYLINDRICAL, t.camera.z = local_ext(g, s.camera.x, s.camera.y, 1, -1.0) - 1.0;
        else
            t.camera.projection = TD_PROJ_ORTHOGRAPHIC;
        render(&v, &t, 0, 1, &r);
        if (r.stats.column_rays)
            print_error("case %d: the column walk applied\n", k);
        assert_int_equal(r.stats.column_rays, 0);
        td_render_result_free(&r);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* A w x h grid of the plane z = 200 + a i + b j, sx 10 m and sy given, with the max-mipmaps
 * `auto` reads (*acc, freed by the caller), and a level depth32f scene of it: eye (x, y, z),
 * heading, fov, an iw x ih image. */
static td_grid *plane_case(int32_t w, int32_t h, double sy, int a, int b, td_accel **acc, td_scene *s,
                           const double eye[3], double heading, double fov, int32_t iw, int32_t ih)
{
    td_grid *g = terrain_seeded(w, h, 10.0, 1, 5);
    td_accel_opts ao;
    g->sy = sy;
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * g->w + i] = (float)(200 + a * i + b * j);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel_opts_for(TD_METHOD_AUTO, &ao);
    assert_int_equal(td_accel_build(g, &ao, acc, NULL, NULL), TD_OK);
    td_scene_defaults(s);
    s->camera.x = eye[0], s->camera.y = eye[1], s->camera.z = eye[2];
    s->camera.heading = heading, s->camera.fov = fov;
    s->image.width = iw, s->image.height = ih, s->image.format = TD_FORMAT_DEPTH32F;
    s->quality.method = TD_METHOD_AUTO;
    return g;
}

/* The height plane's walls at a sample point (found by fuzz_render on level cameras): a
 * plane z = 200 + 2 i + j, the eye on sample (1, 3) looking along the diagonal (heading
 * 135), so the centre column's line runs through samples. Its rays' own lines pass the
 * sample point (4, 0) at the grid's south edge a rounding east of it, clip the corner of
 * cell (4, 0) and meet its wall; the shared line, a rounding the other way, left the grid.
 * Rays that low by a sample point are left to the plain walk: every pixel is td_trace's. */
static void test_columns_plane_vertex(void **state)
{
    td_accel *a = NULL;
    static td_scene s;
    td_render_result r;
    td_camera cam;
    (void)state;
    td_grid *g = plane_case(23, 7, 10.0, 2, 1, &a, &s, (const double[3]){10.0, 30.0, 250.5}, 135.0, 120.0, 11, 19);
    const td_view v = {g, a->tiles};
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        s.quality.surface = (td_surface)sf;
        render(&v, &s, 0, 1, &r);
        assert_true(r.stats.column_rays > 0);
        assert_int_equal(td_camera_setup(&s.camera, 11, 19, g, &cam, NULL), TD_OK);
        for (int32_t k = 0; k < 11 * 19; k++) {
            td_ray ray;
            td_hit h;
            td_camera_ray(&cam, k % 11, k / 11, &ray);
            td_trace(&v, TD_METHOD_AUTO, (td_surface)sf, &ray, &h);
            const float d = h.t < INFINITY ? (float)h.t : INFINITY;
            if (memcmp(&d, &r.depth[k], sizeof d))
                print_error("surface %d pixel (%d, %d): %.9g, td_trace %.9g\n", sf, (int)(k % 11), (int)(k / 11),
                            (double)r.depth[k], (double)d);
            assert_memory_equal(&d, &r.depth[k], sizeof d);
        }
        td_render_result_free(&r);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* A line a rounding off a grid line (found by fuzz_render on level cameras): the eye on
 * row line 6 as the frame computes it (y = 80, sy = 13.333333333333332: V =
 * 6.000000000000001) looking west (heading 270: d_y = -1.8e-16), so the line crosses the
 * row line only 64 m out. The
 * box the first rays pass over ends 40 m out, where the rounded position is exactly 6.0,
 * and the walk went on in the row below, whose columns on the plane surface are 3 m lower.
 * The cells after a box crossed (and at the start) are taken by the crossing times; every
 * pixel is the plain walk's, three samples a side. */
static void test_columns_row_line(void **state)
{
    td_accel *a = NULL;
    static td_scene s;
    td_render_result on, off;
    (void)state;
    /* sy 40 / 3 less an ulp: 80 / sy = 6.000000000000001 */
    td_grid *g = plane_case(25, 24, 13.333333333333332, 2, 3, &a, &s, (const double[3]){200.0, 80.0, 410.5}, 270.0,
                            70.0, 5, 21);
    const td_view v = {g, a->tiles};
    s.quality.samples = 3;
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        s.quality.surface = (td_surface)sf;
        render(&v, &s, 0, 1, &on);
        render(&v, &s, TD_RENDER_OFF_COLUMNS, 1, &off);
        assert_true(on.stats.column_rays > 0);
        for (int32_t k = 0; k < 5 * 21; k++) {
            if (memcmp(&on.depth[k], &off.depth[k], sizeof(float)))
                print_error("surface %d pixel (%d, %d): %.9g, the plain walk %.9g\n", sf, (int)(k % 5),
                            (int)(k / 5), (double)on.depth[k], (double)off.depth[k]);
            assert_memory_equal(&on.depth[k], &off.depth[k], sizeof(float));
        }
        td_render_result_free(&on);
        td_render_result_free(&off);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* td_colwalk_init: an eye above the corners of the cells around it (3 x 3 of them) is
 * taken; one off the grid, on its edge, or as high as its own cell's highest corner is
 * not. */
static void test_colwalk_init(void **state)
{
    td_grid *g = make_grid(3, PLAIN);
    td_colwalk cw;
    const td_view v = {g, NULL};
    (void)state;
    const double x = 40.3 * g->sx, y = 30.6 * g->sy, top = local_ext(g, x, y, 1, 1.0);
    assert_true(td_colwalk_init(&cw, &v, TD_SURFACE_TRIANGLE, (double[3]){x, y, local_ext(g, x, y, 2, 1.0) + 0.01}));
    assert_false(td_colwalk_init(&cw, &v, TD_SURFACE_TRIANGLE, (double[3]){x, y, top}));
    assert_false(td_colwalk_init(&cw, &v, TD_SURFACE_TRIANGLE, (double[3]){-1.0, y, top + 1.0}));
    assert_false(td_colwalk_init(&cw, &v, TD_SURFACE_TRIANGLE, (double[3]){0.0, y, top + 1.0}));
    assert_false(td_colwalk_init(&cw, &v, TD_SURFACE_TRIANGLE,
                                 (double[3]){(g->w - 1) * g->sx, y, top + 1.0}));
    assert_false(td_colwalk_init(&cw, &v, TD_SURFACE_TRIANGLE, (double[3]){x, y, NAN}));
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_colwalk_init),
        cmocka_unit_test(test_columns_match_walk),
        cmocka_unit_test(test_columns_shaded),
        cmocka_unit_test(test_columns_where),
        cmocka_unit_test(test_columns_curved),
        cmocka_unit_test(test_columns_plane_vertex),
        cmocka_unit_test(test_columns_row_line),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
