/* dynlib.h: a shared library's functions resolved at run time (dlopen, dlsym), for the
 * libraries terrad loads on first use instead of linking: GDAL (gdalapi.h), which only
 * some DEM files and map projections need, and libmicrohttpd (server/mhdapi.h), which
 * only `terrad serve` needs. A linked library costs every command its loading at start:
 * libgdal's 116 libraries about 40 ms of CPU, libmicrohttpd and the TLS stack it brings
 * (gnutls, nettle, gmp, p11-kit, ...) 3.3 ms (a `main` linked with jansson and libpng
 * alone starts in 0.8 ms, with libmicrohttpd as well in 4.2: perf stat, 50 runs).
 *
 * Each user keeps its functions in a table (an X-macro list of names, a struct of
 * pointers typed from the library's own prototypes) and fills it once through
 * td_dynlib_load under pthread_once; the table is only read after, so threads share it
 * without locks. */
#ifndef TD_DYNLIB_H
#define TD_DYNLIB_H

#include <stddef.h>

/* Opens `soname` (RTLD_NOW | RTLD_LOCAL; never closed) and writes function names[i] to
 * *slots[i] for i < n. Returns 1 when every name is there; else 0, with dlerror's reason
 * or the first missing name in msg (msglen bytes, terminated). */
int td_dynlib_load(const char *soname, const char *const names[], void **const slots[], size_t n, char *msg,
                   size_t msglen);

#endif
