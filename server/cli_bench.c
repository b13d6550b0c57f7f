/* cli_bench.c: `terrad bench`: the accuracy-vs-time benchmark (DESIGN.md) is a program of
 * its own, terrad-bench (tests/bench), so that terrad does not link Embree, the
 * benchmark's yardstick. This subcommand keeps the command line of the contract: it
 * replaces itself (execv) with the terrad-bench beside this executable, passing every
 * argument after `bench` through; where that program is missing (an image that ships
 * only the daemon), it says so and exits 1. */
#include "cli.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#define TD_BENCH_PROGRAM "terrad-bench"

int td_cli_bench(int argc, char **argv)
{
    char path[4096];
    (void)argc;
    if (!td_cli_sibling(TD_BENCH_PROGRAM, path, sizeof path)) {
        fprintf(stderr, "terrad bench: cannot find the folder of this executable\n");
    } else {
        argv[0] = path; /* argv[0] was "bench"; argv[argc] is NULL */
        execv(path, argv);
        fprintf(stderr,
                "terrad bench: cannot run %s: %s\n"
                "The benchmark is the program " TD_BENCH_PROGRAM ", built beside terrad with the\n"
                "tests (cmake --build build --target " TD_BENCH_PROGRAM "); images that serve only\n"
                "the daemon do not ship it.\n",
                path, strerror(errno));
    }
    return 1;
}
