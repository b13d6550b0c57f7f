/* main.c: the `terrad` command. Dispatches to the subcommands of cli.h, after setting
 * the process's malloc policy (td_malloc_policy). */
#include <stdio.h>
#include <string.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

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

/* Every request allocates and frees buffers of up to a few MB (a 512 x 512 render's 1 MiB
 * of pixels, the sun bound, the samples of each worker), and on the virtual machines
 * terrad runs on a page's first touch costs about 10 us (core/bigalloc.h). glibc's
 * defaults give a freed buffer of more than 128 KiB (at first; the threshold then follows
 * the largest freed) back to the kernel and the next request maps it again: a 512 x 512
 * render of trinidad with shadows took 16.3-18.1 ms (mean of 15, one thread), 13.4 ms
 * with buffers under 4 MiB taken from the heap and 32 MiB of freed memory kept for reuse
 * (the resolve stage, which first writes the pixels, 0.9-2.4 -> 0.8 ms). Larger buffers
 * (a DEM's heights) still get their own mappings, returned when freed. */
static void td_malloc_policy(void)
{
#if defined(__GLIBC__)
    (void)mallopt(M_MMAP_THRESHOLD, 4 << 20);
    (void)mallopt(M_TRIM_THRESHOLD, 32 << 20);
#endif
}

int main(int argc, char **argv)
{
    int rc = 2;
    const char *cmd = argc > 1 ? argv[1] : NULL;

    td_malloc_policy();

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
