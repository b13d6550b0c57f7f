/* test_silhouette.c: the silhouette partition of core/silhouette.c against the walk.
 *
 * On the real DEMs of tests/data (volcano, picos with its voids, the trinidad crop) and
 * for cameras level, grazing, rolled 35 and 90, straight down (vanishing point inside the
 * image: all four fans), below the crests, and outside the grid looking in and away:
 *   - every pixel's bound is safe: the incremental walk's hit on every surface is at or
 *     after it (+inf only for rays that hit nothing);
 *   - td_trace_from the bound gives td_trace's hit bit for bit (t, cell);
 *   - the bound is worth something: most rays of the level views start past their origin.
 * And renders with method silhouette equal the plain walk (devices off) bit for bit:
 * depth and colour with shadows, 2 threads, 2 x 2 samples, perspective and orthographic
 * (which the partition does not handle: its rays take the walk), with the stats counting
 * the partition's rays, entries and steps; and `auto` uses the partition on a view without
 * max-mipmaps, the horizon device on one with them, with the same pixels. */
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
#include "dem.h"
#include "render.h"
#include "silhouette.h"
#include "trace.h"

typedef struct cam_def {
    const char *name;
    double fx, fy, agl; /* position as fractions of the extent; height above zmax (< 0: below) */
    double heading, pitch, roll, fov;
    int min_narrowed_pct; /* rays whose bound is past their origin, at least (percent) */
} cam_def;

static const cam_def cams[] = {
    {"level", 0.3, 0.3, 40, 40, 0, 0, 70, 50},
    {"grazing", 0.2, 0.5, 2, 95, -1, 0, 70, 0},
    {"rolled 35", 0.7, 0.6, 200, 200, -10, 35, 70, 0},
    {"roll 90", 0.5, 0.2, 10, 10, -15, 90, 60, 0},
    {"straight down", 0.5, 0.5, 2000, 0, -90, 0, 70, 0},
    {"vanishing point inside", 0.4, 0.4, 800, 30, -60, 0, 100, 0},
    {"below the crests", 0.5, 0.5, -1, 70, 5, 0, 80, 0},
    {"outside looking in", -0.3, 0.5, 300, 90, -8, 0, 60, 0},
    {"outside looking away", -0.3, 0.5, 300, 270, -8, 0, 60, 0},
};

static td_grid *load(const char *name)
{
    char path[512];
    td_grid *g = NULL;
    td_err err = {0};
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA, name);
    assert_int_equal(td_dem_load(path, NULL, &g, &err), TD_OK);
    return g;
}

static void scene_of(const td_grid *g, const cam_def *c, int w, int h, td_scene *s)
{
    td_scene_defaults(s);
    s->camera.x = c->fx * (g->w - 1) * g->sx;
    s->camera.y = c->fy * (g->h - 1) * g->sy;
    s->camera.z = c->agl < 0.0 ? g->zmin + 0.25 * (g->zmax - g->zmin) : g->zmax + c->agl;
    s->camera.heading = c->heading;
    s->camera.pitch = c->pitch;
    s->camera.roll = c->roll;
    s->camera.fov = c->fov;
    s->image.width = w;
    s->image.height = h;
}

/* Every pixel (and a sub-pixel offset) of one camera's W x H image: the bound is safe
 * and exact. */
static void check_rays(const td_grid *g, const cam_def *c, int W, int H)
{
    td_scene s;
    td_camera cam;
    td_silhouette *silh = NULL;
    td_view v = {g, NULL};
    int narrowed = 0, n = 0;
    scene_of(g, c, W, H, &s);
    assert_int_equal(td_camera_setup(&s.camera, W, H, g, &cam, NULL), TD_OK);
    assert_int_equal(td_silhouette_build(g, &cam, 2, &silh, NULL), TD_OK);
    assert_non_null(silh);
    assert_true(silh->entries > 0 || !strcmp(c->name, "outside looking away"));
    for (int k = 0; k < W * H * 2; k++) {
        td_ray r;
        uint32_t probes = 0;
        double px = (k / 2) % W + (k & 1 ? 0.37 : 0.0), py = (k / 2) / W + (k & 1 ? -0.29 : 0.0);
        td_camera_ray(&cam, px, py, &r);
        double tc = td_silhouette_clear(silh, r.d, &probes);
        assert_true(tc >= 0.0);
        narrowed += tc > 0.0;
        n++;
        for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
            td_hit h0, h1;
            td_trace(&v, TD_METHOD_INCREMENTAL, (td_surface)sf, &r, &h0);
            if (!(h0.t >= tc))
                fail_msg("%s %s pixel (%g, %g): hit %.17g before the bound %.17g", c->name,
                         td_surface_name((td_surface)sf), px, py, h0.t, tc);
            if (tc < INFINITY) {
                td_trace_from(&v, TD_METHOD_SILHOUETTE, (td_surface)sf, &r, tc, &h1);
                assert_memory_equal(&h0.t, &h1.t, sizeof h0.t);
                if (h0.t < INFINITY) {
                    assert_int_equal(h0.ci, h1.ci);
                    assert_int_equal(h0.cj, h1.cj);
                    assert_memory_equal(h0.n, h1.n, sizeof h0.n);
                }
                assert_int_equal(h1.method, TD_METHOD_INCREMENTAL);
            }
        }
    }
    if (narrowed * 100 < c->min_narrowed_pct * n)
        fail_msg("%s: only %d of %d rays narrowed", c->name, narrowed, n);
    td_silhouette_free(silh);
}

static void test_silhouette_bounds(void **state)
{
    static const char *const dems[] = {"volcano.asc", "picos-dtm.asc", "trinidad-crop.f32"};
    (void)state;
    for (size_t d = 0; d < sizeof dems / sizeof dems[0]; d++) {
        td_grid *g = load(dems[d]);
        for (size_t c = 0; c < sizeof cams / sizeof cams[0]; c++)
            check_rays(g, &cams[c], 48, 36);
        td_grid_free(g);
    }
}

/* An eye right over the grid's edge lines and corners, looking straight down (heading 0
 * and 45: the centre ray's horizontal part a rounding's 6e-17, both axes alike): the
 * strip behind such an eye has its far line at the eye, where the walk's ray stays (its
 * position does not move off the line in doubles). Found by fuzz_render (seed
 * silhouette-edge-down): the partition bounded that strip by -inf and called the centre
 * ray a miss where the walk hit at 11.5 m (silhouette.c strip_q). */
static void test_silhouette_eye_on_edge(void **state)
{
    static const double at[][2] = {{0.5, 1.0}, {0.5, 0.0}, {0.0, 0.5}, {1.0, 0.5}, {0.0, 0.0}, {1.0, 1.0}};
    (void)state;
    /* thirds of a metre in the spacings: on some sizes the last line's y / sy rounds under
       its index (8 rows of 4000/3 m: 6.999999999999999), so the walk's ray is inside */
    for (int32_t n = 6; n <= 10; n++) {
        td_grid *g = NULL;
        const int32_t w = n + 5, h = n;
        assert_int_equal(td_grid_create(w, h, 2000.0 / 3.0, 4000.0 / 3.0, 3, NULL, &g, NULL), TD_OK);
        for (int32_t j = 0; j < h; j++)
            for (int32_t i = 0; i < w; i++)
                g->z[(size_t)j * (size_t)w + (size_t)i] = (float)(190.0 + ((i * 7 + j * 3) % 5) + 0.5 * (j % 2));
        assert_int_equal(td_grid_finish(g, NULL), TD_OK);
        for (size_t k = 0; k < sizeof at / sizeof at[0]; k++)
            for (int hd = 0; hd < 2; hd++) {
                cam_def c = {"eye over the edge", at[k][0], at[k][1], 10, hd ? 45 : 0, -90, 0, 70, 0};
                check_rays(g, &c, 11, 9); /* odd: a pixel's centre is the image's */
            }
        td_grid_free(g);
    }
}

/* An orthographic camera gets no partition (its rays take the walk). */
static void test_silhouette_orthographic(void **state)
{
    td_grid *g = load("volcano.asc");
    td_scene s;
    td_camera cam;
    td_silhouette *silh = (td_silhouette *)&s; /* must be reset */
    (void)state;
    td_scene_defaults(&s);
    s.camera.projection = TD_PROJ_ORTHOGRAPHIC;
    assert_int_equal(td_camera_setup(&s.camera, 32, 32, g, &cam, NULL), TD_OK);
    assert_int_equal(td_silhouette_build(g, &cam, 1, &silh, NULL), TD_OK);
    assert_null(silh);
    td_grid_free(g);
}

/* One render of scene s with method m (devices off when plain). */
static void render(const td_grid *g, td_scene *s, td_method m, int plain, td_render_result *res)
{
    td_view v = {g, NULL};
    td_render_opts o;
    td_err err = {0};
    td_render_opts_default(&o);
    o.threads = 2;
    o.off = plain ? TD_RENDER_OFF_HORIZON : 0;
    s->quality.method = m;
    assert_int_equal(td_render(&v, s, &o, res, &err), TD_OK);
}

static void test_silhouette_render(void **state)
{
    static const char *const dems[] = {"volcano.asc", "trinidad-crop.f32"};
    static const td_format fmts[] = {TD_FORMAT_DEPTH32F, TD_FORMAT_PNG};
    (void)state;
    for (size_t d = 0; d < sizeof dems / sizeof dems[0]; d++) {
        td_grid *g = load(dems[d]);
        for (size_t c = 0; c < sizeof cams / sizeof cams[0]; c++) {
            for (int f = 0; f < 2; f++) {
                td_scene s;
                td_render_result a, b;
                scene_of(g, &cams[c], 40, 30, &s);
                s.image.format = fmts[f];
                s.quality.samples = f ? 2 : 1;
                s.quality.surface = f ? TD_SURFACE_TRIANGLE : TD_SURFACE_BILINEAR;
                s.effects.shadows = f;
                s.effects.sun_azimuth = 250;
                s.effects.sun_elevation = 12;
                render(g, &s, TD_METHOD_SILHOUETTE, 0, &a);
                render(g, &s, TD_METHOD_INCREMENTAL, 1, &b);
                if (f)
                    assert_memory_equal(a.rgba, b.rgba, (size_t)40 * 30 * 4);
                else
                    assert_memory_equal(a.depth, b.depth, (size_t)40 * 30 * sizeof(float));
                /* every camera ray from the partition, counted as such, its work in the steps */
                assert_int_equal(a.stats.silhouette_rays, a.stats.rays[TD_RAY_PRIMARY]);
                assert_int_equal(a.stats.method_rays[TD_METHOD_SILHOUETTE], a.stats.rays[TD_RAY_PRIMARY]);
                assert_int_equal(a.stats.coherent_rays, 0);
                assert_true(a.stats.kind_steps[TD_RAY_PRIMARY] >= a.stats.silhouette_entries);
                assert_int_equal(b.stats.silhouette_rays, 0);
                assert_int_equal(b.stats.silhouette_entries, 0);
                assert_int_equal(a.stats.rays[TD_RAY_SHADOW], b.stats.rays[TD_RAY_SHADOW]);
                td_render_result_free(&a);
                td_render_result_free(&b);
            }
        }
        /* orthographic: no partition, the walk, the same pixels */
        td_scene s;
        td_render_result a, b;
        td_scene_defaults(&s);
        s.camera.projection = TD_PROJ_ORTHOGRAPHIC;
        s.image.width = 32, s.image.height = 32, s.image.format = TD_FORMAT_DEPTH32F;
        render(g, &s, TD_METHOD_SILHOUETTE, 0, &a);
        render(g, &s, TD_METHOD_INCREMENTAL, 0, &b);
        assert_memory_equal(a.depth, b.depth, (size_t)32 * 32 * sizeof(float));
        assert_int_equal(a.stats.silhouette_rays, 0);
        assert_int_equal(a.stats.method_rays[TD_METHOD_INCREMENTAL], 32 * 32);
        td_render_result_free(&a);
        td_render_result_free(&b);
        td_grid_free(g);
    }
}

/* `auto` starts its camera rays from the partition on a view whose tiles mostly lack a
 * max-mipmap (a cold dataset: the same pixels as the walk, labelled silhouette), and
 * from the horizon device once they are built (this level camera's by its image columns,
 * colwalk.h, which start from the horizon too). */
static void test_silhouette_auto(void **state)
{
    td_grid *g = load("trinidad-crop.f32");
    td_accel *a = NULL;
    td_accel_opts ao;
    td_scene s;
    td_render_opts o;
    td_render_result cold, warm, plain;
    td_view vc = {g, NULL}, vw;
    (void)state;
    td_accel_opts_default(&ao);
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    vw.grid = g;
    vw.accel = a->tiles;
    scene_of(g, &cams[0], 48, 36, &s);
    s.image.format = TD_FORMAT_DEPTH32F;
    s.quality.method = TD_METHOD_AUTO;
    td_render_opts_default(&o);
    o.threads = 2;
    assert_int_equal(td_render(&vc, &s, &o, &cold, NULL), TD_OK);
    assert_int_equal(td_render(&vw, &s, &o, &warm, NULL), TD_OK);
    o.off = TD_RENDER_OFF_HORIZON;
    assert_int_equal(td_render(&vc, &s, &o, &plain, NULL), TD_OK);
    assert_memory_equal(cold.depth, plain.depth, (size_t)48 * 36 * sizeof(float));
    assert_memory_equal(warm.depth, plain.depth, (size_t)48 * 36 * sizeof(float));
    assert_int_equal(cold.stats.silhouette_rays, cold.stats.rays[TD_RAY_PRIMARY]);
    assert_true(cold.stats.silhouette_entries > 0);
    assert_int_equal(cold.stats.method_rays[TD_METHOD_SILHOUETTE], cold.stats.rays[TD_RAY_PRIMARY]);
    assert_int_equal(cold.stats.coherent_rays, 0);
    assert_int_equal(warm.stats.silhouette_rays, 0);
    assert_int_equal(warm.stats.silhouette_entries, 0);
    assert_true(warm.stats.coherent_rays > 0);
    assert_int_equal(plain.stats.silhouette_rays, 0);
    td_render_result_free(&cold);
    td_render_result_free(&warm);
    td_render_result_free(&plain);
    td_accel_free(a);
    td_grid_free(g);
}

/* The method's name parses and prints through the table. */
static void test_silhouette_name(void **state)
{
    td_method m = TD_METHOD_AUTO;
    (void)state;
    assert_int_equal(td_method_parse("silhouette", &m), TD_OK);
    assert_int_equal(m, TD_METHOD_SILHOUETTE);
    assert_string_equal(td_method_name(TD_METHOD_SILHOUETTE), "silhouette");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_silhouette_bounds),
        cmocka_unit_test(test_silhouette_eye_on_edge),
        cmocka_unit_test(test_silhouette_orthographic),
        cmocka_unit_test(test_silhouette_render),
        cmocka_unit_test(test_silhouette_auto),
        cmocka_unit_test(test_silhouette_name),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
