/* fuzz.h: what the fuzz targets of tests/fuzz share. Each target is one file defining
 * LLVMFuzzerTestOneInput (and, when it needs a set-up, LLVMFuzzerInitialize); it is linked
 * either with libFuzzer (clang -fsanitize=fuzzer, `make fuzz`) or with replay.c, a plain
 * main() that runs every file of the given corpus directories once (ctest label `fuzz`,
 * the regression replay of `make test`, with any compiler).
 *
 * The loaders take file names, so a target writes its input to files in a private
 * directory (under /dev/shm when there is one: no disk traffic) made on first use and
 * removed at exit. */
#ifndef TD_FUZZ_H
#define TD_FUZZ_H

#include <stddef.h>
#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The target's private directory (made on first call). */
const char *fuzz_dir(void);

/* Writes n bytes to `name` in fuzz_dir(); its path into out. Aborts if it cannot (a
 * harness failure, not a finding). */
void fuzz_write(const char *name, const void *data, size_t n, char *out, size_t outsz);

/* Removes `name` from fuzz_dir() (no error if absent). */
void fuzz_remove(const char *name);

/* With FUZZ_VERBOSE set in the environment, prints what a loader or parser answered (to
 * check that the seeds reach what they should); silent otherwise. */
void fuzz_report(const char *what, int status, const char *msg);

/* Splits text (modified in place) at '&' into at most max key=value pairs, as the HTTP
 * layer hands a query string over (decoded): keys[i], values[i]; a pair without '=' gets
 * `missing` as its value. Returns the number of pairs. */
size_t fuzz_split_query(char *text, char **keys, char **values, size_t max, char *missing);

/* The byte budget the loader targets give the loaders: small enough that libFuzzer's
 * 2 GB RSS limit is never the finding, large enough for the seeds. */
#define FUZZ_BUDGET_BYTES ((uint64_t)256 << 20)

#endif
