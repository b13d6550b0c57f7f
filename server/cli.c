/* cli.c: helpers shared by the subcommands. */
#include "cli.h"

#include <stdio.h>

int td_cli_not_landed(const char *name, const char *issue)
{
    fprintf(stderr, "terrad %s: not available yet (%s has not landed)\n", name, issue);
    return 2;
}
