/* cli_serve.c: `terrad serve`. */
#include "cli.h"

int td_cli_serve(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return td_cli_not_landed("serve", "the HTTP service issue");
}
