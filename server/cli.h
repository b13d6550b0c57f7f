/* cli.h: the subcommands of the `terrad` binary. Each lives in its own cli_NAME.c and
 * returns the process exit status: 0 success, 1 runtime failure, 2 usage error. */
#ifndef TD_CLI_H
#define TD_CLI_H

#include <stddef.h>

int td_cli_serve(int argc, char **argv);
int td_cli_render(int argc, char **argv);
int td_cli_trace(int argc, char **argv);
int td_cli_info(int argc, char **argv);
int td_cli_viewshed(int argc, char **argv);
int td_cli_prepare(int argc, char **argv);
/* Runs terrad-bench, the benchmark's own program (tests/bench), from terrad's folder. */
int td_cli_bench(int argc, char **argv);

/* A whole decimal integer in [lo, hi] (no sign games, no trailing text): 1 and *out, or 0. */
int td_cli_parse_int(const char *s, long lo, long hi, int *out);

/* Writes len bytes to path ("-": stdout): 1 on success, 0 on any failure. */
int td_cli_write_file(const char *path, const void *data, size_t len);

/* The path of the program `name` in the folder of the running executable (terrad and
 * terrad-bench are built side by side): 1 and out, or 0 (no /proc/self/exe, too long). */
int td_cli_sibling(const char *name, char *out, size_t cap);

#endif
