/* dynlib.c: see dynlib.h. */
#include "dynlib.h"

#include <dlfcn.h>
#include <stdio.h>

int td_dynlib_load(const char *soname, const char *const names[], void **const slots[], size_t n, char *msg,
                   size_t msglen)
{
    void *h = dlopen(soname, RTLD_NOW | RTLD_LOCAL);
    const char *e = h ? NULL : dlerror();
    size_t i = 0;
    /* dlsym returns a void *, which POSIX requires to convert to a function pointer; ISO C
     * leaves the cast undefined, so each entry is written through a void ** (the form of
     * dlsym's manual page) */
    while (h && i < n && (*slots[i] = dlsym(h, names[i])) != NULL)
        i++;
    if (!h)
        snprintf(msg, msglen, "%s", e ? e : "dlopen failed");
    else if (i < n)
        snprintf(msg, msglen, "%s has no %s", soname, names[i]);
    else if (msglen > 0)
        msg[0] = '\0';
    return h && i == n;
}

td_status td_dynlib_open(td_dynlib *lib, td_err *err)
{
    td_status rc = TD_OK;
    int st = atomic_load_explicit(&lib->state, memory_order_acquire);
    if (st == 0) {
        pthread_mutex_lock(&lib->mu);
        st = atomic_load_explicit(&lib->state, memory_order_relaxed);
        if (st == 0) {
            st = td_dynlib_load(lib->soname, lib->names, lib->slots, lib->n, lib->error, sizeof lib->error) ? 1 : 2;
            if (st == 1 && lib->loaded)
                lib->loaded();
            atomic_store_explicit(&lib->state, st, memory_order_release);
        }
        pthread_mutex_unlock(&lib->mu);
    }
    if (st != 1)
        rc = td_err_set(err, TD_EUNSUPPORTED, "%s could not be loaded (%s): %s", lib->what, lib->soname,
                        lib->error);
    return rc;
}
