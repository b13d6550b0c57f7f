/* fuzz_render.c: the renderer's coherence devices and shadow queries against the plain
 * walk, on small exact terrains and any camera (issue 12: "exact on every method and
 * surface, with roll, looking straight down, and grazing"). What the oracle's camera
 * checks hold on five real views (tests/oracle/oracle.c --cameras), held here for the
 * cameras and terrains a fuzzer finds:
 *  - a depth32f render gives the same floats, bit for bit, with the camera devices on
 *    (horizon, silhouette, beam; on 1 to 3 threads) and off (TD_RENDER_OFF_CAMERA, one
 *    thread), for every method, and every method the same floats as auto;
 *  - each pixel's depth is (float) td_trace's t on td_camera_ray's ray (straight rays, one
 *    sample a pixel);
 *  - except where a render traced its camera rays by image columns (a level camera,
 *    colwalk.h, whose hits are the walk's to the rounding of their parameter): there a
 *    pixel whose depth differs must be a tie, its samples' nearest hit within what
 *    td_trace gives for them lowered and raised by the walk's margin (depth_tie);
 *  - a colour render with shadows gives the same bytes with the shadow devices on and off
 *    (TD_RENDER_OFF_OCCLUSION | TD_RENDER_OFF_SUNLIT: each shadow ray's nearest hit);
 *  - each of its shadow rays is occluded for td_occluded (with the sun bound, and
 *    without) and for td_occluded_par (the render's batches of parallel rays) exactly
 *    when td_trace finds a hit.
 * The input: a grid of 2..33 samples a side (fuzz_terrain.h: exact planes and bilinear
 * patches, or the input's bytes), its spacing, a camera (on a sample's lines, between, or
 * off the grid; above the terrain, among its crests or on the ground; headings along the
 * grid's lines and diagonals or any; pitch level, straight down, grazing or any; roll;
 * fov 1 to 179, or a panorama, or the orthographic top-down view), an image of 1..24 x
 * 1..24 pixels, the sun (grazing to near the zenith), the surface, curvature, voids, and
 * last (so that older seeds keep their meaning) optionally an image of up to 72 x 72,
 * 1 to 3 samples a pixel side and 1 to 3 threads for the renders with the devices on, and
 * levels of detail (square or isometric coarse levels, 1 to 8 pixels a coarse cell: the
 * depths then are the levels' rule's, held on and off and across methods as above, as
 * oracle_lod holds them, but not to td_trace on the full grid), and after them an upright,
 * level camera over the grid and above the corners around it (the column walk's case).
 * Any render may refuse the camera, but all the same way. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "camera.h"
#include "fuzz.h"
#include "fuzz_terrain.h"
#include "lod.h"
#include "render.h"
#include "sunlit.h"
#include "trace.h"

enum { MAX_SIDE = 24, MAX_SIDE_BIG = 72, MAX_SAMPLES = 6144 };

/* How the renders run: threads for those with the devices on, and the coarse levels when
 * the scene asks for levels of detail (NULL otherwise). */
typedef struct run {
    int threads;
    const td_lod *lod;
} run;

/* A finding: says which contract broke (the compiler merges plain abort() calls). */
static void fail(const char *why)
{
    fprintf(stderr, "fuzz_render: %s\n", why);
    abort();
}

/* One value of table t (n entries), or for the last index a value from the next two bytes
 * spread over [lo, hi]. */
static double pick(fuzz_reader *r, const double *t, unsigned n, double lo, double hi)
{
    unsigned k = fuzz_byte(r) % (n + 1);
    double f;
    if (k < n)
        return t[k];
    f = (double)((fuzz_byte(r) << 8) | fuzz_byte(r)) / 65535.0;
    return lo + f * (hi - lo);
}

/* The case and the pixels where depths a and b differ, on stderr (a finding's report). */
static void describe(const td_view *v, const td_scene *sc, const float *a, const float *b, int32_t n)
{
    const td_scene_camera *c = &sc->camera;
    fprintf(stderr, "grid %d x %d, spacing %.17g x %.17g; camera %.17g %.17g %.17g heading %.17g pitch %.17g roll %.17g "
            "fov %.17g projection %d; image %d x %d; surface %d method %d; curvature %d\n",
            (int)v->grid->w, (int)v->grid->h, v->grid->sx, v->grid->sy, c->x, c->y, c->z, c->heading, c->pitch, c->roll,
            c->fov, (int)c->projection, (int)sc->image.width, (int)sc->image.height, (int)sc->quality.surface,
            (int)sc->quality.method, sc->effects.curvature);
    for (int32_t k = 0, shown = 0; k < n && shown < 8; k++)
        if (memcmp(&a[k], &b[k], sizeof a[k])) {
            fprintf(stderr, "  pixel %d (%d, %d): %.9g against %.9g\n", (int)k, (int)(k % sc->image.width),
                    (int)(k / sc->image.width), (double)a[k], (double)b[k]);
            shown++;
        }
}

/* Whether d is pixel k's depth to within a tie: between the nearest hits of its samples'
 * rays (the render's sample positions) lowered and raised by the walk's margin, as
 * td_trace finds them (lowering a ray from above the terrain can only bring its hit nearer). */
static int depth_tie(const td_view *v, const td_scene *sc, const td_camera *cam, int32_t k, float d)
{
    const int n = sc->quality.samples < 1 ? 1 : sc->quality.samples;
    const td_grid *g = v->grid;
    const double m = 1e-6 * (1.0 + fmax(fabs((double)g->zmin), fabs((double)g->zmax)));
    double lo = INFINITY, hi = INFINITY;
    for (int sr = 0; sr < n; sr++)
        for (int sc_ = 0; sc_ < n; sc_++) {
            td_ray r;
            td_hit h;
            td_camera_ray(cam, k % sc->image.width + (sc_ + 0.5) / n - 0.5, k / sc->image.width + (sr + 0.5) / n - 0.5,
                          &r);
            r.o[2] -= m;
            td_trace(v, TD_METHOD_AUTO, sc->quality.surface, &r, &h);
            lo = fmin(lo, h.t);
            r.o[2] += 2.0 * m;
            td_trace(v, TD_METHOD_AUTO, sc->quality.surface, &r, &h);
            hi = fmin(hi, h.t);
        }
    return (double)d >= (double)(float)lo * (1.0 - 1e-6) && (double)d <= (double)(float)hi * (1.0 + 1e-6);
}

/* Depths a and b of the same scene agree: bit for bit, or (cols: a render traced by image
 * columns among them) each differing pixel a tie for both. */
static int depths_agree(const td_view *v, const td_scene *sc, const float *a, const float *b, int cols)
{
    const int32_t n = sc->image.width * sc->image.height;
    td_camera cam;
    int ok = !memcmp(a, b, sizeof(float) * (size_t)n);
    if (!ok && cols && td_camera_setup(&sc->camera, sc->image.width, sc->image.height, v->grid, &cam, NULL) == TD_OK) {
        ok = 1;
        for (int32_t k = 0; k < n && ok; k++)
            ok = !memcmp(&a[k], &b[k], sizeof a[k]) || (depth_tie(v, sc, &cam, k, a[k]) && depth_tie(v, sc, &cam, k, b[k]));
    }
    return ok;
}

/* The shadow rays of sh[0 .. n) (tmax -1: none) that run along the sun's d, in batches of
 * up to 64 as the render sends them: td_occluded_par's answer against td_trace's. */
static void check_par(const td_view *v, td_surface sf, const td_ray *sh, int n, const td_sunlit *lit)
{
    double o[64][3];
    int at[64], np = 0;
    const double *d = NULL;
    for (int k = 0; k <= n; k++) {
        if (k < n && sh[k].tmax >= 0.0 && (!d || !memcmp(sh[k].d, d, sizeof sh[k].d))) {
            d = sh[k].d;
            memcpy(o[np], sh[k].o, sizeof o[np]);
            at[np++] = k;
        }
        if (np > 0 && (np == 64 || k == n)) {
            uint8_t occ[64];
            uint32_t steps = 0;
            td_occluded_par(v, TD_METHOD_AUTO, sf, d, np, (const double(*)[3])o, lit, occ, &steps);
            for (int q = 0; q < np; q++) {
                td_hit h;
                td_trace(v, TD_METHOD_AUTO, sf, &sh[at[q]], &h);
                if (occ[q] != (h.t < INFINITY))
                    fail("the render's batched shadow query is not the walk's answer");
            }
            np = 0;
        }
    }
}

/* The colour render with shadows, devices on and off; then its shadow rays one by one. */
static void check_shadows(const td_view *v, td_scene *sc, int curved, const run *ru)
{
    int32_t n = sc->image.width * sc->image.height, ns = n * sc->quality.samples * sc->quality.samples;
    td_ray *sh = calloc((size_t)ns, sizeof *sh);
    td_render_opts o;
    td_render_result on, off;
    td_err e1 = {0}, e2 = {0};
    td_status r1, r2;
    double a = sc->effects.sun_azimuth * M_PI / 180.0, el = sc->effects.sun_elevation * M_PI / 180.0;
    double sun[3] = {sin(a) * cos(el), cos(a) * cos(el), sin(el)};
    td_sunlit *lit = NULL;
    if (!sh)
        fail("harness");
    sc->image.format = TD_FORMAT_PNG;
    sc->effects.shadows = 1;
    td_render_opts_default(&o);
    o.threads = ru->threads;
    o.lod = ru->lod;
    o.shadow_rays = sh;
    memset(&on, 0, sizeof on);
    memset(&off, 0, sizeof off);
    r1 = td_render(v, sc, &o, &on, &e1);
    o.shadow_rays = NULL;
    o.threads = 1;
    o.off = TD_RENDER_OFF_OCCLUSION | TD_RENDER_OFF_SUNLIT;
    r2 = td_render(v, sc, &o, &off, &e2);
    fuzz_report("render with shadows", r1, e1.msg);
    if (r1 != r2 || (r1 == TD_OK && memcmp(on.rgba, off.rgba, (size_t)n * 4)))
        fail("shadows differ with the occlusion query and the sun bound");
    /* with a render's own bound and with the finer one a server keeps (td_sunlit_build's
       `kept`: blocks of one cell on grids this small) */
    for (int kept = 0; kept < 2 && r1 == TD_OK; kept++) {
        if (td_sunlit_build(v, sun, kept, &lit, &e1))
            fail("harness");
        for (int32_t k = 0; !curved && k < ns; k++) {
            td_hit h;
            uint32_t steps = 0;
            if (!(sh[k].tmax >= 0.0))
                continue;
            td_trace(v, TD_METHOD_AUTO, sc->quality.surface, &sh[k], &h);
            if (td_occluded(v, TD_METHOD_AUTO, sc->quality.surface, &sh[k], lit, &steps) != (h.t < INFINITY) ||
                td_occluded(v, TD_METHOD_AUTO, sc->quality.surface, &sh[k], NULL, &steps) != (h.t < INFINITY))
                fail("a shadow ray's occlusion query is not the walk's answer");
        }
        if (!curved)
            check_par(v, sc->quality.surface, sh, ns, lit);
        td_sunlit_free(lit);
        lit = NULL;
    }
    td_render_result_free(&on);
    td_render_result_free(&off);
    free(sh);
}

/* Depth renders with every method, devices on and off: all the same floats; and each
 * pixel td_trace's on its camera ray (straight rays). */
static void check_depths(const td_view *v, td_scene *sc, int curved, const run *ru)
{
    int32_t n = sc->image.width * sc->image.height;
    float *first = NULL;
    td_status first_rc = TD_OK;
    int first_cols = 0; /* auto's render traced by image columns */
    td_camera cam;
    sc->image.format = TD_FORMAT_DEPTH32F;
    for (int m = TD_METHOD_COUNT - 1; m >= 0; m--) { /* auto first */
        td_render_result res[2];
        td_err err = {0};
        td_status rc[2];
        for (int k = 0; k < 2; k++) {
            td_render_opts o;
            td_render_opts_default(&o);
            o.threads = k ? 1 : ru->threads;
            o.lod = ru->lod;
            o.off = k ? TD_RENDER_OFF_CAMERA : 0;
            sc->quality.method = (td_method)m;
            memset(&res[k], 0, sizeof res[k]);
            rc[k] = td_render(v, sc, &o, &res[k], &err);
        }
        if (m == TD_METHOD_COUNT - 1) {
            first_rc = rc[0];
            fuzz_report("render", rc[0], err.msg);
        }
        if (rc[0] != rc[1] || rc[0] != first_rc)
            fail("refused by one render and not another");
        const int cols = rc[0] == TD_OK && res[0].stats.column_rays > 0;
        if (rc[0] == TD_OK && res[1].stats.column_rays > 0)
            fail("the camera devices off, a render traced by image columns");
        if (rc[0] == TD_OK && !depths_agree(v, sc, res[0].depth, res[1].depth, cols)) {
            describe(v, sc, res[0].depth, res[1].depth, n);
            fail("the coherent camera rays are not the plain walk's");
        }
        if (rc[0] == TD_OK && first && !depths_agree(v, sc, res[0].depth, first, cols || first_cols)) {
            describe(v, sc, res[0].depth, first, n);
            fail("a method's depths are not auto's");
        }
        if (rc[0] == TD_OK && !first) {
            first = malloc(sizeof(float) * (size_t)n);
            if (!first)
                fail("harness");
            memcpy(first, res[0].depth, sizeof(float) * (size_t)n);
            first_cols = cols;
        }
        td_render_result_free(&res[0]);
        td_render_result_free(&res[1]);
    }
    if (first && !curved && sc->quality.samples == 1 && !sc->quality.lod &&
        td_camera_setup(&sc->camera, sc->image.width, sc->image.height, v->grid, &cam, NULL) == TD_OK)
        for (int32_t k = 0; k < n; k++) {
            td_ray r;
            td_hit h;
            td_camera_ray(&cam, k % sc->image.width, k / sc->image.width, &r);
            td_trace(v, TD_METHOD_AUTO, sc->quality.surface, &r, &h);
            float d = h.t < INFINITY ? (float)h.t : INFINITY;
            if (memcmp(&d, &first[k], sizeof d) && !(first_cols && depth_tie(v, sc, &cam, k, first[k])))
                fail("a pixel's depth is not its ray's hit");
        }
    free(first);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const double headings[] = {0, 90, 180, 270, 45, 135, 225, 315, 30};
    static const double pitches[] = {0, -90, -89.999, -45, -3, -0.5, 10, -60};
    static const double rolls[] = {0, 90, -90, 35, 180, -50};
    static const double fovs[] = {70, 170, 1, 30, 120, 179};
    static const double agls[] = {1.0, 10.0, 100.0, 1000.0, 0.5, 1e-3};
    static const double azs[] = {0, 90, 45, 180, 258, 300};
    static const double els[] = {3, 0.5, 30, 89, 60, 10};
    fuzz_reader r = {data, size, 0};
    td_accel *acc = NULL;
    td_accel_opts ao;
    td_scene sc;
    td_grid *g = fuzz_grid(&r, 33);
    if (!g)
        fail("harness");
    const int32_t w = g->w, h = g->h;
    const double sx = g->sx, sy = g->sy;

    td_scene_defaults(&sc);
    /* where: x and y as fractions of the grid (-0.25 .. 1.25), on a sample's lines or not */
    unsigned mode = fuzz_byte(&r), bx = (fuzz_byte(&r) << 8) | fuzz_byte(&r), by = (fuzz_byte(&r) << 8) | fuzz_byte(&r);
    double fx = ((double)bx / 65535.0 * 1.5 - 0.25) * (w - 1), fy = ((double)by / 65535.0 * 1.5 - 0.25) * (h - 1);
    sc.camera.x = ((mode & 1) ? floor(fx) : fx) * sx;
    sc.camera.y = ((mode & 2) ? floor(fy) : fy) * sy;
    /* how high: over the highest sample, among the crests, or a sample's height */
    unsigned zm = fuzz_byte(&r);
    double zmin = INFINITY, zmax = -INFINITY;
    for (size_t k = 0; k < (size_t)w * (size_t)h; k++) {
        zmin = fmin(zmin, g->z[k]);
        zmax = fmax(zmax, g->z[k]);
    }
    if (zm % 3 == 0)
        sc.camera.z = zmax + agls[(zm / 3) % 6];
    else if (zm % 3 == 1)
        sc.camera.z = zmin + (double)(zm / 3) / 85.0 * (zmax - zmin);
    else
        sc.camera.z = g->z[(zm / 3) % ((unsigned)w * (unsigned)h)];
    sc.camera.heading = pick(&r, headings, 9, 0.0, 360.0);
    sc.camera.pitch = pick(&r, pitches, 8, -90.0, 45.0);
    sc.camera.roll = pick(&r, rolls, 6, -180.0, 180.0);
    sc.camera.fov = pick(&r, fovs, 6, 1.0, 179.0);
    unsigned proj = fuzz_byte(&r) % 8;
    if (proj == 6) { /* a panorama all round */
        sc.camera.projection = TD_PROJ_CYLINDRICAL;
        sc.camera.fov = 360.0;
    } else if (proj == 7) { /* top-down over the whole grid */
        sc.camera.projection = TD_PROJ_ORTHOGRAPHIC;
    }
    sc.image.width = 1 + (int32_t)(fuzz_byte(&r) % MAX_SIDE);
    sc.image.height = 1 + (int32_t)(fuzz_byte(&r) % MAX_SIDE);
    sc.effects.sun_azimuth = pick(&r, azs, 6, 0.0, 360.0);
    sc.effects.sun_elevation = pick(&r, els, 6, 0.1, 89.9);
    unsigned opt = fuzz_byte(&r);
    sc.quality.surface = (td_surface)(opt % TD_SURFACE_COUNT);
    int curved = (opt >> 2) & 1;
    sc.effects.curvature = curved;
    uint8_t vb[5]; /* voids: inputs that end before them have none */
    for (int k = 0; k < 5; k++)
        vb[k] = (uint8_t)fuzz_byte(&r);
    fuzz_holes(g, vb[0], vb + 1);
    if (fuzz_byte(&r) & 1) { /* a larger image (several blocks, tall ones upright) */
        sc.image.width = 1 + (int32_t)(fuzz_byte(&r) % MAX_SIDE_BIG);
        sc.image.height = 1 + (int32_t)(fuzz_byte(&r) % MAX_SIDE_BIG);
    }
    unsigned last = fuzz_byte(&r); /* samples a side, threads of the devices' renders */
    sc.quality.samples = 1 + (int)(last % 3);
    while (sc.quality.samples > 1 && (int64_t)sc.image.width * sc.image.height * sc.quality.samples *
                                             sc.quality.samples > MAX_SAMPLES)
        sc.quality.samples--; /* an input's renders bounded (libFuzzer's 20 s under ASan) */
    run ru = {1 + (int)(last / 3 % 3), NULL};
    unsigned lodb = fuzz_byte(&r); /* levels of detail: square or isometric, 1 .. 8 pixels a cell */
    sc.quality.lod = (int)(lodb & 1);
    sc.quality.lod_grid = (lodb >> 1) & 1 ? TD_LOD_GRID_ISOMETRIC : TD_LOD_GRID_SQUARE;
    sc.quality.lod_pixels = 1.0 + (double)((lodb >> 2) % 8);
    if (fuzz_byte(&r) % 4 == 3) { /* an upright, level camera over the grid, above the
                                     corners around it: its columns walked as one
                                     (colwalk.h); the older seeds' bytes here are 0, 17,
                                     80 and 161, which keep their cameras */
        sc.camera.pitch = 0.0;
        sc.camera.roll = 0.0;
        sc.camera.projection = TD_PROJ_PERSPECTIVE;
        sc.quality.lod = 0;
        sc.effects.curvature = curved = 0;
        sc.camera.x = fmin(fmax(sc.camera.x, 0.05 * (w - 1) * sx), 0.95 * (w - 1) * sx);
        sc.camera.y = fmin(fmax(sc.camera.y, 0.05 * (h - 1) * sy), 0.95 * (h - 1) * sy);
        const int32_t i0 = (int32_t)(sc.camera.x / sx), j0 = (int32_t)(sc.camera.y / sy);
        double top = -INFINITY;
        for (int32_t j = j0 - 1; j <= j0 + 2; j++)
            for (int32_t i = i0 - 1; i <= i0 + 2; i++)
                if (i >= 0 && j >= 0 && i < w && j < h && g->z[(size_t)j * w + i] == g->z[(size_t)j * w + i])
                    top = fmax(top, g->z[(size_t)j * w + i]);
        sc.camera.z = (top > -INFINITY ? top : zmax) + agls[(zm / 3) % 6];
    }

    td_accel_opts_default(&ao);
    ao.maxmip = 1;
    ao.planes = 1;
    ao.threads = 1;
    if (td_grid_finish(g, NULL) || td_accel_build(g, &ao, &acc, NULL, NULL))
        fail("harness");
    td_view v = {g, acc->tiles};
    td_lod *lod = NULL;
    if (sc.quality.lod && (td_lod_build(g, TD_LOD_MAX, &ao, &lod, NULL) ||
                           (sc.quality.lod_grid == TD_LOD_GRID_ISOMETRIC && td_lod_add_iso(lod, g, NULL))))
        fail("harness");
    ru.lod = lod;
    check_depths(&v, &sc, curved, &ru);
    check_shadows(&v, &sc, curved, &ru);
    td_lod_free(lod);
    td_accel_free(acc);
    td_grid_free(g);
    return 0;
}
