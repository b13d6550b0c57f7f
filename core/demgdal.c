/* demgdal.c: the GDAL loader (band 1 of anything GDAL opens as a raster).
 *
 * Compiled in only with TERRAD_HAVE_GDAL; the build works without libgdal and then
 * refuses GeoTIFF with a clear message. GDAL's own error printing is replaced by a quiet
 * handler for the duration of the call (core never logs) and its last message is passed
 * on in ours. Rows are read one at a time with GDALRasterIO as float32 straight into
 * their south-based place. Georeference from the geotransform (north-up or south-up;
 * rotated grids are refused), lon/lat when the spatial reference is geographic (spacing
 * in metres at the centre latitude), otherwise projected with the linear unit applied.
 * Voids: the band's nodata value; NaN samples only when nodata is NaN, as in demraw.c.
 * The band's scale and offset, when set, are applied. */
#include "demgdal.h"

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

#else

#include <math.h>
#include <pthread.h>
#include <stdio.h>

#include <cpl_error.h>
#include <gdal.h>
#include <ogr_srs_api.h>

static pthread_once_t td_gdal_once = PTHREAD_ONCE_INIT;

static void gdal_init(void) { GDALAllRegister(); }

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

td_status td_demgdal_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    GDALDatasetH ds = NULL;
    GDALRasterBandH band;
    td_grid *g = NULL;
    td_georef geo;
    double sx = 0, sy = 0, nodata, scale, offset;
    int has_nodata = 0, has_scale = 0, has_offset = 0, south_up = 0;
    int32_t w, h;

    *out = NULL;
    pthread_once(&td_gdal_once, gdal_init);
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
    ds = GDALOpenEx(path, GDAL_OF_RASTER | GDAL_OF_READONLY, NULL, NULL, NULL);
    if (!ds) {
        rc = td_err_set(err, TD_EFORMAT, "%s: GDAL cannot open it as a raster (%s)", path, gdal_msg());
        goto out;
    }
    if (GDALGetRasterCount(ds) < 1) {
        rc = td_err_set(err, TD_EFORMAT, "%s: no raster band", path);
        goto out;
    }
    w = GDALGetRasterXSize(ds);
    h = GDALGetRasterYSize(ds);
    rc = td_demutil_check_limits(path, o, w, h, err);
    if (rc != TD_OK)
        goto out;
    rc = gdal_georef(path, o, ds, w, h, &geo, &sx, &sy, &south_up, err);
    if (rc != TD_OK)
        goto out;
    band = GDALGetRasterBand(ds, 1);
    nodata = GDALGetRasterNoDataValue(band, &has_nodata);
    scale = GDALGetRasterScale(band, &has_scale);
    offset = GDALGetRasterOffset(band, &has_offset);
    if (!has_scale || !isfinite(scale) || scale == 0.0)
        scale = 1.0;
    if (!has_offset || !isfinite(offset))
        offset = 0.0;
    rc = td_demutil_create(path, o, w, h, sx, sy, &g, err);
    if (rc != TD_OK)
        goto out;
    g->geo = geo;
    for (int32_t r = 0; r < h && rc == TD_OK; r++) {
        float *row = g->z + (size_t)(south_up ? r : h - 1 - r) * (size_t)w;
        if (GDALRasterIO(band, GF_Read, 0, r, w, 1, row, w, 1, GDT_Float32, 0, 0) != CE_None) {
            rc = td_err_set(err, TD_EIO, "%s: read failed at row %ld (%s)", path, (long)r, gdal_msg());
            break;
        }
        for (int32_t i = 0; i < w; i++) {
            float v = row[i];
            if (isnan(v)) {
                if (!(has_nodata && isnan(nodata))) {
                    rc = td_err_set(err, TD_EFORMAT, "%s: NaN sample at column %ld, row %ld and the band's nodata is not NaN",
                                    path, (long)i, (long)r);
                    break;
                }
            } else if (has_nodata && v == (float)nodata) {
                row[i] = NAN;
            } else {
                double m = (double)v * scale + offset;
                if (!isfinite(m) || fabs(m) > 3.0e38) {
                    rc = td_err_set(err, TD_ERANGE, "%s: sample at column %ld, row %ld is not finite",
                                    path, (long)i, (long)r);
                    break;
                }
                row[i] = (float)m;
            }
        }
    }
    if (rc == TD_OK)
        rc = td_demutil_finish(path, g, err);
out:
    if (ds)
        GDALClose(ds);
    CPLPopErrorHandler();
    if (rc != TD_OK) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}

#endif
