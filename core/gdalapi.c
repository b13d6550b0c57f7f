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

#include <pthread.h>

#include "dynlib.h"

#ifndef TERRAD_GDAL_SONAME
#define TERRAD_GDAL_SONAME "libgdal.so"
#endif

td_gdal_api td_gdal;

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static char load_error[512]; /* empty once loaded */

/* Every entry from the library (dynlib.h); GDALAllRegister once they are all there. */
static void load(void)
{
#define TD_GDAL_NAME(f) #f,
#define TD_GDAL_SLOT(f) (void **)&td_gdal.f,
    static const char *const names[] = {TD_GDAL_FNS(TD_GDAL_NAME)};
    void **const slots[] = {TD_GDAL_FNS(TD_GDAL_SLOT)};
#undef TD_GDAL_SLOT
#undef TD_GDAL_NAME
    if (td_dynlib_load(TERRAD_GDAL_SONAME, names, slots, sizeof names / sizeof *names, load_error,
                       sizeof load_error))
        td_gdal.GDALAllRegister();
}

td_status td_gdal_open(td_err *err)
{
    td_status rc = TD_OK;
    pthread_once(&load_once, load);
    if (load_error[0])
        rc = td_err_set(err, TD_EUNSUPPORTED, "GDAL could not be loaded (%s): %s", TERRAD_GDAL_SONAME,
                        load_error);
    return rc;
}

#endif
