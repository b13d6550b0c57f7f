/* cli_info.c: `terrad info`. */
#include "cli.h"

int td_cli_info(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return td_cli_not_landed("info", "the DEM loader issue");
}
