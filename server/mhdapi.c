/* mhdapi.c: loads libmicrohttpd on first use and fills the table of mhdapi.h (why: its
 * top comment). */
#define TD_MHDAPI_IMPL
#include "mhdapi.h"

#include "dynlib.h"

#ifndef TERRAD_MHD_SONAME
#define TERRAD_MHD_SONAME "libmicrohttpd.so.12"
#endif

td_mhd_api td_mhd;

#define TD_MHD_NAME(f) #f,
#define TD_MHD_SLOT(f) (void **)&td_mhd.f,
static const char *const names[] = {TD_MHD_FNS(TD_MHD_NAME)};
static void **const slots[] = {TD_MHD_FNS(TD_MHD_SLOT)};
#undef TD_MHD_SLOT
#undef TD_MHD_NAME

static td_dynlib lib = {TERRAD_MHD_SONAME, "libmicrohttpd", names, slots, sizeof names / sizeof *names, NULL,
                        PTHREAD_MUTEX_INITIALIZER, 0, ""};

td_status td_mhd_open(td_err *err) { return td_dynlib_open(&lib, err); }
