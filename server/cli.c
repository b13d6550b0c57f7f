/* cli.c: helpers shared by the subcommands (and by terrad-bench, which links them). */
#include "cli.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int td_cli_parse_int(const char *s, long lo, long hi, int *out)
{
    char *end = NULL;
    long v;
    int ok;
    errno = 0;
    v = strtol(s, &end, 10);
    ok = end != s && *end == '\0' && errno == 0 && v >= lo && v <= hi;
    if (ok)
        *out = (int)v;
    return ok;
}

int td_cli_sibling(const char *name, char *out, size_t cap)
{
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    char *slash;
    int ok = n > 0;
    if (ok) {
        self[n] = '\0';
        slash = strrchr(self, '/');
        ok = slash != NULL;
    }
    if (ok) {
        *slash = '\0';
        ok = (size_t)snprintf(out, cap, "%s/%s", self, name) < cap;
    }
    return ok;
}

int td_cli_write_file(const char *path, const void *data, size_t len)
{
    int ok = 0;
    FILE *f = strcmp(path, "-") ? fopen(path, "wb") : stdout;
    if (f) {
        ok = fwrite(data, 1, len, f) == len;
        if (f != stdout)
            ok = (fclose(f) == 0) && ok;
        else
            ok = (fflush(f) == 0) && ok;
    }
    return ok;
}
