/* fuzz_viewshed.c: the viewshed's sweep (core/vsweep.c) against the plain cast, one
 * segment a sample, byte for byte (docs/viewshed.md: every answer the sweep proves must be
 * the cast's). The input picks a small grid (2..48 samples a side) of exact planes and
 * bilinear patches (tests/unit/vs_terrains.h) or of heights from its own bytes, the
 * spacing, an observer (on a sample, on a grid line, between, or at two doubles the input
 * gives), the eye's and the target's heights (0, 1e-7, 1e-3, 1.5, 30 m; 0, 0.01, 1 m),
 * the surface, curvature, max_distance, voids and a second observer; both algorithms run
 * and must agree, errors included. Its seeds (corpus/viewshed) are the cases of
 * tests/unit/test_vsweep.c that a fuzzer of these terrains found (test_low_eye,
 * test_end_tangent, test_ulp_eyes; diagonal-vertex-hole, test_vertex_hole_diagonal), each
 * failing on the code before its fix, and a few plain ones. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "fuzz.h"
#include "viewshed.h"
#include "fuzz_terrain.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const double eyes[] = {0.0, 1e-7, 1e-3, 1.5, 30.0}, tgts[] = {0.0, 0.01, 1.0};
    fuzz_reader r = {data, size, 0};
    td_accel *acc = NULL;
    td_accel_opts ao;
    td_view v;
    td_grid *g = fuzz_grid(&r, 48);
    if (!g)
        abort();
    const int32_t w = g->w, h = g->h;
    const double sx = g->sx, sy = g->sy;

    /* the observer: on a sample, a column's line, a row's line, between, or two doubles */
    unsigned mode = fuzz_byte(&r) % 5, bx = fuzz_byte(&r) << 8, by;
    bx |= fuzz_byte(&r);
    by = fuzz_byte(&r) << 8;
    by |= fuzz_byte(&r);
    double fx = (double)bx / 65535.0 * (w - 1), fy = (double)by / 65535.0 * (h - 1);
    td_vs_point p = {(mode == 0 || mode == 1 ? floor(fx) : fx) * sx, (mode == 0 || mode == 2 ? floor(fy) : fy) * sy};
    if (mode == 4) {
        p.x = fuzz_double(&r);
        p.y = fuzz_double(&r);
    }
    td_vs_point obs[2] = {p, p};
    td_viewshed_opts o;
    td_viewshed_opts_default(&o);
    o.obs = obs;
    o.nobs = 1;
    unsigned opt = fuzz_byte(&r);
    o.height = eyes[opt % 5];
    o.target_height = tgts[(opt / 5) % 3];
    o.surface = (td_surface)((opt / 15) % TD_SURFACE_COUNT);
    unsigned more = fuzz_byte(&r);
    if (more & 1) {
        o.curvature = 1;
        o.k = 0.13;
    }
    if (more & 2)
        o.max_distance = (double)(more >> 2) / 63.0 * (w + h) * sx;
    uint8_t vb[5]; /* voids last: inputs that end before them have none */
    for (int k = 0; k < 5; k++)
        vb[k] = (uint8_t)fuzz_byte(&r);
    fuzz_holes(g, vb[0], vb + 1);
    if (fuzz_byte(&r) & 1) { /* a second observer (a cumulative viewshed), on a sample */
        unsigned ox = fuzz_byte(&r), oy = fuzz_byte(&r);
        obs[1] = (td_vs_point){(double)(ox % (unsigned)w) * sx, (double)(oy % (unsigned)h) * sy};
        o.nobs = 2;
    }
    td_accel_opts_default(&ao);
    ao.maxmip = 1;
    ao.planes = 1;
    ao.threads = 1;
    if (td_grid_finish(g, NULL) || td_accel_build(g, &ao, &acc, NULL, NULL))
        abort();
    v.grid = g;
    v.accel = acc->tiles;

    size_t n = (size_t)w * (size_t)h;
    uint8_t *a = malloc(n), *b = malloc(n);
    td_viewshed_stats sa, sb;
    td_err ea = {0}, eb = {0};
    if (!a || !b)
        abort();
    o.algo = TD_VS_ALGO_CAST;
    o.threads = 1;
    td_status ra = td_viewshed(&v, &o, a, &sa, &ea);
    o.algo = TD_VS_ALGO_SWEEP;
    o.threads = 1 + (int)(more % 3);
    td_status rb = td_viewshed(&v, &o, b, &sb, &eb);
    fuzz_report("viewshed", ra, ea.msg);
    if (ra != rb || (ra == TD_OK && memcmp(a, b, n) != 0))
        abort(); /* the sweep's answer is not the cast's */
    free(a);
    free(b);
    td_accel_free(acc);
    td_grid_free(g);
    return 0;
}
