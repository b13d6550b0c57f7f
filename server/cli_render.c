/* cli_render.c: `terrad render`. */
#include "cli.h"

int td_cli_render(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return td_cli_not_landed("render", "the rendering issue");
}
