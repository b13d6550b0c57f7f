/* main.c: the `terrad` command. Dispatches to the subcommands of cli.h, after setting
 * the process's malloc policy (td_bigalloc_policy, bigalloc.h) and, for `viewshed`, its
 * scratch on huge pages (td_bigalloc_oneshot: its heap is cold, where a server's and a
 * benchmark's repeated requests reuse theirs; `render` measured no gain: the buffers it
 * allocates after its build reuse the heap the build freed, and fault where they do not). */
#include <stdio.h>
#include <string.h>

#include "bigalloc.h"
#include "cli.h"

/* name, function, one-shot, help */
#define TD_SUBCOMMANDS(X)                                                                   \
    X("serve", td_cli_serve, 0, "serve rendered views over HTTP (default: the demo data)") \
    X("render", td_cli_render, 0, "render a scene JSON to an image")                       \
    X("trace", td_cli_trace, 0, "trace binary rays from stdin, write hit distances")        \
    X("info", td_cli_info, 0, "describe a DEM file")                                       \
    X("prepare", td_cli_prepare, 0, "write a DEM as a prepared dataset (larger than memory)") \
    X("viewshed", td_cli_viewshed, 1, "what can be seen from points of a DEM (PNG)")       \
    X("bench", td_cli_bench, 0, "measure methods and surfaces against Embree")

static void usage(FILE *f)
{
    fprintf(f, "usage: terrad <command> [options]\n\ncommands:\n");
#define TD_X_USAGE(name, fn, oneshot, help) fprintf(f, "  %-8s %s\n", name, help);
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
#define TD_X_DISPATCH(name, fn, oneshot, help)                                           \
    else if (!strcmp(cmd, name)) {                                                          \
        td_bigalloc_oneshot(oneshot);                                                       \
        rc = fn(argc - 1, argv + 1);                                                        \
    }
    TD_SUBCOMMANDS(TD_X_DISPATCH)
#undef TD_X_DISPATCH
    else {
        fprintf(stderr, "terrad: unknown command '%s'\n", cmd);
        usage(stderr);
    }
    return rc;
}
