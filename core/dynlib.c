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
