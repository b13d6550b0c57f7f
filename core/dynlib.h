/* dynlib.h: a shared library's functions resolved at run time (dlopen, dlsym), for the
 * libraries terrad loads on first use instead of linking: GDAL (gdalapi.h), which only
 * some DEM files and map projections need, and libmicrohttpd (server/mhdapi.h), which
 * only `terrad serve` needs. A linked library costs every command its loading at start:
 * libgdal's 116 libraries about 40 ms of CPU, libmicrohttpd and the TLS stack it brings
 * (gnutls, nettle, gmp, p11-kit, ...) 3.3 ms (a `main` linked with jansson and libpng
 * alone starts in 0.8 ms, with libmicrohttpd as well in 4.2: perf stat, 50 runs).
 *
 * Each user keeps its functions in a table (an X-macro list of names, a struct of
 * pointers typed from the library's own prototypes) and describes it in a static
 * td_dynlib: the names, the table's slots, what to call once they are all there. Its
 * entry points call td_dynlib_open, which loads the library on the first call only (a
 * mutex taken until then, an acquire load after) and gives every caller the same answer;
 * the table is written before the load is published and only read after, so threads
 * share it without locks. */
#ifndef TD_DYNLIB_H
#define TD_DYNLIB_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>

#include "status.h"

typedef struct td_dynlib {
    const char *soname;         /* the library to load (its soname) */
    const char *what;           /* its name in messages ("GDAL") */
    const char *const *names;   /* n function names ... */
    void **const *slots;        /* ... and where each goes */
    size_t n;
    void (*loaded)(void);       /* called once every name is there, or NULL */
    pthread_mutex_t mu;         /* PTHREAD_MUTEX_INITIALIZER */
    atomic_int state;           /* 0 not tried, 1 loaded, 2 failed (error says why) */
    char error[512];
} td_dynlib;

/* Opens `soname` (RTLD_NOW | RTLD_LOCAL; never closed) and writes function names[i] to
 * *slots[i] for i < n. Returns 1 when every name is there; else 0, with dlerror's reason
 * or the first missing name in msg (msglen bytes, terminated). */
int td_dynlib_load(const char *soname, const char *const names[], void **const slots[], size_t n, char *msg,
                   size_t msglen);

/* Loads lib on the first call (td_dynlib_load, then lib->loaded); TD_OK when its table is
 * ready, else TD_EUNSUPPORTED naming the library and the reason (every call the same). */
td_status td_dynlib_open(td_dynlib *lib, td_err *err);

#endif
