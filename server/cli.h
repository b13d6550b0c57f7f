/* cli.h: the subcommands of the `terrad` binary. Each lives in its own cli_NAME.c and
 * returns the process exit status: 0 success, 1 runtime failure, 2 usage error or a
 * subcommand that has not landed yet. */
#ifndef TD_CLI_H
#define TD_CLI_H

int td_cli_serve(int argc, char **argv);
int td_cli_render(int argc, char **argv);
int td_cli_trace(int argc, char **argv);
int td_cli_info(int argc, char **argv);
int td_cli_bench(int argc, char **argv);

/* For a subcommand whose issue has not landed: says so on stderr, returns 2. */
int td_cli_not_landed(const char *name, const char *issue);

#endif
