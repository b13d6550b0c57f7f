/* main.c: the `terrad` command. Dispatches to the subcommands of cli.h, after setting
 * the process's malloc policy (td_bigalloc_policy, bigalloc.h). */
#include <stdio.h>
#include <string.h>

#include "bigalloc.h"
#include "cli.h"

#define TD_SUBCOMMANDS(X)                                                          \
    X("serve", td_cli_serve, "serve rendered views over HTTP (default: the demo data)") \
    X("render", td_cli_render, "render a scene JSON to an image")                  \
    X("trace", td_cli_trace, "trace binary rays from stdin, write hit distances")   \
    X("info", td_cli_info, "describe a DEM file")                                  \
    X("prepare", td_cli_prepare, "write a DEM as a prepared dataset (larger than memory)") \
    X("viewshed", td_cli_viewshed, "what can be seen from points of a DEM (PNG)")  \
    X("bench", td_cli_bench, "measure methods and surfaces against Embree")

static void usage(FILE *f)
{
    fprintf(f, "usage: terrad <command> [options]\n\ncommands:\n");
#define TD_X_USAGE(name, fn, help) fprintf(f, "  %-8s %s\n", name, help);
    TD_SUBCOMMANDS(TD_X_USAGE)
#undef TD_X_USAGE
    fprintf(f, "\n`terrad <command> --help` describes each one.\n");
}

int main(int argc, char **argv)
{
    int rc = 2;
    const char *cmd = argc > 1 ? argv[1] : NULL;

    td_bigalloc_policy();

    if (!cmd) {
        usage(stderr);
    } else if (!strcmp(cmd, "-h") || !strcmp(cmd, "--help") || !strcmp(cmd, "help")) {
        usage(stdout);
        rc = 0;
    }
#define TD_X_DISPATCH(name, fn, help) else if (!strcmp(cmd, name)) rc = fn(argc - 1, argv + 1);
    TD_SUBCOMMANDS(TD_X_DISPATCH)
#undef TD_X_DISPATCH
    else {
        fprintf(stderr, "terrad: unknown command '%s'\n", cmd);
        usage(stderr);
    }
    return rc;
}
