/* gdalapi.c: loads libgdal on first use and fills the table of gdalapi.h (why: its top
 * comment). Called by the GDAL users' entry points (demgdal.c, mercator.c) through
 * td_gdal_open; without TERRAD_HAVE_GDAL it refuses as they did. */
#define TD_GDALAPI_IMPL
#include "gdalapi.h"

#ifndef TERRAD_HAVE_GDAL

td_status td_gdal_open(td_err *err)
{
    return td_err_set(err, TD_EUNSUPPORTED, "this terrad was built without libgdal");
}

#else

#include "dynlib.h"

#ifndef TERRAD_GDAL_SONAME
#define TERRAD_GDAL_SONAME "libgdal.so"
#endif

td_gdal_api td_gdal;

static void register_drivers(void) { td_gdal.GDALAllRegister(); }

#define TD_GDAL_NAME(f) #f,
#define TD_GDAL_SLOT(f) (void **)&td_gdal.f,
static const char *const names[] = {TD_GDAL_FNS(TD_GDAL_NAME)};
static void **const slots[] = {TD_GDAL_FNS(TD_GDAL_SLOT)};
#undef TD_GDAL_SLOT
#undef TD_GDAL_NAME

static td_dynlib lib = {TERRAD_GDAL_SONAME, "GDAL", names, slots, sizeof names / sizeof *names, register_drivers,
                        PTHREAD_MUTEX_INITIALIZER, 0, ""};

td_status td_gdal_open(td_err *err) { return td_dynlib_open(&lib, err); }

#endif
