/* test_cache_faults.c: the tile store's disk cache under faults (issue 15, point 5). A cache
 * file that is truncated, has a bit flipped (payload or header), is of another format
 * version, of another dataset or of another tile, or is replaced while the server runs, is
 * detected, ignored and rebuilt (the rebuilt structure is the fresh build's, and is written
 * back valid); a disk that refuses the writes (RLIMIT_FSIZE: writes fail as on a full disk)
 * leaves the built tiles served and no file behind; a write killed before its rename
 * leaves only a *.tmp, which is never read; a file with a valid checksum but contents a
 * tracer would index out of range with is refused too. */
#include <dirent.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

#include "hash.h"
#include "maxmip.h"
#include "maxmip_same.h"
#include "planes.h"
#include "terrain.h"
#include "tilestore.h"

#define TILE_LOG2 5 /* 32 cells: a 129 x 129 grid has 4 x 4 tiles */
#define TILE 5u

static char dir[256];

static td_grid *terrain(uint64_t seed)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err e;
    td_terrain_params_default(&p);
    p.width = 129;
    p.height = 129;
    p.spacing = 30.0;
    p.seed = seed;
    p.feature_m = 1500.0;
    p.relief_m = 600.0;
    assert_int_equal(td_terrain_generate(&p, TILE_LOG2, &g, &e), TD_OK);
    return g;
}

/* A store over the cache directory with dataset "t" (terrain of `seed`). */
static td_store *store_with(uint64_t seed, const char *id)
{
    td_store_opts o = {256u << 20, TILE_LOG2, 8, dir};
    td_store *s = NULL;
    td_err e;
    assert_int_equal(td_store_create(&o, &s, &e), TD_OK);
    assert_int_equal(td_store_add_grid(s, id, "api", terrain(seed), &e), TD_OK);
    return s;
}

/* Preloads tile TILE (both kinds) of dataset 0, rebuilding what is resident. */
static void preload_tile(td_store *s)
{
    size_t one[1] = {TILE}, built;
    td_preload_spec p;
    td_err e;
    memset(&p, 0, sizeof p);
    p.tiles = one;
    p.ntiles = 1;
    p.maxmip = p.planes = 1;
    p.rebuild = 1;
    assert_int_equal(td_store_preload(s, &p, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(built, 1);
}

/* The cache file of dataset `id`, tile TILE, kind ext ("mm" or "pl"): its path in out. */
static void cache_file(const char *id, const char *ext, char *out, size_t n)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    char tail[32];
    size_t idn = strlen(id);
    int found = 0;
    snprintf(tail, sizeof tail, "-%u.%s", TILE, ext);
    assert_non_null(d);
    while ((e = readdir(d)) != NULL) {
        size_t len = strlen(e->d_name), tl = strlen(tail);
        if (!strncmp(e->d_name, id, idn) && e->d_name[idn] == '-' && len > tl &&
            !strcmp(e->d_name + len - tl, tail)) {
            snprintf(out, n, "%s/%s", dir, e->d_name);
            found++;
        }
    }
    closedir(d);
    assert_int_equal(found, 1);
}

static unsigned char *slurp(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    unsigned char *b;
    long len;
    assert_non_null(f);
    fseek(f, 0, SEEK_END);
    len = ftell(f);
    rewind(f);
    b = malloc((size_t)len);
    assert_non_null(b);
    assert_int_equal(fread(b, 1, (size_t)len, f), (size_t)len);
    fclose(f);
    *n = (size_t)len;
    return b;
}

static void spit(const char *path, const void *b, size_t n)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(b, 1, n, f), n);
    assert_int_equal(fclose(f), 0);
}

/* The header's size: the file's u64 at H-16 is its size minus H (payload), then the
 * checksum at H-8. */
static size_t header_bytes(const unsigned char *b, size_t n)
{
    for (size_t k = 16; k <= n; k += 8) {
        uint64_t v;
        memcpy(&v, b + k - 16, 8);
        if (v == n - k)
            return k;
    }
    fail_msg("no header");
    return 0;
}

/* Sets the checksum as a writer would: FNV-1a of the whole file with the field 0. */
static void fix_checksum(unsigned char *b, size_t n)
{
    size_t h = header_bytes(b, n);
    uint64_t sum = 0;
    memcpy(b + h - 8, &sum, 8);
    sum = td_fnv1a(TD_FNV1A_INIT, b, n);
    memcpy(b + h - 8, &sum, 8);
}

/* Cache hits and builds of a store so far. */
static void counts(td_store *s, uint64_t *hits, uint64_t *built)
{
    td_store_stats st;
    td_store_stats_get(s, &st);
    *hits = st.cache_hits;
    *built = st.tiles_built;
}

/* Tile TILE of the store's dataset "t" equals a fresh build, both kinds. */
static void same_as_fresh(td_store *s)
{
    td_snapshot *snap = NULL;
    td_err e;
    const td_view *v;
    td_maxmip *m = NULL;
    td_planes *p = NULL;
    assert_int_equal(td_store_acquire(s, "t", &snap, &e), TD_OK);
    v = td_snapshot_view(snap);
    assert_non_null(v->accel[TILE].maxmip);
    assert_non_null(v->accel[TILE].planes);
    assert_int_equal(td_maxmip_build(v->grid, TILE, &m, &e), TD_OK);
    assert_int_equal(td_planes_build(v->grid, TILE, 8, &p, &e), TD_OK);
    same_maxmip(v->accel[TILE].maxmip, m);
    assert_memory_equal(v->accel[TILE].planes->cone, p->cone, sizeof(td_cone) * (size_t)p->bnx * (size_t)p->bny);
    assert_memory_equal(v->accel[TILE].planes->apex, p->apex, sizeof(float) * ((size_t)p->k + 1));
    td_maxmip_free(m);
    td_planes_free(p);
    td_snapshot_release(snap);
}

/* A fresh store reads tile TILE back from the cache: `hits` hits and `built` builds. */
static void reload_expect(uint64_t hits, uint64_t built)
{
    td_store *s = store_with(3, "t");
    uint64_t h, b;
    preload_tile(s);
    counts(s, &h, &b);
    assert_int_equal(h, hits);
    assert_int_equal(b, built);
    same_as_fresh(s);
    td_store_free(s);
}

static void clean_dir(void)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    char p[600];
    while (d && (e = readdir(d)) != NULL)
        if (e->d_name[0] != '.') {
            snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
            unlink(p);
        }
    if (d)
        closedir(d);
}

static int setup(void **state)
{
    (void)state;
    snprintf(dir, sizeof dir, "%s/terrad-cache-faults-%ld", P_tmpdir, (long)getpid());
    mkdir(dir, 0755);
    clean_dir();
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    clean_dir();
    rmdir(dir);
    return 0;
}

/* Writes the cache for tile TILE of "t" (seed 3): a fresh store, one preload. */
static void populate(void)
{
    td_store *s;
    clean_dir();
    s = store_with(3, "t");
    preload_tile(s);
    td_store_free(s);
    reload_expect(2, 0); /* both files are valid */
}

static void test_truncated(void **state)
{
    char p[600];
    unsigned char *b;
    size_t n;
    (void)state;
    populate();
    cache_file("t", "pl", p, sizeof p);
    b = slurp(p, &n);
    spit(p, b, n - 1); /* one byte short */
    reload_expect(1, 1);
    reload_expect(2, 0); /* rebuilt and written back valid */
    spit(p, b, 100);    /* inside the header */
    reload_expect(1, 1);
    free(b);
}

static void test_bit_flips(void **state)
{
    char p[600];
    unsigned char *b;
    size_t n, h;
    (void)state;
    populate();
    cache_file("t", "mm", p, sizeof p);
    b = slurp(p, &n);
    h = header_bytes(b, n);
    /* in the payload, in the header's shape fields (a level's dimension: not compared with
       anything but the checksum), and in the checksum itself */
    const size_t at[] = {n - 3, h / 2, h - 2};
    for (size_t k = 0; k < sizeof at / sizeof at[0]; k++) {
        b[at[k]] ^= 0x10;
        spit(p, b, n);
        reload_expect(1, 1);
        b[at[k]] ^= 0x10;
    }
    free(b);
}

static void test_other_version(void **state)
{
    char p[600];
    unsigned char *b;
    size_t n;
    uint32_t v;
    (void)state;
    populate();
    cache_file("t", "pl", p, sizeof p);
    b = slurp(p, &n);
    memcpy(&v, b + 8, 4); /* after the 8-byte magic */
    v -= 1;
    memcpy(b + 8, &v, 4);
    fix_checksum(b, n); /* a valid file of the previous version */
    spit(p, b, n);
    reload_expect(1, 1);
    free(b);
}

static void test_other_dataset_and_tile(void **state)
{
    char mine[600], theirs[600];
    unsigned char *b;
    size_t n;
    td_store *s;
    (void)state;
    populate();
    s = store_with(4, "u"); /* another terrain under another id, same cache */
    preload_tile(s);
    td_store_free(s);
    /* u's file for the same tile and kind, put where t's is read */
    cache_file("t", "pl", mine, sizeof mine);
    cache_file("u", "pl", theirs, sizeof theirs);
    b = slurp(theirs, &n);
    spit(mine, b, n);
    free(b);
    reload_expect(1, 1);
    /* t's own file of another tile (same shape: a whole tile) under tile TILE's name */
    {
        char other[600];
        snprintf(other, sizeof other, "%s", mine);
        other[strlen(other) - 4] = '6'; /* "-5.pl" -> "-6.pl" */
        assert_int_equal(access(other, F_OK), -1);
        s = store_with(3, "t");
        {
            size_t six[1] = {6}, built;
            td_preload_spec sp;
            td_err e;
            memset(&sp, 0, sizeof sp);
            sp.tiles = six;
            sp.ntiles = 1;
            sp.planes = 1;
            assert_int_equal(td_store_preload(s, &sp, NULL, NULL, &built, &e), TD_OK);
        }
        td_store_free(s);
        b = slurp(other, &n);
        spit(mine, b, n);
        free(b);
        reload_expect(1, 1);
    }
}

/* Files with a valid checksum whose content would make a tracer index out of range (a
 * buggy or hostile writer): a cone's apex index past the slices, a NaN apex height, a
 * max-mipmap level's dimension changed, its codes' base -inf. Refused after the checksum,
 * rebuilt. */
static void test_forged_checksum(void **state)
{
    char pl[600], mm[600];
    unsigned char *b;
    size_t n, h;
    const float nan = __builtin_nanf("");
    const double ninf = -__builtin_inf();
    int32_t dim;
    (void)state;
    populate();
    cache_file("t", "pl", pl, sizeof pl);
    cache_file("t", "mm", mm, sizeof mm);
    b = slurp(pl, &n);
    h = header_bytes(b, n);
    b[h] = 255; /* cone 0's apex index (k = 8) */
    fix_checksum(b, n);
    spit(pl, b, n);
    reload_expect(1, 1);
    free(b);
    b = slurp(pl, &n); /* rewritten valid by the rebuild */
    memcpy(b + n - sizeof nan, &nan, sizeof nan); /* the last apex height */
    fix_checksum(b, n);
    spit(pl, b, n);
    reload_expect(1, 1);
    free(b);
    b = slurp(mm, &n);
    memcpy(&dim, b + 60, 4); /* dim[1]: after magic, version, kind, fingerprint, tile_log2,
                                param, tile, nx, ny, levels, pad, dim[0] */
    dim -= 1;
    memcpy(b + 60, &dim, 4);
    fix_checksum(b, n);
    spit(mm, b, n);
    reload_expect(1, 1);
    free(b);
    b = slurp(mm, &n); /* rewritten valid by the rebuild */
    memcpy(b + 272, &ninf, sizeof ninf); /* code_base: after offset[17] and slope_scale */
    fix_checksum(b, n);
    spit(mm, b, n);
    reload_expect(1, 1); /* every block would decode to -inf: every ray would pass */
    free(b);
}

/* Replaced while serving: the store runs with its tiles resident; the files are replaced
 * (a corrupt one and a foreign one); the next preload (after an eviction) reads them,
 * refuses both and rebuilds; what is served is the fresh build. */
static void test_replaced_while_serving(void **state)
{
    char pl[600], mm[600];
    unsigned char *b;
    size_t n, ev;
    uint64_t h0, b0, h1, b1;
    td_store *s;
    (void)state;
    populate();
    s = store_with(3, "t");
    preload_tile(s);
    counts(s, &h0, &b0);
    assert_int_equal(h0, 2);
    cache_file("t", "pl", pl, sizeof pl);
    cache_file("t", "mm", mm, sizeof mm);
    b = slurp(mm, &n);
    b[n / 2] ^= 1;
    spit(mm, b, n);
    free(b);
    b = slurp(pl, &n);
    spit(pl, b, n / 2);
    free(b);
    td_store_evict_dataset(s, 0, &ev);
    assert_int_equal(ev, 1);
    preload_tile(s);
    counts(s, &h1, &b1);
    assert_int_equal(h1, h0);     /* no new hit */
    assert_int_equal(b1, b0 + 2); /* both rebuilt */
    same_as_fresh(s);
    td_store_free(s);
    reload_expect(2, 0);
}

/* A disk that refuses the writes: RLIMIT_FSIZE (writes past it fail with EFBIG, as on a
 * full disk; SIGXFSZ ignored). The preload succeeds, the tiles are served, and no file, not
 * even a temporary one, is left. */
static void test_disk_full(void **state)
{
    struct rlimit old, lim;
    td_store *s;
    DIR *d;
    struct dirent *e;
    int files = 0;
    uint64_t h, b;
    (void)state;
    clean_dir();
    signal(SIGXFSZ, SIG_IGN);
    assert_int_equal(getrlimit(RLIMIT_FSIZE, &old), 0);
    lim = old;
    lim.rlim_cur = 200; /* the header fits, the payload does not */
    assert_int_equal(setrlimit(RLIMIT_FSIZE, &lim), 0);
    s = store_with(3, "t");
    preload_tile(s);
    assert_int_equal(setrlimit(RLIMIT_FSIZE, &old), 0);
    counts(s, &h, &b);
    assert_int_equal(h, 0);
    assert_int_equal(b, 2);
    same_as_fresh(s);
    td_store_free(s);
    d = opendir(dir);
    while (d && (e = readdir(d)) != NULL)
        files += e->d_name[0] != '.';
    if (d)
        closedir(d);
    assert_int_equal(files, 0);
    reload_expect(0, 2); /* nothing cached: built again, and cached now */
    reload_expect(2, 0);
}

/* A writer killed before its rename leaves NAME.PID.tmp (here: half a file); the reader
 * never looks at it, and a torn file under the real name (as a writer without the rename
 * would leave) is refused. */
static void test_killed_writer(void **state)
{
    char pl[600], tmp[700];
    unsigned char *b;
    size_t n;
    (void)state;
    populate();
    cache_file("t", "pl", pl, sizeof pl);
    b = slurp(pl, &n);
    snprintf(tmp, sizeof tmp, "%s.99999.tmp", pl);
    spit(tmp, b, n / 2);
    unlink(pl);
    reload_expect(1, 1); /* the tmp was not read: the planes were built */
    spit(pl, b, n / 3);
    reload_expect(1, 1);
    unlink(tmp);
    free(b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_truncated),
        cmocka_unit_test(test_bit_flips),
        cmocka_unit_test(test_other_version),
        cmocka_unit_test(test_other_dataset_and_tile),
        cmocka_unit_test(test_forged_checksum),
        cmocka_unit_test(test_replaced_while_serving),
        cmocka_unit_test(test_disk_full),
        cmocka_unit_test(test_killed_writer),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
