/* hc_tool.c: made-up degenerate DEMs and ray files for tests/hardcases/degenerate.sh, and
 * the judge of `terrad trace` output against the double-precision reference.
 *
 *   hc_tool dem KIND OUT [key=value ...]   writes OUT.f32 + OUT.json (width, height,
 *        spacing_m, nodata); keys: w h sx sy base relief plateau k seed voids tile
 *        (KIND and voids as in hc.h; void samples are written as the nodata value -9999)
 *   hc_tool rays DEM OUT N SEED            N rays of every kind of hc.h (little-endian
 *        float64 ox oy oz dx dy dz) over the DEM as td_dem_load reads it
 *   hc_tool badrays OUT [C]                pairs of a good ray and one with NaN or inf in
 *        component C (0..5 = ox oy oz dx dy dz; all six without C)
 *   hc_tool check DEM RAYS SURFACE HITS [SURFACE HITS ...]   judges each t of HITS (as
 *        `terrad trace` writes them) for the ray of RAYS on SURFACE: NaN, -inf or a t
 *        before the origin is wrong; otherwise the verdict of hc_judge (agree, tie,
 *        float, wrong)
 * Exit status: 0 ok, 1 a wrong answer or a failure, 2 usage. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dem.h"
#include "hc.h"

/* ---- little-endian float64 files ------------------------------------------------------ */
static int write_f64(FILE *f, const double *v, size_t n)
{
    int ok = 1;
    for (size_t k = 0; k < n && ok; k++) {
        unsigned char b[8];
        uint64_t u;
        memcpy(&u, &v[k], 8);
        for (int q = 0; q < 8; q++, u >>= 8)
            b[q] = (unsigned char)(u & 0xff);
        ok = fwrite(b, 1, 8, f) == 8;
    }
    return ok;
}

static double *read_f64(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    double *v = NULL;
    size_t cap = 0, len = 0;
    unsigned char b[8];
    int ok = f != NULL;
    while (ok && fread(b, 1, 8, f) == 8) {
        uint64_t u = 0;
        if (len == cap) {
            double *nv = realloc(v, (cap = cap ? 2 * cap : 4096) * sizeof *v);
            ok = nv != NULL;
            if (!ok)
                break;
            v = nv;
        }
        for (int q = 7; q >= 0; q--)
            u = (u << 8) | b[q];
        memcpy(&v[len++], &u, 8);
    }
    if (f)
        fclose(f);
    if (!ok) {
        free(v);
        v = NULL;
        len = 0;
    }
    *n = len;
    return v;
}

/* ---- dem ------------------------------------------------------------------------------ */
static int parse_kind(const char *s, hc_terrain *out)
{
    int ok = 0;
    for (int k = 0; k < HC_T_COUNT; k++) {
        if (!strcmp(s, hc_terrain_name((hc_terrain)k))) {
            *out = (hc_terrain)k;
            ok = 1;
        }
    }
    return ok;
}

static int parse_voids(const char *s, hc_voids *out)
{
    int ok = 0;
    for (int k = 0; k < HC_V_COUNT; k++) {
        if (!strcmp(s, hc_voids_name((hc_voids)k))) {
            *out = (hc_voids)k;
            ok = 1;
        }
    }
    return ok;
}

static int cmd_dem(int argc, char **argv)
{
    hc_terrain kind = HC_T_FLAT;
    hc_terrain_params p;
    td_grid *g = NULL;
    char path[1024];
    FILE *f = NULL;
    int rc = 1;
    float *row = NULL;

    if (argc < 2 || !parse_kind(argv[0], &kind)) {
        fprintf(stderr, "hc_tool dem: unknown terrain kind\n");
        return 2;
    }
    hc_terrain_defaults(&p, kind);
    for (int k = 2; k < argc; k++) {
        char key[32];
        const char *eq = strchr(argv[k], '=');
        size_t kl = eq ? (size_t)(eq - argv[k]) : 0;
        double v;
        if (!eq || kl >= sizeof key) {
            fprintf(stderr, "hc_tool dem: '%s' is not key=value\n", argv[k]);
            return 2;
        }
        memcpy(key, argv[k], kl);
        key[kl] = '\0';
        v = strtod(eq + 1, NULL);
        if (!strcmp(key, "voids")) {
            if (!parse_voids(eq + 1, &p.voids)) {
                fprintf(stderr, "hc_tool dem: unknown voids '%s'\n", eq + 1);
                return 2;
            }
        } else if (!strcmp(key, "w")) p.w = (int32_t)v;
        else if (!strcmp(key, "h")) p.h = (int32_t)v;
        else if (!strcmp(key, "sx")) p.sx = v, p.sy = v;
        else if (!strcmp(key, "sy")) p.sy = v;
        else if (!strcmp(key, "base")) p.base = v;
        else if (!strcmp(key, "relief")) p.relief = v;
        else if (!strcmp(key, "plateau")) p.plateau = v;
        else if (!strcmp(key, "k")) p.k = (int)v;
        else if (!strcmp(key, "seed")) p.seed = (uint64_t)v;
        else if (!strcmp(key, "tile")) p.tile_log2 = (int)v;
        else {
            fprintf(stderr, "hc_tool dem: unknown key '%s'\n", key);
            return 2;
        }
    }
    g = hc_terrain_make(&p);
    row = malloc(sizeof(float) * (size_t)p.w);
    if (!g || !row)
        goto out;
    snprintf(path, sizeof path, "%s.f32", argv[1]);
    f = fopen(path, "wb");
    if (!f)
        goto out;
    for (int32_t j = g->h - 1; j >= 0; j--) { /* the file's first row is the northern one */
        for (int32_t i = 0; i < g->w; i++) {
            float z = td_grid_at(g, i, j);
            row[i] = isnan(z) ? -9999.0f : z;
        }
        if (fwrite(row, sizeof(float), (size_t)g->w, f) != (size_t)g->w)
            goto out;
    }
    if (fclose(f) != 0) {
        f = NULL;
        goto out;
    }
    snprintf(path, sizeof path, "%s.json", argv[1]);
    f = fopen(path, "w");
    if (!f)
        goto out;
    fprintf(f, "{\"width\": %d, \"height\": %d, \"spacing_m\": [%.17g, %.17g], \"nodata\": -9999,\n"
               " \"description\": \"hc_tool %s voids=%s base=%.17g relief=%.17g seed=%llu\"}\n",
            (int)g->w, (int)g->h, g->sx, g->sy, hc_terrain_name(kind), hc_voids_name(p.voids), p.base,
            p.relief, (unsigned long long)p.seed);
    rc = fclose(f) == 0 ? 0 : 1;
    f = NULL;
out:
    if (f)
        fclose(f);
    if (rc)
        fprintf(stderr, "hc_tool dem: could not write %s\n", argv[1]);
    free(row);
    td_grid_free(g);
    return rc;
}

static td_grid *load(const char *path)
{
    td_dem_opts o;
    td_grid *g = NULL;
    td_err err = {0};
    td_dem_opts_default(&o);
    if (td_dem_load(path, &o, &g, &err) != TD_OK)
        fprintf(stderr, "hc_tool: %s\n", err.msg);
    return g;
}

/* ---- rays ------------------------------------------------------------------------------ */
static int cmd_rays(int argc, char **argv)
{
    td_grid *g;
    FILE *f;
    size_t n;
    uint64_t s;
    int ok;
    if (argc != 4)
        return 2;
    g = load(argv[0]);
    n = (size_t)strtoull(argv[2], NULL, 10);
    s = strtoull(argv[3], NULL, 0);
    f = fopen(argv[1], "wb");
    ok = g && f;
    for (size_t k = 0; k < n && ok; k++) {
        td_ray r;
        hc_ray_make(g, (hc_ray_kind)hc_rng_int(&s, HC_R_COUNT), &s, &r);
        double v[6] = {r.o[0], r.o[1], r.o[2], r.d[0], r.d[1], r.d[2]};
        ok = write_f64(f, v, 6);
    }
    if (f && fclose(f) != 0)
        ok = 0;
    td_grid_free(g);
    return ok ? 0 : 1;
}

static int cmd_badrays(int argc, char **argv)
{
    const double bad[] = {NAN, INFINITY, -INFINITY};
    FILE *f;
    int ok, only = argc == 2 ? atoi(argv[1]) : -1;
    if (argc != 1 && argc != 2)
        return 2;
    f = fopen(argv[0], "wb");
    ok = f != NULL;
    for (int c = 0; c < 6 && ok; c++) {
        if (only >= 0 && c != only)
            continue;
        for (int b = 0; b < 3 && ok; b++) {
            double v[12] = {10, 10, 500, 0.3, 0.2, -1, 10, 10, 500, 0.3, 0.2, -1};
            v[6 + c] = bad[b]; /* the second ray of each pair is bad */
            ok = write_f64(f, v, 12);
        }
    }
    if (f && fclose(f) != 0)
        ok = 0;
    return ok ? 0 : 1;
}

/* ---- check ------------------------------------------------------------------------------- */
/* Judges one hits file for one surface; returns the wrong answers (or 1 on a bad file). */
static uint64_t check_one(const hc_scene *sc, const char *surface, const double *rv, size_t nr,
                          const char *hits_path)
{
    static const char *const vname[HC_VERDICTS] = {"agree", "tie", "float", "WRONG"};
    td_surface sf;
    size_t nh = 0;
    double *hv = read_f64(hits_path, &nh);
    uint64_t v[HC_VERDICTS] = {0}, hits = 0, printed = 0;
    if (td_surface_parse(surface, &sf) != TD_OK || !hv || nr / 6 != nh) {
        fprintf(stderr, "hc_tool check: surface '%s', %zu rays but %s holds %zu hits\n", surface, nr / 6,
                hits_path, nh);
        v[HC_WRONG] = 1;
        nh = 0;
    }
    for (size_t k = 0; k < nh; k++) {
        td_ray r;
        double t = hv[k], ref_t = INFINITY, near_t = INFINITY, strict_t = INFINITY;
        int verdict;
        hc_ray_set(&r, rv[6 * k], rv[6 * k + 1], rv[6 * k + 2], rv[6 * k + 3], rv[6 * k + 4], rv[6 * k + 5]);
        if (isnan(t) || t == -INFINITY || t < r.tmin)
            verdict = HC_WRONG;
        else
            verdict = hc_judge(sc, sf, &r, t, &ref_t, &near_t, &strict_t);
        hits += t < INFINITY;
        v[verdict]++;
        if (verdict == HC_WRONG && printed++ < 10) {
            printf("WRONG %s surface=%s ray %zu: got t=%.17g want t=%.17g (near %.17g strict %.17g)\n",
                   hits_path, surface, k, t, ref_t, near_t, strict_t);
            hc_print_ray(stdout, &r);
        }
    }
    if (nh)
        printf("check %s %s: %zu rays, %llu hits: %llu %s, %llu %s, %llu %s, %llu %s\n", hits_path, surface, nh,
               (unsigned long long)hits, (unsigned long long)v[0], vname[0], (unsigned long long)v[1], vname[1],
               (unsigned long long)v[2], vname[2], (unsigned long long)v[3], vname[3]);
    free(hv);
    return v[HC_WRONG];
}

/* check DEM RAYS SURFACE HITS [SURFACE HITS ...] */
static int cmd_check(int argc, char **argv)
{
    hc_scene sc;
    size_t nr = 0;
    double *rv = NULL;
    uint64_t wrong = 0;
    int rc = 1;
    if (argc < 4 || argc % 2)
        return 2;
    if (hc_scene_init(&sc, argv[0], load(argv[0]), 0) != 0)
        goto out;
    rv = read_f64(argv[1], &nr);
    if (!rv || nr % 6) {
        fprintf(stderr, "hc_tool check: %s is not a whole number of rays\n", argv[1]);
        goto out;
    }
    for (int k = 2; k + 1 < argc; k += 2)
        wrong += check_one(&sc, argv[k], rv, nr, argv[k + 1]);
    rc = wrong ? 1 : 0;
out:
    free(rv);
    hc_scene_free(&sc);
    return rc;
}

int main(int argc, char **argv)
{
    int rc = 2;
    if (argc >= 2 && !strcmp(argv[1], "dem"))
        rc = cmd_dem(argc - 2, argv + 2);
    else if (argc >= 2 && !strcmp(argv[1], "rays"))
        rc = cmd_rays(argc - 2, argv + 2);
    else if (argc >= 2 && !strcmp(argv[1], "badrays"))
        rc = cmd_badrays(argc - 2, argv + 2);
    else if (argc >= 2 && !strcmp(argv[1], "check"))
        rc = cmd_check(argc - 2, argv + 2);
    if (rc == 2)
        fprintf(stderr,
                "usage: hc_tool dem KIND OUT [key=value ...]\n"
                "       hc_tool rays DEM OUT N SEED\n"
                "       hc_tool badrays OUT [COMPONENT]\n"
                "       hc_tool check DEM RAYS SURFACE HITS [SURFACE HITS ...]\n");
    return rc;
}
