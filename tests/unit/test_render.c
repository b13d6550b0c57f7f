/* test_render.c: the renderer (core/render.c) on procedural terrain.
 *
 * - An effect absent from the scene traces no ray and runs no pass (stats: rays by kind,
 *   stage_ran); each effect present runs its pass, traces its rays (exact counts where
 *   they are known) and changes the picture the way it should (shadows only darken, sky
 *   only fills the background, haze only touches the terrain).
 * - Curvature bends rays only when the view reaches far enough for it to move a pixel,
 *   and then meets flat ground where the closed form says; shadow rays bend about their
 *   origin by the right drop (a far wall shadows or not as the parabola says).
 * - Supersampling traces n*n rays per pixel; the image is the same for 1 and 2 threads;
 *   depth agrees with picking; cancellation and unsupported options are refused.
 * - Golden images: small scenes, one per effect, compared by PSNR (>= 35 dB) with
 *   tests/golden/NAME.png. TERRAD_UPDATE_GOLDEN=1 rewrites them (then look at them).
 * - A pick of every pixel traces exactly the render's camera rays (same distances, same
 *   counts, straight and bent); partial stats add up (td_render_stats_add); td_render
 *   and td_render_pick hold every row of the table of limits at both ends, naming the
 *   row's field in err.field. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include <jansson.h>
#include <unistd.h>

#include "accel.h"
#include "cli.h"
#include "dem.h"
#include "limit.h"
#include "render.h"
#include "terrain.h"

#define GOLDEN_DIR TERRAD_TEST_DATA "/../golden"
#define W 64
#define H 48

static td_grid *grid;      /* 129 x 129, 30 m, 600 m of relief */
static td_scene scene;     /* large (pick list): keep it off the stack */

static int setup(void **state)
{
    td_terrain_params p;
    td_err err = {0};
    (void)state;
    td_terrain_params_default(&p);
    p.width = p.height = 129;
    p.spacing = 30.0;
    p.feature_m = 2500.0;
    p.relief_m = 600.0;
    p.base_m = 1000.0;
    p.seed = 11;
    return td_terrain_generate(&p, 6, &grid, &err) != TD_OK;
}

static int teardown(void **state)
{
    (void)state;
    td_grid_free(grid);
    return 0;
}

/* Looking north-east across the terrain from its south-west corner, horizon in view. */
static void base_scene(td_scene *s)
{
    td_scene_defaults(s);
    snprintf(s->dataset, sizeof s->dataset, "procedural");
    s->camera.x = -300.0;
    s->camera.y = -300.0;
    s->camera.z = 2100.0;
    s->camera.heading = 45.0;
    s->camera.pitch = -12.0;
    s->camera.fov = 60.0;
    s->image.width = W;
    s->image.height = H;
    s->quality.method = TD_METHOD_INCREMENTAL;
    s->quality.surface = TD_SURFACE_BILINEAR;
    s->effects.sun_azimuth = 300.0;
    s->effects.sun_elevation = 20.0;
}

static void render(const td_scene *s, int threads, td_render_result *res)
{
    td_view v = {grid, NULL};
    td_render_opts o;
    td_err err = {0};
    td_render_opts_default(&o);
    o.threads = threads;
    td_status st = td_render(&v, s, &o, res, &err);
    if (st)
        print_error("render: %s\n", err.msg);
    assert_int_equal(st, TD_OK);
}

static const int effect_stages[] = {TD_STAGE_CURVATURE, TD_STAGE_WATER, TD_STAGE_SHADOWS,
                                    TD_STAGE_AO, TD_STAGE_HAZE, TD_STAGE_SKY};

/* Asserts that of the optional stages exactly `want` ran (-1: none). */
static void only_stage(const td_render_stats *st, int want)
{
    for (size_t i = 0; i < sizeof effect_stages / sizeof effect_stages[0]; i++) {
        int k = effect_stages[i];
        if (st->stage_ran[k] != (k == want))
            print_error("stage %s ran=%d\n", td_stage_name((td_stage)k), st->stage_ran[k]);
        assert_int_equal(st->stage_ran[k], k == want);
    }
    assert_true(st->stage_ran[TD_STAGE_PRIMARY]);
    assert_true(st->stage_ran[TD_STAGE_RESOLVE]);
}

static void test_absent_effects_cost_nothing(void **state)
{
    td_render_result r;
    (void)state;
    base_scene(&scene);
    render(&scene, 2, &r);
    assert_int_equal(r.stats.rays[TD_RAY_PRIMARY], W * H);
    assert_int_equal(r.stats.rays[TD_RAY_SHADOW], 0);
    assert_int_equal(r.stats.rays[TD_RAY_REFLECTION], 0);
    assert_int_equal(r.stats.rays[TD_RAY_AO], 0);
    assert_int_equal(r.stats.curved_rays, 0);
    only_stage(&r.stats, -1);
    assert_true(r.stats.stage_ran[TD_STAGE_SHADE]);
    assert_true(r.stats.hits > W * H / 4 && r.stats.hits < W * H);
    assert_true(r.stats.steps > 0);
    /* without sky the background is transparent, the terrain opaque */
    int clear = 0, opaque = 0;
    for (int i = 0; i < W * H; i++) {
        clear += r.rgba[4 * i + 3] == 0;
        opaque += r.rgba[4 * i + 3] == 255;
    }
    assert_true(clear > 0 && opaque > 0);
    assert_int_equal(clear + opaque, W * H); /* one sample per pixel: no partial alpha */
    assert_int_equal((uint64_t)opaque, r.stats.hits);
    td_render_result_free(&r);
}

/* Every render says how far its picture is from the exact one: the camera hits' height
 * against the bilinear surface. Bilinear is exact up to rounding; the others are off by
 * what their surface is off, the flat-topped plane most; a hit is never closer to the
 * exact surface than 0 nor farther than the cell's relief. */
static void test_height_error(void **state)
{
    td_render_result r;
    double mean[TD_SURFACE_COUNT];
    (void)state;
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        base_scene(&scene);
        scene.quality.surface = (td_surface)s;
        render(&scene, 2, &r);
        assert_int_equal(r.stats.height_err_hits, r.stats.hits); /* no voids here */
        assert_true(r.stats.height_err_mean_m >= 0.0 && r.stats.height_err_max_m >= r.stats.height_err_mean_m);
        assert_true(r.stats.height_err_max_m < 600.0); /* the terrain's relief */
        mean[s] = r.stats.height_err_mean_m;
        td_render_result_free(&r);
    }
    print_message("  height error, mean m: plane %.3g linear %.3g triangle %.3g bilinear %.3g\n",
                  mean[TD_SURFACE_PLANE], mean[TD_SURFACE_LINEAR], mean[TD_SURFACE_TRIANGLE],
                  mean[TD_SURFACE_BILINEAR]);
    assert_true(mean[TD_SURFACE_BILINEAR] < 1e-6);
    assert_true(mean[TD_SURFACE_TRIANGLE] > 1e-3 && mean[TD_SURFACE_LINEAR] > 1e-3);
    assert_true(mean[TD_SURFACE_PLANE] > mean[TD_SURFACE_TRIANGLE] && mean[TD_SURFACE_PLANE] > mean[TD_SURFACE_LINEAR]);
}

static void test_shadows(void **state)
{
    td_render_result a, b;
    (void)state;
    base_scene(&scene);
    render(&scene, 2, &a);
    scene.effects.shadows = 1;
    render(&scene, 2, &b);
    only_stage(&b.stats, TD_STAGE_SHADOWS);
    assert_true(b.stats.rays[TD_RAY_SHADOW] > 0);
    assert_true(b.stats.rays[TD_RAY_SHADOW] <= b.stats.hits);
    assert_int_equal(b.stats.rays[TD_RAY_AO] + b.stats.rays[TD_RAY_REFLECTION], 0);
    int darker = 0;
    for (int i = 0; i < W * H * 4; i++) {
        assert_true(b.rgba[i] <= a.rgba[i]); /* a shadow never brightens */
        darker += b.rgba[i] < a.rgba[i];
    }
    assert_true(darker > 20);
    td_render_result_free(&a);
    td_render_result_free(&b);
}

/* What td_accel_opts_for builds per method, and that auto draws with the max-mipmap alone
 * what it draws with the planes beside it (it takes the max-mipmap wherever it is
 * resident): the same pixels and the same counts of rays by method, shadows on. */
static void test_auto_reads_what_it_builds(void **state)
{
    (void)state;
    static const int want[TD_METHOD_COUNT][2] = {
        [TD_METHOD_INCREMENTAL] = {0, 0}, [TD_METHOD_HIERARCHICAL] = {1, 0},
        [TD_METHOD_PARAMETRIC] = {0, 1}, [TD_METHOD_AUTO] = {1, 0}, [TD_METHOD_SILHOUETTE] = {0, 0}};
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        td_accel_opts o;
        td_accel_opts_for((td_method)m, &o);
        assert_int_equal(o.maxmip, want[m][0]);
        assert_int_equal(o.planes, want[m][1]);
        assert_int_equal(o.planes_k, TD_PLANES_K_DEFAULT);
    }
    for (int surf = 0; surf < TD_SURFACE_COUNT; surf++) {
        td_render_result r[2];
        td_accel *a[2] = {NULL, NULL};
        for (int k = 0; k < 2; k++) {
            td_accel_opts o;
            td_render_opts ro;
            td_err err = {0};
            if (k == 0)
                td_accel_opts_default(&o);
            else
                td_accel_opts_for(TD_METHOD_AUTO, &o);
            o.threads = 1;
            assert_int_equal(td_accel_build(grid, &o, &a[k], NULL, &err), TD_OK);
            td_view v = {grid, a[k]->tiles};
            base_scene(&scene);
            scene.quality.method = TD_METHOD_AUTO;
            scene.quality.surface = (td_surface)surf;
            scene.effects.shadows = 1;
            td_render_opts_default(&ro);
            ro.threads = 1;
            assert_int_equal(td_render(&v, &scene, &ro, &r[k], &err), TD_OK);
        }
        assert_memory_equal(r[0].rgba, r[1].rgba, (size_t)W * H * 4);
        assert_memory_equal(r[0].stats.method_rays, r[1].stats.method_rays, sizeof r[0].stats.method_rays);
        assert_true(r[0].stats.method_rays[TD_METHOD_HIERARCHICAL] > 0);
        for (int k = 0; k < 2; k++) {
            td_render_result_free(&r[k]);
            td_accel_free(a[k]);
        }
    }
}

static void test_sky_and_haze(void **state)
{
    td_render_result a, b, c;
    (void)state;
    base_scene(&scene);
    render(&scene, 2, &a);
    scene.effects.sky = 1;
    render(&scene, 2, &b);
    only_stage(&b.stats, TD_STAGE_SKY);
    assert_int_equal(b.stats.rays[TD_RAY_SHADOW] + b.stats.rays[TD_RAY_AO] +
                         b.stats.rays[TD_RAY_REFLECTION], 0);
    for (int i = 0; i < W * H; i++) {
        if (a.rgba[4 * i + 3] == 255) /* terrain untouched */
            assert_memory_equal(&a.rgba[4 * i], &b.rgba[4 * i], 4);
        else /* background filled, blue above */
            assert_int_equal(b.rgba[4 * i + 3], 255);
    }
    assert_true(b.rgba[2] > b.rgba[0]);
    scene.effects.sky = 0;
    scene.effects.haze = 1;
    scene.effects.haze_visibility_km = 3.0;
    render(&scene, 2, &c);
    only_stage(&c.stats, TD_STAGE_HAZE);
    int changed = 0;
    for (int i = 0; i < W * H; i++) {
        if (a.rgba[4 * i + 3] == 0)
            assert_int_equal(c.rgba[4 * i + 3], 0); /* haze does not paint the background */
        else
            changed += memcmp(&a.rgba[4 * i], &c.rgba[4 * i], 3) != 0;
    }
    assert_true((uint64_t)changed > c.stats.hits / 2);
    td_render_result_free(&a);
    td_render_result_free(&b);
    td_render_result_free(&c);
}

static void test_water_and_ao(void **state)
{
    td_render_result r;
    (void)state;
    base_scene(&scene);
    scene.effects.water = 1;
    scene.effects.water_level = grid->zmin + 0.3 * (grid->zmax - grid->zmin);
    render(&scene, 2, &r);
    only_stage(&r.stats, TD_STAGE_WATER);
    assert_true(r.stats.rays[TD_RAY_REFLECTION] > 0);
    /* every reflection ray belongs to a camera ray that met the water: bluish pixels */
    int blue = 0;
    for (int i = 0; i < W * H; i++)
        blue += r.rgba[4 * i + 3] == 255 && r.rgba[4 * i + 2] > r.rgba[4 * i];
    assert_true((uint64_t)blue >= r.stats.rays[TD_RAY_REFLECTION] / 2);
    td_render_result_free(&r);

    base_scene(&scene);
    scene.effects.ambient_occlusion = 5;
    render(&scene, 2, &r);
    only_stage(&r.stats, TD_STAGE_AO);
    assert_int_equal(r.stats.rays[TD_RAY_AO], 5 * r.stats.hits);
    td_render_result_free(&r);
}

static void test_supersampling_and_threads(void **state)
{
    td_render_result a, b;
    (void)state;
    base_scene(&scene);
    scene.quality.samples = 3;
    scene.effects.shadows = 1;
    scene.effects.sky = 1;
    scene.effects.haze = 1;
    scene.effects.ambient_occlusion = 4;
    render(&scene, 1, &a);
    render(&scene, 2, &b);
    assert_int_equal(a.stats.rays[TD_RAY_PRIMARY], 9 * W * H);
    assert_int_equal(a.stats.threads, 1);
    assert_int_equal(b.stats.threads, 2);
    for (int k = 0; k < TD_RAY_KIND_COUNT; k++)
        assert_int_equal(a.stats.rays[k], b.stats.rays[k]);
    assert_memory_equal(a.rgba, b.rgba, (size_t)W * H * 4);
    /* edges of the terrain against the background get partial alpha */
    base_scene(&scene);
    scene.quality.samples = 3;
    td_render_result c;
    render(&scene, 2, &c);
    int partial = 0;
    for (int i = 0; i < W * H; i++)
        partial += c.rgba[4 * i + 3] > 0 && c.rgba[4 * i + 3] < 255;
    assert_true(partial > 0);
    td_render_result_free(&a);
    td_render_result_free(&b);
    td_render_result_free(&c);
}

static void test_depth_matches_pick(void **state)
{
    td_render_result r;
    td_view v = {grid, NULL};
    td_err err = {0};
    td_pick pk[3];
    (void)state;
    base_scene(&scene);
    scene.image.format = TD_FORMAT_DEPTH32F;
    scene.effects.shadows = 1; /* irrelevant to depth: must trace nothing */
    render(&scene, 2, &r);
    assert_null(r.rgba);
    assert_non_null(r.depth);
    assert_int_equal(r.stats.rays[TD_RAY_SHADOW], 0);
    assert_false(r.stats.stage_ran[TD_STAGE_SHADE]);
    scene.image.format = TD_FORMAT_PICK;
    scene.npick = 3;
    int px[3][2] = {{32, 40}, {10, 30}, {5, 0}};
    for (int i = 0; i < 3; i++) {
        scene.pick[i][0] = px[i][0];
        scene.pick[i][1] = px[i][1];
    }
    assert_int_equal(td_render_pick(&v, &scene, pk, NULL, &err), TD_OK);
    for (int i = 0; i < 3; i++) {
        float d = r.depth[px[i][1] * W + px[i][0]];
        if (pk[i].hit) {
            assert_float_equal(d, pk[i].distance, 1e-3 * pk[i].distance);
            assert_true(pk[i].height_error_m < 1e-6); /* bilinear: the exact surface */
        } else {
            assert_true(isinf(d));
            assert_true(isnan(pk[i].height_error_m));
        }
    }
    assert_true(pk[0].hit);
    assert_false(pk[2].hit); /* top-left corner: sky */
    /* with water, depth is to the water's surface where it is nearer than the terrain */
    {
        td_render_result rw;
        td_camera cam;
        td_ray ray;
        int nearer = 0;
        scene.image.format = TD_FORMAT_DEPTH32F;
        scene.effects.water = 1;
        scene.effects.water_level = pk[0].p[2] + 50.0;
        render(&scene, 2, &rw);
        assert_int_equal(rw.stats.rays[TD_RAY_REFLECTION], 0); /* depth traces no reflection */
        for (int i = 0; i < W * H; i++) {
            if (isfinite(r.depth[i]))
                assert_true(rw.depth[i] <= r.depth[i] * (1.0f + 1e-6f));
            nearer += rw.depth[i] < r.depth[i] * (1.0f - 1e-4f);
        }
        assert_true(nearer > 0);
        assert_int_equal(td_camera_setup(&scene.camera, W, H, grid, &cam, &err), TD_OK);
        td_camera_ray(&cam, px[0][0], px[0][1], &ray);
        assert_true(ray.d[2] < 0.0);
        double tw = (ray.o[2] - scene.effects.water_level) / -ray.d[2];
        assert_float_equal(rw.depth[px[0][1] * W + px[0][0]], tw, 1e-4 * tw);
        assert_true(tw < pk[0].distance);
        td_render_result_free(&rw);
        scene.effects.water = 0;
    }
    /* depth16 encodes with a scale and 65535 for nothing */
    td_buf b;
    double scale = 0.0;
    scene.image.format = TD_FORMAT_DEPTH16;
    assert_int_equal(td_render_encode(&r, &scene, &b, &scale, &err), TD_OK);
    assert_true(scale > 0.0);
    assert_true(r.stats.stage_ran[TD_STAGE_ENCODE]);
    td_buf_free(&b);
    td_render_result_free(&r);
}

/* Flat ground, a long shallow view: curvature bends the centre ray so that it meets the
 * ground where a*t^2*cos^2(p) + t*sin(p) + h = 0 says, well beyond the straight hit. */
/* Flat ground 25.6 km square at 100 m, and a long, narrow view over it from the south
 * edge, 50 m above the ground, 0.3 degrees down: the far camera rays bend. */
static td_grid *flat_ground_view(td_scene *s)
{
    td_terrain_params p;
    td_grid *flat = NULL;
    td_err err = {0};
    td_terrain_params_default(&p);
    p.width = p.height = 257;
    p.spacing = 100.0;
    p.relief_m = 0.0;
    p.base_m = 100.0;
    assert_int_equal(td_terrain_generate(&p, 6, &flat, &err), TD_OK);
    td_scene_defaults(s);
    s->camera.x = 12800.0;
    s->camera.y = 0.0;
    s->camera.z = 150.0;
    s->camera.pitch = -0.3;
    s->camera.fov = 2.0;
    s->quality.method = TD_METHOD_INCREMENTAL;
    return flat;
}

static void test_curvature(void **state)
{
    td_grid *flat = flat_ground_view(&scene);
    td_err err = {0};
    td_pick pk[1];
    td_render_stats st;
    (void)state;
    td_view v = {flat, NULL};
    scene.image.width = W;
    scene.image.height = H;
    scene.image.format = TD_FORMAT_PICK;
    scene.npick = 1;
    scene.pick[0][0] = (W - 1) / 2.0;
    scene.pick[0][1] = (H - 1) / 2.0; /* exactly the optical axis */
    double sp = sin(-0.3 * M_PI / 180.0), cp = cos(-0.3 * M_PI / 180.0);
    double straight = 50.0 / -sp;
    assert_int_equal(td_render_pick(&v, &scene, pk, &st, &err), TD_OK);
    assert_int_equal(st.curved_rays, 0);
    assert_float_equal(pk[0].distance, straight, 0.01);

    scene.effects.curvature = 1; /* k = 0.13 */
    double a = (1.0 - 0.13) / (2.0 * 6371000.0);
    double A = a * cp * cp, disc = sp * sp - 4.0 * A * 50.0;
    assert_true(disc > 0.0);
    double curved = (-sp - sqrt(disc)) / (2.0 * A);
    assert_int_equal(td_render_pick(&v, &scene, pk, &st, &err), TD_OK);
    assert_int_equal(st.curved_rays, 1);
    assert_true(st.curve_segments >= 1);
    assert_true(pk[0].hit);
    assert_true(curved - straight > 1000.0);
    assert_true(fabs(pk[0].distance - curved) < 0.1 * (curved - straight));
    assert_float_equal(pk[0].p[2], 100.0, 1e-3);

    /* a full render runs the curvature stage */
    td_render_result r;
    td_render_opts o;
    td_render_opts_default(&o);
    scene.image.format = TD_FORMAT_PNG;
    scene.npick = 0;
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_OK);
    assert_true(r.stats.stage_ran[TD_STAGE_CURVATURE]);
    assert_true(r.stats.curved_rays > 0);
    assert_true(r.stats.curved_rays <= r.stats.rays[TD_RAY_PRIMARY]);
    td_render_result_free(&r);

    /* a wide view of the same ground: the drop never reaches a pixel, nothing bends */
    scene.camera.fov = 60.0;
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_OK);
    assert_false(r.stats.stage_ran[TD_STAGE_CURVATURE]);
    assert_int_equal(r.stats.curved_rays, 0);
    td_render_result_free(&r);
    td_grid_free(flat);
}

/* Flat ground 80 km x 2 km at 0 m with a wall of height `wall` from x = 70 km east. */
static td_grid *walled_plain(double wall)
{
    td_grid *g = NULL;
    td_err err = {0};
    assert_int_equal(td_grid_create(801, 21, 100.0, 100.0, 6, NULL, &g, &err), TD_OK);
    for (int32_t j = 0; j < 21; j++)
        for (int32_t i = 0; i < 801; i++)
            g->z[(size_t)j * 801 + (size_t)i] = i >= 700 ? (float)wall : 0.0f;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    return g;
}

/* Mean of R + G + B over the image. */
static double mean_rgb(const td_render_result *r)
{
    double sum = 0.0;
    size_t n = (size_t)r->width * (size_t)r->height;
    for (size_t k = 0; k < n; k++)
        sum += r->rgba[4 * k] + r->rgba[4 * k + 1] + r->rgba[4 * k + 2];
    return sum / (double)n;
}

/* Shadow rays bend about their origin under curvature. The ground near x = 1 km is lit by
 * a sun 5 degrees up in the east over a wall 69 km away: a straight ray passes x = 70 km
 * at 69000 tan 5deg = 6037 m; bent, a*69000^2 = 325 m higher (k = 0.13), 6362 m. A wall of
 * 6300 m shadows the ground only without curvature; one of 6420 m shadows it with
 * curvature too, so the drop is right within -19% .. +18%; one of 5000 m shadows neither.
 * Camera rays are not bent here (their pixel moves only past 480 km). The occlusion
 * device (bent rays as any-hit chords, each asked first straight: its chords lie above the
 * straight ray, so a clear straight ray is a lit bent one) gives the picture that the
 * bent rays' nearest hits give (TD_RENDER_OFF_OCCLUSION); under the 5000 m wall it traces
 * no bent ray at all. */
static void test_curvature_shadows(void **state)
{
    const double walls[3] = {6300.0, 6420.0, 5000.0};
    double lit[3][2];
    (void)state;
    for (int k = 0; k < 3; k++) {
        td_grid *g = walled_plain(walls[k]);
        td_view v = {g, NULL};
        for (int curv = 0; curv < 2; curv++) {
            td_render_result r, plain;
            td_render_opts o;
            td_err err = {0};
            td_scene_defaults(&scene);
            scene.camera.x = 1000.0;
            scene.camera.y = -300.0;
            scene.camera.z = 800.0;
            scene.camera.heading = 0.0;
            scene.camera.pitch = -45.0;
            scene.camera.fov = 30.0;
            scene.image.width = 32;
            scene.image.height = 24;
            scene.quality.method = TD_METHOD_INCREMENTAL;
            scene.effects.sun_azimuth = 90.0;
            scene.effects.sun_elevation = 5.0;
            scene.effects.ambient = 0.0;
            scene.effects.shadows = 1;
            scene.effects.curvature = curv;
            td_render_opts_default(&o);
            o.threads = 2;
            assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_OK);
            assert_int_equal(r.stats.hits, 32 * 24);
            assert_int_equal(r.stats.rays[TD_RAY_SHADOW], 32 * 24);
            assert_int_equal(r.stats.curved_rays, 0);
            /* bent: those whose straight ray is shadowed (every one under the walls that
               shade it straight, none under the 5000 m one) */
            assert_int_equal(r.stats.curved_secondary, curv && k < 2 ? 32 * 24 : 0);
            assert_true(curv && k < 2 ? r.stats.curve_segments >= 32 * 24 : r.stats.curve_segments == 0);
            o.off = TD_RENDER_OFF_OCCLUSION;
            assert_int_equal(td_render(&v, &scene, &o, &plain, &err), TD_OK);
            assert_int_equal(plain.stats.curved_secondary, curv ? 32 * 24 : 0);
            assert_memory_equal(r.rgba, plain.rgba, (size_t)32 * 24 * 4);
            lit[k][curv] = mean_rgb(&r);
            td_render_result_free(&r);
            td_render_result_free(&plain);
        }
        td_grid_free(g);
    }
    print_message("  mean R+G+B: wall 6300 m straight %.1f bent %.1f; wall 6420 m straight %.1f bent %.1f; "
                  "wall 5000 m straight %.1f bent %.1f\n",
                  lit[0][0], lit[0][1], lit[1][0], lit[1][1], lit[2][0], lit[2][1]);
    assert_true(lit[0][0] < 1.0);           /* shadowed, no ambient: black */
    assert_true(lit[0][1] > 10.0);          /* bent over the 6300 m wall: sunlit */
    assert_true(lit[1][0] < 1.0 && lit[1][1] < 1.0); /* 6420 m shadows both */
    assert_true(lit[2][0] > 10.0 && lit[2][1] > 10.0); /* 5000 m neither */
}

/* td_render_opts.sunlit, as the server keeps sun bounds (tilestore.h, td_snapshot_sunlit) */
typedef struct sun_keeper {
    int mode;         /* 0 build and keep; 1 the kept one; 2 one for another sun; 3 none */
    int calls;
    double sun[3];    /* the sun the render asked for */
    td_sunlit *lit;   /* kept (mode 0 builds it on a view with the max-mipmaps) */
    td_sunlit *other; /* built for another sun */
    const td_view *build_view;
} sun_keeper;

static td_status keep_sun(void *ctx, const td_view *v, const double sun[3], const td_sunlit **out, int *kept,
                          td_err *err)
{
    sun_keeper *k = ctx;
    td_status rc = TD_OK;
    k->calls++;
    memcpy(k->sun, sun, sizeof k->sun);
    *out = NULL;
    *kept = k->mode != 0;
    if (k->mode == 0) {
        rc = td_sunlit_build(k->build_view ? k->build_view : v, sun, 0, &k->lit, err);
        *out = k->lit;
    } else if (k->mode == 1) {
        *out = k->lit;
    } else if (k->mode == 2) {
        double other[3] = {sun[1], -sun[0], sun[2]}; /* turned a quarter: same elevation */
        rc = td_sunlit_build(v, other, 0, &k->other, err);
        *out = k->other;
    }
    return rc;
}

/* A sun bound kept from an earlier render (built on a view with the max-mipmaps) gives
 * the render without them the same picture, and the render does not build its own; one
 * for another sun, or none, is not used: the render builds its own, same picture. With
 * the sun bound off the keeper is not asked. */
static void test_kept_sun_bound(void **state)
{
    td_accel *a = NULL;
    td_accel_opts ao;
    td_err err = {0};
    (void)state;
    td_accel_opts_for(TD_METHOD_AUTO, &ao);
    ao.threads = 1;
    assert_int_equal(td_accel_build(grid, &ao, &a, NULL, &err), TD_OK);
    td_view va = {grid, a->tiles}, v = {grid, NULL};
    for (int surf = 0; surf < TD_SURFACE_COUNT; surf++) {
        td_render_result plain, r;
        td_render_opts o;
        sun_keeper k = {0};
        base_scene(&scene);
        scene.quality.surface = (td_surface)surf;
        scene.effects.shadows = 1;
        scene.effects.sun_elevation = 8.0; /* long shadows: the bound ends most rays */
        td_render_opts_default(&o);
        o.threads = 2;
        assert_int_equal(td_render(&v, &scene, &o, &plain, &err), TD_OK);
        assert_int_equal(plain.stats.sun_bound, TD_SUN_BOUND_BUILT);
        o.sunlit = keep_sun;
        o.sunlit_ctx = &k;
        k.build_view = &va;
        const td_sun_bound want[4] = {TD_SUN_BOUND_BUILT, TD_SUN_BOUND_KEPT, TD_SUN_BOUND_BUILT, TD_SUN_BOUND_BUILT};
        for (k.mode = 0; k.mode < 4; k.mode++) {
            k.calls = 0;
            assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_OK);
            assert_int_equal(k.calls, 1);
            assert_true(td_sunlit_fits(k.lit, &v, k.sun));
            assert_int_equal(r.stats.sun_bound, want[k.mode]);
            assert_memory_equal(r.rgba, plain.rgba, (size_t)W * H * 4);
            assert_int_equal(r.stats.rays[TD_RAY_SHADOW], plain.stats.rays[TD_RAY_SHADOW]);
            td_render_result_free(&r);
        }
        assert_false(td_sunlit_fits(k.other, &v, k.sun));
        o.off = TD_RENDER_OFF_SUNLIT;
        k.calls = 0;
        k.mode = 1;
        assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_OK);
        assert_int_equal(k.calls, 0);
        assert_int_equal(r.stats.sun_bound, TD_SUN_BOUND_NONE);
        assert_memory_equal(r.rgba, plain.rgba, (size_t)W * H * 4);
        td_render_result_free(&r);
        td_render_result_free(&plain);
        td_sunlit_free(k.lit);
        td_sunlit_free(k.other);
    }
    td_accel_free(a);
}

static void test_refusals_and_cancel(void **state)
{
    td_render_result r;
    td_view v = {grid, NULL};
    td_err err = {0};
    td_render_opts o;
    atomic_int cancel;
    (void)state;
    td_render_opts_default(&o);
    base_scene(&scene);
    scene.quality.lod = 1; /* no coarse levels given */
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_EUNSUPPORTED);
    assert_non_null(strstr(err.msg, "quality.lod"));
    scene.quality.lod_pixels = 100.0;
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "quality.lod"));
    base_scene(&scene);
    scene.quality.samples = 9;
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "quality.samples"));
    base_scene(&scene);
    scene.camera.fov = 0.0;
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "camera.fov"));
    base_scene(&scene);
    scene.effects.drape[0] = '/';
    snprintf(scene.effects.drape, sizeof scene.effects.drape, "/nonexistent/drape.png");
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_EFORMAT);
    assert_null(r.rgba);
    base_scene(&scene);
    atomic_init(&cancel, 1);
    o.cancel = &cancel;
    assert_int_equal(td_render(&v, &scene, &o, &r, &err), TD_ECANCELED);
    assert_null(r.rgba);
}

/* `terrad render` end to end on a real DEM fixture: image of the asked size, stats with
 * rays by kind and only the stages that ran; a scene error is a usage error (2). */
static void test_cli_render(void **state)
{
    char dir[] = "/tmp/terrad-render-XXXXXX";
    char scene_path[256], out_path[256], stats_path[256], bad_path[256];
    (void)state;
    assert_non_null(mkdtemp(dir));
    snprintf(scene_path, sizeof scene_path, "%s/scene.json", dir);
    snprintf(out_path, sizeof out_path, "%s/out.png", dir);
    snprintf(stats_path, sizeof stats_path, "%s/stats.json", dir);
    snprintf(bad_path, sizeof bad_path, "%s/bad.json", dir);
    FILE *f = fopen(scene_path, "w");
    assert_non_null(f);
    fprintf(f, "{\"dataset\": \"%s/volcano.asc\", \"camera\": {\"position\": {\"x\": 300, "
               "\"y\": -300, \"z\": 500}, \"pitch\": -25, \"fov\": 50}, \"image\": {\"width\": 80, "
               "\"height\": 60}, \"effects\": {\"shadows\": true, \"sky\": true}}",
            TERRAD_TEST_DATA);
    fclose(f);
    char *argv[] = {"render", scene_path, "-o", out_path, "--stats", stats_path, "--threads", "2", NULL};
    assert_int_equal(td_cli_render(8, argv), 0);
    td_image8 *img = NULL;
    td_err err = {0};
    assert_int_equal(td_image_load(out_path, 4, 1u << 20, &img, &err), TD_OK);
    assert_int_equal(img->width, 80);
    assert_int_equal(img->height, 60);
    td_image_free(img);
    json_error_t je;
    json_t *st = json_load_file(stats_path, 0, &je);
    assert_non_null(st);
    json_t *rays = json_object_get(st, "rays"), *stages = json_object_get(st, "stages_ms");
    assert_int_equal(json_integer_value(json_object_get(rays, "primary")), 80 * 60);
    assert_true(json_integer_value(json_object_get(rays, "shadow")) > 0);
    assert_int_equal(json_integer_value(json_object_get(rays, "ao")), 0);
    assert_int_equal(json_integer_value(json_object_get(rays, "reflection")), 0);
    assert_non_null(json_object_get(stages, "primary"));
    assert_non_null(json_object_get(stages, "shadows"));
    assert_non_null(json_object_get(stages, "sky"));
    assert_non_null(json_object_get(stages, "encode"));
    assert_null(json_object_get(stages, "haze"));
    assert_null(json_object_get(stages, "ao"));
    json_decref(st);

    f = fopen(bad_path, "w");
    assert_non_null(f);
    fprintf(f, "{\"dataset\": \"x\", \"camera\": {\"fov\": 500, \"position\": {\"x\": 1, \"y\": 1, \"z\": 1}}}");
    fclose(f);
    char *argv2[] = {"render", bad_path, "-o", out_path, NULL};
    assert_int_equal(td_cli_render(4, argv2), 2);
    unlink(scene_path);
    unlink(out_path);
    unlink(stats_path);
    unlink(bad_path);
    rmdir(dir);
}

/* Reads a ray file of `terrad trace` (little-endian float64 ox oy oz dx dy dz). */
static size_t read_rays(const char *path, td_ray **out)
{
    FILE *f = fopen(path, "rb");
    unsigned char b[48];
    size_t n = 0, cap = 0;
    td_ray *r = NULL;
    assert_non_null(f);
    while (fread(b, sizeof b, 1, f) == 1) {
        if (n == cap) {
            cap = cap ? 2 * cap : 1024;
            r = realloc(r, cap * sizeof *r);
            assert_non_null(r);
        }
        for (int k = 0; k < 6; k++) {
            uint64_t u = 0;
            double v;
            for (int j = 0; j < 8; j++)
                u |= (uint64_t)b[8 * k + j] << (8 * j);
            memcpy(&v, &u, sizeof v);
            if (k < 3)
                r[n].o[k] = v;
            else
                r[n].d[k - 3] = v;
        }
        r[n].tmin = 0.0;
        r[n].tmax = INFINITY;
        n++;
    }
    fclose(f);
    *out = r;
    return n;
}

/* terrad render --rays writes the camera ray of every pixel, and pixel k of a depth32f
 * render is the distance along ray k to its hit (td_trace on the same grid, the scene's
 * method and surface); --shadow-rays writes as many rays as the stats count, each of
 * them occluded exactly where the shaded image is dark from a shadow. */
static void test_cli_rays(void **state)
{
    char dir[] = "/tmp/terrad-rays-XXXXXX", scene_path[256], out_path[256], rays_path[256],
         stats_path[256], dem_path[256];
    td_ray *rays = NULL;
    td_grid *g = NULL;
    td_err err = {0};
    float *depth;
    FILE *f;
    (void)state;
    assert_non_null(mkdtemp(dir));
    snprintf(scene_path, sizeof scene_path, "%s/scene.json", dir);
    snprintf(out_path, sizeof out_path, "%s/out.f32", dir);
    snprintf(rays_path, sizeof rays_path, "%s/rays.bin", dir);
    snprintf(stats_path, sizeof stats_path, "%s/stats.json", dir);
    snprintf(dem_path, sizeof dem_path, "%s/volcano.asc", TERRAD_TEST_DATA);
    f = fopen(scene_path, "w");
    assert_non_null(f);
    fprintf(f, "{\"dataset\": \"%s\", \"camera\": {\"position\": {\"x\": 300, \"y\": -300, \"z\": 400}, "
               "\"heading\": 10, \"pitch\": -12, \"roll\": 20, \"fov\": 70}, \"image\": {\"width\": 64, "
               "\"height\": 48, \"format\": \"depth32f\"}, \"quality\": {\"method\": \"auto\", "
               "\"surface\": \"triangle\"}}", dem_path);
    fclose(f);
    char *argv[] = {"render", scene_path, "-o", out_path, "--rays", rays_path, "--threads", "2", NULL};
    assert_int_equal(td_cli_render(8, argv), 0);
    assert_int_equal(read_rays(rays_path, &rays), 64 * 48);
    assert_int_equal(td_dem_load(dem_path, NULL, &g, &err), TD_OK);
    depth = malloc(64 * 48 * sizeof *depth);
    assert_non_null(depth);
    f = fopen(out_path, "rb");
    assert_non_null(f);
    assert_int_equal(fread(depth, sizeof *depth, 64 * 48, f), 64 * 48);
    fclose(f);
    td_view v = {g, NULL};
    int hits = 0;
    for (int k = 0; k < 64 * 48; k++) {
        td_hit h;
        float t;
        td_trace(&v, TD_METHOD_INCREMENTAL, TD_SURFACE_TRIANGLE, &rays[k], &h);
        t = (float)h.t;
        hits += h.t < INFINITY;
        assert_memory_equal(&t, &depth[k], sizeof t);
    }
    assert_true(hits > 200 && hits < 64 * 48);
    free(rays);

    /* the shadow rays of a shaded render: as many as counted, all from hit points */
    f = fopen(scene_path, "w");
    assert_non_null(f);
    fprintf(f, "{\"dataset\": \"%s\", \"camera\": {\"position\": {\"x\": 300, \"y\": -300, \"z\": 400}, "
               "\"pitch\": -12, \"fov\": 70}, \"image\": {\"width\": 64, \"height\": 48}, "
               "\"effects\": {\"sun\": {\"azimuth\": 250, \"elevation\": 12}, \"shadows\": true}}", dem_path);
    fclose(f);
    snprintf(out_path, sizeof out_path, "%s/out.png", dir);
    char *argv2[] = {"render", scene_path, "-o", out_path, "--shadow-rays", rays_path, "--stats", stats_path, NULL};
    assert_int_equal(td_cli_render(8, argv2), 0);
    json_error_t je;
    json_t *st = json_load_file(stats_path, 0, &je);
    assert_non_null(st);
    size_t n = read_rays(rays_path, &rays);
    assert_int_equal(n, json_integer_value(json_object_get(json_object_get(st, "rays"), "shadow")));
    assert_true(n > 100);
    int shadowed = 0;
    for (size_t k = 0; k < n; k++) {
        uint32_t steps = 0;
        assert_true(rays[k].d[2] > 0.2 && rays[k].d[2] < 0.21); /* sin(12 degrees) */
        shadowed += td_occluded(&v, TD_METHOD_INCREMENTAL, TD_SURFACE_BILINEAR, &rays[k], NULL, &steps);
    }
    assert_true(shadowed > 0 && shadowed < (int)n);
    json_decref(st);
    free(rays);
    free(depth);
    td_grid_free(g);
    unlink(scene_path);
    unlink(out_path);
    unlink(rays_path);
    unlink(stats_path);
    snprintf(out_path, sizeof out_path, "%s/out.f32", dir);
    unlink(out_path);
    rmdir(dir);
}

/* ---- golden images ---- */

static double psnr(const uint8_t *a, const uint8_t *b, size_t n);

/* Level of detail: far pixels end on coarse levels, the picture stays close to the full
 * grid's (PSNR), secondary rays run on the level their camera ray used, and an
 * orthographic view whose pixels cover several cells is traced on one coarse level. */
static void test_level_of_detail(void **state)
{
    td_render_result full, lod;
    td_view v = {grid, NULL};
    td_render_opts o;
    td_lod *levels = NULL;
    td_accel_opts ao;
    td_err err = {0};
    (void)state;
    td_accel_opts_default(&ao);
    ao.maxmip = ao.planes = 0;
    assert_int_equal(td_lod_build(grid, TD_LOD_MAX, &ao, &levels, &err), TD_OK);
    assert_true(levels->levels >= 5); /* 129 -> 65 -> 33 -> 17 -> 9 -> 5 -> 3 -> 2 */
    assert_int_equal(levels->grid[1]->w, 65);
    assert_true(levels->grid[1]->sx == 2.0 * grid->sx);
    /* a coarse sample sits over a base sample and stays within the terrain's range */
    assert_true(levels->grid[1]->zmin >= grid->zmin && levels->grid[1]->zmax <= grid->zmax);

    base_scene(&scene);
    scene.image.width = 160;
    scene.image.height = 120;
    scene.effects.shadows = 1;
    td_render_opts_default(&o);
    o.threads = 2;
    assert_int_equal(td_render(&v, &scene, &o, &full, &err), TD_OK);
    scene.quality.lod = 1;
    scene.quality.lod_pixels = 2.0;
    o.lod = levels;
    assert_int_equal(td_render(&v, &scene, &o, &lod, &err), TD_OK);
    uint64_t coarse = 0;
    for (int k = 1; k <= TD_LOD_MAX; k++)
        coarse += lod.stats.lod_rays[k];
    assert_int_equal(full.stats.lod_rays[0], 160 * 120);
    assert_true(coarse > 0 && lod.stats.lod_rays[0] > 0);
    /* the coarse levels' hits are off the exact surface; the full grid's are not */
    assert_true(full.stats.height_err_mean_m < 1e-6);
    assert_true(lod.stats.height_err_mean_m > 1e-3 && lod.stats.height_err_max_m > lod.stats.height_err_mean_m);
    double q = psnr(full.rgba, lod.rgba, (size_t)160 * 120 * 4);
    print_message("lod: %llu of %d camera rays on coarse levels, steps %llu -> %llu, PSNR %.1f dB\n",
                  (unsigned long long)coarse, 160 * 120, (unsigned long long)full.stats.steps,
                  (unsigned long long)lod.stats.steps, q);
    assert_true(q >= 25.0);
    /* the same far levels on their isometric twins: the same rays per level, hits off the
     * exact surface by about as much, a picture as close */
    td_render_result iso;
    scene.quality.lod_grid = TD_LOD_GRID_ISOMETRIC;
    assert_int_equal(td_render(&v, &scene, &o, &iso, &err), TD_EUNSUPPORTED); /* not built */
    assert_string_equal(err.field, "quality.lod_grid");
    assert_int_equal(td_lod_add_iso(levels, grid, &err), TD_OK);
    assert_int_equal(td_render(&v, &scene, &o, &iso, &err), TD_OK);
    scene.quality.lod_grid = TD_LOD_GRID_SQUARE;
    assert_int_equal(iso.stats.lod_rays[0], lod.stats.lod_rays[0]);
    print_message("iso %g square %g\n", iso.stats.height_err_mean_m, lod.stats.height_err_mean_m);
    assert_true(iso.stats.height_err_mean_m > 1e-3 &&
                iso.stats.height_err_mean_m < 2.0 * lod.stats.height_err_mean_m);
    double qi = psnr(full.rgba, iso.rgba, (size_t)160 * 120 * 4);
    print_message("lod on the isometric twins: height error mean %.3g m (square %.3g m), PSNR %.1f dB\n",
                  iso.stats.height_err_mean_m, lod.stats.height_err_mean_m, qi);
    assert_true(qi >= 25.0);
    assert_true(memcmp(iso.rgba, lod.rgba, (size_t)160 * 120 * 4) != 0);
    td_render_result_free(&iso);
    td_render_result_free(&full);
    td_render_result_free(&lod);

    /* orthographic: 8 cells per pixel -> every ray on level 3 */
    td_scene_defaults(&scene);
    snprintf(scene.dataset, sizeof scene.dataset, "procedural");
    scene.camera.projection = TD_PROJ_ORTHOGRAPHIC;
    scene.camera.extent[0] = 0.0;
    scene.camera.extent[1] = 0.0;
    scene.camera.extent[2] = 128 * 30.0;
    scene.camera.extent[3] = 128 * 30.0;
    scene.image.width = scene.image.height = 16;
    scene.quality.lod = 1;
    assert_int_equal(td_render(&v, &scene, &o, &lod, &err), TD_OK);
    assert_int_equal(lod.stats.lod_rays[3], 16 * 16);
    td_render_result_free(&lod);
    td_lod_free(levels);
}

static double psnr(const uint8_t *a, const uint8_t *b, size_t n)
{
    double se = 0.0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)a[i] - (double)b[i];
        se += d * d;
    }
    double mse = se / (double)n;
    return mse == 0.0 ? INFINITY : 10.0 * log10(255.0 * 255.0 / mse);
}

static void golden(const char *name, const td_scene *s, const td_image8 *drape)
{
    td_view v = {grid, NULL};
    td_render_opts o;
    td_render_result r;
    td_err err = {0};
    td_buf b;
    char path[1024];
    td_render_opts_default(&o);
    o.drape = drape;
    assert_int_equal(td_render(&v, s, &o, &r, &err), TD_OK);
    snprintf(path, sizeof path, "%s/%s.png", GOLDEN_DIR, name);
    const char *upd = getenv("TERRAD_UPDATE_GOLDEN");
    if (upd && !strcmp(upd, "1")) {
        assert_int_equal(td_render_encode(&r, s, &b, NULL, &err), TD_OK);
        FILE *f = fopen(path, "wb");
        assert_non_null(f);
        assert_int_equal(fwrite(b.data, 1, b.len, f), b.len);
        fclose(f);
        td_buf_free(&b);
    } else {
        td_image8 *g = NULL;
        td_status st = td_image_load(path, 4, 1u << 24, &g, &err);
        if (st)
            print_error("%s (regenerate with TERRAD_UPDATE_GOLDEN=1)\n", err.msg);
        assert_int_equal(st, TD_OK);
        assert_int_equal(g->width, r.width);
        assert_int_equal(g->height, r.height);
        double q = psnr(g->px, r.rgba, (size_t)r.width * r.height * 4);
        if (q < 35.0)
            print_error("golden %s: PSNR %.2f dB < 35\n", name, q);
        assert_true(q >= 35.0);
        td_image_free(g);
    }
    td_render_result_free(&r);
}

static void test_golden_images(void **state)
{
    (void)state;
    base_scene(&scene);
    scene.image.width = 96;
    scene.image.height = 64;
    golden("base", &scene, NULL);

    td_scene s = scene;
    s.effects.shadows = 1;
    golden("shadows", &s, NULL);

    s = scene;
    s.effects.sky = 1;
    golden("sky", &s, NULL);

    s = scene;
    s.effects.haze = 1;
    s.effects.haze_visibility_km = 4.0;
    s.effects.sky = 1;
    golden("haze", &s, NULL);

    s = scene;
    s.effects.water = 1;
    s.effects.water_level = grid->zmin + 0.3 * (grid->zmax - grid->zmin);
    s.effects.sky = 1;
    golden("water", &s, NULL);

    s = scene;
    s.effects.ambient_occlusion = 8;
    golden("ao", &s, NULL);

    s = scene;
    s.quality.samples = 3;
    s.quality.smooth_normals = 1;
    golden("ssaa_smooth", &s, NULL);

    s = scene;
    s.camera.projection = TD_PROJ_ORTHOGRAPHIC;
    s.effects.shadows = 1;
    s.quality.surface = TD_SURFACE_TRIANGLE;
    golden("ortho_triangle", &s, NULL);

    /* drape: a 16 x 16 checkerboard of red and white over the grid */
    td_image8 chk;
    uint8_t px[16 * 16 * 3];
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 16; x++) {
            uint8_t *p = &px[3 * (y * 16 + x)];
            int red = ((x / 4) + (y / 4)) & 1;
            p[0] = 230;
            p[1] = red ? 40 : 230;
            p[2] = red ? 40 : 230;
        }
    chk.width = chk.height = 16;
    chk.channels = 3;
    chk.px = px;
    s = scene;
    snprintf(s.effects.drape, sizeof s.effects.drape, "checkerboard");
    golden("drape", &s, &chk);
}


/* Partial stats add up: counts and sums add, stages OR, the larger error wins, the mean
 * is the summed error over the summed hits (the threads' stats, in thread order). */
static void test_stats_add(void **state)
{
    td_render_stats a, b, sum;
    (void)state;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    memset(&sum, 0, sizeof sum);
    a.rays[TD_RAY_PRIMARY] = 10;
    a.rays[TD_RAY_SHADOW] = 4;
    a.steps = 100;
    a.hits = 8;
    a.curved_rays = 2;
    a.curved_secondary = 1;
    a.curve_segments = 7;
    a.method_rays[TD_METHOD_INCREMENTAL] = 10;
    a.lod_rays[0] = 9;
    a.height_err_sum_m = 3.0;
    a.height_err_max_m = 1.5;
    a.height_err_hits = 6;
    a.stage_ran[TD_STAGE_PRIMARY] = 1;
    a.stage_ms[TD_STAGE_PRIMARY] = 2.0;
    b.rays[TD_RAY_PRIMARY] = 5;
    b.rays[TD_RAY_AO] = 20;
    b.steps = 50;
    b.hits = 2;
    b.method_rays[TD_METHOD_HIERARCHICAL] = 5;
    b.lod_rays[1] = 5;
    b.height_err_sum_m = 1.0;
    b.height_err_max_m = 0.5;
    b.height_err_hits = 2;
    b.stage_ran[TD_STAGE_AO] = 1;
    b.stage_ms[TD_STAGE_PRIMARY] = 1.0;
    b.stage_ms[TD_STAGE_AO] = 4.0;
    b.threads = 7;
    b.total_ms = 99.0;

    td_render_stats_add(&sum, &a);
    assert_float_equal(sum.height_err_mean_m, 0.5, 0.0);
    td_render_stats_add(&sum, &b);
    assert_int_equal(sum.rays[TD_RAY_PRIMARY], 15);
    assert_int_equal(sum.rays[TD_RAY_SHADOW], 4);
    assert_int_equal(sum.rays[TD_RAY_AO], 20);
    assert_int_equal(sum.steps, 150);
    assert_int_equal(sum.hits, 10);
    assert_int_equal(sum.curved_rays, 2);
    assert_int_equal(sum.curved_secondary, 1);
    assert_int_equal(sum.curve_segments, 7);
    assert_int_equal(sum.method_rays[TD_METHOD_INCREMENTAL], 10);
    assert_int_equal(sum.method_rays[TD_METHOD_HIERARCHICAL], 5);
    assert_int_equal(sum.lod_rays[0], 9);
    assert_int_equal(sum.lod_rays[1], 5);
    assert_float_equal(sum.height_err_sum_m, 4.0, 0.0);
    assert_float_equal(sum.height_err_max_m, 1.5, 0.0);
    assert_int_equal(sum.height_err_hits, 8);
    assert_float_equal(sum.height_err_mean_m, 4.0 / 8.0, 0.0);
    assert_true(sum.stage_ran[TD_STAGE_PRIMARY] && sum.stage_ran[TD_STAGE_AO]);
    assert_false(sum.stage_ran[TD_STAGE_SHADOWS]);
    assert_float_equal(sum.stage_ms[TD_STAGE_PRIMARY], 3.0, 0.0);
    assert_float_equal(sum.stage_ms[TD_STAGE_AO], 4.0, 0.0);
    assert_int_equal(sum.threads, 0); /* the caller's */
    assert_float_equal(sum.total_ms, 0.0, 0.0);

    /* no hits: the mean is 0, not NaN */
    memset(&sum, 0, sizeof sum);
    memset(&a, 0, sizeof a);
    td_render_stats_add(&sum, &a);
    assert_float_equal(sum.height_err_mean_m, 0.0, 0.0);
}

/* Picks every pixel of the scene (w x h <= TD_SCENE_PICK_MAX) and renders its depth on
 * one thread: the same rays, so the same distances, steps, hits, bent rays and errors. */
static void pick_all_matches_render(const td_view *v, int32_t w, int32_t h, int want_curved)
{
    static td_pick pk[TD_SCENE_PICK_MAX];
    td_render_stats ps;
    td_render_result r;
    td_render_opts o;
    td_err err = {0};
    assert_true(w * h <= TD_SCENE_PICK_MAX);
    scene.image.width = w;
    scene.image.height = h;
    scene.image.format = TD_FORMAT_PICK;
    scene.npick = (int)(w * h);
    for (int i = 0; i < scene.npick; i++) {
        scene.pick[i][0] = i % w;
        scene.pick[i][1] = i / w;
    }
    assert_int_equal(td_render_pick(v, &scene, pk, &ps, &err), TD_OK);
    scene.image.format = TD_FORMAT_DEPTH32F;
    scene.npick = 0;
    td_render_opts_default(&o);
    o.threads = 1;
    /* the render's camera rays from their wedges' horizons: the same depths, bit for bit */
    assert_int_equal(td_render(v, &scene, &o, &r, &err), TD_OK);
    for (int i = 0; i < w * h; i++) {
        float d = pk[i].hit ? (float)pk[i].distance : INFINITY;
        if (memcmp(&d, &r.depth[i], sizeof d))
            print_error("pixel %d: pick %.9g, depth %.9g\n", i, (double)d, (double)r.depth[i]);
        assert_memory_equal(&d, &r.depth[i], sizeof d);
    }
    assert_int_equal(ps.hits, r.stats.hits);
    td_render_result_free(&r);
    /* and traced from their starts, as a pick traces them: the same steps too */
    o.off = TD_RENDER_OFF_CAMERA;
    assert_int_equal(td_render(v, &scene, &o, &r, &err), TD_OK);
    for (int i = 0; i < w * h; i++) {
        float d = pk[i].hit ? (float)pk[i].distance : INFINITY;
        assert_memory_equal(&d, &r.depth[i], sizeof d);
    }
    assert_int_equal(r.stats.coherent_rays, 0);
    assert_int_equal(ps.rays[TD_RAY_PRIMARY], r.stats.rays[TD_RAY_PRIMARY]);
    assert_int_equal(ps.steps, r.stats.steps);
    assert_int_equal(ps.hits, r.stats.hits);
    assert_int_equal(ps.curved_rays, r.stats.curved_rays);
    assert_int_equal(ps.curve_segments, r.stats.curve_segments);
    assert_int_equal(ps.height_err_hits, r.stats.height_err_hits);
    assert_float_equal(ps.height_err_max_m, r.stats.height_err_max_m, 0.0);
    assert_float_equal(ps.height_err_mean_m, r.stats.height_err_mean_m,
                       1e-12 * r.stats.height_err_mean_m); /* summed in block order */
    assert_true(ps.hits > 0 && ps.hits < (uint64_t)(w * h));
    if (want_curved)
        assert_true(ps.curved_rays > 0 && ps.curve_segments > ps.curved_rays);
    else
        assert_int_equal(ps.curved_rays, 0);
    for (int k = 0; k < TD_METHOD_COUNT; k++)
        assert_int_equal(ps.method_rays[k], 0); /* a pick does not count them */
    td_render_result_free(&r);
}

/* picos (tests/data) with the max-mipmaps `auto` reads: *g and *a, freed by the caller. */
static td_view picos_view(td_grid **g, td_accel **a)
{
    char dem_path[256];
    td_accel_opts ao;
    td_err err = {0};
    snprintf(dem_path, sizeof dem_path, "%s/picos-dtm.asc", TERRAD_TEST_DATA);
    assert_int_equal(td_dem_load(dem_path, NULL, g, &err), TD_OK);
    td_accel_opts_for(TD_METHOD_AUTO, &ao);
    assert_int_equal(td_accel_build(*g, &ao, a, NULL, &err), TD_OK);
    return (td_view){*g, (*a)->tiles};
}

/* The rolled bench view of picos (heading 140, pitch -10, fov 70) with roll `roll`, a
 * w x h depth32f image of surface sf. */
static void picos_rolled(td_scene *sc, double roll, int32_t w, int32_t h, td_surface sf)
{
    td_scene_defaults(sc);
    snprintf(sc->dataset, sizeof sc->dataset, "picos");
    sc->camera.x = 560.0, sc->camera.y = 2781.0, sc->camera.z = 2557.0;
    sc->camera.heading = 140.0, sc->camera.pitch = -10.0, sc->camera.roll = roll, sc->camera.fov = 70.0;
    sc->image.width = w, sc->image.height = h;
    sc->image.format = TD_FORMAT_DEPTH32F;
    sc->quality.method = TD_METHOD_AUTO;
    sc->quality.surface = sf;
}

/* Rolled cameras over picos (rough: rays that graze ridges walk far), whose blocks
 * render.c cuts into bands along the verticals (two, or four after a block whose rays took
 * many steps), and an upright one (two column slices, or four): the depths of the rays
 * traced from their starts, bit for bit, on every surface, on one thread and on three (the
 * workers' band orders and slice counts differ). */
static void test_rolled_bands(void **state)
{
    td_grid *g = NULL;
    td_accel *a = NULL;
    td_err err = {0};
    (void)state;
    td_view v = picos_view(&g, &a);
    static const double rolls[] = {35.0, -50.0, 0.0}; /* upright: 2 or 4 column slices */
    for (size_t ri = 0; ri < sizeof rolls / sizeof rolls[0]; ri++)
        for (int surf = 0; surf < TD_SURFACE_COUNT; surf++) {
            td_render_result r[3];
            td_scene sc;
            picos_rolled(&sc, rolls[ri], 256, 192, (td_surface)surf);
            for (int k = 0; k < 3; k++) {
                td_render_opts o;
                td_render_opts_default(&o);
                o.threads = k == 1 ? 3 : 1;
                o.off = k == 2 ? TD_RENDER_OFF_CAMERA : 0;
                assert_int_equal(td_render(&v, &sc, &o, &r[k], &err), TD_OK);
            }
            for (int k = 0; k < 2; k++)
                assert_memory_equal(r[k].depth, r[2].depth, sizeof(float) * 256 * 192);
            assert_true(r[0].stats.hits > 256 * 192 / 4 && r[0].stats.hits < 256 * 192);
            /* the horizon starts the rays nearer their hits: fewer than 2/3 of the steps */
            assert_true(r[0].stats.kind_steps[TD_RAY_PRIMARY] * 3 < r[2].stats.kind_steps[TD_RAY_PRIMARY] * 2);
            for (int k = 0; k < 3; k++)
                td_render_result_free(&r[k]);
        }
    td_accel_free(a);
    td_grid_free(g);
}

/* Rolled cameras whose image leaves a block of one pixel at its corner (17 x 17 and 65 x
 * 33 pixels: blocks of 16) or is one pixel: a one-sample block spans no width across the
 * verticals, and the band sort (band_order) divided by it and wrote out of its counts
 * (fuzz_render: a segmentation fault of `terrad render` on a rolled 65 x 17 image, and of
 * the service on such a request). Such blocks take the column slices: the depths of the
 * plain walk, bit for bit, on every surface, one ray a pixel and 2 x 2. */
static void test_rolled_corner_block(void **state)
{
    td_grid *g = NULL;
    td_accel *a = NULL;
    td_err err = {0};
    (void)state;
    td_view v = picos_view(&g, &a);
    static const int32_t sizes[][2] = {{17, 17}, {65, 33}, {1, 1}};
    int hits = 0;
    for (int si = 0; si < 3; si++)
        for (int surf = 0; surf < TD_SURFACE_COUNT; surf++)
            for (int n = 1; n <= 2; n++) {
                td_render_result r[2];
                td_scene sc;
                picos_rolled(&sc, 35.0, sizes[si][0], sizes[si][1], (td_surface)surf);
                sc.quality.samples = n;
                for (int k = 0; k < 2; k++) {
                    td_render_opts o;
                    td_render_opts_default(&o);
                    o.threads = 1;
                    o.off = k ? TD_RENDER_OFF_CAMERA : 0;
                    assert_int_equal(td_render(&v, &sc, &o, &r[k], &err), TD_OK);
                }
                assert_memory_equal(r[0].depth, r[1].depth, sizeof(float) * (size_t)(sizes[si][0] * sizes[si][1]));
                hits += r[0].stats.hits > 0;
                td_render_result_free(&r[0]);
                td_render_result_free(&r[1]);
            }
    assert_true(hits >= 2 * 2 * TD_SURFACE_COUNT); /* the larger images see terrain */
    td_accel_free(a);
    td_grid_free(g);
}

static void test_pick_traces_the_render_rays(void **state)
{
    td_view v = {grid, NULL};
    (void)state;
    base_scene(&scene);
    scene.quality.surface = TD_SURFACE_TRIANGLE; /* a height error that is not 0 */
    pick_all_matches_render(&v, 32, 24, 0);

    /* the far rays bend (see test_curvature) */
    td_grid *flat = flat_ground_view(&scene);
    td_view fv = {flat, NULL};
    scene.effects.curvature = 1;
    pick_all_matches_render(&fv, 64, 16, 1);
    td_grid_free(flat);
}

/* Sets the scene field of a row of the table of limits (a new row needs a case). */
static void set_limited(td_scene *s, td_limit id, double v)
{
    switch (id) {
    case TD_LIMIT_WIDTH: s->image.width = (int32_t)v; break;
    case TD_LIMIT_HEIGHT: s->image.height = (int32_t)v; break;
    case TD_LIMIT_SAMPLES: s->quality.samples = (int)v; break;
    case TD_LIMIT_LOD_PIXELS: s->quality.lod = 1; s->quality.lod_pixels = v; break;
    case TD_LIMIT_AO_RAYS: s->effects.ambient_occlusion = (int)v; break;
    case TD_LIMIT_AMBIENT: s->effects.ambient = v; break;
    case TD_LIMIT_SUN_ELEVATION: s->effects.sun_elevation = v; break;
    case TD_LIMIT_HAZE_KM: s->effects.haze = 1; s->effects.haze_visibility_km = v; break;
    case TD_LIMIT_CURVATURE_K: s->effects.curvature = 1; s->effects.curvature_k = v; break;
    case TD_LIMIT_PICK: s->npick = (int)v; break;
    default: fail_msg("limit %d: no scene field in this test", (int)id);
    }
}

/* td_render (td_render_pick for the pick count) accepts each row's core max and min and
 * refuses one past either end, with the row's path in err.field. */
static void test_limits_in_core(void **state)
{
    td_view v = {grid, NULL};
    td_render_opts o;
    td_render_result r;
    (void)state;
    td_render_opts_default(&o);
    o.threads = 1;
    for (int id = 0; id < TD_LIMIT_COUNT; id++) {
        const td_limit_row *l = td_limit_get((td_limit)id);
        const double ends[4] = {l->min, l->max, l->min - 1.0, l->max + 1.0};
        for (int k = 0; k < 4; k++) {
            td_err err = {0};
            td_status rc;
            base_scene(&scene);
            scene.image.width = id == TD_LIMIT_HEIGHT ? 1 : 4; /* cheap, also at 65536 */
            scene.image.height = id == TD_LIMIT_WIDTH ? 1 : 3;
            set_limited(&scene, (td_limit)id, ends[k]);
            if (id == TD_LIMIT_PICK) {
                static td_pick pk[TD_SCENE_PICK_MAX];
                memset(scene.pick, 0, sizeof scene.pick);
                scene.image.format = TD_FORMAT_PICK;
                rc = td_render_pick(&v, &scene, pk, NULL, &err);
            } else {
                rc = td_render(&v, &scene, &o, &r, &err);
                if (rc == TD_OK)
                    td_render_result_free(&r);
            }
            if (k >= 2) {
                if (rc != TD_ERANGE || strcmp(err.field, l->path))
                    print_error("%s = %g: %d %s\n", l->path, ends[k], (int)rc, err.msg);
                assert_int_equal(rc, TD_ERANGE);
                assert_string_equal(err.field, l->path);
                assert_memory_equal(err.msg, l->path, strlen(l->path)); /* the text names it too */
            } else {
                /* in range: rendered (lod: refused only for want of coarse levels) */
                if (rc != (id == TD_LIMIT_LOD_PIXELS ? TD_EUNSUPPORTED : TD_OK))
                    print_error("%s = %g: %d %s\n", l->path, ends[k], (int)rc, err.msg);
                assert_int_equal(rc, id == TD_LIMIT_LOD_PIXELS ? TD_EUNSUPPORTED : TD_OK);
            }
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_absent_effects_cost_nothing),
        cmocka_unit_test(test_height_error),
        cmocka_unit_test(test_shadows),
        cmocka_unit_test(test_auto_reads_what_it_builds),
        cmocka_unit_test(test_sky_and_haze),
        cmocka_unit_test(test_water_and_ao),
        cmocka_unit_test(test_supersampling_and_threads),
        cmocka_unit_test(test_depth_matches_pick),
        cmocka_unit_test(test_curvature),
        cmocka_unit_test(test_curvature_shadows),
        cmocka_unit_test(test_kept_sun_bound),
        cmocka_unit_test(test_refusals_and_cancel),
        cmocka_unit_test(test_level_of_detail),
        cmocka_unit_test(test_cli_render),
        cmocka_unit_test(test_cli_rays),
        cmocka_unit_test(test_golden_images),
        cmocka_unit_test(test_stats_add),
        cmocka_unit_test(test_pick_traces_the_render_rays),
        cmocka_unit_test(test_rolled_bands), cmocka_unit_test(test_rolled_corner_block),
        cmocka_unit_test(test_limits_in_core),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
