/* oracle_lod.c: rendered camera views with levels of detail (quality.lod), on the square
 * coarse levels and on their isometric twins (quality.lod_grid), held to the references.
 *
 *   oracle_lod DATASET      (volcano, levi, picos, trinidad-crop)
 *
 * render.c traces a perspective camera ray on level 0 up to d_1, on level l from d_l up to
 * d_(l+1), ..., d_l = 2^l cell / (lod_pixels pixel_angle), and stops at the first level
 * where it hits. For every view, lod_grid, surface and method the render's depths (devices
 * on and off) are the same bit for bit, and equal those of every other method; for `auto`
 * each pixel's depth must be what that rule gives with td_trace on the square levels or
 * td_iso_trace on the twins, and every segment it traced is judged against the double
 * references on that segment: reference.c on the full grid and on the square levels,
 * iso_reference.c on the twin's decoded heights (the twins are two-byte vertices). A
 * segment that misses must miss the reference too (or graze inside its band). lod_pixels
 * is 8, so that on these small grids most far pixels end on coarse levels; the run fails
 * if fewer than a fifth of the hits of either lod_grid do (a test that could pass without
 * a coarse level would prove nothing).
 *
 * The oracle suite's other camera checks (oracle.c --cameras) run without levels of
 * detail; this is their counterpart for quality.lod. Exit status 1 on any disagreement. */
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "cam_view.h"
#include "dem.h"
#include "iso_reference.h"
#include "lod.h"
#include "reference.h"
#include "render.h"

#ifndef TERRAD_TEST_DATA
#define TERRAD_TEST_DATA "tests/data"
#endif

#define MAX_PRINT 8
#define LOD_PIXELS 8.0

/* Placed in the grid's frame as oracle.c's views (cam_view.h), looking across the grid so
 * that most rays go far (the sun does not matter to a depth image). */
static const cam_view views[] = {
    {"level across", 0.05, 0.05, 150, 45, -2, 0, 70, 0, 30},
    {"grazing", 0.02, 0.5, 30, 90, -1, 0, 60, 0, 30},
    {"looking down", 0.1, 0.9, 600, 135, -25, 0, 70, 0, 30},
    {"rolled 35", 0.95, 0.9, 300, 220, -8, 35, 70, 0, 30},
    {"fov 170", 0.5, 0.02, 100, 0, -4, 0, 170, 0, 30},
    {"below the crests", 0.9, 0.1, -1, 300, 3, 0, 80, 0, 30},
};

typedef struct run {
    const td_grid *g;
    td_view view;
    const td_lod *lod;
    td_iso *dec[TD_LOD_MAX + 1];    /* the twins' decoded heights, for iso_reference */
    double eps[TD_LOD_MAX + 1];     /* square band per level (oracle.c's float band) */
    double iso_eps[TD_LOD_MAX + 1]; /* the twins' band (test_isogrid.c's) */
    uint64_t pixels, hits[2][TD_LOD_MAX + 1], segments, agree, tie, wrong; /* hits[iso][level] */
} run;

static const td_grid *level_grid(const run *u, int l) { return l == 0 ? u->g : u->lod->grid[l]; }

static td_status load(const char *name, td_grid **out, td_err *err)
{
    td_status rc;
    td_dem_opts o;
    char path[512];
    td_dem_opts_default(&o);
    o.tile_log2 = 5; /* 32 x 32 cells: rays cross seams often */
    if (!strcmp(name, "levi")) {
        o.encoding = TD_ENC_RGB_DIV;
        o.spacing[0] = o.spacing[1] = 20.0;
    }
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA,
             !strcmp(name, "volcano")         ? "volcano.asc"
             : !strcmp(name, "levi")          ? "levi-topography.png"
             : !strcmp(name, "picos")         ? "picos-dtm.asc"
             : !strcmp(name, "trinidad-crop") ? "trinidad-crop.f32"
                                              : name);
    rc = td_dem_load(path, &o, out, err);
    return rc;
}

/* The float band of oracle.c for grid g: 1 mm plus float32 rounding of the coordinates,
 * times 1 + the steepest slope. */
static double float_band(const td_grid *g)
{
    double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
    double scale = fmax(fmax(X, Y), fmax(fabs(g->zmin), fabs(g->zmax)));
    return (1e-3 + 2.0 * FLT_EPSILON * scale) * (1.0 + td_ref_max_slope(g));
}

/* Segment `seg` of a camera ray traced on level l (square or twin) by the tracer, judged
 * against the reference; returns its t. */
static double segment(run *u, int l, int iso, td_method m, td_surface sf, const td_ray *seg)
{
    td_hit h;
    int wrong;
    if (l > 0 && iso) {
        td_iso_ref_hit ref;
        td_iso_trace(u->lod->iso[l], seg, &h);
        td_iso_ref_trace(u->dec[l], seg, u->iso_eps[l], &ref);
        td_iso_ref_verdict v = td_iso_ref_judge(u->dec[l], seg, &ref, h.t, u->iso_eps[l]);
        u->agree += v == TD_ISO_REF_AGREE;
        u->tie += v == TD_ISO_REF_TIE;
        wrong = v == TD_ISO_REF_WRONG;
    } else {
        td_ref_hit ref;
        const td_view *v = l == 0 ? &u->view : &u->lod->view[l];
        td_trace(v, m, sf, seg, &h);
        td_ref_trace(level_grid(u, l), sf, seg, u->eps[l], &ref);
        td_ref_verdict jv = td_ref_judge(level_grid(u, l), sf, seg, &ref, h.t, u->eps[l]);
        u->agree += jv == TD_REF_AGREE;
        u->tie += jv == TD_REF_TIE;
        wrong = jv == TD_REF_WRONG;
    }
    u->segments++;
    if (wrong && u->wrong++ < MAX_PRINT)
        printf("WRONG level %d %s %s: o %a %a %a d %a %a %a [%a, %a] t %.17g\n", l,
               iso ? "isometric" : "square", td_surface_name(sf), seg->o[0], seg->o[1], seg->o[2],
               seg->d[0], seg->d[1], seg->d[2], seg->tmin, seg->tmax, h.t);
    return h.t;
}

/* A camera ray over the levels by render.c's rule (see the top), each segment judged;
 * *level gets the level it ended on. */
static double lod_ray(run *u, const td_camera *cam, int iso, td_method m, td_surface sf,
                      const td_ray *r, int *level)
{
    const td_grid *g = u->g;
    double cell = g->sx < g->sy ? g->sx : g->sy, t = INFINITY;
    int n = u->lod->levels, l;
    td_ray seg = *r;
    for (l = 0; l <= n && !(t < INFINITY); l++) {
        double d0 = ldexp(cell, l) / (LOD_PIXELS * cam->pixel_angle);
        double d1 = ldexp(cell, l + 1) / (LOD_PIXELS * cam->pixel_angle);
        seg.tmin = l == 0 ? r->tmin : fmax(r->tmin, d0);
        seg.tmax = l == n ? r->tmax : fmin(r->tmax, d1);
        if (seg.tmin > seg.tmax)
            continue;
        t = segment(u, l, iso, m, sf, &seg);
        *level = l;
    }
    return t;
}

/* One view, lod_grid, surface and method: depths with the devices on and off are the
 * same bit for bit and equal auto's; for auto every pixel is the rule's, judged. */
static uint64_t check(run *u, const cam_view *lv, int iso, td_method m, td_surface sf, float *auto_depth)
{
    enum { W = 96, H = 72 };
    const td_grid *g = u->g;
    td_scene sc;
    td_render_opts o;
    td_render_result on = {0}, off = {0};
    td_err err = {0};
    td_camera cam;
    uint64_t errors = 0;
    cam_view_scene(lv, g, W, H, m, sf, &sc);
    sc.quality.lod = 1;
    sc.quality.lod_pixels = LOD_PIXELS;
    sc.quality.lod_grid = iso ? TD_LOD_GRID_ISOMETRIC : TD_LOD_GRID_SQUARE;
    td_render_opts_default(&o);
    o.threads = 1;
    o.lod = u->lod;
    if (cam_view_render(&u->view, &sc, &o, &on, &off, &cam, &err)) {
        printf("ERROR %s: %s\n", lv->name, err.msg);
        errors++;
        goto out;
    }
    for (int k = 0; k < W * H; k++) {
        if (!cam_view_same(&on, &off, auto_depth, m, k)) {
            if (errors++ < MAX_PRINT)
                printf("ERROR %s %s %s/%s pixel %d: devices on %.9g off %.9g auto %.9g\n", lv->name,
                       iso ? "isometric" : "square", td_method_name(m), td_surface_name(sf), k,
                       on.depth[k], off.depth[k], auto_depth[k]);
        }
        if (m == TD_METHOD_AUTO) {
            td_ray r;
            int level = 0;
            auto_depth[k] = on.depth[k];
            td_camera_ray(&cam, k % W, k / W, &r);
            double t = lod_ray(u, &cam, iso, m, sf, &r, &level);
            if ((float)t != on.depth[k] && errors++ < MAX_PRINT)
                printf("ERROR %s %s %s pixel %d: render %.9g, the levels' rule %.9g\n", lv->name,
                       iso ? "isometric" : "square", td_surface_name(sf), k, on.depth[k], t);
            u->pixels++;
            u->hits[iso][level] += t < INFINITY;
        }
    }
out:
    td_render_result_free(&on);
    td_render_result_free(&off);
    return errors;
}

int main(int argc, char **argv)
{
    td_err err = {0};
    td_grid *g = NULL;
    td_accel *acc = NULL;
    td_lod *lod = NULL;
    td_accel_opts ao;
    td_accel_stats as;
    run u;
    uint64_t errors = 0;
    float *auto_depth = calloc(96 * 72, sizeof *auto_depth);
    int rc = 1;

    memset(&u, 0, sizeof u);
    if (argc != 2) {
        fprintf(stderr, "usage: %s volcano|levi|picos|trinidad-crop\n", argv[0]);
        goto out;
    }
    td_accel_opts_default(&ao);
    ao.threads = 2;
    if (!auto_depth || load(argv[1], &g, &err) || td_accel_build(g, &ao, &acc, &as, &err) ||
        td_lod_build(g, TD_LOD_MAX, &ao, &lod, &err) || td_lod_add_iso(lod, g, &err)) {
        fprintf(stderr, "oracle_lod: %s\n", err.msg[0] ? err.msg : "out of memory");
        goto out;
    }
    u.g = g;
    u.view = (td_view){g, acc->tiles};
    u.lod = lod;
    u.eps[0] = float_band(g);
    for (int l = 1; l <= lod->levels; l++) {
        if (td_iso_unpack(lod->iso[l]->packed, &u.dec[l], &err)) {
            fprintf(stderr, "oracle_lod: %s\n", err.msg);
            goto out;
        }
        u.eps[l] = float_band(lod->grid[l]);
        u.iso_eps[l] = 1e-6 * (1.0 + fmax(fabs(u.dec[l]->zmin), fabs(u.dec[l]->zmax)));
    }
    printf("dataset %s: %d x %d samples, %d coarse levels, lod_pixels %g\n", argv[1], (int)g->w,
           (int)g->h, lod->levels, LOD_PIXELS);
    for (size_t v = 0; v < sizeof views / sizeof views[0]; v++) {
        for (int iso = 0; iso < 2; iso++) {
            uint64_t e0 = errors, w0 = u.wrong;
            for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                errors += check(&u, &views[v], iso, TD_METHOD_AUTO, (td_surface)sf, auto_depth);
                for (int m = 0; m < TD_METHOD_AUTO; m++)
                    errors += check(&u, &views[v], iso, (td_method)m, (td_surface)sf, auto_depth);
            }
            printf("view %-18s %-9s every method and surface: %s\n", views[v].name,
                   iso ? "isometric" : "square", errors > e0 || u.wrong > w0 ? "ERRORS" : "ok");
        }
    }
    printf("pixels %" PRIu64 "\n", u.pixels);
    for (int iso = 0; iso < 2; iso++) {
        uint64_t coarse = 0, all = u.hits[iso][0];
        printf("%s: hits by level", iso ? "isometric" : "square");
        for (int l = 0; l <= lod->levels; l++)
            printf(" %" PRIu64, u.hits[iso][l]);
        for (int l = 1; l <= lod->levels; l++)
            coarse += u.hits[iso][l];
        all += coarse;
        printf("\n");
        if (5 * coarse < all) {
            printf("ERROR: only %" PRIu64 " of %" PRIu64 " hits on coarse levels\n", coarse, all);
            errors++;
        }
    }
    printf("segments %" PRIu64 " judged: %" PRIu64 " agree, %" PRIu64 " ties, %" PRIu64 " wrong\n",
           u.segments, u.agree, u.tie, u.wrong);
    errors += u.wrong;
    printf("%s: %" PRIu64 " unexplained disagreements\n", errors ? "FAIL" : "PASS", errors);
    rc = errors ? 1 : 0;
out:
    for (int l = 0; l <= TD_LOD_MAX; l++)
        td_iso_free(u.dec[l]);
    td_lod_free(lod);
    td_accel_free(acc);
    td_grid_free(g);
    free(auto_depth);
    return rc;
}
