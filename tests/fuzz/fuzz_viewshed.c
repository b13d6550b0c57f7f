/* fuzz_viewshed.c: the viewshed's sweep (core/vsweep.c) against the plain cast, one
 * segment a sample, byte for byte (docs/viewshed.md: every answer the sweep proves must be
 * the cast's). The input picks a small grid (2..48 samples a side) of exact planes and
 * bilinear patches (tests/unit/vs_terrains.h) or of heights from its own bytes, the
 * spacing, an observer (on a sample, on a grid line, between, or at two doubles the input
 * gives), the eye's and the target's heights (0, 1e-7, 1e-3, 1.5, 30 m; 0, 0.01, 1 m),
 * the surface, curvature, max_distance, voids and a second observer; both algorithms run
 * and must agree, errors included. Its seeds (corpus/viewshed) are the cases of
 * tests/unit/test_vsweep.c that a fuzzer of these terrains found (test_low_eye,
 * test_end_tangent, test_ulp_eyes), each failing on the code before its fix, and a few
 * plain ones. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "fuzz.h"
#include "viewshed.h"
#include "../unit/vs_terrains.h"

typedef struct reader {
    const uint8_t *p;
    size_t n, at;
} reader;

/* The next byte, 0 past the end */
static unsigned byte(reader *r) { return r->at < r->n ? r->p[r->at++] : 0u; }

/* The next 8 bytes as a double (0 past the end) */
static double dbl(reader *r)
{
    uint8_t b[8];
    double d;
    for (int k = 0; k < 8; k++)
        b[k] = (uint8_t)byte(r);
    memcpy(&d, b, sizeof d);
    return d;
}

/* Heights: one of vs_terrains.h's exact terrains, or (the kind after them) the input's
 * bytes, a byte a sample in 0.25 m steps. */
static void fill(td_grid *g, reader *r)
{
    int kind = (int)(byte(r) % (VS_T_COUNT + 1));
    double a = (double)(byte(r) % 7) - 3.0, b = (double)(byte(r) % 7) - 3.0;
    double c = ((double)(byte(r) % 9) - 4.0) * 0.25, d = (double)(byte(r) % 3);
    int i0 = (int)(byte(r) % (unsigned)g->w), j0 = (int)(byte(r) % (unsigned)g->h);
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] =
                (float)(kind == VS_T_COUNT ? 200.0 + 0.25 * ((double)byte(r) - 128.0)
                                           : vs_exact_z(kind, a, b, c, d, i0, j0, i, j));
}

/* Voids, from byte v (the input's last field, so that inputs without it have none):
 * v % 4 = 0 none, 1 a rectangle (from the four bytes after it), 2 the samples with
 * (5 i + 3 j + v / 4) % 7 == 0, 3 a row and a column through the grid's middle. */
static void holes(td_grid *g, unsigned v, const uint8_t *rect)
{
    int32_t w = g->w, h = g->h;
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++) {
            int hole = 0;
            if (v % 4 == 1)
                hole = i >= rect[0] % w && i <= rect[0] % w + rect[1] % 6 && j >= rect[2] % h &&
                       j <= rect[2] % h + rect[3] % 6;
            else if (v % 4 == 2)
                hole = (5 * i + 3 * j + (int)(v / 4)) % 7 == 0;
            else if (v % 4 == 3)
                hole = i == w / 2 || j == h / 2;
            if (hole)
                g->z[(size_t)j * (size_t)w + (size_t)i] = NAN;
        }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const double sxs[] = {10.0, 7.5, 1.0, 1000.0}, aspect[] = {1.0, 4.0 / 3.0, 5.0 / 3.0, 0.75};
    static const double eyes[] = {0.0, 1e-7, 1e-3, 1.5, 30.0}, tgts[] = {0.0, 0.01, 1.0};
    reader r = {data, size, 0};
    td_grid *g = NULL;
    td_accel *acc = NULL;
    td_accel_opts ao;
    td_view v;
    int32_t w = 2 + (int32_t)(byte(&r) % 47), h = 2 + (int32_t)(byte(&r) % 47);
    unsigned sp = byte(&r);
    double sx = sxs[sp % 4], sy = sx * aspect[(sp >> 2) % 4];
    if (td_grid_create(w, h, sx, sy, 3 + (int)((sp >> 4) % 3), NULL, &g, NULL))
        abort();
    fill(g, &r);

    /* the observer: on a sample, a column's line, a row's line, between, or two doubles */
    unsigned mode = byte(&r) % 5, bx = byte(&r) << 8, by;
    bx |= byte(&r);
    by = byte(&r) << 8;
    by |= byte(&r);
    double fx = (double)bx / 65535.0 * (w - 1), fy = (double)by / 65535.0 * (h - 1);
    td_vs_point p = {(mode == 0 || mode == 1 ? floor(fx) : fx) * sx, (mode == 0 || mode == 2 ? floor(fy) : fy) * sy};
    if (mode == 4) {
        p.x = dbl(&r);
        p.y = dbl(&r);
    }
    td_vs_point obs[2] = {p, p};
    td_viewshed_opts o;
    td_viewshed_opts_default(&o);
    o.obs = obs;
    o.nobs = 1;
    unsigned opt = byte(&r);
    o.height = eyes[opt % 5];
    o.target_height = tgts[(opt / 5) % 3];
    o.surface = (td_surface)((opt / 15) % TD_SURFACE_COUNT);
    unsigned more = byte(&r);
    if (more & 1) {
        o.curvature = 1;
        o.k = 0.13;
    }
    if (more & 2)
        o.max_distance = (double)(more >> 2) / 63.0 * (w + h) * sx;
    uint8_t vb[5]; /* voids last: inputs that end before them have none */
    for (int k = 0; k < 5; k++)
        vb[k] = (uint8_t)byte(&r);
    holes(g, vb[0], vb + 1);
    if (byte(&r) & 1) { /* a second observer (a cumulative viewshed), on a sample */
        unsigned ox = byte(&r), oy = byte(&r);
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
