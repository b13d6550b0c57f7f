/* mercator.c: Web Mercator XYZ tile math and the OGR transformations of mercator.h.
 *
 * Called by server/maps.c for every map tile and TileJSON, by the map benchmark and the
 * tests. The tile math is arithmetic on the EPSG:3857 square; every change of CRS goes
 * through OGR (PROJ). The per-tile cost is the lattice: (px/8 + 1)^2 + (px/8)^2 points
 * (2113 for 256 px, about 2 ms to UTM, 0.1 ms to lon/lat) instead of px^2 (60 ms to UTM). */
#include "mercator.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gdalapi.h" /* GDAL's API, loaded on first use (td_gdal_open) */

static double dmin(double a, double b) { return a < b ? a : b; }
static double dmax(double a, double b) { return a > b ? a : b; }

void td_merc_tile_bounds(int z, int32_t x, int32_t y, double b[4])
{
    double side = 2.0 * TD_MERC_HALF / ldexp(1.0, z);
    b[0] = -TD_MERC_HALF + (double)x * side;
    b[2] = -TD_MERC_HALF + (double)(x + 1) * side;
    b[3] = TD_MERC_HALF - (double)y * side;
    b[1] = TD_MERC_HALF - (double)(y + 1) * side;
}

double td_merc_pixel_m(int z, int px) { return 2.0 * TD_MERC_HALF / ((double)px * ldexp(1.0, z)); }

int td_merc_zoom_for(double ground_m, double lat_deg)
{
    /* a Mercator pixel covers pixel_m * cos(lat) on the ground */
    double c = cos(lat_deg * M_PI / 180.0), z;
    if (!(ground_m > 0.0) || !(c > 0.0))
        return 0;
    z = ceil(log2(2.0 * TD_MERC_HALF * c / (256.0 * ground_m)) - 1e-9);
    return z < 0.0 ? 0 : z > TD_MERC_MAX_ZOOM ? TD_MERC_MAX_ZOOM : (int)z;
}

void td_merc_tile_range(const double m[4], int z, int32_t r[4])
{
    double side = 2.0 * TD_MERC_HALF / ldexp(1.0, z), n = ldexp(1.0, z) - 1.0;
    r[0] = (int32_t)dmax(0.0, dmin(n, floor((m[0] + TD_MERC_HALF) / side)));
    r[2] = (int32_t)dmax(0.0, dmin(n, floor((m[2] + TD_MERC_HALF) / side)));
    r[1] = (int32_t)dmax(0.0, dmin(n, floor((TD_MERC_HALF - m[3]) / side)));
    r[3] = (int32_t)dmax(0.0, dmin(n, floor((TD_MERC_HALF - m[1]) / side)));
}

#ifndef TERRAD_HAVE_GDAL

struct td_merc_proj {
    int unused;
};

td_status td_merc_proj_create(const char *path, const td_grid *g, td_merc_proj **out, td_err *err)
{
    (void)path;
    (void)g;
    *out = NULL;
    return td_err_set(err, TD_EUNSUPPORTED, "map tiles need GDAL/PROJ, which this build lacks");
}
td_status td_merc_proj_clone(const td_merc_proj *p, td_merc_proj **out, td_err *err)
{
    (void)p;
    *out = NULL;
    return td_err_set(err, TD_EUNSUPPORTED, "map tiles need GDAL/PROJ, which this build lacks");
}
void td_merc_proj_free(td_merc_proj *p) { (void)p; }
const char *td_merc_proj_name(const td_merc_proj *p) { return p ? "" : ""; }
double td_merc_proj_grid_north(const td_merc_proj *p) { return p ? 0.0 : 0.0; }
void td_merc_proj_bounds(const td_merc_proj *p, double ll[4], double merc[4], double centre[2])
{
    (void)p;
    memset(ll, 0, 4 * sizeof *ll);
    memset(merc, 0, 4 * sizeof *merc);
    centre[0] = centre[1] = 0.0;
}
td_status td_merc_positions(td_merc_proj *p, int z, int32_t x, int32_t y, int px, double *xy,
                            int *exact, double *foot_m, td_err *err)
{
    (void)p, (void)z, (void)x, (void)y, (void)px, (void)xy, (void)exact, (void)foot_m;
    return td_err_set(err, TD_EUNSUPPORTED, "map tiles need GDAL/PROJ, which this build lacks");
}
td_status td_merc_to_lonlat(td_merc_proj *p, double x, double y, double ll[2], td_err *err)
{
    (void)p, (void)x, (void)y, (void)ll;
    return td_err_set(err, TD_EUNSUPPORTED, "map tiles need GDAL/PROJ, which this build lacks");
}

#else

struct td_merc_proj {
    char *wkt;       /* the dataset's CRS */
    char name[128];
    td_georef geo;
    double sx, sy;
    int32_t w, h;
    OGRSpatialReferenceH merc, crs, ll;
    OGRCoordinateTransformationH to_crs; /* EPSG:3857 -> the dataset's CRS */
    OGRCoordinateTransformationH to_ll;  /* the dataset's CRS -> lon/lat (EPSG:4326) */
    double bounds_ll[4], bounds_merc[4], centre[2];
    double grid_north; /* true north's azimuth from the frame's y axis, degrees */
};

static OGRSpatialReferenceH srs_epsg(int code)
{
    OGRSpatialReferenceH s = OSRNewSpatialReference(NULL);
    if (s && OSRImportFromEPSG(s, code) != OGRERR_NONE) {
        OSRDestroySpatialReference(s);
        s = NULL;
    }
    if (s)
        OSRSetAxisMappingStrategy(s, OAMS_TRADITIONAL_GIS_ORDER);
    return s;
}

/* The sidecar's crs text, when it is a CRS definition PROJ reads without files or the
 * network (EPSG/ESRI codes, WKT, PROJ strings, OGC URNs). */
static OGRSpatialReferenceH srs_from_text(const char *t)
{
    static const char *const ok[] = {"EPSG:", "ESRI:", "+proj", "PROJCS[", "GEOGCS[", "PROJCRS[",
                                     "GEOGCRS[", "urn:ogc:def:crs:"};
    OGRSpatialReferenceH s = NULL;
    int allowed = 0;
    for (size_t k = 0; k < sizeof ok / sizeof ok[0]; k++)
        allowed |= !strncmp(t, ok[k], strlen(ok[k]));
    if (allowed && !strstr(t, "://")) {
        s = OSRNewSpatialReference(NULL);
        if (s && OSRSetFromUserInput(s, t) != OGRERR_NONE) {
            OSRDestroySpatialReference(s);
            s = NULL;
        }
    }
    return s;
}

/* The file's own CRS through GDAL (GeoTIFF, .asc + .prj, SRTM), or NULL. */
static OGRSpatialReferenceH srs_from_file(const char *path)
{
    OGRSpatialReferenceH s = NULL;
    GDALDatasetH ds; /* GDAL is loaded: td_merc_proj_create's td_gdal_open */
    CPLPushErrorHandler(CPLQuietErrorHandler);
    ds = path ? GDALOpenEx(path, GDAL_OF_RASTER | GDAL_OF_READONLY, NULL, NULL, NULL) : NULL;
    if (ds) {
        OGRSpatialReferenceH f = GDALGetSpatialRef(ds);
        s = f ? OSRClone(f) : NULL;
        GDALClose(ds);
    }
    CPLPopErrorHandler();
    return s;
}

/* The dataset's CRS (see mercator.h), matching the grid's kind, or NULL. */
static OGRSpatialReferenceH srs_resolve(const char *path, const td_grid *g)
{
    OGRSpatialReferenceH s = srs_from_file(path);
    if (!s && g->geo.crs[0])
        s = srs_from_text(g->geo.crs);
    if (s && (OSRIsGeographic(s) != 0) != (g->geo.kind == TD_GEO_LONLAT)) {
        OSRDestroySpatialReference(s); /* a CRS of the other kind than the georeference */
        s = NULL;
    }
    if (!s && g->geo.kind == TD_GEO_LONLAT)
        s = srs_epsg(4326);
    if (s)
        OSRSetAxisMappingStrategy(s, OAMS_TRADITIONAL_GIS_ORDER);
    return s;
}

/* The CRS coordinates of dataset-frame point (x, y) and back. */
static void frame_to_crs(const td_merc_proj *p, double x, double y, double *X, double *Y)
{
    *X = p->geo.x0 + x / p->sx * p->geo.dx;
    *Y = p->geo.y0 + y / p->sy * p->geo.dy;
}

static void crs_to_frame(const td_merc_proj *p, double *X, double *Y)
{
    *X = (*X - p->geo.x0) / p->geo.dx * p->sx;
    *Y = (*Y - p->geo.y0) / p->geo.dy * p->sy;
}

/* The azimuth of true north in the dataset frame at the grid's centre (the meridian
 * convergence of a projected CRS; 0 for lon/lat): from the centre and a point 0.001
 * degree north of it, both through PROJ. */
static td_status grid_north(td_merc_proj *p, td_err *err)
{
    double X[2] = {p->centre[0], p->centre[0]}, Y[2] = {p->centre[1], p->centre[1] + 1e-3};
    int ok[2] = {0, 0};
    OGRCoordinateTransformationH t = OCTNewCoordinateTransformation(p->ll, p->crs);
    td_status rc = TD_OK;
    if (!t || !OCTTransformEx(t, 2, X, Y, NULL, ok) || !ok[0] || !ok[1]) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "lon/lat does not transform to the dataset's CRS");
    } else {
        crs_to_frame(p, &X[0], &Y[0]);
        crs_to_frame(p, &X[1], &Y[1]);
        p->grid_north = atan2(X[1] - X[0], Y[1] - Y[0]) * 180.0 / M_PI;
    }
    if (t)
        OCTDestroyCoordinateTransformation(t);
    return rc;
}

/* Bounds and centre: 64 points a side of the grid's outline, to lon/lat and EPSG:3857. */
static td_status proj_bounds(td_merc_proj *p, td_err *err)
{
    enum { N = 64 };
    double X[4 * N + 1], Y[4 * N + 1], mx[4 * N + 1], my[4 * N + 1];
    int ok[4 * N + 1], bad = 0;
    double W = (double)(p->w - 1) * p->sx, H = (double)(p->h - 1) * p->sy;
    OGRCoordinateTransformationH to_merc = OCTNewCoordinateTransformation(p->ll, p->merc);
    for (int k = 0; k < N; k++) {
        double f = (double)k / N;
        frame_to_crs(p, f * W, 0.0, &X[k], &Y[k]);
        frame_to_crs(p, W, f * H, &X[N + k], &Y[N + k]);
        frame_to_crs(p, W - f * W, H, &X[2 * N + k], &Y[2 * N + k]);
        frame_to_crs(p, 0.0, H - f * H, &X[3 * N + k], &Y[3 * N + k]);
    }
    frame_to_crs(p, 0.5 * W, 0.5 * H, &X[4 * N], &Y[4 * N]);
    bad = !to_merc || !OCTTransformEx(p->to_ll, 4 * N + 1, X, Y, NULL, ok);
    for (int k = 0; k <= 4 * N && !bad; k++)
        bad = !ok[k];
    memcpy(mx, X, sizeof mx);
    memcpy(my, Y, sizeof my);
    bad = bad || !OCTTransformEx(to_merc, 4 * N, mx, my, NULL, ok);
    for (int k = 0; k < 4 * N && !bad; k++)
        bad = !ok[k];
    if (!bad) {
        p->bounds_ll[0] = p->bounds_ll[1] = p->bounds_merc[0] = p->bounds_merc[1] = INFINITY;
        p->bounds_ll[2] = p->bounds_ll[3] = p->bounds_merc[2] = p->bounds_merc[3] = -INFINITY;
        for (int k = 0; k < 4 * N; k++) {
            p->bounds_ll[0] = dmin(p->bounds_ll[0], X[k]);
            p->bounds_ll[1] = dmin(p->bounds_ll[1], Y[k]);
            p->bounds_ll[2] = dmax(p->bounds_ll[2], X[k]);
            p->bounds_ll[3] = dmax(p->bounds_ll[3], Y[k]);
            p->bounds_merc[0] = dmin(p->bounds_merc[0], mx[k]);
            p->bounds_merc[1] = dmin(p->bounds_merc[1], my[k]);
            p->bounds_merc[2] = dmax(p->bounds_merc[2], mx[k]);
            p->bounds_merc[3] = dmax(p->bounds_merc[3], my[k]);
        }
        p->centre[0] = X[4 * N];
        p->centre[1] = Y[4 * N];
        bad = grid_north(p, err) != TD_OK;
    }
    if (to_merc)
        OCTDestroyCoordinateTransformation(to_merc);
    return bad ? td_err_set(err, TD_EUNSUPPORTED, "the grid's extent does not transform to lon/lat and "
                            "Web Mercator (outside the CRS's area, or beyond 85 degrees of latitude)")
               : TD_OK;
}

/* The transformations and spatial references of p from its crs (p->wkt set). */
static td_status proj_open(td_merc_proj *p, td_err *err)
{
    td_status rc = TD_OK;
    p->merc = srs_epsg(3857);
    p->ll = srs_epsg(4326);
    p->crs = OSRNewSpatialReference(NULL);
    if (!p->merc || !p->ll || !p->crs || OSRImportFromWkt(p->crs, &(char *){p->wkt}) != OGRERR_NONE) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "PROJ does not know EPSG:3857, EPSG:4326 or the dataset's CRS");
        goto out;
    }
    OSRSetAxisMappingStrategy(p->crs, OAMS_TRADITIONAL_GIS_ORDER);
    p->to_crs = OCTNewCoordinateTransformation(p->merc, p->crs);
    p->to_ll = OCTNewCoordinateTransformation(p->crs, p->ll);
    if (!p->to_crs || !p->to_ll)
        rc = td_err_set(err, TD_EUNSUPPORTED, "no transformation between Web Mercator and the dataset's CRS");
out:
    return rc;
}

td_status td_merc_proj_create(const char *path, const td_grid *g, td_merc_proj **out, td_err *err)
{
    td_status rc = TD_OK;
    td_merc_proj *p = NULL;
    OGRSpatialReferenceH s = NULL;
    const char *name;
    int pushed = 0;
    *out = NULL;
    if (g->geo.kind == TD_GEO_NONE) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "the dataset has no georeference (lon/lat or a projected CRS)");
        goto out;
    }
    rc = td_gdal_open(err);
    if (rc != TD_OK)
        goto out;
    pushed = 1;
    CPLPushErrorHandler(CPLQuietErrorHandler); /* failures come back as td_err, not logs */
    s = srs_resolve(path, g);
    p = calloc(1, sizeof *p);
    if (!s) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "the dataset is projected, but its CRS is unknown: "
                        "give it a .prj, a GeoTIFF's CRS or the sidecar's origin.crs (e.g. \"EPSG:32613\")");
        goto out;
    }
    if (!p || OSRExportToWkt(s, &p->wkt) != OGRERR_NONE) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
        goto out;
    }
    name = OSRGetName(s);
    snprintf(p->name, sizeof p->name, "%s", name ? name : "");
    p->geo = g->geo;
    p->sx = g->sx;
    p->sy = g->sy;
    p->w = g->w;
    p->h = g->h;
    rc = proj_open(p, err);
    if (rc == TD_OK)
        rc = proj_bounds(p, err);
out:
    if (pushed)
        CPLPopErrorHandler();
    if (s)
        OSRDestroySpatialReference(s);
    if (rc) {
        td_merc_proj_free(p);
        p = NULL;
    }
    *out = p;
    return rc;
}

td_status td_merc_proj_clone(const td_merc_proj *src, td_merc_proj **out, td_err *err)
{
    td_status rc = TD_OK;
    td_merc_proj *p = calloc(1, sizeof *p);
    *out = NULL;
    if (!p || !(p->wkt = CPLStrdup(src->wkt))) {
        free(p);
        return td_err_set(err, TD_ENOMEM, "out of memory");
    }
    memcpy(p->name, src->name, sizeof p->name);
    p->geo = src->geo;
    p->sx = src->sx;
    p->sy = src->sy;
    p->w = src->w;
    p->h = src->h;
    memcpy(p->bounds_ll, src->bounds_ll, sizeof p->bounds_ll);
    memcpy(p->bounds_merc, src->bounds_merc, sizeof p->bounds_merc);
    memcpy(p->centre, src->centre, sizeof p->centre);
    p->grid_north = src->grid_north;
    CPLPushErrorHandler(CPLQuietErrorHandler);
    rc = proj_open(p, err);
    CPLPopErrorHandler();
    if (rc) {
        td_merc_proj_free(p);
        p = NULL;
    }
    *out = p;
    return rc;
}

void td_merc_proj_free(td_merc_proj *p)
{
    if (!p)
        return;
    if (p->to_crs)
        OCTDestroyCoordinateTransformation(p->to_crs);
    if (p->to_ll)
        OCTDestroyCoordinateTransformation(p->to_ll);
    if (p->merc)
        OSRDestroySpatialReference(p->merc);
    if (p->crs)
        OSRDestroySpatialReference(p->crs);
    if (p->ll)
        OSRDestroySpatialReference(p->ll);
    CPLFree(p->wkt);
    free(p);
}

const char *td_merc_proj_name(const td_merc_proj *p) { return p->name; }

double td_merc_proj_grid_north(const td_merc_proj *p) { return p->grid_north; }

void td_merc_proj_bounds(const td_merc_proj *p, double ll[4], double merc[4], double centre[2])
{
    memcpy(ll, p->bounds_ll, sizeof p->bounds_ll);
    memcpy(merc, p->bounds_merc, sizeof p->bounds_merc);
    memcpy(centre, p->centre, sizeof p->centre);
}

/* EPSG:3857 points (X, Y) to the dataset frame in place; NaN where PROJ fails. */
static td_status to_frame(td_merc_proj *p, size_t n, double *X, double *Y, int *ok, td_err *err)
{
    if (n > (size_t)INT32_MAX)
        return td_err_set(err, TD_ERANGE, "too many points");
    CPLPushErrorHandler(CPLQuietErrorHandler); /* points outside the CRS's domain: NaN, no log */
    if (!OCTTransformEx(p->to_crs, (int)n, X, Y, NULL, ok))
        memset(ok, 0, n * sizeof *ok);
    CPLPopErrorHandler();
    for (size_t k = 0; k < n; k++) {
        if (ok[k] && isfinite(X[k]) && isfinite(Y[k])) {
            crs_to_frame(p, &X[k], &Y[k]);
        } else {
            X[k] = Y[k] = NAN;
        }
    }
    return TD_OK;
}

/* The lattice every TD_MERC_LATTICE pixels (nodes at pixel-centre indices 0, 8, .. px)
 * and the check at its cells' centres; 1 when the interpolation is within tolerance
 * (xy then filled), 0 when it is not (or a node failed). */
static int lattice(td_merc_proj *p, const double b[4], int px, double *X, double *Y, int *ok,
                   double *xy, double *foot, td_err *err)
{
    const int S = TD_MERC_LATTICE, L = px / S + 1, C = px / S;
    double ps = (b[2] - b[0]) / px, worst = 0.0;
    double *cx = X + (size_t)L * L, *cy = Y + (size_t)L * L;
    int good = 1;
    for (int r = 0; r < L; r++)
        for (int c = 0; c < L; c++) {
            X[r * L + c] = b[0] + (c * S + 0.5) * ps;
            Y[r * L + c] = b[3] - (r * S + 0.5) * ps;
        }
    for (int r = 0; r < C; r++)
        for (int c = 0; c < C; c++) {
            cx[r * C + c] = b[0] + (c * S + S / 2 + 0.5) * ps;
            cy[r * C + c] = b[3] - (r * S + S / 2 + 0.5) * ps;
        }
    if (to_frame(p, (size_t)L * L + (size_t)C * C, X, Y, ok, err))
        return 0;
    *foot = INFINITY;
    for (int r = 0; r < C && good; r++)
        for (int c = 0; c < C && good; c++) {
            const int i00 = r * L + c, i01 = i00 + 1, i10 = i00 + L, i11 = i10 + 1;
            double ix = 0.25 * (X[i00] + X[i01] + X[i10] + X[i11]);
            double iy = 0.25 * (Y[i00] + Y[i01] + Y[i10] + Y[i11]);
            double fx = hypot(X[i01] - X[i00], Y[i01] - Y[i00]) / S;
            double fy = hypot(X[i10] - X[i00], Y[i10] - Y[i00]) / S;
            good = isfinite(ix) && isfinite(iy) && isfinite(cx[r * C + c]);
            *foot = dmin(*foot, dmin(fx, fy));
            worst = dmax(worst, hypot(ix - cx[r * C + c], iy - cy[r * C + c]));
        }
    good = good && worst <= TD_MERC_LATTICE_TOL * *foot;
    for (int r = 0; r < px && good; r++)
        for (int c = 0; c < px; c++) {
            int lr = r / S, lc = c / S;
            double u = (double)(c - lc * S) / S, v = (double)(r - lr * S) / S;
            const int i00 = lr * L + lc, i01 = i00 + 1, i10 = i00 + L, i11 = i10 + 1;
            double *o = &xy[2 * ((size_t)r * px + c)];
            o[0] = (1 - v) * ((1 - u) * X[i00] + u * X[i01]) + v * ((1 - u) * X[i10] + u * X[i11]);
            o[1] = (1 - v) * ((1 - u) * Y[i00] + u * Y[i01]) + v * ((1 - u) * Y[i10] + u * Y[i11]);
        }
    return good;
}

/* Every pixel through PROJ (the fallback of the lattice). */
static td_status exact(td_merc_proj *p, const double b[4], int px, double *xy, double *foot, td_err *err)
{
    td_status rc = TD_OK;
    size_t n = (size_t)px * (size_t)px;
    double ps = (b[2] - b[0]) / px;
    double *X = malloc(n * sizeof *X), *Y = malloc(n * sizeof *Y);
    int *ok = malloc(n * sizeof *ok);
    if (!X || !Y || !ok) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
        goto out;
    }
    for (int r = 0; r < px; r++)
        for (int c = 0; c < px; c++) {
            X[(size_t)r * px + c] = b[0] + (c + 0.5) * ps;
            Y[(size_t)r * px + c] = b[3] - (r + 0.5) * ps;
        }
    rc = to_frame(p, n, X, Y, ok, err);
    *foot = INFINITY;
    for (size_t k = 0; k < n && rc == TD_OK; k++) {
        xy[2 * k] = X[k];
        xy[2 * k + 1] = Y[k];
        if (k % (size_t)px + 1 < (size_t)px && k + (size_t)px < n) {
            double f = dmin(hypot(X[k + 1] - X[k], Y[k + 1] - Y[k]), hypot(X[k + px] - X[k], Y[k + px] - Y[k]));
            if (isfinite(f)) /* NaN where PROJ failed */
                *foot = dmin(*foot, f);
        }
    }
out:
    free(X);
    free(Y);
    free(ok);
    return rc;
}

td_status td_merc_positions(td_merc_proj *p, int z, int32_t x, int32_t y, int px, double *xy,
                            int *exact_out, double *foot_m, td_err *err)
{
    td_status rc = TD_OK;
    double b[4];
    const int L = px / TD_MERC_LATTICE + 1;
    size_t n = (size_t)L * L * 2;
    double *X = NULL, *Y = NULL;
    int *ok = NULL;
    *exact_out = 0;
    if (z < 0 || z > TD_MERC_MAX_ZOOM || x < 0 || y < 0 || x >= (1 << z) || y >= (1 << z) || px < TD_MERC_LATTICE ||
        px % TD_MERC_LATTICE || px > 4096)
        return td_err_set(err, TD_EINVAL, "no tile %d/%d/%d of %d pixels", z, (int)x, (int)y, px);
    td_merc_tile_bounds(z, x, y, b);
    X = malloc(n * sizeof *X);
    Y = malloc(n * sizeof *Y);
    ok = malloc(n * sizeof *ok);
    if (!X || !Y || !ok) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
        goto out;
    }
    if (!lattice(p, b, px, X, Y, ok, xy, foot_m, err)) {
        rc = exact(p, b, px, xy, foot_m, err);
        *exact_out = 1;
    }
out:
    free(X);
    free(Y);
    free(ok);
    return rc;
}

td_status td_merc_to_lonlat(td_merc_proj *p, double x, double y, double ll[2], td_err *err)
{
    int ok = 0, done;
    frame_to_crs(p, x, y, &ll[0], &ll[1]);
    CPLPushErrorHandler(CPLQuietErrorHandler);
    done = OCTTransformEx(p->to_ll, 1, &ll[0], &ll[1], NULL, &ok) && ok;
    CPLPopErrorHandler();
    return done ? TD_OK : td_err_set(err, TD_ERANGE, "(%g, %g) does not transform to lon/lat", x, y);
}

#endif
