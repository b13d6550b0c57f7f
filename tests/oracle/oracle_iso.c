/* oracle_iso.c: the isometric lattice's walk (td_iso_trace, core/isogrid.c) against Embree
 * and the double-precision reference, as oracle.c holds the square grid's surfaces.
 *
 *   oracle_iso DATASET [--rays N]     (volcano, levi, picos, trinidad-crop)
 *
 * Per dataset: the lattice with square rows and the equilateral one at the grid's density
 * (floats), and the levels of detail's isometric twins 1-3 (two-byte vertices). Embree
 * gets each as a triangle mesh built here from isogrid.h's layout alone (vertex (r, c) at
 * td_iso_x, r b; the strip between rows r and r+1 cut into O-based and E-based triangles;
 * triangles with a void corner left out), so a lattice whose triangles differ from its
 * description shows. Rays: camera fans from above the highest sample, random rays from
 * around and below the lattice toward it, rays along each of the three families of
 * lattice lines, rays grazing a sample (+-1e-9 m). td_iso_trace and Embree agree when
 * their hits lie within 1 mm plus float32 rounding of the point (td_ref_tol) or both
 * miss, as in oracle.c; a disagreement is settled by iso_reference.c on the same heights
 * (the decoded ones for packed lattices, band 1e-6 of the heights as in test_isogrid.c):
 * terrad right = "embree wrong", inside the band = "tie", else an error. Embree wrong on
 * more than 5% of a lattice's rays is an error too (the float mesh misses grazing and
 * along-the-line rays by a rounding: 0.3-2.8%; a mesh cut the other way, 27%), so the
 * walk and the reference cannot share a wrong idea of the lattice. Exit status 1 on any
 * error. */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dem.h"
#include "embree_ref.h"
#include "iso_reference.h"
#include "lod.h"
#include "reference.h"

#ifndef TERRAD_TEST_DATA
#define TERRAD_TEST_DATA "tests/data"
#endif

#define MAX_PRINT 8

typedef struct tally {
    uint64_t rays, hits, agree, embree_wrong, tie, error;
} tally;

static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

/* Embree's mesh of lattice l, from the layout of isogrid.h. */
static td_status mesh_of(const td_iso *l, td_embree **out, td_err *err)
{
    td_status rc = TD_ENOMEM;
    size_t nv = td_iso_row_offset(l->nx, l->ny), nt = 0;
    double *v = malloc(3 * nv * sizeof *v);
    uint32_t *t = malloc(3 * (size_t)(l->ny - 1) * (size_t)(2 * l->nx - 1) * sizeof *t);
    *out = NULL;
    if (!v || !t) {
        td_err_set(err, rc, "oracle_iso: out of memory");
        goto out;
    }
    for (int32_t r = 0; r < l->ny; r++) {
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            double *p = v + 3 * (td_iso_row_offset(l->nx, r) + (size_t)c);
            p[0] = (r & 1) ? (c == 0 ? 0.0 : (c == l->nx ? (l->nx - 1) * l->a : (c - 0.5) * l->a)) : c * l->a;
            p[1] = r * l->b;
            p[2] = td_iso_at(l, r, c);
        }
    }
    for (int32_t r = 0; r + 1 < l->ny; r++) {
        /* E: the strip's even row, O: its odd row */
        uint32_t E = (uint32_t)td_iso_row_offset(l->nx, (r & 1) ? r + 1 : r);
        uint32_t O = (uint32_t)td_iso_row_offset(l->nx, (r & 1) ? r : r + 1);
        for (int32_t q = 0; q < 2 * l->nx - 1; q++) {
            uint32_t c = (uint32_t)(q / 2), k[3];
            if (!(q & 1))
                k[0] = O + c, k[1] = O + c + 1, k[2] = E + c; /* O-based */
            else
                k[0] = E + c, k[1] = E + c + 1, k[2] = O + c + 1; /* E-based */
            if (isnan(v[3 * k[0] + 2]) || isnan(v[3 * k[1] + 2]) || isnan(v[3 * k[2] + 2]))
                continue;
            memcpy(t + 3 * nt++, k, sizeof k);
        }
    }
    rc = td_embree_build_mesh(v, nv, t, nt, out, err);
out:
    free(v);
    free(t);
    return rc;
}

/* The rays for lattice l: see the top of the file. */
static size_t make_rays(const td_iso *l, size_t n, uint64_t *seed, td_ray *rays)
{
    double X = (l->nx - 1) * l->a, Y = (l->ny - 1) * l->b, dz = l->zmax - l->zmin + 1.0;
    for (size_t k = 0; k < n; k++) {
        td_ray *r = &rays[k];
        int kind = (int)(k % 5);
        int32_t row = 1 + (int32_t)(rnd(seed) * (l->ny - 2)), col = 1 + (int32_t)(rnd(seed) * (l->nx - 2));
        double vx = td_iso_x(l, row, col), vy = row * l->b, vz = td_iso_at(l, row, col);
        double p[3] = {rnd(seed) * X, rnd(seed) * Y, l->zmin + rnd(seed) * dz};
        vz = isnan(vz) ? l->zmax : vz;
        *r = (td_ray){{0, 0, 0}, {0, 0, 0}, 0.0, INFINITY};
        if (kind == 0) { /* camera fan from above */
            double o[3] = {X * rnd(seed), Y * rnd(seed), l->zmax + 0.3 * dz};
            for (int a = 0; a < 3; a++)
                r->o[a] = o[a], r->d[a] = p[a] - o[a];
        } else if (kind == 1) { /* from around and below */
            double o[3] = {(rnd(seed) * 1.4 - 0.2) * X, (rnd(seed) * 1.4 - 0.2) * Y, l->zmin + (rnd(seed) * 1.6 - 0.3) * dz};
            for (int a = 0; a < 3; a++)
                r->o[a] = o[a], r->d[a] = p[a] - o[a];
        } else if (kind == 2) { /* along a family of lattice lines through a sample */
            static const double dir[3][2] = {{1.0, 0.0}, {0.5, 1.0}, {-0.5, 1.0}};
            int f = (int)(rnd(seed) * 3);
            r->o[0] = vx, r->o[1] = vy, r->o[2] = vz + 20.0 * rnd(seed) - 10.0;
            r->d[0] = dir[f][0] * l->a, r->d[1] = dir[f][1] * l->b, r->d[2] = 0.2 * (rnd(seed) - 0.5);
            r->tmin = -1e4;
        } else if (kind == 3) { /* grazing a sample */
            double ang = 2.0 * M_PI * rnd(seed);
            r->o[0] = vx - 10.0 * l->a * cos(ang), r->o[1] = vy - 10.0 * l->b * sin(ang);
            r->o[2] = vz + ((int)(rnd(seed) * 3) - 1) * 1e-9;
            r->d[0] = l->a * cos(ang), r->d[1] = l->b * sin(ang), r->d[2] = 0.0;
            r->tmax = 12.0;
        } else { /* steep, at a sample */
            r->o[0] = vx + 2.0 * l->a * (rnd(seed) - 0.5), r->o[1] = vy + 2.0 * l->b * (rnd(seed) - 0.5);
            r->o[2] = vz + 50.0;
            r->d[0] = vx - r->o[0], r->d[1] = vy - r->o[1], r->d[2] = -50.0;
        }
    }
    return n;
}

/* n rays on lattice l (the walk's), Embree on its mesh, disagreements settled on fl (l's
 * heights as floats). */
static void check(const char *what, const td_iso *l, const td_iso *fl, size_t n, uint64_t *seed, tally *t)
{
    td_err err = {0};
    td_embree *emb = NULL;
    td_ray *rays = calloc(n, sizeof *rays);
    double *te = calloc(n, sizeof *te);
    double eps = 1e-6 * (1.0 + fmax(fabs(l->zmin), fabs(l->zmax)));
    tally t0 = *t;
    if (!rays || !te || mesh_of(l, &emb, &err)) {
        printf("ERROR %s: %s\n", what, err.msg[0] ? err.msg : "out of memory");
        t->error++;
        goto out;
    }
    make_rays(l, n, seed, rays);
    td_embree_trace_many(emb, rays, n, te);
    for (size_t k = 0; k < n; k++) {
        const td_ray *r = &rays[k];
        td_hit h;
        td_iso_trace(l, r, &h);
        t->rays++;
        t->hits += h.t < INFINITY;
        int same = !(h.t < INFINITY) && !(te[k] < INFINITY);
        if (h.t < INFINITY && te[k] < INFINITY)
            same = td_ref_dist(r, h.t, te[k]) <= td_ref_tol(h.p);
        if (same) {
            t->agree++;
        } else {
            td_iso_ref_hit ref;
            td_iso_ref_trace(fl, r, eps, &ref);
            td_iso_ref_verdict v = td_iso_ref_judge(fl, r, &ref, h.t, eps);
            if (v == TD_ISO_REF_AGREE) {
                t->embree_wrong++;
            } else if (v == TD_ISO_REF_TIE) {
                t->tie++;
            } else if (t->error++ < MAX_PRINT) {
                printf("ERROR %s: o %a %a %a d %a %a %a [%a, %a] terrad %.17g embree %.17g ref %.17g\n",
                       what, r->o[0], r->o[1], r->o[2], r->d[0], r->d[1], r->d[2], r->tmin, r->tmax,
                       h.t, te[k], ref.t);
            }
        }
    }
    if (20 * (t->embree_wrong - t0.embree_wrong) > t->rays - t0.rays) {
        printf("ERROR %s: Embree wrong on more than 5%% of the rays: not the lattice's mesh?\n", what);
        t->error++;
    }
    printf("%-28s %8" PRIu64 " rays, %8" PRIu64 " hits: %" PRIu64 " agree with Embree, %" PRIu64
           " Embree wrong, %" PRIu64 " ties, %" PRIu64 " errors\n", what, t->rays - t0.rays,
           t->hits - t0.hits, t->agree - t0.agree, t->embree_wrong - t0.embree_wrong, t->tie - t0.tie,
           t->error - t0.error);
out:
    td_embree_free(emb);
    free(rays);
    free(te);
}

int main(int argc, char **argv)
{
    td_err err = {0};
    td_grid *g = NULL;
    td_lod *lod = NULL;
    td_dem_opts o;
    td_accel_opts ao = {0, 0, 1, 1, 0, 0};
    tally t = {0};
    uint64_t seed = 1414;
    size_t n = 60000;
    char path[512];
    int rc = 1;

    if (argc == 4 && !strcmp(argv[2], "--rays"))
        n = (size_t)strtoul(argv[3], NULL, 10);
    else if (argc != 2)
        argc = 0;
    if (argc == 0 || n == 0) {
        fprintf(stderr, "usage: %s volcano|levi|picos|trinidad-crop [--rays N]\n", argv[0]);
        goto out;
    }
    td_dem_opts_default(&o);
    if (!strcmp(argv[1], "levi")) {
        o.encoding = TD_ENC_RGB_DIV;
        o.spacing[0] = o.spacing[1] = 20.0;
    }
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA,
             !strcmp(argv[1], "volcano")         ? "volcano.asc"
             : !strcmp(argv[1], "levi")          ? "levi-topography.png"
             : !strcmp(argv[1], "picos")         ? "picos-dtm.asc"
             : !strcmp(argv[1], "trinidad-crop") ? "trinidad-crop.f32"
                                                 : argv[1]);
    if (td_dem_load(path, &o, &g, &err) || td_lod_build(g, 3, &ao, &lod, &err) ||
        td_lod_add_iso(lod, g, &err)) {
        fprintf(stderr, "oracle_iso: %s\n", err.msg);
        goto out;
    }
    for (int k = 0; k < 2; k++) {
        td_iso *l = NULL;
        if (td_iso_from_grid(g, 1, (td_iso_rows)k, &l, &err)) {
            fprintf(stderr, "oracle_iso: %s\n", err.msg);
            goto out;
        }
        check(k ? "equilateral" : "square rows", l, l, n, &seed, &t);
        td_iso_free(l);
    }
    for (int k = 1; k <= lod->levels; k++) {
        td_iso *fl = NULL;
        char what[64];
        if (td_iso_unpack(lod->iso[k]->packed, &fl, &err)) {
            fprintf(stderr, "oracle_iso: %s\n", err.msg);
            goto out;
        }
        snprintf(what, sizeof what, "LOD %d twin, two-byte", k);
        check(what, lod->iso[k], fl, n / 2, &seed, &t);
        td_iso_free(fl);
    }
    printf("total: %" PRIu64 " rays, %" PRIu64 " agree with Embree, %" PRIu64 " Embree wrong, %" PRIu64
           " ties, %" PRIu64 " errors\n%s\n", t.rays, t.agree, t.embree_wrong, t.tie, t.error,
           t.error ? "FAIL" : "PASS");
    rc = t.error ? 1 : 0;
out:
    td_lod_free(lod);
    td_grid_free(g);
    return rc;
}
