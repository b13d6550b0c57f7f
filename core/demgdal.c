/* demgdal.c: the GDAL loader (band 1 of anything GDAL opens as a raster).
 *
 * Compiled in only with TERRAD_HAVE_GDAL; the build works without libgdal and then
 * refuses GeoTIFF with a clear message. GDAL's own error printing is replaced by a quiet
 * handler for the duration of the call (core never logs) and its last message is passed
 * on in ours. Rows are read one at a time with GDALRasterIO as float32 straight into
 * their south-based place. Georeference from the geotransform (north-up or south-up;
 * rotated grids are refused), lon/lat when the spatial reference is geographic (spacing
 * in metres at the centre latitude), otherwise projected with the linear unit applied.
 * Voids: the band's nodata value; NaN samples only when nodata is NaN, as in demraw.c
 * (both loaders state their rules as a td_demutil_f32 for td_demutil_f32_row). The band's
 * scale and offset, when set, are applied. GDAL itself is loaded on the first call
 * (gdalapi.h: td_gdal_open), not linked in. */
#include "demgdal.h"

#include <stdlib.h>
#include <string.h>

#include "demutil.h"

int td_demgdal_recognised(const char *path)
{
    static const char *const exts[] = {"tif", "tiff", "gtiff", "vrt", "img", "dem", "bil",
                                       "flt", "grd", "nc", "jp2", "dt0", "dt1", "dt2", "ter",
                                       "adf", "kea", "rst", "xyz"};
    char ext[16];
    int ok = 0;
    td_demutil_ext(path, ext, sizeof ext);
    for (size_t k = 0; k < sizeof exts / sizeof exts[0] && !ok; k++)
        ok = !strcmp(ext, exts[k]);
    return ok;
}

#ifndef TERRAD_HAVE_GDAL

td_status td_demgdal_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    (void)o;
    *out = NULL;
    return td_err_set(err, TD_EUNSUPPORTED,
                      "%s: this format is read through GDAL, and this terrad was built without "
                      "libgdal (install libgdal-dev and rebuild)",
                      path);
}

td_status td_demgdal_stream_open(const char *path, const td_dem_opts *o, td_demgdal_stream **out,
                                 td_grid *shape, td_err *err)
{
    td_grid *g = NULL;
    (void)shape;
    *out = NULL;
    return td_demgdal_load(path, o, &g, err);
}

td_status td_demgdal_stream_rows(td_demgdal_stream *s, int32_t r0, int32_t n, float *dst,
                                 td_err *err)
{
    (void)s;
    (void)r0;
    (void)n;
    (void)dst;
    return td_err_set(err, TD_EUNSUPPORTED, "built without libgdal");
}

void td_demgdal_stream_close(td_demgdal_stream *s) { (void)s; }

#else

#include <math.h>
#include <stdio.h>

#include "gdalapi.h" /* GDAL's API, loaded on first use (td_gdal_open) */

static const char *gdal_msg(void)
{
    const char *m = CPLGetLastErrorMsg();
    return m && *m ? m : "not a raster format GDAL recognises";
}

static td_status gdal_georef(const char *path, const td_dem_opts *o, GDALDatasetH ds, int32_t w,
                             int32_t h, td_georef *geo, double *sx, double *sy, int *south_up,
                             td_err *err)
{
    td_status rc = TD_OK;
    double gt[6];
    td_demside sc;
    OGRSpatialReferenceH srs;
    const char *name;

    memset(geo, 0, sizeof *geo);
    memset(&sc, 0, sizeof sc);
    *south_up = 0;
    if (GDALGetGeoTransform(ds, gt) == CE_None) {
        if (gt[2] != 0.0 || gt[4] != 0.0 || gt[1] <= 0.0 || gt[5] == 0.0) {
            rc = td_err_set(err, TD_EUNSUPPORTED, "%s: rotated or degenerate geotransform", path);
            goto out;
        }
        *south_up = gt[5] > 0.0;
        srs = GDALGetSpatialRef(ds);
        geo->kind = srs && OSRIsGeographic(srs) ? TD_GEO_LONLAT : TD_GEO_PROJECTED;
        geo->dx = gt[1];
        geo->dy = fabs(gt[5]);
        geo->x0 = gt[0] + 0.5 * gt[1];
        /* sample (0, 0) is the SOUTH-west one */
        geo->y0 = *south_up ? gt[3] + 0.5 * gt[5] : gt[3] + ((double)h - 0.5) * gt[5];
        name = srs ? OSRGetName(srs) : NULL;
        snprintf(geo->crs, sizeof geo->crs, "%s", name ? name : "");
        if (geo->kind == TD_GEO_PROJECTED) {
            double unit = srs ? OSRGetLinearUnits(srs, NULL) : 1.0;
            sc.has_spacing = 1;
            sc.spacing[0] = geo->dx * (unit > 0.0 ? unit : 1.0);
            sc.spacing[1] = geo->dy * (unit > 0.0 ? unit : 1.0);
        }
    }
    rc = td_demutil_spacing(path, o, &sc, geo, w, h, sx, sy, err);
out:
    return rc;
}

/* Opens band 1's dataset and checks its size against the limits. */
static td_status gdal_open(const char *path, const td_dem_opts *o, GDALDatasetH *ds, int32_t *w,
                           int32_t *h, td_err *err)
{
    td_status rc = TD_OK;
    *ds = GDALOpenEx(path, GDAL_OF_RASTER | GDAL_OF_READONLY, NULL, NULL, NULL);
    if (!*ds) {
        rc = td_err_set(err, TD_EFORMAT, "%s: GDAL cannot open it as a raster (%s)", path, gdal_msg());
    } else if (GDALGetRasterCount(*ds) < 1) {
        rc = td_err_set(err, TD_EFORMAT, "%s: no raster band", path);
    } else {
        *w = GDALGetRasterXSize(*ds);
        *h = GDALGetRasterYSize(*ds);
        rc = td_demutil_check_limits(path, o, *w, *h, err);
    }
    return rc;
}

/* Band 1 and how it stores heights: its nodata (a NaN nodata makes NaN samples voids),
 * and metres = value*scale + offset (1 and 0 when unset or not usable). */
static GDALRasterBandH gdal_band(GDALDatasetH ds, td_demutil_f32 *p)
{
    GDALRasterBandH band = GDALGetRasterBand(ds, 1);
    int has_nodata = 0, has_scale = 0, has_offset = 0;
    double nodata = GDALGetRasterNoDataValue(band, &has_nodata);
    double scale = GDALGetRasterScale(band, &has_scale);
    double offset = GDALGetRasterOffset(band, &has_offset);
    memset(p, 0, sizeof *p);
    p->nan_void = has_nodata && isnan(nodata);
    snprintf(p->nan_why, sizeof p->nan_why, " and the band's nodata is not NaN");
    p->has_nodata = has_nodata;
    p->nodata = (float)nodata;
    p->scale = !has_scale || !isfinite(scale) || scale == 0.0 ? 1.0 : scale;
    p->offset = !has_offset || !isfinite(offset) ? 0.0 : offset;
    p->max_abs = 3.0e38;
    return band;
}

/* Row by row as float32 into the south-based place (row r of a south-up raster is the
 * grid's row r). */
static td_status gdal_read(const char *path, GDALRasterBandH band, const td_demutil_f32 *p,
                           int south_up, td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    for (int32_t r = 0; r < g->h && rc == TD_OK; r++) {
        float *row = south_up ? g->z + (size_t)r * (size_t)g->w : td_demutil_file_row(g, r);
        if (GDALRasterIO(band, GF_Read, 0, r, g->w, 1, row, g->w, 1, GDT_Float32, 0, 0) != CE_None)
            rc = td_err_set(err, TD_EIO, "%s: read failed at row %ld (%s)", path, (long)r, gdal_msg());
        else
            rc = td_demutil_f32_row(path, p, row, g->w, r, err);
    }
    return rc;
}

td_status td_demgdal_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc;
    GDALDatasetH ds = NULL;
    GDALRasterBandH band = NULL;
    td_demutil_f32 p;
    td_grid *g = NULL;
    td_georef geo;
    double sx = 0, sy = 0;
    int south_up = 0;
    int32_t w = 0, h = 0;

    rc = td_gdal_open(err);
    if (rc != TD_OK)
        goto out;
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
    rc = gdal_open(path, o, &ds, &w, &h, err);
    if (rc == TD_OK)
        rc = gdal_georef(path, o, ds, w, h, &geo, &sx, &sy, &south_up, err);
    if (rc == TD_OK) {
        band = gdal_band(ds, &p);
        rc = td_demutil_create(path, o, w, h, sx, sy, &geo, &g, err);
    }
    if (rc == TD_OK)
        rc = gdal_read(path, band, &p, south_up, g, err);
    if (ds)
        GDALClose(ds);
    CPLPopErrorHandler();
out:
    return td_demutil_deliver(path, rc, g, out, err);
}

/* --- streaming ------------------------------------------------------------------- */

struct td_demgdal_stream {
    char path[TD_DEMUTIL_PATH_MAX];
    GDALDatasetH ds;
    GDALRasterBandH band;
    td_demutil_f32 p;
    int32_t w, h;
    int south_up;
};

td_status td_demgdal_stream_open(const char *path, const td_dem_opts *o, td_demgdal_stream **out,
                                 td_grid *shape, td_err *err)
{
    td_status rc = TD_OK;
    td_demgdal_stream *s = calloc(1, sizeof *s);

    *out = NULL;
    memset(shape, 0, sizeof *shape);
    if (!s) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
        goto out;
    }
    snprintf(s->path, sizeof s->path, "%s", path);
    rc = td_gdal_open(err);
    if (rc != TD_OK)
        goto out;
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
    rc = gdal_open(path, o, &s->ds, &s->w, &s->h, err);
    if (rc == TD_OK)
        rc = gdal_georef(path, o, s->ds, s->w, s->h, &shape->geo, &shape->sx, &shape->sy,
                         &s->south_up, err);
    CPLPopErrorHandler();
    if (rc == TD_OK) {
        s->band = gdal_band(s->ds, &s->p);
        shape->w = s->w;
        shape->h = s->h;
        shape->tile_log2 = o->tile_log2 ? o->tile_log2 : TD_TILE_LOG2_DEFAULT;
        *out = s;
        s = NULL;
    }
out:
    td_demgdal_stream_close(s);
    return rc;
}

td_status td_demgdal_stream_rows(td_demgdal_stream *s, int32_t r0, int32_t n, float *dst,
                                 td_err *err)
{
    td_status rc = TD_OK;
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
    if (!s->south_up &&
        GDALRasterIO(s->band, GF_Read, 0, r0, s->w, n, dst, s->w, n, GDT_Float32, 0, 0) != CE_None)
        rc = td_err_set(err, TD_EIO, "%s: read failed at rows %ld..%ld (%s)", s->path, (long)r0,
                        (long)(r0 + n - 1), gdal_msg());
    for (int32_t k = 0; k < n && rc == TD_OK && s->south_up; k++)
        if (GDALRasterIO(s->band, GF_Read, 0, s->h - 1 - (r0 + k), s->w, 1, dst + (size_t)k * (size_t)s->w,
                         s->w, 1, GDT_Float32, 0, 0) != CE_None)
            rc = td_err_set(err, TD_EIO, "%s: read failed at row %ld (%s)", s->path,
                            (long)(r0 + k), gdal_msg());
    CPLPopErrorHandler();
    for (int32_t k = 0; k < n && rc == TD_OK; k++)
        rc = td_demutil_f32_row(s->path, &s->p, dst + (size_t)k * (size_t)s->w, s->w, r0 + k, err);
    return rc;
}

void td_demgdal_stream_close(td_demgdal_stream *s)
{
    if (s) {
        if (s->ds)
            GDALClose(s->ds);
        free(s);
    }
}

#endif
