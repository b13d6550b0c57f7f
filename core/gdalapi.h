/* gdalapi.h: GDAL's C API through a table loaded on first use (dynlib.h), not linked in.
 *
 * Linking libgdal made every terrad command pay for the dynamic loader bringing in libgdal
 * and the 116 libraries it needs, and their constructors: about 40 ms of CPU on every
 * start (a `main` linked with jansson, libpng and libmicrohttpd started in 2-3 ms, with
 * libgdal as well in 40-55 ms, shared machine; libmicrohttpd is now loaded the same way),
 * although most commands (an .f32, .asc, .hgt or .png DEM, a render, a viewshed) never
 * call it. The GDAL users (demgdal.c,
 * mercator.c) include this header instead of GDAL's: it includes GDAL's headers for the
 * types and constants and turns each function they call into the table's entry, so their
 * code reads as GDAL's own. Each entry point calls td_gdal_open first, which loads the
 * library once (pthread_once; the table is written there and only read after, so threads
 * share it without locks) and refuses with TD_EUNSUPPORTED, naming the library and
 * dlerror's reason, when it cannot. Only with TERRAD_HAVE_GDAL; the library's name is
 * the soname CMake found (TERRAD_GDAL_SONAME). A function added to a GDAL user must be
 * added to TD_GDAL_FNS and given its #define below. */
#ifndef TD_GDALAPI_H
#define TD_GDALAPI_H

#include "status.h"

/* Loads GDAL once and registers its drivers (GDALAllRegister); TD_OK when the table is
 * ready, else TD_EUNSUPPORTED with the reason in err (every call gives the same). */
td_status td_gdal_open(td_err *err);

#ifdef TERRAD_HAVE_GDAL
#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal.h>
#include <ogr_srs_api.h>

#define TD_GDAL_FNS(X)                                                                             \
    X(CPLErrorReset) X(CPLGetLastErrorMsg) X(CPLPopErrorHandler) X(CPLPushErrorHandler)            \
    X(CPLQuietErrorHandler) X(CPLStrdup) X(VSIFree) X(GDALAllRegister) X(GDALClose)               \
    X(GDALGetGeoTransform) X(GDALGetRasterBand) X(GDALGetRasterCount) X(GDALGetRasterNoDataValue) \
    X(GDALGetRasterOffset) X(GDALGetRasterScale) X(GDALGetRasterXSize) X(GDALGetRasterYSize)      \
    X(GDALGetSpatialRef) X(GDALOpenEx) X(GDALRasterIO) X(OCTDestroyCoordinateTransformation)      \
    X(OCTNewCoordinateTransformation) X(OCTTransformEx) X(OSRClone) X(OSRDestroySpatialReference) \
    X(OSRExportToWkt) X(OSRGetLinearUnits) X(OSRGetName) X(OSRImportFromEPSG) X(OSRImportFromWkt) \
    X(OSRIsGeographic) X(OSRNewSpatialReference) X(OSRSetAxisMappingStrategy) X(OSRSetFromUserInput)

#define TD_GDAL_MEMBER(f) __typeof__(f) *f;
typedef struct td_gdal_api {
    TD_GDAL_FNS(TD_GDAL_MEMBER)
} td_gdal_api;
#undef TD_GDAL_MEMBER

/* Filled by td_gdal_open; read only after it returned TD_OK. */
extern td_gdal_api td_gdal;

#ifndef TD_GDALAPI_IMPL /* gdalapi.c names the real functions to take their types */
#define CPLErrorReset (td_gdal.CPLErrorReset)
#define CPLGetLastErrorMsg (td_gdal.CPLGetLastErrorMsg)
#define CPLPopErrorHandler (td_gdal.CPLPopErrorHandler)
#define CPLPushErrorHandler (td_gdal.CPLPushErrorHandler)
#define CPLQuietErrorHandler (td_gdal.CPLQuietErrorHandler)
#define CPLStrdup (td_gdal.CPLStrdup)
#define VSIFree (td_gdal.VSIFree) /* and so CPLFree, cpl_conv.h's name for it */
#define GDALAllRegister (td_gdal.GDALAllRegister)
#define GDALClose (td_gdal.GDALClose)
#define GDALGetGeoTransform (td_gdal.GDALGetGeoTransform)
#define GDALGetRasterBand (td_gdal.GDALGetRasterBand)
#define GDALGetRasterCount (td_gdal.GDALGetRasterCount)
#define GDALGetRasterNoDataValue (td_gdal.GDALGetRasterNoDataValue)
#define GDALGetRasterOffset (td_gdal.GDALGetRasterOffset)
#define GDALGetRasterScale (td_gdal.GDALGetRasterScale)
#define GDALGetRasterXSize (td_gdal.GDALGetRasterXSize)
#define GDALGetRasterYSize (td_gdal.GDALGetRasterYSize)
#define GDALGetSpatialRef (td_gdal.GDALGetSpatialRef)
#define GDALOpenEx (td_gdal.GDALOpenEx)
#define GDALRasterIO (td_gdal.GDALRasterIO)
#define OCTDestroyCoordinateTransformation (td_gdal.OCTDestroyCoordinateTransformation)
#define OCTNewCoordinateTransformation (td_gdal.OCTNewCoordinateTransformation)
#define OCTTransformEx (td_gdal.OCTTransformEx)
#define OSRClone (td_gdal.OSRClone)
#define OSRDestroySpatialReference (td_gdal.OSRDestroySpatialReference)
#define OSRExportToWkt (td_gdal.OSRExportToWkt)
#define OSRGetLinearUnits (td_gdal.OSRGetLinearUnits)
#define OSRGetName (td_gdal.OSRGetName)
#define OSRImportFromEPSG (td_gdal.OSRImportFromEPSG)
#define OSRImportFromWkt (td_gdal.OSRImportFromWkt)
#define OSRIsGeographic (td_gdal.OSRIsGeographic)
#define OSRNewSpatialReference (td_gdal.OSRNewSpatialReference)
#define OSRSetAxisMappingStrategy (td_gdal.OSRSetAxisMappingStrategy)
#define OSRSetFromUserInput (td_gdal.OSRSetFromUserInput)
#endif
#endif

#endif
