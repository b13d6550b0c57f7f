/* cli_trace.c: `terrad trace`. */
#include "cli.h"

int td_cli_trace(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return td_cli_not_landed("trace", "the tracer issue");
}
