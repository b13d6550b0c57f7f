/* cli.c: helpers shared by the subcommands. */
#include "cli.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>

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
