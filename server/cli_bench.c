/* cli_bench.c: `terrad bench`. */
#include "cli.h"

int td_cli_bench(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return td_cli_not_landed("bench", "the benchmark issue");
}
