/* replay.c: a plain main() for the fuzz targets, so that their corpora run as regression
 * tests with any compiler (ctest label `fuzz`; under ASan + UBSan in `make test`'s
 * sanitizer build). Arguments are files or directories (every regular file in them, in
 * name order); each is given once to LLVMFuzzerTestOneInput. A finding aborts (sanitizer
 * report or assertion), as it would under libFuzzer. */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fuzz.h"

int LLVMFuzzerInitialize(int *argc, char ***argv) __attribute__((weak));

static int run_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    uint8_t *buf = NULL;
    long n = -1;
    int ok = 0;
    if (f && fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
        buf = malloc((size_t)n + 1);
        ok = buf && fread(buf, 1, (size_t)n, f) == (size_t)n;
    }
    if (f)
        fclose(f);
    if (ok)
        LLVMFuzzerTestOneInput(buf, (size_t)n);
    else
        fprintf(stderr, "replay: cannot read %s\n", path);
    free(buf);
    return ok;
}

static int by_name(const struct dirent **a, const struct dirent **b)
{
    return strcmp((*a)->d_name, (*b)->d_name);
}

int main(int argc, char **argv)
{
    long done = 0, failed = 0;
    if (LLVMFuzzerInitialize)
        LLVMFuzzerInitialize(&argc, &argv);
    for (int i = 1; i < argc; i++) {
        struct stat st;
        if (stat(argv[i], &st) == 0 && S_ISDIR(st.st_mode)) {
            struct dirent **names = NULL;
            int n = scandir(argv[i], &names, NULL, by_name);
            for (int k = 0; k < n; k++) {
                char p[4096];
                snprintf(p, sizeof p, "%s/%s", argv[i], names[k]->d_name);
                if (stat(p, &st) == 0 && S_ISREG(st.st_mode)) {
                    if (run_file(p))
                        done++;
                    else
                        failed++;
                }
                free(names[k]);
            }
            free(names);
            if (n < 0)
                failed++;
        } else if (run_file(argv[i])) {
            done++;
        } else {
            failed++;
        }
    }
    printf("replayed %ld inputs, %ld unreadable\n", done, failed);
    return failed || done == 0 ? 1 : 0;
}
