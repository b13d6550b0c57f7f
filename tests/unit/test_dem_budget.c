/* test_dem_budget.c: memory follows the data, not the header (issue 15, point 2). Tiny files
 * made here claim huge grids and must be refused before the grid is allocated, with a
 * message naming the file and the sizes; a PNG's decode buffers are counted in the byte
 * budget together with the grid (and an interlaced PNG needs no more than a plain one); a
 * .prj whose CRS does not fit the coordinates is refused naming the .prj. */
#include <dirent.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>
#include <png.h>

#include "dem.h"
#include "demutil.h"

static char tmpdir[256];

static void tmp_path(const char *name, char *out, size_t outsz)
{
    snprintf(out, outsz, "%s/%s", tmpdir, name);
}

static void spit(const char *path, const void *buf, size_t len)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(buf, 1, len, f), len);
    assert_int_equal(fclose(f), 0);
}

/* Refused with `want`, no grid, and every one of the NULL-terminated `needles` in the
 * message (the file's path is always one). */
static void refused_with(const char *path, const td_dem_opts *o, td_status want, ...)
{
    td_grid *g = (td_grid *)0x1;
    td_err err = {0};
    va_list ap;
    const char *needle;
    td_status st = td_dem_load(path, o, &g, &err);
    print_message("  refused: [%s] %s\n", td_status_json(st), err.msg);
    assert_int_equal(st, want);
    assert_null(g);
    assert_non_null(strstr(err.msg, path));
    va_start(ap, want);
    while ((needle = va_arg(ap, const char *)) != NULL) {
        if (!strstr(err.msg, needle))
            print_message("  missing '%s'\n", needle);
        assert_non_null(strstr(err.msg, needle));
    }
    va_end(ap);
}

static td_grid *loads(const char *path, const td_dem_opts *o)
{
    td_grid *g = NULL;
    td_err err = {0};
    td_status st = td_dem_load(path, o, &g, &err);
    if (st != TD_OK)
        print_message("unexpected refusal: %s\n", err.msg);
    assert_int_equal(st, TD_OK);
    return g;
}

/* ---- PNG bytes by hand (chunks with their CRC) ------------------------------------------ */

static uint32_t crc32_png(const unsigned char *p, size_t n)
{
    uint32_t c = 0xffffffffu;
    for (size_t k = 0; k < n; k++) {
        c ^= p[k];
        for (int b = 0; b < 8; b++)
            c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return c ^ 0xffffffffu;
}

static void put_be32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

/* Appends chunk `type` with n data bytes at buf + *len. */
static void chunk(unsigned char *buf, size_t *len, const char *type, const unsigned char *data,
                  uint32_t n)
{
    put_be32(buf + *len, n);
    memcpy(buf + *len + 4, type, 4);
    if (n)
        memcpy(buf + *len + 8, data, n);
    put_be32(buf + *len + 8 + n, crc32_png(buf + *len + 4, 4 + (size_t)n));
    *len += 12 + n;
}

/* Signature, IHDR (w x h, depth, colour type, interlace), a 1-entry PLTE for palette images,
 * a tiny IDAT (a zlib stream of a few zero bytes) and IEND: a valid start whose header
 * claims far more than its bytes hold. */
static size_t tiny_png(unsigned char *buf, uint32_t w, uint32_t h, int depth, int ctype,
                       int interlace)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    static const unsigned char idat[] = {0x78, 0x9c, 0x63, 0x00, 0x00, 0x00, 0x01, 0x00, 0x01};
    unsigned char ihdr[13], plte[3] = {1, 134, 160};
    size_t len = 8;
    memcpy(buf, sig, 8);
    put_be32(ihdr, w);
    put_be32(ihdr + 4, h);
    ihdr[8] = (unsigned char)depth;
    ihdr[9] = (unsigned char)ctype;
    ihdr[10] = 0;
    ihdr[11] = 0;
    ihdr[12] = (unsigned char)interlace;
    chunk(buf, &len, "IHDR", ihdr, 13);
    if (ctype == PNG_COLOR_TYPE_PALETTE)
        chunk(buf, &len, "PLTE", plte, 3);
    chunk(buf, &len, "IDAT", idat, sizeof idat);
    chunk(buf, &len, "IEND", NULL, 0);
    return len;
}

/* A real, complete 1-bit palette PNG of w x h pixels, all index 0 (compresses about
 * 1000:1), written by libpng. */
static void bomb_png(const char *path, uint32_t w, uint32_t h, int interlace)
{
    png_color pal[2] = {{1, 134, 160}, {1, 135, 4}};
    FILE *f = fopen(path, "wb");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    unsigned char *row = calloc((w + 7) / 8, 1);
    int passes;
    assert_non_null(f);
    assert_non_null(row);
    png_init_io(png, f);
    png_set_IHDR(png, info, w, h, 1, PNG_COLOR_TYPE_PALETTE, interlace, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_set_PLTE(png, info, pal, 2);
    png_set_compression_level(png, 9);
    png_write_info(png, info);
    passes = png_set_interlace_handling(png);
    for (int p = 0; p < passes; p++)
        for (uint32_t r = 0; r < h; r++)
            png_write_row(png, row);
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    free(row);
    assert_int_equal(fclose(f), 0);
}

/* ---- tests ------------------------------------------------------------------------------ */

/* A 65-byte .asc claiming 16000 x 16000 (1 GB of grid, within the default budget) is
 * refused for what its bytes can hold, not allocated and then found truncated. The
 * boundary: 2 x 2 values in exactly 7 bytes ("1 2 3 4") load. */
static void test_asc_header_claims_too_much(void **state)
{
    char p[512];
    const char *head = "ncols 16000\nnrows 16000\nxllcorner 0\nyllcorner 0\ncellsize 30\n";
    char text[256];
    td_grid *g;
    (void)state;
    tmp_path("claims.asc", p, sizeof p);
    snprintf(text, sizeof text, "%s1 2 3 4\n", head);
    spit(p, text, strlen(text));
    refused_with(p, NULL, TD_EFORMAT, "16000 x 16000 = 256000000 values", "hold at most 4", NULL);

    /* one value short of the bound: 3 x 3 needs 17 bytes after the header */
    snprintf(text, sizeof text, "ncols 3\nnrows 3\nxllcorner 0\nyllcorner 0\ncellsize 30\n1 2 3 4 5 6 7 8");
    spit(p, text, strlen(text));
    refused_with(p, NULL, TD_EFORMAT, "3 x 3 = 9 values", NULL);
    /* exactly the bound loads */
    snprintf(text, sizeof text, "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 30\n1 2 3 4");
    spit(p, text, strlen(text));
    g = loads(p, NULL);
    assert_true(td_grid_at(g, 0, 0) == 3.0f && td_grid_at(g, 1, 1) == 2.0f);
    td_grid_free(g);
    unlink(p);
}

/* 69..81-byte PNGs whose IHDR claims 16000 x 16000 (plain and interlaced, palette and RGB and
 * gray16): refused for what their bytes can decompress to, naming the sizes. */
static void test_png_header_claims_too_much(void **state)
{
    static const struct {
        int depth, ctype, interlace;
        td_dem_encoding enc;
    } cases[] = {
        {1, PNG_COLOR_TYPE_PALETTE, 1, TD_ENC_TERRAIN_RGB},
        {1, PNG_COLOR_TYPE_PALETTE, 0, TD_ENC_TERRAIN_RGB},
        {8, PNG_COLOR_TYPE_RGB, 1, TD_ENC_TERRARIUM},
        {16, PNG_COLOR_TYPE_GRAY, 0, TD_ENC_GRAY16},
    };
    unsigned char buf[256];
    char p[512];
    (void)state;
    tmp_path("claims.png", p, sizeof p);
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        td_dem_opts o;
        size_t len = tiny_png(buf, 16000, 16000, cases[k].depth, cases[k].ctype, cases[k].interlace);
        char want[64];
        assert_true(len < 100);
        spit(p, buf, len);
        td_dem_opts_default(&o);
        o.encoding = cases[k].enc;
        o.spacing[0] = 30;
        o.limits.max_bytes = (uint64_t)1 << 30;
        snprintf(want, sizeof want, "its %zu bytes can hold", len);
        refused_with(p, &o, TD_EFORMAT, "16000 x 16000 pixels", want, NULL);
    }
    unlink(p);
}

/* A complete palette PNG that decompresses about 1000:1: the grid and the decode buffers
 * are one budget. Just under grid + buffers it is refused naming both sizes; at it, the
 * plain and the interlaced file load (the interlaced one needs no whole-image buffer) to the
 * same heights. */
static void test_png_bomb_budget(void **state)
{
    const uint32_t w = 1500, h = 1200;
    const uint64_t grid = td_grid_bytes((int32_t)w, (int32_t)h, TD_TILE_LOG2_DEFAULT);
    const uint64_t bufs = 3u * ((uint64_t)w * 3u + 64u); /* three rows of RGB */
    char p[512], q[512], want[160];
    td_grid *a, *b;
    td_dem_opts o;
    (void)state;
    tmp_path("bomb.png", p, sizeof p);
    tmp_path("bomb-adam7.png", q, sizeof q);
    bomb_png(p, w, h, PNG_INTERLACE_NONE);
    bomb_png(q, w, h, PNG_INTERLACE_ADAM7);
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_TERRAIN_RGB;
    o.spacing[0] = 30;
    o.limits.max_bytes = grid + bufs - 1;
    snprintf(want, sizeof want, "(%llu bytes) and decode buffers (%llu bytes) need %llu bytes, over the budget of %llu",
             (unsigned long long)grid, (unsigned long long)bufs, (unsigned long long)(grid + bufs),
             (unsigned long long)(grid + bufs - 1));
    refused_with(p, &o, TD_ETOOBIG, "grid of 1500 x 1200 samples", want, NULL);
    refused_with(q, &o, TD_ETOOBIG, "grid of 1500 x 1200 samples", want, NULL);
    o.limits.max_bytes = grid + bufs;
    a = loads(p, &o);
    b = loads(q, &o);
    assert_int_equal(a->w, 1500);
    assert_int_equal(b->h, 1200);
    assert_memory_equal(a->z, b->z, (size_t)w * h * sizeof(float));
    assert_true(fabs(a->z[0] - 0.0f) < 1e-3 && a->zmin == a->zmax); /* 0x0186a0 -> 0 m */
    td_grid_free(a);
    td_grid_free(b);
    unlink(p);
    unlink(q);
}

/* GEOGCS over projected coordinates, and PROJCS over what can only be degrees: refused,
 * naming the .prj. The fitting pairs load. */
static void test_asc_prj_mismatch(void **state)
{
    const char *geog = "GEOGCS[\"GCS_WGS_1984\",DATUM[\"D_WGS_1984\",SPHEROID[\"WGS_1984\",6378137.0,"
                       "298.257223563]],PRIMEM[\"Greenwich\",0.0],UNIT[\"Degree\",0.0174532925199433]]";
    const char *proj = "PROJCS[\"WGS_1984_UTM_Zone_13N\",GEOGCS[\"GCS_WGS_1984\",UNIT[\"Degree\","
                       "0.0174532925199433]],PROJECTION[\"Transverse_Mercator\"],UNIT[\"Meter\",1.0]]";
    const char *utm = "ncols 2\nnrows 2\nxllcorner 500000\nyllcorner 4100000\ncellsize 30\n1 2\n3 4\n";
    const char *deg = "ncols 2\nnrows 2\nxllcorner -105.5\nyllcorner 37.25\ncellsize 0.000833333\n1 2\n3 4\n";
    char a[512], prj[512];
    td_grid *g;
    (void)state;
    tmp_path("crs.asc", a, sizeof a);
    tmp_path("crs.prj", prj, sizeof prj);

    spit(a, utm, strlen(utm));
    spit(prj, geog, strlen(geog));
    refused_with(a, NULL, TD_EFORMAT, prj, "says geographic", "is not degrees", NULL);
    spit(prj, proj, strlen(proj));
    g = loads(a, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->sx == 30.0);
    td_grid_free(g);

    spit(a, deg, strlen(deg));
    refused_with(a, NULL, TD_EFORMAT, prj, "says projected", "are degrees", NULL);
    spit(prj, geog, strlen(geog));
    g = loads(a, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT);
    assert_true(g->sx > 70.0 && g->sx < 75.0); /* 3 arc-seconds at 37.25 N: about 73.7 m */
    td_grid_free(g);
    unlink(a);
    unlink(prj);
}

static int group_setup(void **state)
{
    (void)state;
    snprintf(tmpdir, sizeof tmpdir, "/tmp/terrad-test-dem-budget-XXXXXX");
    return mkdtemp(tmpdir) ? 0 : -1;
}

static int group_teardown(void **state)
{
    (void)state;
    rmdir(tmpdir);
    return 0;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_asc_header_claims_too_much),
        cmocka_unit_test(test_png_header_claims_too_much),
        cmocka_unit_test(test_png_bomb_budget),
        cmocka_unit_test(test_asc_prj_mismatch),
    };
    return cmocka_run_group_tests(tests, group_setup, group_teardown);
}
