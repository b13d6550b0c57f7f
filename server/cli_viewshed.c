/* cli_viewshed.c: `terrad viewshed`: what can be seen from one or more points of a DEM,
 * by the same code as POST /v1/viewshed (core/viewshed.c for the answer,
 * server/viewshed.c for the picture and the figures).
 *
 *   terrad viewshed --dem FILE --observer X,Y [--observer X,Y ...] --height H
 *                   [--target-height T] [--max-distance M] [--curvature K]
 *                   [--surface S] [--method M] [--algorithm A] [--threads N] -o OUT.png
 *                   [--stats FILE]
 *
 * Observers are in the dataset frame (metres east and north of the south-west sample).
 * OUT.png: 8-bit gray in the DEM's grid, row 0 north: 255 seen, 0 not, 128 outside
 * max_distance or void; with several observers, the number that see each sample (255
 * outside). --stats FILE: the JSON of the service's "json" format, plus load and build
 * times (wall) and each stage's process CPU time (cpu_ms: load, accel, viewshed,
 * encode). Exit status: 0 ok, 1 runtime failure (load, bad observer), 2 usage error. */
#include "cli.h"
#include "clock.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "accel.h"
#include "dem.h"
#include "bigalloc.h"
#include "viewshed_api.h" /* the encoder and the figures, shared with the service */

typedef struct vs_cli {
    const char *dem, *out, *stats;
    td_vs_point obs[TD_VS_MAX_OBSERVERS];
    td_viewshed_opts o;
    int have_height;
} vs_cli;

static void vs_usage(FILE *f)
{
    fprintf(f,
            "usage: terrad viewshed --dem FILE --observer X,Y [--observer X,Y ...] --height H\n"
            "                       [--target-height T] [--max-distance M] [--curvature K]\n"
            "                       [--surface S] [--method M] [--algorithm A] [--threads N]\n"
            "                       -o OUT.png [--stats FILE]\n"
            "\n"
            "What can be seen from X,Y (dataset frame: metres east, north of the south-west\n"
            "sample), the eye H metres above the ground, a target T metres above each sample.\n"
            "  --max-distance M  horizontal metres (default: no limit)\n"
            "  --curvature K     Earth curvature with refraction coefficient K (e.g. 0.13)\n"
            "  --surface S       plane, linear, triangle, bilinear (default bilinear)\n"
            "  --method M        incremental, hierarchical, parametric, auto (default auto)\n"
            "  --algorithm A     sweep (default: the exact horizon sweep, casting what it\n"
            "                    cannot prove) or cast (one segment a sample); same answers\n"
            "  --threads N       threads (default: one per core)\n"
            "  -o OUT.png        8-bit gray, row 0 north: 255 seen, 0 not, 128 outside or void;\n"
            "                    several observers: how many see each sample, 255 outside\n"
            "  --stats FILE      JSON: counts, visible area, timings\n");
}

/* A finite number, the whole string. */
static int parse_num(const char *s, double *out)
{
    char *end = NULL;
    double v = strtod(s, &end);
    int ok = end != s && *end == '\0' && isfinite(v);
    if (ok)
        *out = v;
    return ok;
}

static int parse_xy(const char *s, td_vs_point *p)
{
    char buf[128], *comma;
    int ok = strlen(s) < sizeof buf;
    if (ok) {
        strcpy(buf, s);
        comma = strchr(buf, ',');
        ok = comma != NULL;
        if (ok) {
            *comma = '\0';
            ok = parse_num(buf, &p->x) && parse_num(comma + 1, &p->y);
        }
    }
    return ok;
}

/* One option and its value into c; 0 when it is unknown or its value bad. */
static int vs_option(vs_cli *c, const char *opt, const char *val)
{
    int ok = 1;
    if (!strcmp(opt, "--dem"))
        c->dem = val;
    else if (!strcmp(opt, "-o"))
        c->out = val;
    else if (!strcmp(opt, "--stats"))
        c->stats = val;
    else if (!strcmp(opt, "--observer"))
        ok = c->o.nobs < TD_VS_MAX_OBSERVERS && parse_xy(val, &c->obs[c->o.nobs++]);
    else if (!strcmp(opt, "--height"))
        ok = c->have_height = parse_num(val, &c->o.height);
    else if (!strcmp(opt, "--target-height"))
        ok = parse_num(val, &c->o.target_height);
    else if (!strcmp(opt, "--max-distance"))
        ok = parse_num(val, &c->o.max_distance);
    else if (!strcmp(opt, "--curvature"))
        ok = c->o.curvature = parse_num(val, &c->o.k);
    else if (!strcmp(opt, "--surface"))
        ok = td_surface_parse(val, &c->o.surface) == TD_OK;
    else if (!strcmp(opt, "--method"))
        ok = td_method_parse(val, &c->o.method) == TD_OK;
    else if (!strcmp(opt, "--algorithm"))
        ok = td_vs_algo_parse(val, &c->o.algo) == TD_OK;
    else if (!strcmp(opt, "--threads"))
        ok = td_cli_parse_int(val, 1, 1024, &c->o.threads);
    else
        ok = 0;
    return ok;
}

/* The command line into c; -1 to go on, else the exit status (help 0, misuse 2). */
static int vs_args(int argc, char **argv, vs_cli *c)
{
    int rc = -1;
    for (int a = 1; a < argc && rc < 0; a += 2) {
        const char *opt = argv[a], *val = a + 1 < argc ? argv[a + 1] : NULL;
        if (!strcmp(opt, "-h") || !strcmp(opt, "--help")) {
            vs_usage(stdout);
            rc = 0;
        } else if (!val || !vs_option(c, opt, val)) {
            fprintf(stderr, "terrad viewshed: bad or incomplete option %s%s%s\n", opt, val ? " " : "",
                    val ? val : "");
            vs_usage(stderr);
            rc = 2;
        }
    }
    if (rc < 0 && (!c->dem || !c->out || !c->o.nobs || !c->have_height)) {
        fprintf(stderr, "terrad viewshed: --dem, --observer, --height and -o are required\n");
        vs_usage(stderr);
        rc = 2;
    }
    return rc;
}

/* The process CPU time of each stage (ck: clock() at the start and at each stage's end):
 * what a loaded machine inflates least; with --threads 1 the viewshed's is its own. */
static json_t *vs_cpu_json(const clock_t ck[5])
{
    static const char *const names[4] = {"load", "accel", "viewshed", "encode"};
    json_t *o = json_object();
    for (int k = 0; k < 4 && o; k++)
        json_object_set_new(o, names[k], json_real(1e3 * (double)(ck[k + 1] - ck[k]) / CLOCKS_PER_SEC));
    return o;
}

/* Loads, builds the max-mipmaps (or planes) the method needs, computes, writes. */
static int vs_run(vs_cli *c)
{
    int rc = 1;
    td_err err = {0};
    td_dem_opts dopts;
    td_accel_opts ao;
    td_accel *acc = NULL;
    td_grid *g = NULL;
    td_view v;
    td_viewshed_stats st;
    td_buf png = {0};
    json_t *js = NULL;
    uint8_t *counts = NULL;
    double t0 = td_clock_s(), t_load, t_accel;
    clock_t ck[5] = {clock(), 0, 0, 0, 0}; /* process CPU time at each stage's end */

    td_dem_opts_default(&dopts);
    if (td_dem_load(c->dem, &dopts, &g, &err)) {
        fprintf(stderr, "terrad viewshed: %s\n", err.msg);
        goto out;
    }
    t_load = td_clock_s();
    ck[1] = clock();
    td_accel_opts_for(c->o.method, &ao);
    ao.threads = c->o.threads;
    ao.minima = 0; /* no sun bound to read them */
    ao.transient = 1;
    if ((ao.maxmip || ao.planes) && td_accel_build(g, &ao, &acc, NULL, &err)) {
        fprintf(stderr, "terrad viewshed: %s: %s\n", c->dem, err.msg);
        goto out;
    }
    t_accel = td_clock_s();
    ck[2] = clock();
    v.grid = g;
    v.accel = acc ? acc->tiles : NULL;
    counts = td_bigalloc_scratch((size_t)g->w * (size_t)g->h); /* written whole next (bigalloc.h) */
    if (!counts) {
        fprintf(stderr, "terrad viewshed: out of memory\n");
        goto out;
    }
    if (td_viewshed(&v, &c->o, counts, &st, &err)) {
        fprintf(stderr, "terrad viewshed: %s\n", err.msg);
        goto out;
    }
    ck[3] = clock();
    js = td_vs_answer(c->dem, g, &c->o, &st, counts);
    if (td_vs_encode(g, c->o.nobs, counts, &png, &err) || !td_cli_write_file(c->out, png.data, png.len)) {
        fprintf(stderr, "terrad viewshed: cannot write %s: %s\n", c->out, err.msg[0] ? err.msg : "i/o error");
        goto out;
    }
    ck[4] = clock();
    if (c->stats) {
        json_object_set_new(js, "load_ms", json_real(1e3 * (t_load - t0)));
        json_object_set_new(js, "accel_ms", json_real(1e3 * (t_accel - t_load)));
        json_object_set_new(js, "cpu_ms", vs_cpu_json(ck));
        if (!js || json_dump_file(js, c->stats, JSON_INDENT(2) | JSON_REAL_PRECISION(10))) {
            fprintf(stderr, "terrad viewshed: cannot write %s\n", c->stats);
            goto out;
        }
    }
    rc = 0;
out:
    json_decref(js);
    td_buf_free(&png);
    free(counts);
    td_accel_free(acc);
    td_grid_free(g);
    return rc;
}

int td_cli_viewshed(int argc, char **argv)
{
    vs_cli *c = calloc(1, sizeof *c);
    int rc = 1;
    if (!c) {
        fprintf(stderr, "terrad viewshed: out of memory\n");
        goto out;
    }
    td_viewshed_opts_default(&c->o);
    c->o.obs = c->obs;
    rc = vs_args(argc, argv, c);
    if (rc < 0)
        rc = vs_run(c);
out:
    free(c);
    return rc;
}
