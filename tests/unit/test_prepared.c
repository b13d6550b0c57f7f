/* test_prepared.c: the prepared form (core/prepared.h). A prepared dataset must open as
 * exactly the grid td_dem_load makes of its source (heights bit for bit, statistics and
 * tile records the same), whichever the tile size, chunking, voids or format (.f32
 * streamed, GeoTIFF streamed through GDAL, .asc through its loader); a prepare stopped after
 * some chunks must continue and end with the same files; and a truncated heights file, an
 * index of another version, a corrupted tiles.bin or a corrupted chunk must be refused with
 * the file and the reason. The blocked copy (heights.blk) holds every sample where
 * td_grid_corner says, for any block size, and a render of every method and surface reads
 * it alone: the same pixels as the source with the row-major mapping made unreadable. */
#include <fcntl.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>
#include <jansson.h>

#include "accel.h"
#include "dem.h"
#include "lod.h"
#include "maxmip.h"
#include "planes.h"
#include "prepaccel.h"
#include "prepared.h"
#include "render.h"
#include "scene.h"

#ifdef TERRAD_HAVE_GDAL
#include <gdal.h>
#endif

static char tmp_root[256];

static int setup(void **state)
{
    (void)state;
    snprintf(tmp_root, sizeof tmp_root, "/tmp/td-prepared-XXXXXX");
    return mkdtemp(tmp_root) ? 0 : -1;
}

static int teardown(void **state)
{
    char cmd[300];
    (void)state;
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp_root);
    return system(cmd) == 0 ? 0 : -1;
}

static void tmp_path(const char *name, char *out, size_t n)
{
    snprintf(out, n, "%s/%s", tmp_root, name);
}

static void data_path(const char *name, char *out, size_t n)
{
    snprintf(out, n, "%s/%s", TERRAD_TEST_DATA, name);
}

static void opts(td_prepare_opts *o, int tile_log2, int32_t chunk_rows)
{
    memset(o, 0, sizeof *o);
    td_dem_opts_default(&o->dem);
    o->dem.tile_log2 = tile_log2;
    o->chunk_rows = chunk_rows;
}

/* A mapped grid a equals grid b bit for bit: shape, spacing, tiling, statistics,
 * georeference, heights and tile records. */
static void assert_same_grid(const td_grid *a, const td_grid *b)
{
    assert_non_null(a->map);
    assert_int_equal(a->w, b->w);
    assert_int_equal(a->h, b->h);
    assert_true(a->sx == b->sx && a->sy == b->sy);
    assert_int_equal(a->tile_log2, b->tile_log2);
    assert_int_equal(a->tiles_x, b->tiles_x);
    assert_int_equal(a->tiles_y, b->tiles_y);
    assert_true((a->zmin == b->zmin && a->zmax == b->zmax) || (isnan(a->zmin) && isnan(b->zmin)));
    assert_int_equal(a->voids, b->voids);
    assert_int_equal(a->geo.kind, b->geo.kind);
    assert_true(a->geo.x0 == b->geo.x0 && a->geo.y0 == b->geo.y0);
    assert_true(a->geo.dx == b->geo.dx && a->geo.dy == b->geo.dy);
    assert_memory_equal(a->z, b->z, (size_t)a->w * (size_t)a->h * sizeof(float));
    assert_memory_equal(a->tiles, b->tiles, (size_t)a->tiles_x * (size_t)a->tiles_y * sizeof(td_tile));
    /* every sample through a->cz (heights.blk for the full grid): bit for bit b's */
    for (int32_t j = 0; j < a->h; j++)
        for (int32_t i = 0; i < a->w; i++) {
            float x = td_grid_sample(a, i, j), y = b->z[(size_t)j * (size_t)b->w + (size_t)i];
            if (memcmp(&x, &y, sizeof x))
                fail_msg("sample (%d, %d): %g through cz, %g in the source", (int)i, (int)j, x, y);
        }
}

/* The mapped structures `got` of a prepared layer are, tile by tile, the max-mipmap and
 * K-slice planes td_maxmip_build and td_planes_build make of the in-memory grid ref: the
 * same shapes, scales and bytes. */
static void assert_same_accel(const td_tile_accel *got, const td_grid *ref)
{
    td_err e = {0};
    assert_non_null(got);
    for (size_t t = 0; t < (size_t)ref->tiles_x * (size_t)ref->tiles_y; t++) {
        td_maxmip *m = NULL;
        td_planes *pl = NULL;
        const td_maxmip *a = got[t].maxmip;
        const td_planes *b = got[t].planes;
        size_t codes = 0;
        assert_int_equal(td_maxmip_build(ref, t, &m, &e), TD_OK);
        assert_int_equal(td_planes_build(ref, t, TD_PLANES_K_DEFAULT, &pl, &e), TD_OK);
        assert_non_null(a);
        assert_non_null(b);
        assert_int_equal(a->levels, m->levels);
        assert_memory_equal(a->dim, m->dim, sizeof m->dim);
        assert_memory_equal(a->offset, m->offset, sizeof m->offset);
        assert_true(a->base == m->base && a->step == m->step);
        for (int l = 1; l <= m->levels; l++)
            codes += (size_t)m->dim[l] * (size_t)m->dim[l];
        assert_memory_equal(a->code, m->code, codes * sizeof(uint16_t));
        assert_int_equal(b->k, pl->k);
        assert_int_equal(b->nx, pl->nx);
        assert_int_equal(b->ny, pl->ny);
        assert_int_equal(b->bnx, pl->bnx);
        assert_int_equal(b->bny, pl->bny);
        assert_true(b->slope_scale == pl->slope_scale);
        assert_memory_equal(b->apex, pl->apex, ((size_t)pl->k + 1) * sizeof(float));
        assert_memory_equal(b->cone, pl->cone, (size_t)pl->bnx * (size_t)pl->bny * sizeof(td_cone));
        td_maxmip_free(m);
        td_planes_free(pl);
    }
}

/* The prepared levels of p equal td_lod_build's levels of the loaded grid ref, bit for bit
 * (heights, tile records, statistics, spacing, georeference): the levels the LOD oracle
 * holds to the references are the ones a prepared dataset serves. */
static void assert_same_levels(td_prepared *p, const td_grid *ref)
{
    td_lod *want = NULL, *got;
    td_accel_opts ao;
    td_err e = {0};
    td_accel_opts_default(&ao);
    ao.maxmip = ao.planes = 0;
    assert_int_equal(td_lod_build(ref, TD_LOD_MAX, &ao, &want, &e), TD_OK);
    got = td_prepared_take_lod(p);
    assert_non_null(got);
    assert_true(want->levels >= 1);
    assert_int_equal(got->levels, want->levels);
    for (int k = 1; k <= want->levels; k++) {
        assert_ptr_equal(got->view[k].grid, got->grid[k]);
        assert_same_grid(got->grid[k], want->grid[k]);
        assert_same_accel(got->view[k].accel, want->grid[k]);
    }
    td_lod_free(got);
    td_lod_free(want);
}

/* The prepared grid in dir equals the loader's grid of src, bit for bit, and so do its
 * coarse levels td_lod_build's. */
static void assert_same_as_loaded(const char *src, const char *dir, int tile_log2, int block_log2)
{
    td_dem_opts lo;
    td_grid *ref = NULL, *g;
    td_prepared *p = NULL;
    td_err e = {0};

    td_dem_opts_default(&lo);
    lo.tile_log2 = tile_log2;
    assert_int_equal(td_dem_load(src, &lo, &ref, &e), TD_OK);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    g = td_prepared_take_grid(p);
    assert_non_null(g->bmap);
    assert_int_equal(g->cz.log2, block_log2 ? block_log2 : TD_PREPARED_BLOCK_LOG2);
    assert_int_equal(g->cz.stride, (1u << g->cz.log2) + 1u);
    assert_same_grid(g, ref);
    assert_same_accel(td_prepared_accel(p), ref);
    assert_same_levels(p, ref);
    td_grid_free(g);
    td_grid_free(ref);
    td_prepared_free(p);
}

static void prepare_blk(const char *src, const char *dir, int tile_log2, int32_t chunk_rows, int block_log2,
                        td_prepare_result *res)
{
    td_prepare_opts o;
    td_err e = {0};
    opts(&o, tile_log2, chunk_rows);
    o.block_log2 = block_log2;
    if (td_prepare(src, dir, &o, res, &e) != TD_OK)
        fail_msg("%s", e.msg);
}

static void prepare_ok(const char *src, const char *dir, int tile_log2, int32_t chunk_rows,
                       td_prepare_result *res)
{
    prepare_blk(src, dir, tile_log2, chunk_rows, 0, res);
}

static void test_f32_same_as_loader(void **state)
{
    char src[512], dir[512];
    td_prepare_result res;
    (void)state;
    data_path("trinidad-crop.f32", src, sizeof src);
    /* tiles of 32 (7 x 5, shared edges), chunks that are not a multiple of the tile size
       and a last chunk shorter than the others */
    tmp_path("f32-t5", dir, sizeof dir);
    prepare_blk(src, dir, 5, 23, 3, &res); /* blocks of 8: 25 x 19, the last ones partly past the grid */
    assert_int_equal(res.streamed, 1);
    assert_int_equal(res.resumed_rows, 0);
    assert_int_equal(res.w, 200);
    assert_int_equal(res.h, 150);
    assert_same_as_loaded(src, dir, 5, 3);
    tmp_path("f32-t8", dir, sizeof dir);
    prepare_ok(src, dir, 8, 0, &res);
    assert_same_as_loaded(src, dir, 8, 0);
}

/* A .f32 with NaN voids (and a tile of voids only): voids, tile ranges of +-inf. */
static void test_voids(void **state)
{
    char src[512], side[512], dir[512];
    const int32_t w = 40, h = 33;
    float *z = malloc((size_t)w * h * sizeof *z);
    FILE *f;
    td_prepare_result res;
    (void)state;
    assert_non_null(z);
    for (int32_t r = 0; r < h; r++)
        for (int32_t i = 0; i < w; i++)
            z[r * w + i] = (i < 17 && r < 17) ? NAN : (float)(100.0 + 3.0 * sin(i * 0.3) + r * 0.25);
    tmp_path("voids.f32", src, sizeof src);
    tmp_path("voids.json", side, sizeof side);
    f = fopen(src, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(z, sizeof *z, (size_t)w * h, f), (size_t)w * h);
    fclose(f);
    f = fopen(side, "w");
    assert_non_null(f);
    fprintf(f, "{\"width\": %d, \"height\": %d, \"spacing_m\": 10, \"nodata\": \"nan\"}", (int)w, (int)h);
    fclose(f);
    tmp_path("voids-p", dir, sizeof dir);
    prepare_ok(src, dir, 4, 5, &res);
    assert_same_as_loaded(src, dir, 4, 0);
    /* blocks of 4: the last sample row (32) starts a band of its own */
    tmp_path("voids-b4", dir, sizeof dir);
    prepare_blk(src, dir, 4, 5, 2, &res);
    assert_same_as_loaded(src, dir, 4, 2);
    /* a block size out of range is refused, naming it */
    {
        td_prepare_opts o;
        td_err e = {0};
        opts(&o, 4, 5);
        o.block_log2 = 9;
        tmp_path("voids-b512", dir, sizeof dir);
        assert_int_equal(td_prepare(src, dir, &o, &res, &e), TD_EINVAL);
        assert_string_equal(e.field, "block_log2");
    }
    free(z);
}

/* .asc goes through its loader (not streamed) and ends the same. */
static void test_asc_whole(void **state)
{
    char src[512], dir[512];
    td_prepare_result res;
    (void)state;
    data_path("volcano.asc", src, sizeof src);
    tmp_path("volcano-p", dir, sizeof dir);
    prepare_ok(src, dir, 4, 7, &res);
    assert_int_equal(res.streamed, 0);
    assert_same_as_loaded(src, dir, 4, 0);
}

static void test_geotiff_streamed(void **state)
{
    (void)state;
#ifdef TERRAD_HAVE_GDAL
    char src[512], tif[512], dir[512];
    td_grid *ref = NULL;
    td_dem_opts lo;
    td_err e = {0};
    td_prepare_result res;
    GDALDatasetH ds;
    double gt[6] = {500000.0, 30.0, 0.0, 4100000.0, 0.0, -30.0};
    char *copt[] = {"TILED=YES", "BLOCKXSIZE=64", "BLOCKYSIZE=64", NULL};

    data_path("trinidad-crop.f32", src, sizeof src);
    td_dem_opts_default(&lo);
    assert_int_equal(td_dem_load(src, &lo, &ref, &e), TD_OK);
    GDALAllRegister();
    tmp_path("crop.tif", tif, sizeof tif);
    ds = GDALCreate(GDALGetDriverByName("GTiff"), tif, ref->w, ref->h, 1, GDT_Float32, copt);
    assert_non_null(ds);
    assert_int_equal(GDALSetGeoTransform(ds, gt), CE_None);
    for (int32_t r = 0; r < ref->h; r++)
        assert_int_equal(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Write, 0, r, ref->w, 1,
                                      ref->z + (size_t)(ref->h - 1 - r) * (size_t)ref->w, ref->w, 1,
                                      GDT_Float32, 0, 0),
                         CE_None);
    GDALClose(ds);
    td_grid_free(ref);
    tmp_path("tif-p", dir, sizeof dir);
    prepare_ok(tif, dir, 6, 50, &res);
    assert_int_equal(res.streamed, 1);
    assert_same_as_loaded(tif, dir, 6, 0);
#endif
}

static int stop_after_3(void *cls, int64_t done, int64_t total, int32_t w)
{
    int *calls = cls;
    (void)done;
    (void)total;
    (void)w;
    return ++*calls >= 3;
}

static void file_bytes(const char *dir, const char *name, unsigned char **buf, size_t *n)
{
    char p[600];
    FILE *f;
    struct stat st;
    snprintf(p, sizeof p, "%s/%s", dir, name);
    assert_int_equal(stat(p, &st), 0);
    *n = (size_t)st.st_size;
    *buf = malloc(*n + 1);
    f = fopen(p, "rb");
    assert_non_null(f);
    assert_int_equal(fread(*buf, 1, *n, f), *n);
    fclose(f);
}

static void assert_same_file(const char *a, const char *b, const char *name)
{
    unsigned char *x, *y;
    size_t nx, ny;
    file_bytes(a, name, &x, &nx);
    file_bytes(b, name, &y, &ny);
    assert_int_equal(nx, ny);
    assert_memory_equal(x, y, nx);
    free(x);
    free(y);
}

/* Stopped after 3 chunks of 16 rows (south rows 102..149 written), then continued: with
 * blocks of 32 the band in progress (south rows 96..128) and with blocks of 4 (band 100..104)
 * is read back from heights.f32; every file ends as an uninterrupted run's. With skip 10,
 * stopped after the 10 chunks and 3 of the 16 tile rows of structures (accel.tab, accel.bin)
 * instead. */
static void resume_blk(int block_log2, const char *dirname, const char *refname, int skip)
{
    char src[512], dir[512], ref[512];
    td_prepare_opts o;
    td_prepare_result res;
    td_err e = {0};
    int calls = -skip;
    data_path("trinidad-crop.f32", src, sizeof src);
    tmp_path(dirname, dir, sizeof dir);
    opts(&o, 5, 16);
    o.block_log2 = block_log2;
    o.progress = stop_after_3;
    o.cls = &calls;
    assert_int_equal(td_prepare(src, dir, &o, &res, &e), TD_ECANCELED);
    if (!strstr(e.msg, skip ? "after 3 of 16 tile rows of structures" : "after 3 of 10 chunks"))
        fail_msg("%s", e.msg);
    assert_false(td_prepared_is(dir));
    assert_true(td_prepared_unfinished(dir));
    /* the second run continues after the three chunks written */
    prepare_blk(src, dir, 5, 16, block_log2, &res);
    assert_int_equal(res.resumed_rows, skip ? 150 : 48);
    assert_false(td_prepared_unfinished(dir));
    tmp_path(refname, ref, sizeof ref);
    prepare_blk(src, ref, 5, 16, block_log2, &res);
    assert_same_file(dir, ref, TD_PREPARED_HEIGHTS);
    assert_same_file(dir, ref, TD_PREPARED_BLOCKS);
    assert_same_file(dir, ref, TD_PREPARED_TILES);
    assert_same_file(dir, ref, TD_PREPARED_INDEX);
    assert_same_file(dir, ref, TD_PACC_TAB);
    assert_same_file(dir, ref, TD_PACC_BIN);
    for (int k = 1; k <= 8; k++) {
        char name[32];
        snprintf(name, sizeof name, TD_PREPARED_LEVEL_FMT, k);
        assert_same_file(dir, ref, name);
        snprintf(name, sizeof name, TD_PREPARED_LEVEL_TILES_FMT, k);
        assert_same_file(dir, ref, name);
    }
    /* a third run finds it done */
    prepare_blk(src, dir, 5, 16, block_log2, &res);
    assert_int_equal(res.already, 1);
    assert_same_as_loaded(src, dir, 5, block_log2);
}

static void test_resume(void **state)
{
    (void)state;
    resume_blk(0, "resume", "resume-ref", 0);
    resume_blk(2, "resume-b4", "resume-b4-ref", 0);
    resume_blk(0, "resume-acc", "resume-acc-ref", 10);
}

/* A fresh prepared copy named `name` of the crop, 10 chunks of 16 rows. */
static void fresh(const char *name, char *dir, size_t n)
{
    char src[512];
    td_prepare_result res;
    data_path("trinidad-crop.f32", src, sizeof src);
    tmp_path(name, dir, n);
    prepare_ok(src, dir, 5, 16, &res);
}

static void flip_byte(const char *dir, const char *name, long at)
{
    char p[600];
    FILE *f;
    int c;
    snprintf(p, sizeof p, "%s/%s", dir, name);
    f = fopen(p, "r+b");
    assert_non_null(f);
    assert_int_equal(fseek(f, at, SEEK_SET), 0);
    c = fgetc(f);
    assert_int_equal(fseek(f, at, SEEK_SET), 0);
    fputc(c ^ 0x10, f);
    fclose(f);
}

static void assert_refused(const char *dir, td_status want, const char *n1, const char *n2)
{
    td_prepared *p = NULL;
    td_err e = {0};
    assert_int_equal(td_prepared_open(dir, &p, &e), want);
    assert_null(p);
    if (!strstr(e.msg, n1) || !strstr(e.msg, n2))
        fail_msg("'%s' does not name '%s' and '%s'", e.msg, n1, n2);
}

static void test_truncated(void **state)
{
    char dir[512], p[600];
    (void)state;
    fresh("trunc", dir, sizeof dir);
    snprintf(p, sizeof p, "%s/%s", dir, TD_PREPARED_HEIGHTS);
    assert_int_equal(truncate(p, 200 * 150 * 4 - 4), 0);
    assert_refused(dir, TD_EFORMAT, "heights.f32", "truncated");
    snprintf(p, sizeof p, "%s/%s", dir, TD_PREPARED_TILES);
    fresh("trunc-tiles", dir, sizeof dir);
    snprintf(p, sizeof p, "%s/%s", dir, TD_PREPARED_TILES);
    assert_int_equal(truncate(p, 10), 0);
    assert_refused(dir, TD_EFORMAT, "tiles.bin", "truncated");
    fresh("trunc-blocks", dir, sizeof dir);
    snprintf(p, sizeof p, "%s/%s", dir, TD_PREPARED_BLOCKS);
    assert_int_equal(truncate(p, 5 * 30492 - 4), 0); /* 5 bands of 7 blocks of 33 x 33 */
    assert_refused(dir, TD_EFORMAT, "heights.blk", "truncated");
    fresh("trunc-accel", dir, sizeof dir);
    snprintf(p, sizeof p, "%s/%s", dir, TD_PACC_BIN);
    assert_int_equal(truncate(p, 1000), 0);
    assert_refused(dir, TD_EFORMAT, "accel.bin", "truncated");
}

/* The index of dir as text (the caller frees it), and written back. */
static char *index_text(const char *dir)
{
    char p[600], *text;
    json_t *j;
    snprintf(p, sizeof p, "%s/%s", dir, TD_PREPARED_INDEX);
    j = json_load_file(p, 0, NULL);
    assert_non_null(j);
    text = json_dumps(j, JSON_COMPACT | JSON_PRESERVE_ORDER);
    json_decref(j);
    assert_non_null(text);
    return text;
}

static void index_put(const char *dir, char *text)
{
    char p[600];
    FILE *f;
    snprintf(p, sizeof p, "%s/%s", dir, TD_PREPARED_INDEX);
    f = fopen(p, "wb");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
    free(text);
}

static void test_other_version(void **state)
{
    char dir[512], *text, *v;
    (void)state;
    fresh("version", dir, sizeof dir);
    text = index_text(dir);
    v = strstr(text, "\"version\":4");
    assert_non_null(v);
    v[strlen("\"version\":")] = '7';
    index_put(dir, text);
    assert_refused(dir, TD_EUNSUPPORTED, "terrad.json", "version 7");
}

static void test_corrupt_tiles(void **state)
{
    char dir[512];
    (void)state;
    fresh("tiles", dir, sizeof dir);
    flip_byte(dir, TD_PREPARED_TILES, 24 * 3 + 17); /* a zmin byte of tile 3 */
    assert_refused(dir, TD_EFORMAT, "tiles.bin", "checksum");
    fresh("accel-tab", dir, sizeof dir);
    flip_byte(dir, TD_PACC_TAB, 48 * 5 + 9); /* tile 5's code base */
    assert_refused(dir, TD_EFORMAT, "accel.tab", "checksum");
}

/* The heights' chunks come first, then each level's: 10 + 5 + 3 + 2 + 1 + 1 + 1 + 1 + 1
 * for the 200 x 150 crop in chunks of 16 rows (levels 101 x 76, 51 x 39, 26 x 20, 14 x 11,
 * 8 x 6, 5 x 4, 3 x 3, 2 x 2), then heights.blk's 5 bands (of 7 blocks of 33 x 33 samples,
 * 30492 bytes), then the tile rows of structures of tiles of 32 cells: 5 + 3 + 2 + 1 x 6. */
static void test_corrupt_chunk(void **state)
{
    char dir[512];
    td_prepared *p = NULL;
    td_err e = {0};
    (void)state;
    fresh("chunk", dir, sizeof dir);
    /* file rows 48..63 are chunk 3: south rows 86..101 */
    flip_byte(dir, TD_PREPARED_HEIGHTS, (long)(90 * 200 + 7) * 4 + 2);
    /* lod2.f32 (51 x 39): its file rows 16..31 (chunk 1, chunk 16 of all) are south rows 7..22 */
    flip_byte(dir, "lod2.f32", (long)(10 * 51 + 5) * 4 + 2);
    /* band 1 (south rows 32..64), its block 2's sample (7, 3) */
    flip_byte(dir, TD_PREPARED_BLOCKS, 30492 + (long)(2 * 33 * 33 + 3 * 33 + 7) * 4 + 1);
    /* the first tile's structures (its apex heights): tile row 0 of the full grid */
    flip_byte(dir, TD_PACC_BIN, 9);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK); /* open reads no heights */
    assert_int_equal(td_prepared_levels(p), 8);
    assert_int_equal(td_prepared_chunks(p), 46);
    for (int32_t c = 0; c < 46; c++) {
        td_status rc = td_prepared_verify_chunk(p, c, &e);
        if (c == 3) {
            assert_int_equal(rc, TD_EFORMAT);
            assert_non_null(strstr(e.msg, "heights.f32: chunk 3 (file rows 48..63)"));
            assert_non_null(strstr(e.msg, "corrupted"));
        } else if (c == 16) {
            assert_int_equal(rc, TD_EFORMAT);
            if (!strstr(e.msg, "lod2.f32: chunk 1 (file rows 16..31)") || !strstr(e.msg, "corrupted"))
                fail_msg("%s", e.msg);
        } else if (c == 26) {
            assert_int_equal(rc, TD_EFORMAT);
            if (!strstr(e.msg, "heights.blk: band 1 (south rows 32..64)") || !strstr(e.msg, "corrupted"))
                fail_msg("%s", e.msg);
        } else if (c == 30) {
            assert_int_equal(rc, TD_EFORMAT);
            if (!strstr(e.msg, "accel.bin: layer 0 tile 0 (tile row 0)") || !strstr(e.msg, "corrupted"))
                fail_msg("%s", e.msg);
        } else {
            assert_int_equal(rc, TD_OK);
        }
    }
    assert_int_equal(td_prepared_verify_chunk(p, 46, &e), TD_EINVAL);
    td_prepared_free(p);
}

/* A level's files are checked at open as the heights' are: truncated heights, corrupted
 * tile records, an index whose levels do not match the grid. */
static void test_levels_refused(void **state)
{
    char dir[512], p[600], *text, *v;
    (void)state;
    fresh("lod-trunc", dir, sizeof dir);
    snprintf(p, sizeof p, "%s/lod1.f32", dir);
    assert_int_equal(truncate(p, 101 * 76 * 4 - 8), 0);
    assert_refused(dir, TD_EFORMAT, "lod1.f32", "truncated");
    fresh("lod-tiles", dir, sizeof dir);
    flip_byte(dir, "lod3.tiles", 17); /* tile 0's zmin */
    assert_refused(dir, TD_EFORMAT, "lod3.tiles", "checksum");
    fresh("lod-missing", dir, sizeof dir);
    snprintf(p, sizeof p, "%s/lod5.f32", dir);
    assert_int_equal(unlink(p), 0);
    assert_refused(dir, TD_EIO, "lod5.f32", "cannot open");
    /* one level fewer in the index than the grid has */
    fresh("lod-count", dir, sizeof dir);
    text = index_text(dir);
    v = strstr(text, "\"levels\":[");
    assert_non_null(v);
    v += strlen("\"levels\":[");
    memmove(v, strchr(v, '}') + 2, strlen(strchr(v, '}') + 2) + 1); /* drops level 1's entry */
    index_put(dir, text);
    assert_refused(dir, TD_EFORMAT, "terrad.json", "coarse levels");
}

/* Residency: a mapped grid's pages count once touched, and none after a trim. */
static void test_resident(void **state)
{
    char dir[512];
    td_prepared *p = NULL;
    td_err e = {0};
    td_grid *g;
    volatile float sum = 0;
    (void)state;
    fresh("resident", dir, sizeof dir);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    g = td_prepared_take_grid(p);
    for (size_t k = 0; k < (size_t)g->w * (size_t)g->h; k += 256)
        sum += g->z[k];
    for (size_t k = 0; k < g->bmap_bytes / 4; k += 256)
        sum += ((const float *)g->bmap)[k];
    assert_true(td_prepared_resident(g) >= 200 * 150 * 4 + 5 * 30492 - 8192);
    assert_true(td_prepared_cached(g) >= 200 * 150 * 4 + 5 * 30492 - 8192);
    td_prepared_trim(g);
    assert_int_equal(td_prepared_resident(g), 0);
    td_grid_free(g);
    td_prepared_free(p);
}

static void drop_cached(const char *dir, const char *name)
{
    char path[600];
    int fd;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    fd = open(path, O_RDONLY);
    assert_true(fd >= 0);
    assert_int_equal(posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED), 0);
    close(fd);
}

/* After a render ran out of page-in time, the blocks around its camera are asked into the
 * page cache: with both heights files dropped from it, td_prepared_willneed_near of 4 cells
 * around sample (100, 75) brings in that block (band 2, block 3: 4356 bytes) and not the
 * grid: at most a band of blocks (30492 bytes), none of heights.f32. (The read is the
 * kernel's, asynchronous: polled for up to 5 s.) */
static void test_willneed_near(void **state)
{
    char dir[512];
    td_prepared *p = NULL;
    td_err e = {0};
    td_grid *g;
    uint64_t got = 0;
    (void)state;
    fresh("near", dir, sizeof dir);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    g = td_prepared_take_grid(p);
    drop_cached(dir, TD_PREPARED_HEIGHTS);
    drop_cached(dir, TD_PREPARED_BLOCKS);
    assert_int_equal(td_prepared_cached(g), 0);
    td_prepared_willneed_near(g, 100.0 * g->sx, 75.0 * g->sy, 4);
    for (int k = 0; k < 500 && !got; k++) {
        struct timespec nap = {0, 10 * 1000 * 1000};
        nanosleep(&nap, NULL);
        got = td_prepared_cached(g);
    }
    assert_true(got > 0);
    assert_true(got <= 30492 + 4096);
    td_grid_free(g);
    td_prepared_free(p);
}

/* An 80 x 50 view of the crop from (7000, -2000, z) looking north, pitch degrees down,
 * method m on surface su, one thread. */
static void crop_view(td_scene *sc, td_render_opts *o, double z, double pitch, int m, int su)
{
    td_scene_defaults(sc);
    sc->camera.x = 7000.0;
    sc->camera.y = -2000.0;
    sc->camera.z = z;
    sc->camera.pitch = -pitch;
    sc->image.width = 80;
    sc->image.height = 50;
    sc->quality.method = (td_method)m;
    sc->quality.surface = (td_surface)su;
    td_render_opts_default(o);
    o->threads = 1;
}

/* The crop loaded in memory with tiles of 32 cells and its structures built (the planes
 * too when asked; one thread): what a prepared copy's mapped structures are held to. */
static void load_crop_ref(const char *src, int planes, td_grid **ref, td_accel **ra)
{
    td_dem_opts lo;
    td_accel_opts ao;
    td_err e = {0};
    td_dem_opts_default(&lo);
    lo.tile_log2 = 5;
    assert_int_equal(td_dem_load(src, &lo, ref, &e), TD_OK);
    td_accel_opts_default(&ao);
    ao.planes = planes;
    ao.threads = 1;
    assert_int_equal(td_accel_build(*ref, &ao, ra, NULL, &e), TD_OK);
}

/* A render (every method on every surface, shadows, ambient occlusion, smooth normals,
 * with the tiles' max-mipmaps and planes the prepare wrote, mapped) reads heights.blk and
 * accel.bin alone: with the row-major heights.f32 mapping made unreadable (PROT_NONE: any
 * read of it is a crash), the pixels are the source's, byte for byte, and so are the
 * steps of the source with the structures built in memory, which differ from those of
 * the same render without them (parametric and auto: fewer). */
static void test_render_reads_blocks(void **state)
{
    char src[512], dir[512];
    td_prepare_result res;
    td_prepared *p = NULL;
    td_grid *g, *ref = NULL;
    td_accel *ra = NULL;
    td_err e = {0};
    (void)state;
    data_path("trinidad-crop.f32", src, sizeof src);
    tmp_path("render-b8", dir, sizeof dir);
    prepare_blk(src, dir, 5, 0, 3, &res);
    load_crop_ref(src, 1, &ref, &ra);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    g = td_prepared_take_grid(p);
    assert_int_equal(mprotect(g->map, g->map_bytes, PROT_NONE), 0);
    for (int m = 0; m < TD_METHOD_COUNT; m++)
        for (int s = 0; s < TD_SURFACE_COUNT; s++) {
            td_view va = {g, td_prepared_accel(p)}, vb = {ref, ra->tiles}, vc = {g, NULL};
            td_scene sc;
            td_render_opts o;
            td_render_result a, b, c;
            crop_view(&sc, &o, 2600.0, 10.0, m, s);
            sc.quality.smooth_normals = s == TD_SURFACE_BILINEAR;
            sc.effects.shadows = 1;
            sc.effects.ambient_occlusion = s == TD_SURFACE_TRIANGLE ? 4 : 0;
            assert_int_equal(td_render(&va, &sc, &o, &a, &e), TD_OK);
            assert_int_equal(td_render(&vb, &sc, &o, &b, &e), TD_OK);
            assert_int_equal(td_render(&vc, &sc, &o, &c, &e), TD_OK);
            assert_memory_equal(a.rgba, b.rgba, (size_t)80 * 50 * 4);
            assert_memory_equal(a.rgba, c.rgba, (size_t)80 * 50 * 4);
            assert_int_equal(a.stats.steps, b.stats.steps);
            /* used: a near view of small tiles costs the max-mipmap's climbs more than it
               saves (hierarchical), the cones save a fifth or more (parametric, auto) */
            if (m == TD_METHOD_HIERARCHICAL)
                assert_true(a.stats.steps != c.stats.steps);
            if (m == TD_METHOD_PARAMETRIC || m == TD_METHOD_AUTO)
                assert_true(a.stats.steps < c.stats.steps);
            td_render_result_free(&a);
            td_render_result_free(&b);
            td_render_result_free(&c);
        }
    assert_int_equal(mprotect(g->map, g->map_bytes, PROT_READ), 0);
    td_accel_free(ra);
    td_grid_free(g);
    td_grid_free(ref);
    td_prepared_free(p);
}

/* A far view with levels of detail (quality.lod, 8 pixels a coarse cell: the first level
 * from 1.3 km on) from 4 km up, 2 km above the highest sample: every camera ray passes
 * above the full grid's tiles until it is on the levels, so a render reads no
 * full-resolution sample at all, not even to measure a coarse hit's height error (which
 * read the full grid under every far pixel: a page each on a grid larger than memory).
 * Both mappings of the full grid unreadable: the render succeeds, every ray ends on a
 * level, and no error is counted. */
static void test_lod_reads_no_full_grid(void **state)
{
    char src[512], dir[512];
    td_prepare_result res;
    td_prepared *p = NULL;
    td_grid *g;
    td_lod *lod;
    td_scene sc;
    td_render_opts o;
    td_render_result r;
    td_err e = {0};
    uint64_t hits = 0;
    (void)state;
    data_path("trinidad-crop.f32", src, sizeof src);
    tmp_path("lod-far", dir, sizeof dir);
    prepare_ok(src, dir, 5, 0, &res);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    g = td_prepared_take_grid(p);
    lod = td_prepared_take_lod(p);
    assert_non_null(lod);
    assert_int_equal(mprotect(g->map, g->map_bytes, PROT_NONE), 0);
    assert_int_equal(mprotect(g->bmap, g->bmap_bytes, PROT_NONE), 0);
    crop_view(&sc, &o, 4000.0, 20.0, TD_METHOD_AUTO, TD_SURFACE_BILINEAR);
    sc.quality.lod = 1;
    sc.quality.lod_pixels = 8.0;
    o.lod = lod;
    {
        td_view v = {g, NULL};
        assert_int_equal(td_render(&v, &sc, &o, &r, &e), TD_OK);
    }
    assert_int_equal(r.stats.lod_rays[0], 0);
    for (int k = 1; k <= lod->levels; k++)
        hits += r.stats.lod_rays[k];
    assert_true(hits > 0);
    assert_int_equal(r.stats.height_err_hits, 0);
    td_render_result_free(&r);
    assert_int_equal(mprotect(g->map, g->map_bytes, PROT_READ), 0);
    assert_int_equal(mprotect(g->bmap, g->bmap_bytes, PROT_READ), 0);
    td_lod_free(lod);
    td_grid_free(g);
    td_prepared_free(p);
}

/* Far rays on the levels of detail step with the levels' mapped structures: a far view
 * (quality.lod) of the prepared grid, its levels' views holding accel.bin's structures,
 * gives the picture and the steps of the source with td_lod_build's levels (their
 * structures built in memory), every method that uses them on every surface, and other
 * steps than the same levels without them (parametric: fewer). */
static void test_lod_structures_used(void **state)
{
    char src[512], dir[512];
    td_prepare_result res;
    td_prepared *p = NULL;
    td_grid *g, *ref = NULL;
    td_lod *lod, *rl = NULL, bare;
    td_accel_opts ao;
    td_accel *ra = NULL;
    td_err e = {0};
    static const int methods[] = {TD_METHOD_HIERARCHICAL, TD_METHOD_PARAMETRIC, TD_METHOD_AUTO};
    (void)state;
    data_path("trinidad-crop.f32", src, sizeof src);
    tmp_path("lod-acc", dir, sizeof dir);
    prepare_ok(src, dir, 5, 0, &res);
    load_crop_ref(src, 1, &ref, &ra);
    td_accel_opts_default(&ao);
    ao.threads = 1;
    assert_int_equal(td_lod_build(ref, TD_LOD_MAX, &ao, &rl, &e), TD_OK);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    g = td_prepared_take_grid(p);
    lod = td_prepared_take_lod(p);
    assert_non_null(lod);
    bare = *lod;
    for (int k = 1; k <= bare.levels; k++)
        bare.view[k].accel = NULL;
    for (int m = 0; m < 3; m++)
        for (int s = 0; s < TD_SURFACE_COUNT; s++) {
            td_view va = {g, td_prepared_accel(p)}, vb = {ref, ra->tiles};
            td_scene sc;
            td_render_opts o;
            td_render_result a, b, c;
            uint64_t far = 0;
            crop_view(&sc, &o, 4000.0, 20.0, methods[m], s);
            sc.quality.lod = 1;
            sc.quality.lod_pixels = 8.0;
            o.lod = lod;
            assert_int_equal(td_render(&va, &sc, &o, &a, &e), TD_OK);
            o.lod = rl;
            assert_int_equal(td_render(&vb, &sc, &o, &b, &e), TD_OK);
            o.lod = &bare;
            assert_int_equal(td_render(&va, &sc, &o, &c, &e), TD_OK);
            for (int k = 1; k <= lod->levels; k++)
                far += a.stats.lod_rays[k];
            assert_true(far > 0);
            assert_memory_equal(a.rgba, b.rgba, (size_t)80 * 50 * 4);
            assert_memory_equal(a.rgba, c.rgba, (size_t)80 * 50 * 4);
            assert_int_equal(a.stats.steps, b.stats.steps);
            /* used: on levels this small (tiles of 32 cells, the largest 101 x 76 samples)
               the max-mipmap's climbs cost more steps than they save (hierarchical), the
               cones save some (auto's choice depends on the surface) */
            if (methods[m] == TD_METHOD_PARAMETRIC   ? !(a.stats.steps < c.stats.steps)
                : methods[m] == TD_METHOD_HIERARCHICAL ? a.stats.steps == c.stats.steps
                                                       : 0)
                fail_msg("%s on %s: %llu steps with the levels' structures, %llu without",
                         td_method_name(methods[m]), td_surface_name(s), (unsigned long long)a.stats.steps,
                         (unsigned long long)c.stats.steps);
            td_render_result_free(&a);
            td_render_result_free(&b);
            td_render_result_free(&c);
        }
    td_lod_free(lod);
    td_lod_free(rl);
    td_accel_free(ra);
    td_grid_free(g);
    td_grid_free(ref);
    td_prepared_free(p);
}

/* Without planes (terrad prepare --planes-k 0: max-mipmaps only, about half of the
 * structures' bytes): every tile has its max-mipmap and no planes, and every method still
 * gives the source's picture (parametric walks cell by cell: the steps of a render of the
 * source with max-mipmaps alone built). */
static void test_no_planes(void **state)
{
    char src[512], dir[512], with[512];
    td_prepare_result res;
    td_prepare_opts po;
    td_prepared *p = NULL;
    td_grid *g, *ref = NULL;
    td_accel *ra = NULL;
    td_err e = {0};
    struct stat a, b;
    (void)state;
    data_path("trinidad-crop.f32", src, sizeof src);
    tmp_path("no-planes", dir, sizeof dir);
    opts(&po, 5, 0);
    po.planes_k = TD_PREPARE_NO_PLANES;
    if (td_prepare(src, dir, &po, &res, &e) != TD_OK)
        fail_msg("%s", e.msg);
    tmp_path("with-planes", with, sizeof with);
    prepare_ok(src, with, 5, 0, &res);
    {
        char pa[600], pb[600];
        snprintf(pa, sizeof pa, "%s/%s", dir, TD_PACC_BIN);
        snprintf(pb, sizeof pb, "%s/%s", with, TD_PACC_BIN);
        assert_int_equal(stat(pa, &a), 0);
        assert_int_equal(stat(pb, &b), 0);
        assert_true(a.st_size < b.st_size);
    }
    load_crop_ref(src, 0, &ref, &ra);
    assert_int_equal(td_prepared_open(dir, &p, &e), TD_OK);
    for (int c = 0; c < td_prepared_chunks(p); c++)
        assert_int_equal(td_prepared_verify_chunk(p, c, &e), TD_OK);
    g = td_prepared_take_grid(p);
    for (size_t t = 0; t < (size_t)g->tiles_x * (size_t)g->tiles_y; t++) {
        assert_non_null(td_prepared_accel(p)[t].maxmip);
        assert_null(td_prepared_accel(p)[t].planes);
    }
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        td_view va = {g, td_prepared_accel(p)}, vb = {ref, ra->tiles};
        td_scene sc;
        td_render_opts o;
        td_render_result x, y;
        crop_view(&sc, &o, 2600.0, 10.0, m, TD_SURFACE_BILINEAR);
        sc.effects.shadows = 1;
        assert_int_equal(td_render(&va, &sc, &o, &x, &e), TD_OK);
        assert_int_equal(td_render(&vb, &sc, &o, &y, &e), TD_OK);
        assert_memory_equal(x.rgba, y.rgba, (size_t)80 * 50 * 4);
        assert_int_equal(x.stats.steps, y.stats.steps);
        td_render_result_free(&x);
        td_render_result_free(&y);
    }
    td_accel_free(ra);
    td_grid_free(g);
    td_grid_free(ref);
    td_prepared_free(p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_f32_same_as_loader), cmocka_unit_test(test_voids),
        cmocka_unit_test(test_asc_whole),          cmocka_unit_test(test_geotiff_streamed),
        cmocka_unit_test(test_resume),             cmocka_unit_test(test_truncated),
        cmocka_unit_test(test_other_version),      cmocka_unit_test(test_corrupt_tiles),
        cmocka_unit_test(test_corrupt_chunk),      cmocka_unit_test(test_levels_refused),
        cmocka_unit_test(test_resident),           cmocka_unit_test(test_render_reads_blocks),
        cmocka_unit_test(test_lod_reads_no_full_grid), cmocka_unit_test(test_lod_structures_used),
        cmocka_unit_test(test_no_planes),          cmocka_unit_test(test_willneed_near),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
