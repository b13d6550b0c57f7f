/* fuzz_util.c: the private directory and file writing of fuzz.h. */
#include "fuzz.h"

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char fuzz_dirname[256];

static void fuzz_cleanup(void)
{
    DIR *d = opendir(fuzz_dirname);
    struct dirent *e;
    char p[600];
    while (d && (e = readdir(d)) != NULL) {
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            snprintf(p, sizeof p, "%s/%s", fuzz_dirname, e->d_name);
            if (unlink(p) != 0) {
                /* a directory made by a target (the cache's): one level down */
                DIR *sub = opendir(p);
                struct dirent *f;
                char q[900];
                while (sub && (f = readdir(sub)) != NULL) {
                    snprintf(q, sizeof q, "%s/%s", p, f->d_name);
                    unlink(q);
                }
                if (sub)
                    closedir(sub);
                rmdir(p);
            }
        }
    }
    if (d)
        closedir(d);
    rmdir(fuzz_dirname);
}

const char *fuzz_dir(void)
{
    if (!fuzz_dirname[0]) {
        struct stat st;
        const char *base = stat("/dev/shm", &st) == 0 && access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
        snprintf(fuzz_dirname, sizeof fuzz_dirname, "%s/terrad-fuzz-XXXXXX", base);
        if (!mkdtemp(fuzz_dirname)) {
            perror("fuzz: mkdtemp");
            abort();
        }
        atexit(fuzz_cleanup);
    }
    return fuzz_dirname;
}

void fuzz_write(const char *name, const void *data, size_t n, char *out, size_t outsz)
{
    FILE *f;
    snprintf(out, outsz, "%s/%s", fuzz_dir(), name);
    f = fopen(out, "wb");
    if (!f || (n && fwrite(data, 1, n, f) != n) || fclose(f)) {
        perror("fuzz: write");
        abort();
    }
}

void fuzz_remove(const char *name)
{
    char p[600];
    snprintf(p, sizeof p, "%s/%s", fuzz_dir(), name);
    unlink(p);
}

void fuzz_report(const char *what, int status, const char *msg)
{
    static int verbose = -1;
    if (verbose < 0)
        verbose = getenv("FUZZ_VERBOSE") != NULL;
    if (verbose)
        fprintf(stderr, "%s: status %d%s%s\n", what, status, status ? ": " : "", status ? msg : "");
}

size_t fuzz_split_query(char *text, char **keys, char **values, size_t max, char *missing)
{
    size_t n = 0;
    for (char *s = text, *next; s && n < max; s = next) {
        char *eq;
        next = strchr(s, '&');
        if (next)
            *next++ = '\0';
        eq = strchr(s, '=');
        if (eq)
            *eq++ = '\0';
        keys[n] = s;
        values[n++] = eq ? eq : missing;
    }
    return n;
}
