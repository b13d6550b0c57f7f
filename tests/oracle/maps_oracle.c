/* maps_oracle.c: Web Mercator map tiles (core/mercator.c, core/maptile.c) against the
 * double-precision reference and against GDAL's own tools.
 *
 *   oracle_maps           every method on every surface, on a lon/lat dataset
 *                         (trinidad-crop) and a UTM one (trinidad-utm13) on the full grid,
 *                         and on N37W105.hgt's level of detail 1 (a zoom-9 tile, every 4th
 *                         pixel, judged on that level's grid), a shaded tile with cast
 *                         shadows and the sun low: each pixel's vertical ray and
 *                         shadow ray (td_maptile_render's copies) traced by td_trace are
 *                         judged against reference.c; td_occluded (with the sun bound)
 *                         answers as td_trace does; the pixel is 255 n.sun (ambient 0)
 *                         where its shadow ray is unoccluded, 0 where it is occluded; terrarium heights are the reference's
 *                         vertical hit height within half the encoding's step.
 *   oracle_maps --peers   against gdalwarp and gdaldem on the same tile bounds in
 *                         EPSG:3857 (N37W105.hgt, lon/lat, and trinidad-utm13.tif, UTM):
 *                         terrain-rgb decodes to gdalwarp -r bilinear's heights within the
 *                         encoding's step (0.05 m) plus 0.01 m; the shaded tile without
 *                         shadows (ambient 0, so grey = 255 n.sun) correlates with gdaldem
 *                         hillshade warped the same way (Pearson r >= 0.95), and its mean
 *                         difference is printed.
 * Prints the figures; exit status 0 when every check holds. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <gdal.h>

#include "accel.h"
#include "dem.h"
#include "maptile.h"
#include "mercator.h"
#include "reference.h"
#include "shade.h"
#include "sunlit.h"

#define PX 256

typedef struct tile_run {
    double xy[2 * PX * PX];
    uint8_t rgba[4 * PX * PX];
    td_ray rays[2 * PX * PX];
    double foot;
    int level;
} tile_run;

static td_grid *load(const char *name, td_merc_proj **proj)
{
    char path[1024];
    td_grid *g = NULL;
    td_err e = {0};
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA, name);
    if (td_dem_load(path, NULL, &g, &e) || td_merc_proj_create(path, g, proj, &e)) {
        fprintf(stderr, "oracle_maps: %s: %s\n", path, e.msg);
        exit(2);
    }
    return g;
}

/* One tile of style spec->style (levels of detail from lod, which may be NULL); the level
 * it was traced on into t->level. */
static void run_tile(const td_view *v, const td_lod *lod, td_merc_proj *proj, const td_maptile_spec *spec, int z,
                     int x, int y, tile_run *t)
{
    td_err e = {0};
    td_sunlit *lit = NULL;
    td_maptile_stats st;
    int exact = 0;
    if (td_merc_positions(proj, z, x, y, PX, t->xy, &exact, &t->foot, &e) ||
        (spec->shadows && td_sunlit_build(v, spec->sun, 0, &lit, &e)) ||
        td_maptile_render(v, lod, lit, spec, t->xy, PX, t->foot, t->rgba, t->rays, &st, &e)) {
        fprintf(stderr, "oracle_maps: tile %d/%d/%d: %s\n", z, x, y, e.msg);
        exit(2);
    }
    t->level = st.level;
    td_sunlit_free(lit);
}

/* A ray's td_trace answer judged against the reference; 1 when wrong. */
static int wrong(const td_view *v, td_method m, td_surface s, const td_ray *r, double eps, td_hit *h)
{
    td_ref_hit ref;
    td_trace(v, m, s, r, h);
    td_ref_trace(v->grid, s, r, eps, &ref);
    return td_ref_judge(v->grid, s, r, &ref, h->t, eps) == TD_REF_WRONG;
}

/* The band of the reference on grid g (as oracle.c's: float rounding times the slope). */
static double band(const td_grid *g)
{
    double scale = fmax(fmax((g->w - 1) * g->sx, (g->h - 1) * g->sy), fmax(fabs(g->zmin), fabs(g->zmax)));
    return (1e-3 + 2.0 * FLT_EPSILON * scale) * (1.0 + td_ref_max_slope(g));
}

typedef struct tally {
    long rays, shadowed, hcheck, errors;
    double hworst;
} tally;

/* A shaded tile's pixels (t) on view lv, every stride-th, with the terrarium tile of the
 * same surface (enc) when check_heights: each vertical and shadow ray judged, the
 * pixel's grey. */
static void judge(const td_view *lv, const td_maptile_spec *sp, const tile_run *t, const tile_run *enc,
                  int check_heights, double eps, int stride, const char *name, tally *ty)
{
    for (int k = 0; k < PX * PX; k += stride) {
        const td_ray *vr = &t->rays[2 * k], *sr = &t->rays[2 * k + 1];
        td_hit h, hs;
        uint32_t steps = 0;
        double ns;
        if (!(vr->tmax >= 0.0))
            continue;
        ty->rays++;
        if (wrong(lv, sp->method, sp->surface, vr, eps, &h) && ty->errors++ < 10)
            printf("WRONG %s %s/%s pixel %d: vertical ray t %.9g\n", name, td_method_name(sp->method),
                   td_surface_name(sp->surface), k, h.t);
        if (check_heights && h.t < INFINITY) {
            /* the terrarium height is the reference's vertical hit (half a step) */
            double dz = fabs(td_maptile_decode(TD_MAPSTYLE_TERRARIUM, &enc->rgba[4 * k]) - h.p[2]);
            ty->hworst = fmax(ty->hworst, dz);
            ty->hcheck++;
            if (dz > 1.0 / 512.0 + eps && ty->errors++ < 10)
                printf("WRONG %s %s pixel %d: terrarium height off by %.6f m\n", name, td_surface_name(sp->surface), k,
                       dz);
        }
        if (!(sr->tmax >= 0.0))
            continue;
        ty->rays++;
        /* the pixel: 255 n.sun where lit (ambient 0), 0 in shadow */
        ns = h.n[0] * sp->sun[0] + h.n[1] * sp->sun[1] + h.n[2] * sp->sun[2];
        if ((wrong(lv, sp->method, sp->surface, sr, eps, &hs) ||
             td_occluded(lv, sp->method, sp->surface, sr, NULL, &steps) != (hs.t < INFINITY) ||
             t->rgba[4 * k] != (hs.t < INFINITY ? 0 : lround(255.0 * ns))) &&
            ty->errors++ < 10)
            printf("WRONG %s %s/%s pixel %d: shadow ray t %.9g, pixel %d\n", name, td_method_name(sp->method),
                   td_surface_name(sp->surface), k, hs.t, t->rgba[4 * k]);
        ty->shadowed += hs.t < INFINITY;
    }
}

/* Every method on every surface over tile z/x/y of a dataset, on the full grid, or with
 * its levels of detail (the tile then traced on a coarse level, judged against the
 * reference on that level's grid); returns the unexplained errors. */
static long check_dataset(const char *name, int z, int x, int y, int with_lod)
{
    td_merc_proj *proj = NULL;
    td_grid *g = load(name, &proj);
    td_accel *acc = NULL;
    td_lod *lod = NULL;
    td_accel_opts ao;
    td_err e = {0};
    tile_run *t = malloc(sizeof *t), *enc = malloc(sizeof *enc);
    long errors = 0;
    td_accel_opts_default(&ao);
    ao.maxmip = ao.planes = 1;
    ao.threads = 2;
    if (!t || !enc || td_accel_build(g, &ao, &acc, NULL, &e) ||
        (with_lod && td_lod_build(g, TD_LOD_MAX, &ao, &lod, &e))) {
        fprintf(stderr, "oracle_maps: %s\n", e.msg);
        exit(2);
    }
    td_view v = {g, acc->tiles};
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        td_maptile_spec sp;
        tally ty = {0, 0, 0, 0, 0.0};
        const td_view *lv;
        td_maptile_spec_default(&sp);
        sp.surface = (td_surface)s;
        sp.style = TD_MAPSTYLE_TERRARIUM;
        run_tile(&v, lod, proj, &sp, z, x, y, enc);
        lv = enc->level ? &lod->view[enc->level] : &v;
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            sp.method = (td_method)m;
            sp.style = TD_MAPSTYLE_SHADED;
            td_shade_sun_dir(300.0, 5.0, sp.sun); /* from the west-north-west, low */
            sp.ambient = 0.0;
            run_tile(&v, lod, proj, &sp, z, x, y, t);
            /* with levels of detail, every 4th pixel: a coarse level's shadow rays run far */
            judge(lv, &sp, t, enc, m == 0, band(lv->grid), with_lod ? 4 : 1, name, &ty);
        }
        printf("%s tile %d/%d/%d (level %d) %s: %ld rays judged over every method (%ld shadowed), terrarium within "
               "%.5f m of the reference at %ld pixels: %ld wrong\n",
               name, z, x, y, enc->level, td_surface_name((td_surface)s), ty.rays, ty.shadowed, ty.hworst, ty.hcheck,
               ty.errors);
        errors += ty.errors + (ty.shadowed == 0); /* the tile must hold shadows to mean anything */
        errors += with_lod && enc->level == 0; /* and be traced on a coarse level when asked */
    }
    td_lod_free(lod);
    td_accel_free(acc);
    td_merc_proj_free(proj);
    td_grid_free(g);
    free(t);
    free(enc);
    return errors;
}

/* gdalwarp's output as doubles (PX x PX, rows from the north); NaN for no data. */
static int read_tif(const char *path, double *out)
{
    GDALDatasetH ds = GDALOpen(path, GA_ReadOnly);
    int ok = 0, has = 0;
    if (ds) {
        GDALRasterBandH b = GDALGetRasterBand(ds, 1);
        double nd = GDALGetRasterNoDataValue(b, &has);
        ok = GDALRasterIO(b, GF_Read, 0, 0, PX, PX, out, PX, PX, GDT_Float64, 0, 0) == CE_None;
        for (int k = 0; ok && has && k < PX * PX; k++)
            if (out[k] == nd)
                out[k] = NAN;
        GDALClose(ds);
    }
    return ok;
}

static int sh(const char *cmd)
{
    int rc = system(cmd);
    if (rc != 0)
        fprintf(stderr, "oracle_maps: failed (%d): %s\n", rc, cmd);
    return rc;
}

/* One dataset against gdalwarp and gdaldem over tile z/x/y; returns failed checks. */
static long peers(const char *name, int geographic, int z, int x, int y, const char *tmp)
{
    char src[1024], cmd[4096];
    td_merc_proj *proj = NULL;
    td_grid *g = load(name, &proj);
    td_view v = {g, NULL};
    tile_run *t = malloc(sizeof *t);
    double *ref = malloc(PX * PX * sizeof *ref), b[4], worst = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, sd = 0;
    long n = 0, fails = 0, nh = 0;
    td_maptile_spec sp;
    snprintf(src, sizeof src, "%s/%s", TERRAD_TEST_DATA, name);
    td_merc_tile_bounds(z, x, y, b);
    /* heights: -et 0, PROJ for every pixel (gdalwarp's default approximates to 1/8 pixel) */
    snprintf(cmd, sizeof cmd,
             "gdalwarp -q -overwrite -t_srs EPSG:3857 -te %.10f %.10f %.10f %.10f -ts %d %d -r bilinear -et 0 "
             "-ot Float64 '%s' '%s/h.tif'",
             b[0], b[1], b[2], b[3], PX, PX, src, tmp);
    fails += sh(cmd) != 0;
    snprintf(cmd, sizeof cmd, "%s/h.tif", tmp);
    if (!fails && read_tif(cmd, ref)) {
        td_maptile_spec_default(&sp);
        sp.style = TD_MAPSTYLE_TERRAIN_RGB;
        run_tile(&v, NULL, proj, &sp, z, x, y, t);
        for (int k = 0; k < PX * PX; k++) {
            double h = td_maptile_decode(TD_MAPSTYLE_TERRAIN_RGB, &t->rgba[4 * k]);
            if (isnan(h) || isnan(ref[k]))
                continue;
            worst = fmax(worst, fabs(h - ref[k]));
            nh++;
        }
        printf("%s tile %d/%d/%d: terrain-rgb against gdalwarp -r bilinear: %ld pixels, largest difference "
               "%.4f m (allowed 0.06)\n", name, z, x, y, nh, worst);
        fails += nh < PX * PX / 2 || worst > 0.06;
    } else {
        fails++;
    }
    /* hillshade: gdaldem on the projected grid, warped the same way; gdaldem has one
       horizontal scale, wrong in x on a lon/lat grid, so there it shades gdalwarp's
       heights in EPSG:3857 (whose metres are ground metres / cos(lat): -s 1 / cos) */
    if (geographic)
        snprintf(cmd, sizeof cmd, "gdaldem hillshade -q -az 315 -alt 45 -s %.9f -compute_edges '%s/h.tif' "
                 "'%s/hs3857.tif'", 1.0 / cos(atan(sinh(0.5 * (b[1] + b[3]) / 6378137.0))), tmp, tmp);
    else
        snprintf(cmd, sizeof cmd,
                 "gdaldem hillshade -q -az 315 -alt 45 -compute_edges '%s' '%s/hs.tif' && "
                 "gdalwarp -q -overwrite -t_srs EPSG:3857 -te %.10f %.10f %.10f %.10f -ts %d %d -r bilinear -et 0 "
                 "-ot Float64 '%s/hs.tif' '%s/hs3857.tif'",
                 src, tmp, b[0], b[1], b[2], b[3], PX, PX, tmp, tmp);
    fails += sh(cmd) != 0;
    snprintf(cmd, sizeof cmd, "%s/hs3857.tif", tmp);
    if (!fails && read_tif(cmd, ref)) {
        td_maptile_spec_default(&sp);
        sp.shadows = 0;
        sp.ambient = 0.0;
        run_tile(&v, NULL, proj, &sp, z, x, y, t);
        for (int k = 0; k < PX * PX; k++) {
            double a = t->rgba[4 * k], c = ref[k];
            if (!t->rgba[4 * k + 3] || isnan(c) || c == 0.0)
                continue;
            sx += a, sy += c, sxx += a * a, syy += c * c, sxy += a * c, sd += fabs(a - c);
            n++;
        }
        if (n > 1) {
            double r = (n * sxy - sx * sy) / sqrt((n * sxx - sx * sx) * (n * syy - sy * sy));
            printf("%s tile %d/%d/%d: shaded (no shadows, no ambient) against gdaldem hillshade (%s): %ld "
                   "pixels, Pearson r %.4f (required 0.95), mean |difference| %.2f grey levels\n",
                   name, z, x, y, geographic ? "of gdalwarp's heights" : "warped", n, r, sd / n);
            fails += !(r >= 0.95);
        } else {
            fails++;
        }
    } else {
        fails++;
    }
    free(t);
    free(ref);
    td_merc_proj_free(proj);
    td_grid_free(g);
    return fails;
}

int main(int argc, char **argv)
{
    long errors = 0;
    if (argc > 1 && !strcmp(argv[1], "--peers")) {
        char tmp[] = "/tmp/terrad-peers-XXXXXX", cmd[300];
        GDALAllRegister();
        if (!mkdtemp(tmp))
            return 2;
        errors += peers("N37W105.hgt", 1, 12, 859, 1585, tmp);
        errors += peers("trinidad-utm13.tif", 0, 13, 1719, 3171, tmp);
        snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp);
        errors += system(cmd) != 0;
    } else {
        errors += check_dataset("trinidad-crop.f32", 13, 1719, 3171, 0);
        errors += check_dataset("trinidad-utm13.tif", 13, 1719, 3171, 0);
        errors += check_dataset("N37W105.hgt", 9, 107, 198, 1); /* 242 m pixels on 73.5 m cells: level 1 */
    }
    printf("%s: %ld failed checks\n", errors ? "FAIL" : "PASS", errors);
    return errors ? 1 : 0;
}
