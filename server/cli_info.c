/* cli_info.c: `terrad info [options] FILE`: loads a DEM the way `serve` would and
 * describes it: size, spacing, extent, height range over valid samples, voids,
 * georeference, tiles and resident memory. With --json, one JSON object (jansson) on
 * stdout, for scripts and tests; keys: file, width, height, spacing [sx, sy], extent
 * [ex, ey] (metres between the outer samples), min, max (null when every sample is a
 * void), voids, tiles {x, y, count, size}, bytes, georef (null or {kind, x0, y0, dx, dy,
 * crs}, x0/y0 of the south-west sample).
 * Exit status: 0 ok, 1 the file cannot be loaded (the reason, naming the file, on
 * stderr), 2 usage error. */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

#include "dem.h"

static void info_usage(FILE *f)
{
    fprintf(f,
            "usage: terrad info [--json] [--encoding E] [--scale S] [--offset O] [--divisor D]\n"
            "                   [--spacing SX[,SY]] [--nodata V] FILE\n"
            "\n"
            "Loads a DEM (.f32 + .json sidecar, .asc, .hgt, .png, GeoTIFF%s) and prints its\n"
            "size, spacing, extent, height range, voids, georeference, tiles and memory.\n"
            "  --json          one JSON object instead of text\n"
            "  --encoding E    PNG heights: gray16, terrain-rgb, terrarium, rgb-div (required\n"
            "                  unless <name>.json beside the PNG gives \"encoding\")\n"
            "  --scale S, --offset O   gray16: metres = value*S + O\n"
            "  --divisor D     rgb-div: metres = (R*65536 + G*256 + B) / D\n"
            "  --spacing SX[,SY]       sample spacing in metres (overrides the file's)\n"
            "  --nodata V      PNG: raw value that marks a void\n",
            td_dem_have_gdal() ? " and other GDAL formats" : " (needs GDAL)");
}

static int parse_num(const char *s, double *out)
{
    char *end = NULL;
    double v;
    int ok;
    errno = 0;
    v = strtod(s, &end);
    ok = end != s && *end == '\0' && errno != ERANGE && isfinite(v);
    if (ok)
        *out = v;
    return ok;
}

static int parse_spacing(const char *s, double sp[2])
{
    char buf[128];
    char *comma;
    int ok = snprintf(buf, sizeof buf, "%s", s) < (int)sizeof buf;
    if (ok) {
        comma = strchr(buf, ',');
        if (comma)
            *comma = '\0';
        ok = parse_num(buf, &sp[0]) && sp[0] > 0.0;
        sp[1] = sp[0];
        if (ok && comma)
            ok = parse_num(comma + 1, &sp[1]) && sp[1] > 0.0;
    }
    return ok;
}

static const char *geo_kind_name(td_geo_kind k)
{
    return k == TD_GEO_LONLAT ? "lonlat" : k == TD_GEO_PROJECTED ? "projected" : "none";
}

static json_t *num_or_null(double v) { return isnan(v) ? json_null() : json_real(v); }

static int print_json(const char *path, const td_grid *g)
{
    int rc = 1;
    uint64_t bytes = td_grid_bytes(g->w, g->h, g->tile_log2);
    json_t *o = json_pack("{s:s, s:i, s:i, s:[f,f], s:[f,f], s:o, s:o, s:I, s:{s:i, s:i, s:I, s:i}, s:I}",
                          "file", path, "width", (json_int_t)g->w, "height", (json_int_t)g->h,
                          "spacing", g->sx, g->sy, "extent", (g->w - 1) * g->sx, (g->h - 1) * g->sy,
                          "min", num_or_null(g->zmin), "max", num_or_null(g->zmax),
                          "voids", (json_int_t)g->voids, "tiles", "x", (int)g->tiles_x, "y",
                          (int)g->tiles_y, "count", (json_int_t)g->tiles_x * g->tiles_y, "size",
                          (int)td_grid_tile_size(g), "bytes", (json_int_t)bytes);
    if (o && g->geo.kind != TD_GEO_NONE)
        json_object_set_new(o, "georef",
                            json_pack("{s:s, s:f, s:f, s:f, s:f, s:s}", "kind", geo_kind_name(g->geo.kind),
                                      "x0", g->geo.x0, "y0", g->geo.y0, "dx", g->geo.dx, "dy",
                                      g->geo.dy, "crs", g->geo.crs));
    else if (o)
        json_object_set_new(o, "georef", json_null());
    if (o) {
        char *text = json_dumps(o, JSON_INDENT(2) | JSON_REAL_PRECISION(17));
        if (text) {
            printf("%s\n", text);
            free(text);
            rc = 0;
        }
        json_decref(o);
    }
    if (rc)
        fprintf(stderr, "terrad info: %s: out of memory formatting JSON\n", path);
    return rc;
}

static void print_text(const char *path, const td_grid *g)
{
    uint64_t bytes = td_grid_bytes(g->w, g->h, g->tile_log2);
    double n = (double)g->w * (double)g->h;
    printf("file      %s\n", path);
    printf("size      %d x %d samples (%d x %d cells)\n", (int)g->w, (int)g->h, (int)g->w - 1,
           (int)g->h - 1);
    printf("spacing   %.4f x %.4f m\n", g->sx, g->sy);
    printf("extent    %.1f x %.1f m\n", (g->w - 1) * g->sx, (g->h - 1) * g->sy);
    if (isnan(g->zmin))
        printf("heights   none (every sample is a void)\n");
    else
        printf("heights   %.3f .. %.3f m\n", (double)g->zmin, (double)g->zmax);
    printf("voids     %lld (%.2f %%)\n", (long long)g->voids, 100.0 * (double)g->voids / n);
    if (g->geo.kind == TD_GEO_LONLAT)
        printf("georef    lon/lat, south-west sample at %.9f, %.9f, step %.10g x %.10g deg%s%s\n",
               g->geo.x0, g->geo.y0, g->geo.dx, g->geo.dy, g->geo.crs[0] ? ", " : "", g->geo.crs);
    else if (g->geo.kind == TD_GEO_PROJECTED)
        printf("georef    projected, south-west sample at %.3f, %.3f, step %.6g x %.6g%s%s\n",
               g->geo.x0, g->geo.y0, g->geo.dx, g->geo.dy, g->geo.crs[0] ? ", " : "", g->geo.crs);
    else
        printf("georef    none (local metres)\n");
    printf("tiles     %d x %d = %lld of %d x %d cells\n", (int)g->tiles_x, (int)g->tiles_y,
           (long long)g->tiles_x * g->tiles_y, (int)td_grid_tile_size(g), (int)td_grid_tile_size(g));
    printf("memory    %llu bytes (%.2f MiB) resident\n", (unsigned long long)bytes,
           (double)bytes / 1048576.0);
}

/* One option that takes a value into opts: 0, or 2 for a bad value. */
static int value_option(const char *a, const char *v, td_dem_opts *opts)
{
    int rc = 0;
    if (!strcmp(a, "--encoding")) {
        if (td_dem_encoding_parse(v, &opts->encoding) != TD_OK || opts->encoding == TD_ENC_NONE) {
            fprintf(stderr, "terrad info: unknown encoding '%s' (gray16, terrain-rgb, terrarium, rgb-div)\n", v);
            rc = 2;
        }
    } else if (!strcmp(a, "--scale")) {
        rc = parse_num(v, &opts->scale) && opts->scale != 0.0 ? 0 : 2;
        opts->given |= TD_DEM_GIVEN_SCALE;
    } else if (!strcmp(a, "--offset")) {
        rc = parse_num(v, &opts->offset) ? 0 : 2;
        opts->given |= TD_DEM_GIVEN_OFFSET;
    } else if (!strcmp(a, "--divisor")) {
        rc = parse_num(v, &opts->divisor) && opts->divisor > 0.0 ? 0 : 2;
        opts->given |= TD_DEM_GIVEN_DIVISOR;
    } else if (!strcmp(a, "--spacing")) {
        rc = parse_spacing(v, opts->spacing) ? 0 : 2;
    } else if (!strcmp(a, "--nodata")) {
        rc = parse_num(v, &opts->nodata) ? 0 : 2;
        opts->has_nodata = 1;
    }
    return rc;
}

int td_cli_info(int argc, char **argv)
{
    int rc = 0, json = 0, help = 0;
    const char *path = NULL;
    td_dem_opts opts;
    td_grid *g = NULL;
    td_err err = {0};
    td_status st;

    td_dem_opts_default(&opts);
    for (int k = 1; k < argc && rc == 0; k++) {
        const char *a = argv[k];
        const char *v = k + 1 < argc ? argv[k + 1] : NULL;
        int takes = !strcmp(a, "--encoding") || !strcmp(a, "--scale") || !strcmp(a, "--offset") ||
                    !strcmp(a, "--divisor") || !strcmp(a, "--spacing") || !strcmp(a, "--nodata");
        if (takes && !v) {
            fprintf(stderr, "terrad info: %s needs a value\n", a);
            rc = 2;
        } else if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            help = 1;
        } else if (!strcmp(a, "--json")) {
            json = 1;
        } else if (takes) {
            rc = value_option(a, v, &opts);
        } else if (a[0] == '-' && a[1] != '\0') {
            fprintf(stderr, "terrad info: unknown option '%s'\n", a);
            rc = 2;
        } else if (path) {
            fprintf(stderr, "terrad info: one FILE only ('%s' and '%s')\n", path, a);
            rc = 2;
        } else {
            path = a;
        }
        if (rc == 2 && takes && v)
            fprintf(stderr, "terrad info: bad value '%s' for %s\n", v, a);
        if (takes)
            k++;
    }
    if (rc == 0 && help) {
        info_usage(stdout);
        goto out;
    }
    if (rc == 0 && !path) {
        fprintf(stderr, "terrad info: no FILE given\n");
        rc = 2;
    }
    if (rc == 2) {
        info_usage(stderr);
        goto out;
    }
    st = td_dem_load(path, &opts, &g, &err);
    if (st != TD_OK) {
        fprintf(stderr, "terrad info: %s\n", err.msg);
        rc = 1;
        goto out;
    }
    if (json)
        rc = print_json(path, g);
    else
        print_text(path, g);
out:
    td_grid_free(g);
    return rc;
}
