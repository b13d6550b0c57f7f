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

#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>

#ifndef TERRAD_GDAL_SONAME
#define TERRAD_GDAL_SONAME "libgdal.so"
#endif

td_gdal_api td_gdal;

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static char load_error[512]; /* empty once loaded */

/* dlopen and dlsym every entry; GDALAllRegister once they are all there. */
static void load(void)
{
    void *h = dlopen(TERRAD_GDAL_SONAME, RTLD_NOW | RTLD_LOCAL);
    const char *missing = NULL, *e = h ? NULL : dlerror();
    /* dlsym returns a void *, which POSIX requires to convert to a function pointer; ISO C
     * leaves the cast undefined, so the entry is written through a void ** (the form of
     * dlsym's manual page) */
#define TD_GDAL_SYM(f)                                                                             \
    if (h && !missing && !(*(void **)&td_gdal.f = dlsym(h, #f)))                                   \
        missing = #f;
    TD_GDAL_FNS(TD_GDAL_SYM)
#undef TD_GDAL_SYM
    if (!h)
        snprintf(load_error, sizeof load_error, "%s", e ? e : "dlopen failed");
    else if (missing)
        snprintf(load_error, sizeof load_error, "%s has no %s", TERRAD_GDAL_SONAME, missing);
    else
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
