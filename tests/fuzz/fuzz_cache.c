/* fuzz_cache.c: the on-disk tile cache reader (server/tilestore.c: cache_read and each
 * kind's alloc), through the store's public API as the server uses it. Set-up: a store
 * with a cache directory and a 33 x 33 grid of 4 tiles, preloaded once, leaves one cache
 * file per tile and kind. Each input replaces one of them: the first byte's bits 0-2 pick
 * the file; bit 6 sets the header's payload size, and bit 7 its checksum (FNV-1a of the
 * header with the checksum taken as 0, then the payload), to match the bytes that follow (so the fuzzer also reaches what lies behind those checks, as a file
 * written with a valid checksum by a buggy or hostile writer would); the rest is the file.
 * Then a fresh store over the same grid preloads that tile (reading the file, or refusing
 * it and rebuilding), and rays are traced through the result with every method and
 * surface, so a structure accepted from the file is also used.
 *
 * The header's size is learnt from the files the set-up wrote (the u64 payload size 16
 * bytes before its end, the u64 checksum 8 before), so the target follows the format. */
#define _GNU_SOURCE /* memmem, memrchr */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "fuzz.h"
#include "hash.h"
#include "log.h"
#include "terrain.h"
#include "tilestore.h"

#define TILE_LOG2 4
#define FILES_MAX 8

static char cache_dir[600];
static char files[FILES_MAX][900];
static size_t tiles_of[FILES_MAX];
static int kind_of[FILES_MAX];
static int nfiles;
static size_t hdr_bytes;

static td_grid *grid(void)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err e;
    td_terrain_params_default(&p);
    p.width = 33;
    p.height = 33;
    p.spacing = 30.0;
    p.seed = 7;
    p.feature_m = 600.0;
    p.relief_m = 300.0;
    if (td_terrain_generate(&p, TILE_LOG2, &g, &e) != TD_OK)
        abort();
    return g;
}

static td_store *store(void)
{
    td_store_opts o = {64u << 20, TILE_LOG2, 8, cache_dir};
    td_store *s = NULL;
    td_err e;
    if (td_store_create(&o, &s, &e) != TD_OK || td_store_add_grid(s, "f", "api", grid(), &e) != TD_OK)
        abort();
    return s;
}

static uint64_t get64(const uint8_t *p)
{
    uint64_t v;
    memcpy(&v, p, 8);
    return v;
}

/* The header's size: the offset H at which the file's u64 at H-16 is its size minus H. */
static size_t learn_header(const char *path)
{
    FILE *f = fopen(path, "rb");
    uint8_t buf[4096];
    size_t n = f ? fread(buf, 1, sizeof buf, f) : 0, h = 0;
    struct stat st;
    if (f)
        fclose(f);
    if (stat(path, &st) != 0)
        abort();
    for (size_t k = 16; k <= n && !h; k += 8)
        if (get64(buf + k - 16) == (uint64_t)st.st_size - k)
            h = k;
    if (!h)
        abort();
    return h;
}

/* FUZZ_CACHE_SEEDS=DIR: the set-up's files as seed inputs (selector byte + file), named
 * seed-N, to refresh corpus/cache after a format change. */
static void write_seeds(const char *dir)
{
    for (int k = 0; k < nfiles; k++) {
        char p[1200];
        FILE *in = fopen(files[k], "rb"), *out;
        int c;
        snprintf(p, sizeof p, "%s/seed-%d", dir, k);
        out = fopen(p, "wb");
        if (!in || !out)
            abort();
        fputc(k, out);
        while ((c = fgetc(in)) != EOF)
            fputc(c, out);
        fclose(in);
        fclose(out);
    }
}

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    td_store *s;
    td_preload_spec all;
    size_t built;
    td_err e;
    DIR *d;
    struct dirent *ent;
    (void)argc;
    (void)argv;
    td_log_set_level(TD_LOG_ERROR); /* a rejected file is a warning per input */
    snprintf(cache_dir, sizeof cache_dir, "%s/cache", fuzz_dir());
    s = store();
    memset(&all, 0, sizeof all);
    all.maxmip = all.planes = 1;
    if (td_store_preload(s, &all, NULL, NULL, &built, &e) != TD_OK)
        abort();
    td_store_free(s);
    d = opendir(cache_dir);
    while (d && (ent = readdir(d)) != NULL && nfiles < FILES_MAX) {
        const char *t = strrchr(ent->d_name, 't'), *dot = strrchr(ent->d_name, '.');
        const char *dash = dot ? memrchr(ent->d_name, '-', (size_t)(dot - ent->d_name)) : NULL;
        if (!dot || !dash || !t || ent->d_name[0] == '.')
            continue;
        snprintf(files[nfiles], sizeof files[nfiles], "%s/%s", cache_dir, ent->d_name);
        tiles_of[nfiles] = strtoul(dash + 1, NULL, 10);
        kind_of[nfiles] = !strcmp(dot, ".pl") ? TD_PART_PLANES : TD_PART_MAXMIP;
        nfiles++;
    }
    if (d)
        closedir(d);
    if (nfiles != FILES_MAX)
        abort();
    hdr_bytes = learn_header(files[0]);
    if (getenv("FUZZ_CACHE_SEEDS"))
        write_seeds(getenv("FUZZ_CACHE_SEEDS"));
    return 0;
}

/* A few rays from above the grid, down at several angles and headings, through every
 * method and surface. */
static void trace_all(td_store *s)
{
    td_snapshot *snap = NULL;
    td_err e;
    if (td_store_acquire(s, "f", &snap, &e) != TD_OK)
        abort();
    for (int k = 0; k < 8; k++) {
        td_ray r = {{-20.0 + 3.0 * k, 15.0 * k, 600.0}, {40.0, 25.0 - 5.0 * k, -9.0 - k}, 0.0, 1e30};
        for (int m = 0; m < TD_METHOD_COUNT; m++)
            for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                td_hit hit;
                td_trace(td_snapshot_view(snap), (td_method)m, (td_surface)sf, &r, &hit);
            }
    }
    td_snapshot_release(snap);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    uint8_t *buf;
    size_t n, which;
    td_store *s;
    td_preload_spec one;
    size_t built;
    td_err e;
    FILE *f;

    if (size < 1)
        return 0;
    which = data[0] & 7u;
    n = size - 1;
    buf = malloc(n ? n : 1);
    if (!buf)
        abort();
    memcpy(buf, data + 1, n);
    if (n >= hdr_bytes && (data[0] & 0x40)) {
        uint64_t payload = n - hdr_bytes;
        memcpy(buf + hdr_bytes - 16, &payload, 8);
    }
    if (n >= hdr_bytes && (data[0] & 0x80)) { /* as cache_checksum: header (checksum 0), payload */
        uint64_t sum = 0;
        memcpy(buf + hdr_bytes - 8, &sum, 8);
        sum = td_fnv1a(TD_FNV1A_INIT, buf, n);
        memcpy(buf + hdr_bytes - 8, &sum, 8);
    }
    f = fopen(files[which], "wb");
    if (!f || (n && fwrite(buf, 1, n, f) != n) || fclose(f))
        abort();
    free(buf);

    s = store();
    memset(&one, 0, sizeof one);
    one.tiles = &tiles_of[which];
    one.ntiles = 1;
    one.build[kind_of[which]] = 1;
    if (td_store_preload(s, &one, NULL, NULL, &built, &e) == TD_OK) {
        td_store_stats st;
        td_store_stats_get(s, &st);
        fuzz_report(st.cache_hits ? "cache (file used)" : "cache (file refused, rebuilt)", 0, "");
        trace_all(s);
    }
    td_store_free(s);
    return 0;
}
