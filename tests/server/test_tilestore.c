/* test_tilestore.c: the tile store on its own (no HTTP): dataset ids and directory
 * scanning (nothing outside the directory), the memory budget with LRU and pinning,
 * the dataset counters kept as tiles change (against a count over a snapshot), failed
 * preloads leaving resident tiles alone, the disk cache (hit, and rejection of a
 * corrupted file), drapes decoded once and kept within the budget, and the concurrency
 * contract: renders tracing through snapshots (and sharing a drape) while another
 * thread rebuilds and evicts tiles see every hit exactly as the incremental tracer
 * does; heights edits (versions, old snapshots intact, the touched tiles' parts out and
 * rebuilt from the new heights, an edit racing a preload, the disk cache keyed by edited
 * heights, a restart forgetting edits) and renders during a stream of edits, each seeing
 * exactly the heights of its version. Built twice: plainly (and under ASan by `make test`), and with
 * ThreadSanitizer (test_tilestore_tsan). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "image.h"
#include "maxmip.h"
#include "maxmip_same.h"
#include "planes.h"
#include "reference.h"
#include "terrain.h"
#include "tilestore.h"

#define TILE_LOG2 5 /* 32 cells: a 257 x 257 grid has 8 x 8 tiles */

static td_grid *terrain(uint64_t seed)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err e;
    td_terrain_params_default(&p);
    p.width = 257;
    p.height = 257;
    p.spacing = 30.0;
    p.seed = seed;
    p.feature_m = 3000.0;
    p.relief_m = 800.0;
    assert_int_equal(td_terrain_generate(&p, TILE_LOG2, &g, &e), TD_OK);
    return g;
}

static td_store *store_new(uint64_t budget, const char *cache)
{
    td_store_opts o = {budget, TILE_LOG2, 8, cache};
    td_store *s = NULL;
    td_err e;
    assert_int_equal(td_store_create(&o, &s, &e), TD_OK);
    return s;
}

/* Bytes one tile's maxmip + planes take (built here, for the budgets below). */
static uint64_t tile_bytes(const td_grid *g)
{
    td_maxmip *m = NULL;
    td_planes *p = NULL;
    td_err e;
    uint64_t b;
    assert_int_equal(td_maxmip_build(g, 0, &m, &e), TD_OK);
    assert_int_equal(td_planes_build(g, 0, 8, &p, &e), TD_OK);
    b = m->bytes + p->bytes;
    td_maxmip_free(m);
    td_planes_free(p);
    return b;
}

/* A preload of dataset 0: tiles (NULL: all of them), what to build, pin, rebuild. */
static td_preload_spec spec(const size_t *tiles, size_t n, int maxmip, int planes, int pin,
                            int rebuild)
{
    td_preload_spec p;
    memset(&p, 0, sizeof p);
    p.tiles = tiles;
    p.ntiles = n;
    p.maxmip = maxmip;
    p.planes = planes;
    p.pin = pin;
    p.rebuild = rebuild;
    return p;
}

/* The dataset's counters (kept as tiles change) against a count over a snapshot. */
static void check_counters(td_store *s, size_t idx)
{
    td_dataset_info di;
    td_snapshot *snap = NULL;
    td_err e;
    const td_view *v;
    size_t resident = 0, mm = 0, pl = 0;
    uint64_t bytes = 0;
    td_store_info(s, idx, &di);
    assert_int_equal(td_store_acquire(s, di.id, &snap, &e), TD_OK);
    v = td_snapshot_view(snap);
    for (size_t t = 0; t < di.ntiles; t++) {
        const td_tile_accel *a = &v->accel[t];
        resident += a->maxmip || a->planes;
        mm += a->maxmip != NULL;
        pl += a->planes != NULL;
        bytes += (a->maxmip ? a->maxmip->bytes : 0) + (a->planes ? a->planes->bytes : 0);
    }
    assert_int_equal(di.resident_tiles, resident);
    assert_int_equal(di.maxmip_tiles, mm);
    assert_int_equal(di.planes_tiles, pl);
    assert_int_equal(di.part_tiles[TD_PART_MAXMIP], mm);
    assert_int_equal(di.part_tiles[TD_PART_PLANES], pl);
    assert_int_equal(td_snapshot_count(snap, TD_PART_MAXMIP), mm);
    assert_int_equal(td_snapshot_count(snap, TD_PART_PLANES), pl);
    assert_int_equal(di.accel_bytes, bytes);
    assert_true(di.pinned_tiles <= resident);
    td_snapshot_release(snap);
}

static void test_ids(void **state)
{
    (void)state;
    assert_true(td_store_id_valid("levi"));
    assert_true(td_store_id_valid("N37W105.v2_a-b"));
    assert_false(td_store_id_valid(""));
    assert_false(td_store_id_valid(".hidden"));
    assert_false(td_store_id_valid(".."));
    assert_false(td_store_id_valid("a/b"));
    assert_false(td_store_id_valid("a b"));
    assert_false(td_store_id_valid("x%2f"));
    assert_false(td_store_id_valid("0123456789012345678901234567890123456789012345678901234567890123456789"));
}

static void copy_file(const char *from, const char *to)
{
    FILE *a = fopen(from, "rb"), *b = fopen(to, "wb");
    char buf[65536];
    size_t n;
    assert_non_null(a);
    assert_non_null(b);
    while ((n = fread(buf, 1, sizeof buf, a)) > 0)
        assert_int_equal(fwrite(buf, 1, n, b), n);
    fclose(a);
    fclose(b);
}

static void test_add_dir(void **state)
{
    char dir[256], p[512], q[512];
    td_store *s = store_new(64u << 20, NULL);
    td_dataset_info di;
    td_err e;
    int n = 0;
    (void)state;
    snprintf(dir, sizeof dir, "%s/terrad-store-%ld", P_tmpdir, (long)getpid());
    snprintf(p, sizeof p, "rm -rf %s", dir);
    assert_int_equal(system(p), 0);
    assert_int_equal(mkdir(dir, 0755), 0);
    snprintf(p, sizeof p, "%s/data", dir);
    assert_int_equal(mkdir(p, 0755), 0);
    /* a file: id volcano */
    snprintf(p, sizeof p, "%s/data/volcano.asc", dir);
    copy_file(TERRAD_TEST_DATA "/volcano.asc", p);
    /* a folder with one DEM: id picos */
    snprintf(p, sizeof p, "%s/data/picos", dir);
    assert_int_equal(mkdir(p, 0755), 0);
    snprintf(p, sizeof p, "%s/data/picos/dtm.asc", dir);
    copy_file(TERRAD_TEST_DATA "/picos-dtm.asc", p);
    /* a link to a DEM outside the directory: skipped */
    snprintf(p, sizeof p, "%s/outside.asc", dir);
    copy_file(TERRAD_TEST_DATA "/volcano.asc", p);
    snprintf(q, sizeof q, "%s/data/escape.asc", dir);
    assert_int_equal(symlink(p, q), 0);
    /* not a DEM, a hidden file, a bad id: skipped */
    snprintf(p, sizeof p, "%s/data/notes.txt", dir);
    copy_file(TERRAD_TEST_DATA "/volcano.asc", p);
    snprintf(p, sizeof p, "%s/data/.hidden.asc", dir);
    copy_file(TERRAD_TEST_DATA "/volcano.asc", p);
    snprintf(p, sizeof p, "%s/data/bad name.asc", dir);
    copy_file(TERRAD_TEST_DATA "/volcano.asc", p);

    snprintf(p, sizeof p, "%s/data", dir);
    assert_int_equal(td_store_add_dir(s, p, "data", &n, &e), TD_OK);
    assert_int_equal(n, 2);
    assert_int_equal(td_store_count(s), 2);
    assert_true(td_store_find(s, "picos") >= 0);
    assert_true(td_store_find(s, "volcano") >= 0);
    assert_int_equal(td_store_find(s, "escape"), -1);
    assert_int_equal(td_store_find(s, "outside"), -1);
    td_store_info(s, (size_t)td_store_find(s, "picos"), &di);
    assert_int_equal(di.grid->w, 714);
    assert_int_equal(di.grid->h, 482);
    assert_string_equal(di.file, "dtm.asc");
    assert_string_equal(di.origin, "data");
    /* the same directory again: ids are taken, nothing is added */
    assert_int_equal(td_store_add_dir(s, p, "data", &n, &e), TD_OK);
    assert_int_equal(n, 0);
    snprintf(p, sizeof p, "%s/none", dir);
    assert_int_equal(td_store_add_dir(s, p, "data", &n, &e), TD_ENOTFOUND);
    td_store_free(s);
    snprintf(p, sizeof p, "rm -rf %s", dir);
    assert_int_equal(system(p), 0);
}

/* What a dataset costs from load: its heights and its levels of detail (tilestore.c
 * builds them with max-mipmaps only, like this). */
static uint64_t dataset_bytes(const td_grid *g)
{
    td_lod *lod = NULL;
    td_accel_opts ao;
    uint64_t bytes;
    td_accel_opts_default(&ao);
    ao.planes = 0;
    ao.threads = 1;
    assert_int_equal(td_lod_build(g, TD_LOD_MAX, &ao, &lod, NULL), TD_OK);
    bytes = td_grid_bytes(g->w, g->h, g->tile_log2) + lod->bytes;
    td_lod_free(lod);
    return bytes;
}

static void test_budget_lru_pin(void **state)
{
    td_grid *g = terrain(7);
    uint64_t gb = dataset_bytes(g), tb = tile_bytes(g);
    /* Heights + room for 10 tiles (with the up-front bound's slack). */
    uint64_t budget = gb + 10 * tb + tb / 2;
    td_store *s = store_new(budget, NULL);
    td_store_stats st;
    td_dataset_info di;
    td_err e;
    size_t built, first[6] = {0, 1, 2, 3, 4, 5}, second[6] = {10, 11, 12, 13, 14, 15}, pinned[2] = {20, 21};
    td_preload_spec all = spec(NULL, 0, 1, 1, 0, 0);
    td_preload_spec a = spec(first, 6, 1, 1, 0, 0), b = spec(second, 6, 1, 1, 0, 0);
    td_preload_spec pin = spec(pinned, 2, 1, 1, 1, 0);
    (void)state;
    assert_int_equal(td_store_add_grid(s, "t", "api", g, &e), TD_OK);
    /* 64 tiles cannot fit: refused up front, nothing built. */
    assert_int_equal(td_store_preload(s, &all, NULL, NULL, &built, &e), TD_ETOOBIG);
    assert_non_null(strstr(e.msg, "budget"));
    td_store_stats_get(s, &st);
    assert_int_equal(st.resident_tiles, 0);
    assert_int_equal(st.tiles_built, 0);

    assert_int_equal(td_store_preload(s, &pin, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(td_store_preload(s, &a, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(built, 6);
    td_store_stats_get(s, &st);
    assert_int_equal(st.resident_tiles, 8);
    assert_true(st.resident_bytes <= budget);
    /* Six more: LRU evicts four of the first six, never the pinned pair. */
    assert_int_equal(td_store_preload(s, &b, NULL, NULL, &built, &e), TD_OK);
    td_store_stats_get(s, &st);
    assert_true(st.resident_bytes <= budget);
    assert_true(st.resident_tiles <= 10);
    assert_true(st.tiles_evicted >= 4);
    td_store_info(s, 0, &di);
    assert_int_equal(di.pinned_tiles, 2);
    check_counters(s, 0);
    {
        td_snapshot *snap = NULL;
        const td_view *v;
        assert_int_equal(td_store_acquire(s, "t", &snap, &e), TD_OK);
        v = td_snapshot_view(snap);
        for (int k = 0; k < 6; k++)
            assert_non_null(v->accel[second[k]].planes); /* the newest stay */
        assert_non_null(v->accel[20].maxmip);
        assert_non_null(v->accel[21].planes);
        assert_null(v->accel[0].maxmip); /* the oldest went first */
        td_snapshot_release(snap);
    }
    /* A bad tile index is refused before anything changes. */
    {
        size_t bad[2] = {30, 64};
        td_preload_spec x = spec(bad, 2, 1, 1, 0, 0);
        td_store_stats_get(s, &st);
        assert_int_equal(td_store_preload(s, &x, NULL, NULL, &built, &e), TD_EINVAL);
        assert_non_null(strstr(e.msg, "tiles[1]"));
    }
    /* Eviction by the admin drops pinned tiles too. */
    td_store_evict_dataset(s, 0, &built);
    assert_true(built >= 8);
    td_store_stats_get(s, &st);
    assert_int_equal(st.resident_tiles, 0);
    assert_int_equal(st.resident_bytes, gb);
    check_counters(s, 0);
    td_store_info(s, 0, &di);
    assert_int_equal(di.pinned_tiles, 0);
    assert_int_equal(td_store_acquire(s, "nope", &(td_snapshot *){NULL}, &e), TD_ENOTFOUND);
    td_store_free(s);
}

static void test_disk_cache(void **state)
{
    char dir[256], cmd[600], path[600];
    td_grid *g1 = terrain(3), *g2 = terrain(3), *g3 = terrain(3);
    td_store *s;
    td_store_stats st;
    td_err e;
    size_t built, one[1] = {9};
    td_preload_spec all = spec(NULL, 0, 1, 1, 0, 0), p9 = spec(one, 1, 1, 1, 0, 1);
    td_snapshot *b = NULL;
    (void)state;
    snprintf(dir, sizeof dir, "%s/terrad-cache-%ld", P_tmpdir, (long)getpid());
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    assert_int_equal(system(cmd), 0);

    s = store_new(256u << 20, dir);
    assert_int_equal(td_store_add_grid(s, "t", "api", g1, &e), TD_OK);
    assert_int_equal(td_store_preload(s, &all, NULL, NULL, &built, &e), TD_OK);
    td_store_stats_get(s, &st);
    assert_int_equal(st.tiles_built, 128); /* 64 maxmip + 64 planes */
    assert_int_equal(st.cache_hits, 0);
    td_store_free(s);

    /* A restart reads everything back. */
    s = store_new(256u << 20, dir);
    assert_int_equal(td_store_add_grid(s, "t", "api", g2, &e), TD_OK);
    assert_int_equal(td_store_preload(s, &all, NULL, NULL, &built, &e), TD_OK);
    td_store_stats_get(s, &st);
    assert_int_equal(st.tiles_built, 0);
    assert_int_equal(st.cache_hits, 128);
    /* Identical to a fresh build. */
    assert_int_equal(td_store_acquire(s, "t", &b, &e), TD_OK);
    {
        const td_view *v = td_snapshot_view(b);
        td_maxmip *m = NULL;
        td_planes *p = NULL;
        assert_int_equal(td_maxmip_build(v->grid, 9, &m, &e), TD_OK);
        assert_int_equal(td_planes_build(v->grid, 9, 8, &p, &e), TD_OK);
        same_maxmip(v->accel[9].maxmip, m);
        assert_memory_equal(v->accel[9].planes->cone, p->cone, sizeof(td_cone) * (size_t)p->bnx * (size_t)p->bny);
        assert_memory_equal(v->accel[9].planes->apex, p->apex, sizeof(float) * ((size_t)p->k + 1));
        assert_true(v->accel[9].planes->slope_scale == p->slope_scale);
        assert_int_equal(v->accel[9].planes->bytes, p->bytes);
        td_maxmip_free(m);
        td_planes_free(p);
    }
    td_snapshot_release(b);
    td_store_free(s);

    /* A flipped payload byte fails the checksum: rejected and rebuilt. */
    snprintf(cmd, sizeof cmd, "ls %s/*-t5-9.pl", dir);
    {
        FILE *ls = popen(cmd, "r"), *f;
        long size;
        assert_non_null(ls);
        assert_non_null(fgets(path, sizeof path, ls));
        pclose(ls);
        path[strcspn(path, "\n")] = '\0';
        f = fopen(path, "r+b");
        assert_non_null(f);
        fseek(f, 0, SEEK_END);
        size = ftell(f);
        fseek(f, size - 5, SEEK_SET);
        {
            int c = fgetc(f);
            fseek(f, size - 5, SEEK_SET);
            fputc(c ^ 0xff, f);
        }
        fclose(f);
    }
    s = store_new(256u << 20, dir);
    assert_int_equal(td_store_add_grid(s, "t", "api", g3, &e), TD_OK);
    assert_int_equal(td_store_preload(s, &p9, NULL, NULL, &built, &e), TD_OK);
    td_store_stats_get(s, &st);
    assert_int_equal(st.cache_hits, 1);   /* the maxmip */
    assert_int_equal(st.tiles_built, 1);  /* the planes, rebuilt */
    td_store_free(s);
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    assert_int_equal(system(cmd), 0);
}

static int cancel_after_3(void *cls, const char *phase, size_t done, size_t total)
{
    int *calls = cls;
    (void)phase;
    (void)done;
    (void)total;
    return ++*calls > 3;
}

static void test_failed_preload_publishes_nothing(void **state)
{
    /* A preload that stops half-way (here: cancelled after a few tiles) publishes none
     * of what it built, and what was resident stays, the very same structures. */
    td_grid *g = terrain(5);
    td_store *s = store_new(256u << 20, NULL);
    td_err e;
    size_t built, four[4] = {0, 1, 2, 3}, eight[8] = {0, 1, 2, 3, 4, 5, 6, 7};
    td_preload_spec first = spec(four, 4, 1, 0, 0, 0);   /* maxmip of tiles 0..3 */
    td_preload_spec second = spec(eight, 8, 1, 1, 0, 1); /* rebuild both on 0..7 */
    td_snapshot *a = NULL, *b = NULL;
    int calls = 0;
    td_store_stats st;
    (void)state;
    assert_int_equal(td_store_add_grid(s, "t", "api", g, &e), TD_OK);
    assert_int_equal(td_store_preload(s, &first, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(td_store_acquire(s, "t", &a, &e), TD_OK);
    assert_int_equal(td_store_preload(s, &second, cancel_after_3, &calls, &built, &e), TD_ECANCELED);
    assert_int_equal(built, 0);
    assert_true(calls > 3);
    assert_int_equal(td_store_acquire(s, "t", &b, &e), TD_OK);
    for (size_t t = 0; t < 64; t++) {
        assert_ptr_equal(td_snapshot_view(a)->accel[t].maxmip, td_snapshot_view(b)->accel[t].maxmip);
        assert_null(td_snapshot_view(b)->accel[t].planes);
    }
    assert_int_equal(td_snapshot_count(b, TD_PART_MAXMIP), 4);
    td_store_stats_get(s, &st);
    assert_int_equal(st.resident_tiles, 4);
    assert_int_equal(st.resident_bytes, dataset_bytes(td_snapshot_view(b)->grid) +
                                            (uint64_t)(4 * td_snapshot_view(b)->accel[0].maxmip->bytes));
    td_snapshot_release(a);
    td_snapshot_release(b);
    td_store_free(s);
}

/* Writes a w x h PNG whose pixel (x, y) is (x * 20, y * 30, 7) to path. */
static void write_png(const char *path, int32_t w, int32_t h)
{
    uint8_t *rgba = malloc((size_t)w * (size_t)h * 4);
    td_buf b = {0};
    td_err e;
    FILE *f;
    assert_non_null(rgba);
    for (int32_t y = 0; y < h; y++)
        for (int32_t x = 0; x < w; x++) {
            uint8_t *px = rgba + ((size_t)y * (size_t)w + (size_t)x) * 4;
            px[0] = (uint8_t)(x * 20);
            px[1] = (uint8_t)(y * 30);
            px[2] = 7;
            px[3] = 255;
        }
    assert_int_equal(td_image_encode_rgba(rgba, w, h, &b, &e), TD_OK);
    f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(b.data, 1, b.len, f), b.len);
    fclose(f);
    td_buf_free(&b);
    free(rgba);
}

static void test_drape(void **state)
{
    /* A drape is decoded on first use and kept with its dataset, counted in the budget;
     * over the budget a snapshot keeps its own copy; a missing file is an error. */
    td_grid *g = terrain(13), *g2 = terrain(13);
    uint64_t gb = dataset_bytes(g);
    td_store *s = store_new(gb + (1u << 20), NULL), *tight = store_new(gb + 100, NULL);
    td_snapshot *a = NULL, *b = NULL, *c = NULL;
    const td_image8 *ia = NULL, *ib = NULL, *ic = NULL;
    td_dataset_info di;
    td_store_stats st;
    td_err e;
    char path[256];
    (void)state;
    snprintf(path, sizeof path, "%s/terrad-drape-%ld.png", P_tmpdir, (long)getpid());
    write_png(path, 8, 6);
    assert_int_equal(td_store_add_grid(s, "t", "api", g, &e), TD_OK);
    assert_int_equal(td_store_add_grid(tight, "t", "api", g2, &e), TD_OK);
    assert_int_equal(td_store_acquire(s, "t", &a, &e), TD_OK);
    assert_string_equal(td_snapshot_dir(a), "");
    assert_int_equal(td_snapshot_drape(a, path, &ia, &e), TD_OK);
    assert_int_equal(ia->width, 8);
    assert_int_equal(ia->height, 6);
    assert_int_equal(ia->channels, 3);
    assert_int_equal(ia->px[(5 * 8 + 3) * 3 + 0], 60);
    assert_int_equal(ia->px[(5 * 8 + 3) * 3 + 1], 150);
    assert_int_equal(ia->px[(5 * 8 + 3) * 3 + 2], 7);
    td_store_info(s, 0, &di);
    assert_true(di.drape_bytes >= 8 * 6 * 3);
    td_store_stats_get(s, &st);
    assert_int_equal(st.resident_bytes, gb + di.drape_bytes);
    /* decoded once: the next render shares it, also after the first released it */
    td_snapshot_release(a);
    assert_int_equal(td_store_acquire(s, "t", &b, &e), TD_OK);
    assert_int_equal(td_snapshot_drape(b, path, &ib, &e), TD_OK);
    assert_ptr_equal(ib, ia);
    assert_int_equal(td_snapshot_drape(b, "/nonexistent/drape.png", &ic, &e), TD_EFORMAT);
    assert_null(ic);
    assert_non_null(strstr(e.msg, "/nonexistent/drape.png"));
    td_snapshot_release(b);

    /* no room: each snapshot decodes its own, nothing is kept */
    assert_int_equal(td_store_acquire(tight, "t", &a, &e), TD_OK);
    assert_int_equal(td_store_acquire(tight, "t", &c, &e), TD_OK);
    assert_int_equal(td_snapshot_drape(a, path, &ia, &e), TD_OK);
    assert_int_equal(td_snapshot_drape(c, path, &ic, &e), TD_OK);
    assert_ptr_not_equal(ia, ic);
    assert_memory_equal(ia->px, ic->px, 8 * 6 * 3);
    td_store_info(tight, 0, &di);
    assert_int_equal(di.drape_bytes, 0);
    td_store_stats_get(tight, &st);
    assert_int_equal(st.resident_bytes, gb);
    td_snapshot_release(a);
    td_snapshot_release(c);
    td_store_free(s);
    td_store_free(tight);
    unlink(path);
}

/* --- sun bounds (td_snapshot_sunlit) --------------------------------------------------- */

static float *block(int32_t w, int32_t h, float z);

/* The sun's unit direction at azimuth az (degrees clockwise from north), elevation el */
static void sun_dir(double az, double el, double d[3])
{
    double a = az * M_PI / 180.0, e = el * M_PI / 180.0;
    d[0] = sin(a) * cos(e);
    d[1] = cos(a) * cos(e);
    d[2] = sin(e);
}

/* The bound equals a fresh build on the snapshot's heights without any structure, as a
 * render's own bound (fine 0) or as a kept one (fine 1). */
static void same_as_fresh(const td_snapshot *snap, const double sun[3], const td_sunlit *lit, int fine)
{
    td_view plain = {td_snapshot_view(snap)->grid, NULL};
    td_sunlit *f = NULL;
    td_err e;
    assert_int_equal(td_sunlit_build(&plain, sun, fine, &f, &e), TD_OK);
    assert_non_null(f);
    assert_true(td_sunlit_fits(lit, &plain, sun));
    assert_int_equal(lit->na, f->na);
    assert_int_equal(lit->nst, f->nst);
    assert_memory_equal(lit->h, f->h, (size_t)f->na * (size_t)f->nst * sizeof *f->h);
    td_sunlit_free(f);
}

/* A sun bound is built on the first use of the heights with a sun and kept with the
 * dataset (counted in the budget) for the next snapshots with that sun, the last
 * TD_STORE_SUNS (4) suns, least recently used out first; an edit's heights start afresh
 * while a snapshot of the old ones keeps its bound; without room each snapshot builds
 * its own; a sun below the horizon gives none (and keeps no place). */
static void test_sun_bounds(void **state)
{
    td_grid *g = terrain(17), *g2 = terrain(17);
    uint64_t gb = dataset_bytes(g);
    td_store *s = store_new(gb + (64u << 20), NULL), *tight = store_new(gb + 100, NULL);
    td_snapshot *a = NULL, *b = NULL, *c = NULL;
    const td_sunlit *la = NULL, *lb = NULL, *lc = NULL;
    td_dataset_info di;
    td_store_stats st;
    td_edit_result res;
    td_err e;
    double sun[6][3];
    int kept = -1;
    (void)state;
    for (int k = 0; k < 6; k++)
        sun_dir(200.0 + 20.0 * k, 10.0, sun[k]);
    assert_int_equal(td_store_add_grid(s, "t", "api", g, &e), TD_OK);
    assert_int_equal(td_store_add_grid(tight, "t", "api", g2, &e), TD_OK);
    assert_int_equal(td_store_acquire(s, "t", &a, &e), TD_OK);
    assert_true(td_sunlit_kept_finer(g));
    assert_int_equal(td_snapshot_sunlit(a, sun[0], &la, &kept, &e), TD_OK);
    assert_non_null(la);
    assert_int_equal(kept, 0);
    same_as_fresh(a, sun[0], la, 0); /* a sun's first use: a render's own bound */
    const int coarse = la->shift; /* (la is gone once a releases it and the finer replaces it) */
    td_store_stats_get(s, &st);
    assert_int_equal(st.sun_built, 1);
    assert_int_equal(st.sun_kept, 0);
    assert_true(st.sun_bytes >= la->bytes);
    assert_int_equal(st.resident_bytes, gb + st.sun_bytes);
    /* its second use, also after the first snapshot released it: the finer kept bound
       replaces it; the third takes that one */
    td_snapshot_release(a);
    assert_int_equal(td_store_acquire(s, "t", &b, &e), TD_OK);
    assert_int_equal(td_snapshot_sunlit(b, sun[0], &lb, &kept, &e), TD_OK);
    assert_int_equal(kept, 0);
    same_as_fresh(b, sun[0], lb, 1);
    assert_true(lb->shift < coarse);
    td_store_stats_get(s, &st);
    assert_int_equal(st.sun_built, 2);
    assert_int_equal(st.sun_kept, 0); /* counted as the answer says: built */
    assert_true(st.sun_bytes >= lb->bytes && st.sun_bytes < lb->bytes + 1024); /* the coarse one dropped */
    la = lb;
    assert_int_equal(td_snapshot_sunlit(b, sun[0], &lb, &kept, &e), TD_OK);
    assert_ptr_equal(lb, la);
    assert_int_equal(kept, 1);
    /* below the horizon: none */
    double down[3] = {0.0, 0.6, -0.8};
    assert_int_equal(td_snapshot_sunlit(b, down, &lb, &kept, &e), TD_OK);
    assert_null(lb);
    /* four more suns: sun 0, the least recently used, is dropped */
    size_t bytes[5] = {la->bytes};
    for (int k = 1; k < 5; k++) {
        assert_int_equal(td_snapshot_sunlit(b, sun[k], &lb, &kept, &e), TD_OK);
        assert_int_equal(kept, 0);
        same_as_fresh(b, sun[k], lb, 0);
        bytes[k] = lb->bytes;
    }
    assert_int_equal(td_snapshot_sunlit(b, sun[4], &lb, &kept, &e), TD_OK); /* its second use */
    assert_int_equal(kept, 0);
    same_as_fresh(b, sun[4], lb, 1);
    bytes[4] = lb->bytes;
    assert_int_equal(td_snapshot_sunlit(b, sun[4], &lb, &kept, &e), TD_OK);
    assert_int_equal(kept, 1);
    assert_int_equal(td_snapshot_sunlit(b, sun[0], &la, &kept, &e), TD_OK); /* dropped: anew */
    assert_int_equal(kept, 0);
    same_as_fresh(b, sun[0], la, 0);
    bytes[0] = la->bytes;
    td_store_stats_get(s, &st);
    assert_int_equal(st.sun_kept, 2);
    assert_int_equal(st.sun_built, 9); /* and the sun below the horizon */
    {
        size_t want = bytes[0] + bytes[2] + bytes[3] + bytes[4]; /* and four small records */
        assert_true(st.sun_bytes >= want && st.sun_bytes < want + 4096);
    }
    /* an edit: the kept bounds go, b keeps its own; the new heights get a new bound */
    {
        td_grid_region r = {100, 100, 20, 20};
        float *z = block(20, 20, 9000.0f);
        assert_int_equal(td_store_edit(s, 0, &r, z, &res, &e), TD_OK);
        free(z);
        free((void *)res.rebuild.tiles);
    }
    td_store_stats_get(s, &st);
    assert_int_equal(st.sun_bytes, 0);
    assert_int_equal(st.resident_bytes, gb);
    same_as_fresh(b, sun[0], la, 0); /* still b's, of the old heights */
    assert_int_equal(td_store_acquire(s, "t", &c, &e), TD_OK);
    assert_int_equal(td_snapshot_sunlit(c, sun[0], &lc, &kept, &e), TD_OK);
    assert_int_equal(kept, 0);
    same_as_fresh(c, sun[0], lc, 0);
    assert_true(memcmp(lc->h, la->h, (size_t)la->na * (size_t)la->nst * sizeof *la->h) != 0);
    /* a snapshot of the old heights asking again builds (and does not keep) its own */
    assert_int_equal(td_snapshot_sunlit(b, sun[1], &lb, &kept, &e), TD_OK);
    assert_int_equal(kept, 0);
    same_as_fresh(b, sun[1], lb, 0);
    td_store_info(s, 0, &di);
    td_store_stats_get(s, &st);
    assert_int_equal(st.resident_bytes, gb + st.sun_bytes);
    assert_int_equal(di.sun_bytes, st.sun_bytes); /* the dataset's own figure */
    assert_true(st.sun_bytes >= lc->bytes && st.sun_bytes < lc->bytes + 1024);
    td_snapshot_release(b);
    td_snapshot_release(c);

    /* no room: each snapshot builds its own, nothing is kept */
    assert_int_equal(td_store_acquire(tight, "t", &a, &e), TD_OK);
    assert_int_equal(td_store_acquire(tight, "t", &c, &e), TD_OK);
    assert_int_equal(td_snapshot_sunlit(a, sun[0], &la, &kept, &e), TD_OK);
    assert_int_equal(td_snapshot_sunlit(c, sun[0], &lc, &kept, &e), TD_OK);
    assert_int_equal(kept, 0);
    assert_ptr_not_equal(la, lc);
    same_as_fresh(c, sun[0], lc, 0);
    td_store_stats_get(tight, &st);
    assert_int_equal(st.sun_bytes, 0);
    assert_int_equal(st.resident_bytes, gb);
    td_snapshot_release(a);
    td_snapshot_release(c);

    /* room for a sun's first bound but not for its finer one: the second use builds the
       finer for its snapshot alone, the first stays kept, and later uses take it without
       building again */
    {
        td_grid *g3 = terrain(17);
        td_view plain = {g3, NULL};
        td_sunlit *f = NULL;
        const td_sunlit *l0 = NULL, *l1 = NULL;
        assert_int_equal(td_sunlit_build(&plain, sun[0], 0, &f, &e), TD_OK);
        td_store *mid = store_new(dataset_bytes(g3) + f->bytes + 4096, NULL);
        td_sunlit_free(f);
        assert_int_equal(td_store_add_grid(mid, "t", "api", g3, &e), TD_OK);
        assert_int_equal(td_store_acquire(mid, "t", &a, &e), TD_OK);
        assert_int_equal(td_snapshot_sunlit(a, sun[0], &l0, &kept, &e), TD_OK);
        assert_int_equal(kept, 0);
        td_store_stats_get(mid, &st);
        assert_true(st.sun_bytes >= l0->bytes); /* kept */
        assert_int_equal(td_snapshot_sunlit(a, sun[0], &l1, &kept, &e), TD_OK);
        assert_int_equal(kept, 0);
        same_as_fresh(a, sun[0], l1, 1);
        td_store_stats_get(mid, &st);
        assert_int_equal(st.sun_built, 2);
        assert_true(st.sun_bytes >= l0->bytes && st.sun_bytes < l0->bytes + 1024); /* the first, still */
        for (int k = 0; k < 2; k++) {
            assert_int_equal(td_snapshot_sunlit(a, sun[0], &l1, &kept, &e), TD_OK);
            assert_int_equal(kept, 1);
            assert_ptr_equal(l1, l0);
        }
        td_store_stats_get(mid, &st);
        assert_int_equal(st.sun_built, 2);
        assert_int_equal(st.sun_kept, 2);
        td_snapshot_release(a);
        td_store_free(mid);
    }
    td_store_free(s);
    td_store_free(tight);
}

/* --- edits (td_store_edit) ------------------------------------------------------------- */

/* A region of w x h samples at (x, y), file order, all at height z (a block). */
static float *block(int32_t w, int32_t h, float z)
{
    float *b = malloc((size_t)w * (size_t)h * sizeof *b);
    for (int32_t k = 0; k < w * h; k++)
        b[k] = z;
    return b;
}

/* Every part of the snapshot equals a fresh build from the grid it traces. */
static void check_parts_fresh(td_store *s, const char *id)
{
    td_snapshot *snap = NULL;
    td_err e;
    const td_view *v;
    assert_int_equal(td_store_acquire(s, id, &snap, &e), TD_OK);
    v = td_snapshot_view(snap);
    for (size_t t = 0; t < (size_t)(v->grid->tiles_x * v->grid->tiles_y); t++) {
        if (v->accel[t].maxmip) {
            td_maxmip *m = NULL;
            assert_int_equal(td_maxmip_build(v->grid, t, &m, &e), TD_OK);
            same_maxmip(v->accel[t].maxmip, m);
            td_maxmip_free(m);
        }
        if (v->accel[t].planes) {
            td_planes *p = NULL;
            assert_int_equal(td_planes_build(v->grid, t, 8, &p, &e), TD_OK);
            assert_memory_equal(v->accel[t].planes->cone, p->cone,
                                sizeof(td_cone) * (size_t)p->bnx * (size_t)p->bny);
            td_planes_free(p);
        }
    }
    td_snapshot_release(snap);
}

/* A store holding terrain(seed) as "t", every tile preloaded. */
static td_store *preloaded(uint64_t seed)
{
    td_store *s = store_new(256u << 20, NULL);
    td_preload_spec all = spec(NULL, 0, 1, 1, 0, 0);
    td_err e;
    size_t built;
    assert_int_equal(td_store_add_grid(s, "t", "api", terrain(seed), &e), TD_OK);
    assert_int_equal(td_store_preload(s, &all, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(built, 64);
    return s;
}

/* An edit: a new version at once, the old one intact for a snapshot that holds it, the
 * touched tiles' parts out (and listed for the rebuild), the others kept. */
static void test_edit_versions(void **state)
{
    td_store *s = preloaded(5);
    td_err e;
    size_t built;
    td_grid_region r = {40, 180, 30, 20}; /* columns 40..69, file rows 180..199 */
    float *z = block(30, 20, 5000.0f);
    td_snapshot *before = NULL, *after = NULL;
    td_edit_result res;
    td_dataset_info di;
    (void)state;
    td_store_info(s, 0, &di);
    assert_int_equal(di.version, 1);
    assert_int_equal(di.chain, 0);
    assert_int_equal(td_store_acquire(s, "t", &before, &e), TD_OK);
    assert_int_equal(td_store_edit(s, 0, &r, z, &res, &e), TD_OK);
    /* grid rows 256-180 = 76 down to 57: tile rows 1 (samples 32..64) and 2 (64..96);
     * columns 40..69: tile columns 1 (32..64) and 2 (64..96) */
    assert_int_equal(res.version, 2);
    assert_true(res.chain != 0);
    assert_int_equal(res.touched, 4);
    assert_int_equal(res.rebuild.ntiles, 4);
    assert_true(res.rebuild.maxmip && res.rebuild.planes && !res.rebuild.pin);
    {
        size_t want[4] = {1 * 8 + 1, 1 * 8 + 2, 2 * 8 + 1, 2 * 8 + 2};
        for (int i = 0; i < 4; i++) {
            int found = 0;
            for (size_t k = 0; k < res.rebuild.ntiles; k++)
                found |= res.rebuild.tiles[k] == want[i];
            assert_true(found);
        }
    }
    td_store_info(s, 0, &di);
    assert_int_equal(di.version, 2);
    assert_true(di.grid->zmax == 5000.0f);
    assert_int_equal(di.resident_tiles, 64 - 4);
    check_counters(s, 0);
    /* the old snapshot: the old heights and all its parts, untouched */
    assert_int_equal(td_snapshot_version(before, NULL), 1);
    assert_true(td_snapshot_view(before)->grid->zmax < 5000.0f);
    assert_int_equal(td_snapshot_count(before, TD_PART_MAXMIP), 64);
    assert_int_equal(td_store_acquire(s, "t", &after, &e), TD_OK);
    {
        const td_view *v = td_snapshot_view(after);
        uint64_t chain = 0;
        assert_int_equal(td_snapshot_version(after, &chain), 2);
        assert_true(chain == res.chain);
        assert_true(td_grid_at(v->grid, 40, 76) == 5000.0f);
        assert_true(td_grid_at(v->grid, 69, 57) == 5000.0f);
        assert_true(td_grid_at(v->grid, 70, 57) != 5000.0f);
        assert_true(td_grid_at(v->grid, 40, 56) != 5000.0f);
        assert_true(td_grid_at(v->grid, 39, 76) != 5000.0f);
        for (size_t k = 0; k < res.rebuild.ntiles; k++)
            assert_null(v->accel[res.rebuild.tiles[k]].maxmip);
        assert_int_equal(td_snapshot_count(after, TD_PART_PLANES), 60);
    }
    td_snapshot_release(before);
    td_snapshot_release(after);
    /* the rebuild job's preload: everything back, built from the new heights */
    assert_int_equal(td_store_preload(s, &res.rebuild, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(built, 4);
    td_store_info(s, 0, &di);
    assert_int_equal(di.resident_tiles, 64);
    check_parts_fresh(s, "t");
    check_counters(s, 0);
    free((void *)res.rebuild.tiles);
    free(z);
    td_store_free(s);
}

typedef struct race {
    td_store *s;
    int fired;
    td_edit_result res;
} race;

/* The preload's progress: the first time it reaches the planes, an edit lands. */
static int edit_midway(void *cls, const char *phase, size_t done, size_t total)
{
    race *rc = cls;
    (void)done;
    (void)total;
    if (!rc->fired && !strcmp(phase, "planes")) {
        td_grid_region r = {0, 0, 257, 40}; /* the northern 40 rows: tile row 7 and 6 */
        float *z = block(257, 40, 1.0f);
        td_err e;
        rc->fired = 1;
        assert_int_equal(td_store_edit(rc->s, 0, &r, z, &rc->res, &e), TD_OK);
        free(z);
    }
    return 0;
}

/* An edit racing a preload of the same tiles: the preload's parts of the touched tiles
 * (built from the old heights) are never published; the edit's rebuild makes them. */
static void test_edit_races_preload(void **state)
{
    race rc;
    td_err e;
    size_t built;
    td_preload_spec all = spec(NULL, 0, 1, 1, 0, 0);
    td_dataset_info di;
    (void)state;
    memset(&rc, 0, sizeof rc);
    rc.s = store_new(256u << 20, NULL);
    assert_int_equal(td_store_add_grid(rc.s, "t", "api", terrain(6), &e), TD_OK);
    assert_int_equal(td_store_preload(rc.s, &all, edit_midway, &rc, &built, &e), TD_OK);
    assert_true(rc.fired);
    assert_int_equal(rc.res.touched, 16);     /* rows 256..217: tile rows 6 and 7 */
    assert_int_equal(rc.res.rebuild.ntiles, 0); /* nothing was resident yet */
    assert_int_equal(built, 64 - 16);
    td_store_info(rc.s, 0, &di);
    assert_int_equal(di.resident_tiles, 48);
    check_parts_fresh(rc.s, "t");
    /* a preload now builds them from the new heights */
    assert_int_equal(td_store_preload(rc.s, &all, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(built, 16);
    check_parts_fresh(rc.s, "t");
    check_counters(rc.s, 0);
    free((void *)rc.res.rebuild.tiles);
    td_store_free(rc.s);
}

/* The disk cache after an edit: the edited tiles' files are keyed by their heights, so
 * the old ones are not read for the new heights; a restart (edits are in memory only)
 * reads the original ones back; the same edit again finds its own files. */
static void test_edit_cache(void **state)
{
    char dir[256], cmd[600];
    td_store *s;
    td_store_stats st;
    td_err e;
    size_t built;
    td_preload_spec all = spec(NULL, 0, 1, 1, 0, 0);
    td_grid_region r = {100, 100, 10, 10}; /* one tile: samples 100..109 */
    float *z = block(10, 10, 3000.0f);
    td_edit_result res;
    td_dataset_info di;
    (void)state;
    snprintf(dir, sizeof dir, "%s/terrad-cache-edit-%ld", P_tmpdir, (long)getpid());
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    assert_int_equal(system(cmd), 0);
    for (int run = 0; run < 3; run++) {
        s = store_new(256u << 20, dir);
        assert_int_equal(td_store_add_grid(s, "t", "api", terrain(7), &e), TD_OK);
        td_store_info(s, 0, &di);
        assert_int_equal(di.version, 1); /* a restart: the file's heights again */
        assert_true(di.grid->zmax < 3000.0f);
        assert_int_equal(td_store_preload(s, &all, NULL, NULL, &built, &e), TD_OK);
        td_store_stats_get(s, &st);
        assert_int_equal(st.cache_hits, run == 0 ? 0 : 128);
        if (run < 2) {
            assert_int_equal(td_store_edit(s, 0, &r, z, &res, &e), TD_OK);
            assert_int_equal(res.rebuild.ntiles, 1);
            assert_int_equal(td_store_preload(s, &res.rebuild, NULL, NULL, &built, &e), TD_OK);
            td_store_stats_get(s, &st);
            /* first run: built (the old files do not match); second: its own files */
            assert_int_equal(st.cache_hits, run == 0 ? 0 : 130);
            assert_int_equal(st.tiles_built, run == 0 ? 130 : 0);
            check_parts_fresh(s, "t");
            free((void *)res.rebuild.tiles);
        }
        td_store_free(s);
    }
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    assert_int_equal(system(cmd), 0);
    free(z);
}


/* Rays into an edited region judged by the double-precision reference of the edited
 * heights (tests/oracle/reference.c), every method on every surface, before the rebuild
 * (the touched tiles without acceleration) and after it: a structure built from the old
 * heights would step over the new wall. Returns the wrong answers. */
static int judge_edited(td_store *s, const td_ray *rays, int n)
{
    static const td_method methods[] = {TD_METHOD_INCREMENTAL, TD_METHOD_HIERARCHICAL,
                                        TD_METHOD_PARAMETRIC, TD_METHOD_AUTO};
    td_snapshot *snap = NULL;
    td_err e;
    const td_view *v;
    const td_grid *g;
    double scale, eps;
    int wrong = 0;
    assert_int_equal(td_store_acquire(s, "t", &snap, &e), TD_OK);
    v = td_snapshot_view(snap);
    g = v->grid;
    scale = fmax(fmax((g->w - 1) * g->sx, (g->h - 1) * g->sy), fmax(fabs(g->zmin), fabs(g->zmax)));
    eps = (1e-3 + 2.0 * FLT_EPSILON * scale) * (1.0 + td_ref_max_slope(g));
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
        for (int i = 0; i < n; i++) {
            td_ref_hit ref;
            td_ref_trace(g, (td_surface)sf, &rays[i], eps, &ref);
            for (size_t m = 0; m < sizeof methods / sizeof methods[0]; m++) {
                td_hit h;
                td_trace(v, methods[m], (td_surface)sf, &rays[i], &h);
                wrong += td_ref_judge(g, (td_surface)sf, &rays[i], &ref, h.t, eps) == TD_REF_WRONG;
            }
        }
    td_snapshot_release(snap);
    return wrong;
}

static void test_edit_against_reference(void **state)
{
    td_store *s = preloaded(9);
    td_dataset_info di;
    td_err e;
    size_t built;
    td_grid_region r = {60, 60, 80, 70}; /* columns 60..139, file rows 60..129: 4 x 4 tiles */
    float *z = malloc(80 * 70 * sizeof *z);
    td_ray rays[120];
    td_edit_result res;
    int hits = 0;
    (void)state;
    float zmax, zmin;
    td_store_info(s, 0, &di);
    zmax = di.grid->zmax;
    zmin = di.grid->zmin;
    for (int row = 0; row < 70; row++)
        for (int col = 0; col < 80; col++)
            z[row * 80 + col] = col < 20 ? zmax + 300.0f           /* a wall */
                              : col < 50 ? zmin - 200.0f + (float)row /* a pit, sloping */
                              : row % 9 == 4 ? NAN                    /* void rows */
                              : 0.5f * zmax + 3.0f * (float)(col - 50);
    assert_int_equal(td_store_edit(s, 0, &r, z, &res, &e), TD_OK);
    for (int i = 0; i < 120; i++) {
        td_ray *ry = &rays[i];
        ry->tmin = 0.0;
        ry->tmax = INFINITY;
        ry->o[1] = (256 - 128 + 66.0 * (i % 40) / 40.0) * 30.0; /* the region's rows */
        ry->d[0] = 1.0;
        ry->d[1] = 0.02 * ((i % 5) - 2);
        if (i < 40) { /* from the west, level, into the wall (or grazing its top) */
            ry->o[0] = 100.0;
            ry->o[2] = zmax + 50.0 + 7.5 * i;
            ry->d[2] = 0.0;
        } else if (i < 80) { /* from above the wall, steeply down into the pit */
            ry->o[0] = 1900.0;
            ry->o[2] = zmax + 400.0;
            ry->d[2] = -1.2 - 0.02 * (i - 40);
        } else { /* straight down onto the pit, the slope and its void rows */
            ry->o[0] = (62.0 + 1.9 * (i - 80)) * 30.0;
            ry->o[2] = zmax + 1000.0;
            ry->d[0] = 0.01;
            ry->d[1] = -0.01;
            ry->d[2] = -1.0;
        }
    }
    {
        td_snapshot *snap = NULL;
        assert_int_equal(td_store_acquire(s, "t", &snap, &e), TD_OK);
        for (int i = 0; i < 120; i++) {
            td_hit h;
            td_trace(td_snapshot_view(snap), TD_METHOD_INCREMENTAL, TD_SURFACE_BILINEAR, &rays[i], &h);
            hits += isfinite(h.t) && h.p[0] >= 60 * 30.0 && h.p[0] <= 139 * 30.0;
        }
        td_snapshot_release(snap);
    }
    assert_true(hits > 60); /* most rays end in the edited region */
    assert_int_equal(judge_edited(s, rays, 120), 0);
    assert_int_equal(res.touched, 16);
    assert_int_equal(td_store_preload(s, &res.rebuild, NULL, NULL, &built, &e), TD_OK);
    assert_int_equal(built, 16);
    assert_int_equal(judge_edited(s, rays, 120), 0);
    free((void *)res.rebuild.tiles);
    free(z);
    td_store_free(s);
}

/* --- concurrency ------------------------------------------------------------------------ */

enum { NRAYS = 96 };

typedef struct shared {
    td_store *s;
    td_ray rays[NRAYS];
    double ref[NRAYS];     /* incremental hits, before any acceleration existed */
    atomic_int stop;
    atomic_int mismatches, snapshots, with_accel;
    uint64_t budget, slack;
    atomic_int over_budget;
    char drape[256]; /* every snapshot asks for it: decoded once, kept, shared */
    atomic_int bad_drapes;
    double sun[2][3];       /* every snapshot asks for one of two suns' bounds */
    td_sunlit *sun_ref[2];  /* each built on the plain grid */
    atomic_int bad_suns;
} shared;

static int same_t(double a, double b)
{
    return (isinf(a) && isinf(b)) || fabs(a - b) <= 1e-6 * (1.0 + fabs(a));
}

static void *reader(void *arg)
{
    shared *sh = arg;
    static const td_method methods[] = {TD_METHOD_HIERARCHICAL, TD_METHOD_PARAMETRIC, TD_METHOD_AUTO};
    int k = 0;
    while (!atomic_load(&sh->stop) || k < 3) {
        td_snapshot *snap = NULL;
        td_err e;
        const td_view *v;
        if (td_store_acquire(sh->s, "t", &snap, &e) != TD_OK)
            continue;
        v = td_snapshot_view(snap);
        if (td_snapshot_count(snap, TD_PART_MAXMIP) + td_snapshot_count(snap, TD_PART_PLANES) > 0)
            atomic_fetch_add(&sh->with_accel, 1);
        {
            const td_image8 *img = NULL;
            if (td_snapshot_drape(snap, sh->drape, &img, &e) != TD_OK || img->width != 8 ||
                img->px[(5 * 8 + 3) * 3] != 60)
                atomic_fetch_add(&sh->bad_drapes, 1);
        }
        {
            const td_sunlit *lit = NULL, *ref = sh->sun_ref[k & 1];
            int kept = 0;
            /* built on whatever snapshot came first: from max-mipmap codes (rounded up,
               at most a code step above the maxima) where it held them, so at or above the
               plain grid's bound and close to it, never below */
            int bad = td_snapshot_sunlit(snap, sh->sun[k & 1], &lit, &kept, &e) != TD_OK ||
                      !td_sunlit_fits(lit, v, sh->sun[k & 1]) || lit->na != ref->na || lit->nst != ref->nst;
            for (size_t i = 0; !bad && i < (size_t)ref->na * (size_t)ref->nst; i++)
                bad = !(lit->h[i] >= ref->h[i] && lit->h[i] <= ref->h[i] + 1.0f);
            if (bad)
                atomic_fetch_add(&sh->bad_suns, 1);
        }
        for (int i = 0; i < NRAYS; i++) {
            td_hit h;
            td_trace(v, methods[k % 3], TD_SURFACE_BILINEAR, &sh->rays[i], &h);
            if (!same_t(h.t, sh->ref[i]))
                atomic_fetch_add(&sh->mismatches, 1);
        }
        td_snapshot_release(snap);
        atomic_fetch_add(&sh->snapshots, 1);
        k++;
    }
    return NULL;
}

static void test_concurrent_snapshots(void **state)
{
    td_grid *g = terrain(11);
    shared *sh = calloc(1, sizeof *sh);
    pthread_t th[2];
    td_err e;
    td_view plain;
    size_t built;
    uint64_t gb = dataset_bytes(g), tb;
    uint64_t x = 0x9e3779b97f4a7c15ULL;
    (void)state;
    assert_non_null(sh);
    tb = tile_bytes(g);
    plain.grid = g;
    plain.accel = NULL;
    for (int k = 0; k < 2; k++) {
        sun_dir(250.0 + 40.0 * k, 12.0, sh->sun[k]);
        assert_int_equal(td_sunlit_build(&plain, sh->sun[k], 1, &sh->sun_ref[k], &e), TD_OK);
    }
    /* Room for 24 of the 64 tiles (preloads of 16 keep evicting each other) and the two
       suns' bounds. */
    sh->budget = gb + 24 * tb + tb + 2 * (sh->sun_ref[0]->bytes + sh->sun_ref[1]->bytes);
    sh->slack = tb;
    sh->s = store_new(sh->budget, NULL);
    snprintf(sh->drape, sizeof sh->drape, "%s/terrad-drape-c%ld.png", P_tmpdir, (long)getpid());
    write_png(sh->drape, 8, 6);
    for (int i = 0; i < NRAYS; i++) {
        td_ray *r = &sh->rays[i];
        td_hit h;
        double u, v2;
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        u = (double)(x % 10000) / 10000.0;
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        v2 = (double)(x % 10000) / 10000.0;
        r->o[0] = -500.0;
        r->o[1] = u * 7680.0;
        r->o[2] = (double)g->zmax + 200.0;
        r->d[0] = 1.0;
        r->d[1] = (v2 - 0.5) * 0.6;
        r->d[2] = -0.02 - 0.1 * v2;
        r->tmin = 0.0;
        r->tmax = INFINITY;
        td_trace(&plain, TD_METHOD_INCREMENTAL, TD_SURFACE_BILINEAR, r, &h);
        sh->ref[i] = h.t;
    }
    assert_int_equal(td_store_add_grid(sh->s, "t", "api", g, &e), TD_OK);
    {
        /* both suns' bounds kept while the budget has room (no tile is evicted for one
           later): the readers share them, each snapshot with a reference of its own */
        td_snapshot *snap = NULL;
        const td_sunlit *lit = NULL;
        int kept = 1;
        assert_int_equal(td_store_acquire(sh->s, "t", &snap, &e), TD_OK);
        for (int k = 0; k < 2; k++)
            for (int use = 0; use < 2; use++) { /* the second use builds the finer bound */
                assert_int_equal(td_snapshot_sunlit(snap, sh->sun[k], &lit, &kept, &e), TD_OK);
                assert_int_equal(kept, 0);
            }
        td_snapshot_release(snap);
    }
    for (int i = 0; i < 2; i++)
        assert_int_equal(pthread_create(&th[i], NULL, reader, sh), 0);
    for (int round = 0; round < 12; round++) {
        size_t tiles[16];
        td_store_stats st;
        td_preload_spec p = spec(tiles, 16, 1, 1, round % 4 == 3, 1);
        for (int k = 0; k < 16; k++)
            tiles[k] = (size_t)((round * 16 + k * 5) % 64);
        assert_int_equal(td_store_preload(sh->s, &p, NULL, NULL, &built, &e), TD_OK);
        td_store_stats_get(sh->s, &st);
        if (st.resident_bytes > sh->budget + sh->slack)
            atomic_fetch_add(&sh->over_budget, 1);
        if (round % 4 == 3) {
            td_store_evict_dataset(sh->s, 0, &built);
            assert_true(built > 0);
        }
    }
    atomic_store(&sh->stop, 1);
    for (int i = 0; i < 2; i++)
        pthread_join(th[i], NULL);
    assert_int_equal(atomic_load(&sh->mismatches), 0);
    assert_int_equal(atomic_load(&sh->over_budget), 0);
    assert_true(atomic_load(&sh->snapshots) >= 6);
    assert_int_equal(atomic_load(&sh->bad_drapes), 0);
    assert_int_equal(atomic_load(&sh->bad_suns), 0);
    check_counters(sh->s, 0);
    {
        td_store_stats st;
        td_store_stats_get(sh->s, &st);
        print_message("  sun bounds: %llu kept, %llu built, %llu bytes\n", (unsigned long long)st.sun_kept, (unsigned long long)st.sun_built, (unsigned long long)st.sun_bytes);
        assert_true(st.sun_kept > 0 && st.sun_built == 4 && st.sun_bytes > 0);
    }
    td_sunlit_free(sh->sun_ref[0]);
    td_sunlit_free(sh->sun_ref[1]);
    unlink(sh->drape);
    td_store_free(sh->s);
    free(sh);
}


/* Renders during a stream of edits: one thread flips a block of the grid up and back
 * down (odd versions hold the original heights, even ones the block), and rebuilds the
 * touched tiles' acceleration after every other edit, while two threads trace rays
 * through snapshots with every method. Each snapshot's hits must all equal the
 * incremental tracer's on the heights of its version: never a mix, never a part built
 * from other heights. The editor waits until some snapshot has seen each version. */
typedef struct edits_shared {
    td_store *s;
    td_ray rays[NRAYS];
    double ref[2][NRAYS]; /* [0] the block (even versions), [1] the original (odd) */
    atomic_int stop, mismatches, snapshots;
    atomic_uint_fast64_t seen; /* highest version a snapshot traced */
} edits_shared;

static void *edit_reader(void *arg)
{
    edits_shared *sh = arg;
    static const td_method methods[] = {TD_METHOD_HIERARCHICAL, TD_METHOD_PARAMETRIC,
                                        TD_METHOD_AUTO, TD_METHOD_INCREMENTAL};
    int k = 0;
    while (!atomic_load(&sh->stop)) {
        td_snapshot *snap = NULL;
        td_err e;
        uint64_t ver, seen;
        if (td_store_acquire(sh->s, "t", &snap, &e) != TD_OK)
            continue;
        ver = td_snapshot_version(snap, NULL);
        for (int i = 0; i < NRAYS; i++) {
            td_hit h;
            td_trace(td_snapshot_view(snap), methods[k % 4], TD_SURFACE_BILINEAR, &sh->rays[i], &h);
            if (!same_t(h.t, sh->ref[ver & 1][i]))
                atomic_fetch_add(&sh->mismatches, 1);
        }
        td_snapshot_release(snap);
        seen = atomic_load(&sh->seen);
        while (ver > seen && !atomic_compare_exchange_weak(&sh->seen, &seen, ver))
            ;
        atomic_fetch_add(&sh->snapshots, 1);
        k++;
    }
    return NULL;
}

static void test_edits_under_renders(void **state)
{
    edits_shared *sh = calloc(1, sizeof *sh);
    td_grid *a = terrain(12), *b = NULL;
    td_grid_region r = {96, 96, 64, 64}; /* 9 tiles */
    float *up = block(64, 64, 0.0f), *down = malloc(64 * 64 * sizeof *down);
    td_view view = {NULL, NULL};
    pthread_t th[2];
    td_err e;
    size_t built, differ = 0;
    td_preload_spec all = spec(NULL, 0, 1, 1, 0, 0);
    (void)state;
    for (int32_t row = 0; row < 64; row++)
        for (int32_t col = 0; col < 64; col++) {
            down[row * 64 + col] = td_grid_at(a, 96 + col, a->h - 1 - (96 + row));
            up[row * 64 + col] = a->zmax + 1000.0f;
        }
    assert_int_equal(td_grid_edit_apply(a, &r, up, &b, &e), TD_OK);
    for (int i = 0; i < NRAYS; i++) {
        td_ray *ry = &sh->rays[i];
        td_hit h;
        /* from the west toward the block's rows (grid rows 97..160), descending */
        ry->o[0] = -500.0;
        ry->o[1] = (100.0 + 56.0 * i / NRAYS) * 30.0;
        ry->o[2] = (double)a->zmax + 200.0;
        ry->d[0] = 1.0;
        ry->d[1] = 0.05 * (i % 7 - 3) / 3.0;
        ry->d[2] = -0.01 - 0.04 * (i % 5) / 4.0;
        ry->tmin = 0.0;
        ry->tmax = INFINITY;
        view.grid = b;
        td_trace(&view, TD_METHOD_INCREMENTAL, TD_SURFACE_BILINEAR, ry, &h);
        sh->ref[0][i] = h.t;
        view.grid = a;
        td_trace(&view, TD_METHOD_INCREMENTAL, TD_SURFACE_BILINEAR, ry, &h);
        sh->ref[1][i] = h.t;
        differ += !same_t(sh->ref[0][i], sh->ref[1][i]);
    }
    assert_true(differ > NRAYS / 2); /* the two pictures can be told apart */
    sh->s = store_new(256u << 20, NULL);
    assert_int_equal(td_store_add_grid(sh->s, "t", "api", a, &e), TD_OK);
    assert_int_equal(td_store_preload(sh->s, &all, NULL, NULL, &built, &e), TD_OK);
    atomic_store(&sh->seen, 0);
    for (int i = 0; i < 2; i++)
        assert_int_equal(pthread_create(&th[i], NULL, edit_reader, sh), 0);
    for (int round = 0; round < 16; round++) {
        td_edit_result res;
        assert_int_equal(td_store_edit(sh->s, 0, &r, round % 2 ? down : up, &res, &e), TD_OK);
        assert_int_equal(res.version, (uint64_t)round + 2);
        if (round % 4 < 2 && res.rebuild.ntiles)
            assert_int_equal(td_store_preload(sh->s, &res.rebuild, NULL, NULL, &built, &e), TD_OK);
        free((void *)res.rebuild.tiles);
        while (atomic_load(&sh->seen) < res.version)
            sched_yield();
    }
    atomic_store(&sh->stop, 1);
    for (int i = 0; i < 2; i++)
        pthread_join(th[i], NULL);
    assert_int_equal(atomic_load(&sh->mismatches), 0);
    assert_true(atomic_load(&sh->snapshots) >= 16);
    check_parts_fresh(sh->s, "t");
    check_counters(sh->s, 0);
    td_store_free(sh->s);
    td_grid_free(b);
    free(up);
    free(down);
    free(sh);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ids),
        cmocka_unit_test(test_add_dir),
        cmocka_unit_test(test_budget_lru_pin),
        cmocka_unit_test(test_disk_cache),
        cmocka_unit_test(test_failed_preload_publishes_nothing),
        cmocka_unit_test(test_drape),
        cmocka_unit_test(test_sun_bounds),
        cmocka_unit_test(test_concurrent_snapshots),
        cmocka_unit_test(test_edit_versions),
        cmocka_unit_test(test_edit_races_preload),
        cmocka_unit_test(test_edit_cache),
        cmocka_unit_test(test_edit_against_reference),
        cmocka_unit_test(test_edits_under_renders),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
