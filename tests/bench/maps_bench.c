/* maps_bench.c: what Web Mercator map tiles cost (issue 17): tiles per second for each
 * style on one thread, and what cast shadows add.
 *
 *   build/maps-bench SRC_DIR [OUT.md] [--runs N]
 *
 * For each dataset (the demo's trinidad, lon/lat; N37W105.hgt, lon/lat; trinidad-utm13.tif,
 * UTM 13N) and two zooms (the TileJSON's maxzoom, traced on the full grid, and two below,
 * on the level of detail that fits: lod.h), every tile of the zoom that meets the dataset
 * (at most 16, the ones nearest its centre) is made as the service makes it: pixel
 * positions through PROJ (mercator.h), the pixels (maptile.h), the PNG (image.h). The
 * dataset's acceleration is what `terrad serve --preload all` keeps: max-mipmaps and
 * parameter planes on the full grid, max-mipmaps on the levels of detail. Styles:
 * terrain-rgb, terrarium, shaded without shadows, shaded with shadows at sun 315/45 (the
 * default) and at 270/8 (long shadows). Each tile set is made --runs times (default 5);
 * the figures are the medians over runs of the per-tile means. One thread, no HTTP.
 * Prints a markdown table (and writes it to OUT.md when given). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "accel.h"
#include "bigalloc.h"
#include "clock.h"
#include "dem.h"
#include "image.h"
#include "lod.h"
#include "maptile.h"
#include "mercator.h"
#include "shade.h"
#include "sunlit.h"

#define PX 256
#define MAX_TILES 16
#define MAX_RUNS 21

typedef struct style_row {
    const char *label;
    td_mapstyle style;
    int shadows;
    double az, el;
    int kept; /* the sun bound built once before the tiles, as the server keeps it
                 (td_snapshot_sunlit) for the tiles after the first with that sun; else
                 built for each tile, as for a dataset's first tile with a sun */
} style_row;

static const style_row rows[] = {
    {"terrain-rgb", TD_MAPSTYLE_TERRAIN_RGB, 0, 0, 0, 0},
    {"terrarium", TD_MAPSTYLE_TERRARIUM, 0, 0, 0, 0},
    {"shaded, no shadows", TD_MAPSTYLE_SHADED, 0, 315, 45, 0},
    {"shaded, shadows, sun 315/45", TD_MAPSTYLE_SHADED, 1, 315, 45, 0},
    {"shaded, shadows, sun 315/45, bound kept", TD_MAPSTYLE_SHADED, 1, 315, 45, 1},
    {"shaded, shadows, sun 270/8", TD_MAPSTYLE_SHADED, 1, 270, 8, 0},
    {"shaded, shadows, sun 270/8, bound kept", TD_MAPSTYLE_SHADED, 1, 270, 8, 1},
};

typedef struct figures {
    double ms_pos, ms_trace, ms_png, rays, steps;
    int level, tiles;
} figures;

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_d);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* The tiles of zoom z meeting the dataset, nearest its centre first (at most MAX_TILES). */
typedef struct tile_d {
    int32_t x, y;
    double d;
} tile_d;

static int cmp_tile(const void *a, const void *b)
{
    return cmp_d(&((const tile_d *)a)->d, &((const tile_d *)b)->d);
}

static int tiles_of(const td_merc_proj *p, int z, int32_t t[][2])
{
    double ll[4], m[4], c[2], side = 2.0 * TD_MERC_HALF / ldexp(1.0, z);
    int32_t r[4];
    size_t n = 0;
    tile_d *all;
    td_merc_proj_bounds(p, ll, m, c);
    td_merc_tile_range(m, z, r);
    all = malloc((size_t)(r[2] - r[0] + 1) * (size_t)(r[3] - r[1] + 1) * sizeof *all);
    if (!all)
        return 0;
    for (int32_t y = r[1]; y <= r[3]; y++)
        for (int32_t x = r[0]; x <= r[2]; x++) {
            all[n].x = x, all[n].y = y;
            all[n++].d = hypot(-TD_MERC_HALF + (x + 0.5) * side - 0.5 * (m[0] + m[2]),
                               TD_MERC_HALF - (y + 0.5) * side - 0.5 * (m[1] + m[3]));
        }
    qsort(all, n, sizeof *all, cmp_tile);
    if (n > MAX_TILES)
        n = MAX_TILES;
    for (size_t k = 0; k < n; k++)
        t[k][0] = all[k].x, t[k][1] = all[k].y;
    free(all);
    return (int)n;
}

/* One style over a tile set, runs times: the medians into f. */
static int measure(const td_view *v, const td_lod *lod, td_merc_proj *p, const style_row *row, int z,
                   int32_t t[][2], int nt, int runs, figures *f)
{
    static double xy[2 * PX * PX];
    static uint8_t rgba[4 * PX * PX];
    double pos[MAX_RUNS], tr[MAX_RUNS], png[MAX_RUNS];
    td_maptile_spec sp;
    td_err e = {0};
    td_sunlit *kept = NULL;
    td_maptile_spec_default(&sp);
    sp.style = row->style;
    sp.shadows = row->shadows;
    td_shade_sun_dir(row->az + 0.0, row->el, sp.sun);
    memset(f, 0, sizeof *f);
    f->tiles = nt;
    if (row->kept && td_sunlit_build(v, sp.sun, 1, &kept, &e))
        goto fail;
    for (int r = 0; r < runs; r++) {
        double a = 0, b = 0, c = 0, rays = 0, steps = 0;
        for (int k = 0; k < nt; k++) {
            td_maptile_stats st;
            td_sunlit *lit = NULL;
            td_buf buf = {0};
            double foot = 0, t0 = td_clock_s(), t1, t2;
            int exact = 0, level;
            if (td_merc_positions(p, z, t[k][0], t[k][1], PX, xy, &exact, &foot, &e))
                goto fail;
            t1 = td_clock_s();
            level = td_maptile_level(v->grid, lod, foot, sp.lod_pixels);
            if (sp.style == TD_MAPSTYLE_SHADED && sp.shadows && level == 0 && !kept &&
                td_sunlit_build(v, sp.sun, 0, &lit, &e))
                goto fail;
            if (td_maptile_render(v, lod, level == 0 && kept ? kept : lit, &sp, xy, PX, foot, rgba, NULL, &st, &e))
                goto fail;
            td_sunlit_free(lit);
            t2 = td_clock_s();
            if (td_image_encode_rgba(rgba, PX, PX, &buf, &e))
                goto fail;
            td_buf_free(&buf);
            a += t1 - t0, b += t2 - t1, c += td_clock_s() - t2;
            rays += (double)(st.primary_rays + st.shadow_rays);
            steps += (double)st.steps;
            f->level = st.level;
        }
        pos[r] = 1e3 * a / nt, tr[r] = 1e3 * b / nt, png[r] = 1e3 * c / nt;
        f->rays = rays / nt;
        f->steps = steps / nt;
    }
    f->ms_pos = median(pos, runs);
    f->ms_trace = median(tr, runs);
    f->ms_png = median(png, runs);
    td_sunlit_free(kept);
    return 0;
fail:
    fprintf(stderr, "maps-bench: %s\n", e.msg);
    td_sunlit_free(kept);
    return -1;
}

static int dataset(const char *path, const char *label, int runs, FILE *out)
{
    td_grid *g = NULL;
    td_accel *acc = NULL;
    td_lod *lod = NULL;
    td_merc_proj *p = NULL;
    td_accel_opts ao, lo;
    td_err e = {0};
    double ll[4], m[4], c[2];
    int rc = -1, maxz;
    td_accel_opts_default(&ao);
    ao.maxmip = ao.planes = 1;
    ao.threads = 1;
    td_accel_opts_default(&lo);
    lo.planes = 0;
    lo.threads = 1;
    if (td_dem_load(path, NULL, &g, &e) || td_accel_build(g, &ao, &acc, NULL, &e) ||
        td_lod_build(g, TD_LOD_MAX, &lo, &lod, &e) || td_merc_proj_create(path, g, &p, &e)) {
        fprintf(stderr, "maps-bench: %s: %s\n", path, e.msg);
        goto out;
    }
    td_merc_proj_bounds(p, ll, m, c);
    maxz = td_merc_zoom_for(g->sx < g->sy ? g->sx : g->sy, c[1]);
    for (int dz = 0; dz <= 2; dz += 2) {
        int32_t t[MAX_TILES][2];
        int z = maxz - dz, nt = tiles_of(p, z, t);
        double base = 0;
        td_view v = {g, acc->tiles};
        for (size_t s = 0; s < sizeof rows / sizeof rows[0]; s++) {
            figures f;
            double total;
            if (measure(&v, lod, p, &rows[s], z, t, nt, runs, &f))
                goto out;
            total = f.ms_pos + f.ms_trace + f.ms_png;
            if (s == 2)
                base = f.ms_trace;
            fprintf(out, "| %s | %d (level %d), %d tiles | %s | %.0f | %.2f | %.2f | %.2f | %.0f | %.2f | ", label, z,
                    f.level, f.tiles, rows[s].label, 1e3 / total, f.ms_pos, f.ms_trace, f.ms_png, f.rays,
                    f.rays > 0 ? f.steps / f.rays : 0.0);
            if (s >= 3 && base > 0)
                fprintf(out, "+%.2f ms (x%.2f) |\n", f.ms_trace - base, f.ms_trace / base);
            else
                fprintf(out, " |\n");
        }
    }
    rc = 0;
out:
    td_merc_proj_free(p);
    td_lod_free(lod);
    td_accel_free(acc);
    td_grid_free(g);
    return rc;
}

int main(int argc, char **argv)
{
    int runs = 5, rc = 0;
    const char *src = NULL, *outp = NULL;
    char path[3][1024];
    const char *labels[3] = {"trinidad (demo, lon/lat, 600 x 500)", "N37W105.hgt (lon/lat, 1201 x 1201)",
                             "trinidad-utm13.tif (UTM 13N, 154 x 154)"};
    td_bigalloc_policy(); /* terrad's: the tiles' buffers as the server allocates them */
    FILE *out = stdout;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!src)
            src = argv[i];
        else
            outp = argv[i];
    }
    if (!src || runs < 1 || runs > MAX_RUNS) {
        fprintf(stderr, "usage: maps-bench SRC_DIR [OUT.md] [--runs N (1..%d)]\n", MAX_RUNS);
        return 2;
    }
    snprintf(path[0], sizeof path[0], "%s/data/trinidad/blanca.f32", src);
    snprintf(path[1], sizeof path[1], "%s/tests/data/N37W105.hgt", src);
    snprintf(path[2], sizeof path[2], "%s/tests/data/trinidad-utm13.tif", src);
    if (outp && !(out = fopen(outp, "w"))) {
        perror(outp);
        return 2;
    }
    {
        time_t now = time(NULL);
        char when[32];
        strftime(when, sizeof when, "%Y-%m-%d %H:%M UTC", gmtime(&now));
        fprintf(out,
                "# Map tiles: what each style costs\n\n"
                "Written by `build/maps-bench . docs/maps-bench.md --runs %d` (tests/bench/maps_bench.c) on %s.\n"
                "One thread, no HTTP: per 256-pixel tile, the pixel positions through PROJ, the pixels (rays down "
                "and toward the sun, or heights), the PNG; medians over %d runs of the mean over the tiles of the "
                "zoom nearest the dataset's centre (at most 16). `tiles/s` counts all three. *shadows add* is the "
                "pixels' time against `shaded, no shadows` at the same zoom; *bound kept*: the shadow rays' sun "
                "bound built once before the tiles, as the server keeps it for a dataset's tiles after the first "
                "with that sun (`td_snapshot_sunlit`), else built for each tile as for the first. Acceleration as `terrad serve "
                "--preload all` keeps it. A shared 2-core machine: read the figures as indicative.\n\n",
                runs, when, runs);
    }
    fprintf(out, "| dataset | zoom | style | tiles/s | positions ms | pixels ms | PNG ms | rays/tile | steps/ray | shadows add |\n"
                 "|---|---|---|---|---|---|---|---|---|---|\n");
    for (int d = 0; d < 3 && !rc; d++)
        rc = dataset(path[d], labels[d], runs, out);
    if (out != stdout)
        fclose(out);
    return rc ? 1 : 0;
}
