/* mhdapi.c: loads libmicrohttpd on first use and fills the table of mhdapi.h (why: its
 * top comment). */
#define TD_MHDAPI_IMPL
#include "mhdapi.h"

#include <pthread.h>

#include "dynlib.h"

#ifndef TERRAD_MHD_SONAME
#define TERRAD_MHD_SONAME "libmicrohttpd.so.12"
#endif

td_mhd_api td_mhd;

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static char load_error[512]; /* empty once loaded */

static void load(void)
{
#define TD_MHD_NAME(f) #f,
#define TD_MHD_SLOT(f) (void **)&td_mhd.f,
    static const char *const names[] = {TD_MHD_FNS(TD_MHD_NAME)};
    void **const slots[] = {TD_MHD_FNS(TD_MHD_SLOT)};
#undef TD_MHD_SLOT
#undef TD_MHD_NAME
    (void)td_dynlib_load(TERRAD_MHD_SONAME, names, slots, sizeof names / sizeof *names, load_error,
                         sizeof load_error);
}

td_status td_mhd_open(td_err *err)
{
    td_status rc = TD_OK;
    pthread_once(&load_once, load);
    if (load_error[0])
        rc = td_err_set(err, TD_EUNSUPPORTED, "libmicrohttpd could not be loaded (%s): %s", TERRAD_MHD_SONAME,
                        load_error);
    return rc;
}
