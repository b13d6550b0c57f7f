/* test_dem.c: every DEM loader on the real fixtures of tests/data, checked against the
 * numbers of their reference JSONs (copied from the reference JSONs of ../shared/data and
 * trinidad/dem.json), and every loader refusing broken input: truncated, corrupted,
 * oversized (a header claiming 100000 x 100000), non-numeric and NaN-laden copies made at
 * run time in a temporary directory. A refusal must return the right status, leave no
 * grid, and name the file in its message; under `make test-asan` none may read past a
 * buffer or leak. The loaders' shared helpers (demutil.h) are tested on their own at the
 * end. Memory follows the data (issue 15): tiny files claiming huge grids are refused
 * before the grid is allocated, a PNG's decode buffers count in the budget with the grid,
 * and a .prj whose CRS does not fit the coordinates is refused naming it. */
#include <dirent.h>
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>
#include <png.h>

#include "dem.h"
#include "demutil.h"

#ifdef TERRAD_HAVE_GDAL
#include <cpl_conv.h>
#include <gdal.h>
#include <ogr_srs_api.h>
#endif

static char tmpdir[256];

/* ---- helpers ------------------------------------------------------------------------ */

static void fixture(const char *name, char *out, size_t outsz)
{
    snprintf(out, outsz, "%s/%s", TERRAD_TEST_DATA, name);
}

static void tmpfile_path(const char *name, char *out, size_t outsz)
{
    snprintf(out, outsz, "%s/%s", tmpdir, name);
}

static unsigned char *slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    unsigned char *buf = NULL;
    long n;
    assert_non_null(f);
    assert_int_equal(fseek(f, 0, SEEK_END), 0);
    n = ftell(f);
    assert_true(n >= 0);
    rewind(f);
    buf = malloc((size_t)n + 1);
    assert_non_null(buf);
    assert_int_equal(fread(buf, 1, (size_t)n, f), (size_t)n);
    buf[n] = 0;
    fclose(f);
    *len = (size_t)n;
    return buf;
}

static void spit(const char *path, const void *buf, size_t len)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(buf, 1, len, f), len);
    assert_int_equal(fclose(f), 0);
}

static void spit_text(const char *path, const char *text) { spit(path, text, strlen(text)); }

static td_grid *load_ok(const char *path, const td_dem_opts *o)
{
    td_grid *g = NULL;
    td_err err = {0};
    td_status st = td_dem_load(path, o, &g, &err);
    if (st != TD_OK)
        print_message("unexpected refusal: %s\n", err.msg);
    assert_int_equal(st, TD_OK);
    assert_non_null(g);
    return g;
}

/* Refused with status `want` (or any failure when want is TD_OK), no grid, message
 * names the file. */
static void refused(const char *path, const td_dem_opts *o, td_status want)
{
    td_grid *g = (td_grid *)0x1;
    td_err err = {0};
    td_status st = td_dem_load(path, o, &g, &err);
    print_message("  refused %s: [%s] %s\n", strrchr(path, '/') + 1, td_status_json(st), err.msg);
    if (want == TD_OK)
        assert_int_not_equal(st, TD_OK);
    else
        assert_int_equal(st, want);
    assert_null(g);
    assert_non_null(strstr(err.msg, path));
}

static double grid_mean(const td_grid *g)
{
    double s = 0.0;
    size_t n = 0;
    for (size_t k = 0; k < (size_t)g->w * (size_t)g->h; k++)
        if (!isnan(g->z[k])) {
            s += g->z[k];
            n++;
        }
    return n ? s / (double)n : NAN;
}

/* Sample at column i of the file's row r (row 0 = north). */
static float at_file_row(const td_grid *g, int32_t i, int32_t r)
{
    return td_grid_at(g, i, g->h - 1 - r);
}

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

static uint32_t be32(const unsigned char *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3];
}

static void put_be32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

/* Offset of the first chunk of `type` (its length field), or 0. */
static size_t png_chunk(const unsigned char *buf, size_t len, const char *type)
{
    size_t off = 8;
    while (off + 12 <= len) {
        uint32_t n = be32(buf + off);
        if (!memcmp(buf + off + 4, type, 4))
            return off;
        off += 12 + (size_t)n;
    }
    return 0;
}

static void png_fix_crc(unsigned char *buf, size_t off)
{
    uint32_t n = be32(buf + off);
    put_be32(buf + off + 8 + n, crc32_png(buf + off + 4, 4 + (size_t)n));
}

/* ---- setup -------------------------------------------------------------------------- */

static int group_setup(void **state)
{
    (void)state;
    snprintf(tmpdir, sizeof tmpdir, "/tmp/terrad-test-dem-XXXXXX");
    return mkdtemp(tmpdir) ? 0 : -1;
}

static int group_teardown(void **state)
{
    DIR *d = opendir(tmpdir);
    struct dirent *e;
    char p[512];
    (void)state;
    while (d && (e = readdir(d))) {
        if (e->d_name[0] != '.') {
            snprintf(p, sizeof p, "%s/%s", tmpdir, e->d_name);
            unlink(p);
        }
    }
    if (d)
        closedir(d);
    rmdir(tmpdir);
    return 0;
}

/* ---- ESRI ASCII --------------------------------------------------------------------- */

static void test_asc_volcano(void **state)
{
    char p[512];
    td_grid *g;
    (void)state;
    fixture("volcano.asc", p, sizeof p);
    g = load_ok(p, NULL);
    assert_int_equal(g->w, 61);
    assert_int_equal(g->h, 87);
    assert_true(g->sx == 10.0 && g->sy == 10.0);
    assert_true(g->zmin == 94.0f && g->zmax == 195.0f);
    assert_int_equal(g->voids, 0);
    assert_true(fabs(grid_mean(g) - 130.1878651) < 1e-4); /* awk over the file */
    /* north row first in the file: its first line is 94 ... 94 95 (column 14) */
    assert_true(at_file_row(g, 0, 0) == 94.0f);
    assert_true(at_file_row(g, 14, 0) == 95.0f);
    /* last line (south): 103 104 104 105 */
    assert_true(td_grid_at(g, 0, 0) == 103.0f);
    assert_true(td_grid_at(g, 3, 0) == 105.0f);
    /* xllcorner 0, cellsize 10: sample (0, 0) is half a cell in; small cells? no: metres */
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->geo.x0 == 5.0 && g->geo.y0 == 5.0);
    assert_int_equal(g->tiles_x * g->tiles_y, 1);
    td_grid_free(g);
}

static void test_asc_picos(void **state)
{
    char p[512];
    td_grid *g;
    (void)state;
    fixture("picos-dtm.asc", p, sizeof p);
    g = load_ok(p, NULL);
    /* picos/dtm.reference.json */
    assert_int_equal(g->w, 714);
    assert_int_equal(g->h, 482);
    assert_int_equal(g->voids, 30403);
    assert_true(g->zmin == 1375.0699462890625f);
    assert_true(g->zmax == 2614.169921875f);
    assert_true(fabs(grid_mean(g) - 1843.0728759765625) < 1e-2);
    assert_true(fabs(g->sx - 4.8889) < 1e-4);
    assert_true(fabs(g->sy - 6.6805) < 1e-4);
    /* lon/lat: cellsize 0.00006 deg, corner -4.813150034548 -> first sample half a cell in */
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT);
    assert_true(fabs(g->geo.x0 - (-4.813150034548 + 0.5 * 0.000060132227)) < 1e-12);
    assert_true(fabs(g->geo.y0 - (43.166002468076 + 0.5 * 0.000060132227)) < 1e-12);
    assert_true(g->geo.dx == 0.000060132227);
    /* the ragged void frame: the file's first sample is -9999 */
    assert_true(isnan(at_file_row(g, 0, 0)));
    td_grid_free(g);
}

static void test_asc_variants(void **state)
{
    char p[512];
    td_grid *g;
    (void)state;
    /* xllcenter, dx/dy, NODATA, mixed-case keys, values in any whitespace layout */
    tmpfile_path("centre.asc", p, sizeof p);
    spit_text(p, "NCOLS 3\nnrows 2\nxllcenter 500000\nYLLCENTER 4100000\ndx 30\ndy 25\n"
                 "nodata_value -9999\n1.5 2 -9999\n\t4e2   5 6\n");
    g = load_ok(p, NULL);
    assert_int_equal(g->w, 3);
    assert_int_equal(g->h, 2);
    assert_true(g->sx == 30.0 && g->sy == 25.0);
    assert_int_equal(g->voids, 1);
    assert_true(isnan(at_file_row(g, 2, 0)));
    assert_true(at_file_row(g, 0, 0) == 1.5f);
    assert_true(td_grid_at(g, 0, 0) == 400.0f);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->geo.x0 == 500000.0 && g->geo.y0 == 4100000.0);
    td_grid_free(g);

    /* CRLF line ends, a trailing newline-less last value */
    tmpfile_path("crlf.asc", p, sizeof p);
    spit_text(p, "ncols 2\r\nnrows 2\r\nxllcorner 0\r\nyllcorner 0\r\ncellsize 5\r\n1 2\r\n3 4");
    g = load_ok(p, NULL);
    assert_true(at_file_row(g, 1, 1) == 4.0f && at_file_row(g, 0, 0) == 1.0f);
    td_grid_free(g);

    /* a .prj beside the file decides geographic vs projected */
    tmpfile_path("tiny.asc", p, sizeof p);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 0.05\n1 2\n3 4\n");
    g = load_ok(p, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT); /* the documented rule without .prj */
    td_grid_free(g);
    tmpfile_path("tiny.prj", p, sizeof p);
    spit_text(p, "PROJCS[\"local\",UNIT[\"metre\",1]]");
    tmpfile_path("tiny.asc", p, sizeof p);
    g = load_ok(p, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->sx == 0.05);
    td_grid_free(g);

    /* the projected CRS's linear unit scales the cell size to metres: a real ESRI .prj
       in US survey feet (WKT1: the GEOGCS's degree comes first), and WKT2's LENGTHUNIT */
    tmpfile_path("tiny.prj", p, sizeof p);
    spit_text(p, "PROJCS[\"NAD_1983_StatePlane_Colorado_Central_FIPS_0502_Feet\",GEOGCS[\"GCS_North_"
                 "American_1983\",DATUM[\"D_North_American_1983\",SPHEROID[\"GRS_1980\",6378137.0,"
                 "298.257222101]],PRIMEM[\"Greenwich\",0.0],UNIT[\"Degree\",0.0174532925199433]],"
                 "PROJECTION[\"Lambert_Conformal_Conic\"],PARAMETER[\"False_Easting\",3000000.000316083],"
                 "PARAMETER[\"Central_Meridian\",-105.5],UNIT[\"Foot_US\",0.3048006096012192]]");
    tmpfile_path("tiny.asc", p, sizeof p);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 3000000\nyllcorner 1500000\ncellsize 10\n1 2\n3 4\n");
    g = load_ok(p, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(fabs(g->sx - 3.048006096012192) < 1e-12 && g->sy == g->sx);
    assert_true(g->geo.dx == 10.0); /* the georeference stays in the CRS's units */
    assert_true(td_grid_at(g, 0, 0) == 3.0f); /* heights are not scaled */
    td_grid_free(g);
    {
        td_dem_opts o;
        td_dem_opts_default(&o);
        o.spacing[0] = 2.5; /* --spacing still overrides */
        g = load_ok(p, &o);
        assert_true(g->sx == 2.5);
        td_grid_free(g);
    }
    tmpfile_path("tiny.prj", p, sizeof p);
    spit_text(p, "PROJCRS[\"x\",BASEGEOGCRS[\"y\",ANGLEUNIT[\"degree\",0.0174532925199433]],"
                 "CS[Cartesian,2],LENGTHUNIT[\"US survey foot\", 0.304800609601219]]");
    tmpfile_path("tiny.asc", p, sizeof p);
    g = load_ok(p, NULL);
    assert_true(fabs(g->sx - 3.04800609601219) < 1e-12);
    td_grid_free(g);
    /* a compound CRS: the projected part's metre, not the vertical part's foot after it */
    tmpfile_path("tiny.prj", p, sizeof p);
    spit_text(p, "COMPD_CS[\"x\",PROJCS[\"UTM [13N]\",GEOGCS[\"g\",UNIT[\"Degree\",0.0174532925199433]],"
                 "PROJECTION[\"Transverse_Mercator\"],UNIT[\"metre\",1,AUTHORITY[\"EPSG\",\"9001\"]]],"
                 "VERT_CS[\"v\",VERT_DATUM[\"d\",2005],UNIT[\"foot\",0.3048]]]");
    tmpfile_path("tiny.asc", p, sizeof p);
    g = load_ok(p, NULL);
    assert_true(g->sx == 10.0);
    td_grid_free(g);
    /* a unit that is there but unreadable is refused, naming the .prj */
    tmpfile_path("tiny.prj", p, sizeof p);
    spit_text(p, "PROJCS[\"local\",UNIT[\"furlong\",-201.168]]");
    tmpfile_path("tiny.asc", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    {
        td_grid *none = NULL;
        td_err err = {0};
        assert_int_equal(td_dem_load(p, NULL, &none, &err), TD_EFORMAT);
        assert_non_null(strstr(err.msg, "tiny.prj"));
    }
    tmpfile_path("tiny.prj", p, sizeof p);
    unlink(p);
}

static void test_asc_refusals(void **state)
{
    char src[512], p[512];
    size_t len;
    unsigned char *buf;
    td_dem_opts o;
    (void)state;
    fixture("volcano.asc", src, sizeof src);
    buf = slurp(src, &len);

    tmpfile_path("trunc.asc", p, sizeof p); /* cut mid-data */
    spit(p, buf, len / 2);
    refused(p, NULL, TD_EFORMAT);
    spit(p, buf, 40); /* cut in the header */
    refused(p, NULL, TD_EFORMAT);
    spit(p, "", 0);
    refused(p, NULL, TD_EFORMAT);

    tmpfile_path("extra.asc", p, sizeof p); /* one value too many */
    {
        unsigned char *b2 = malloc(len + 8);
        assert_non_null(b2);
        memcpy(b2, buf, len);
        memcpy(b2 + len, " 100\n", 5);
        spit(p, b2, len + 5);
        free(b2);
    }
    refused(p, NULL, TD_EFORMAT);

    /* a bad token in the middle of the data, in several spellings (inserted, so it is
       reached long before the value count could run out) */
    {
        static const char *const bad[] = {"abc", "nan", "NaN", "inf", "-inf", "12x", "0x1F", "1e999", "--3"};
        for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
            unsigned char *b2 = malloc(len + 16);
            size_t at = len / 2;
            assert_non_null(b2);
            while (buf[at] != ' ')
                at++;
            memcpy(b2, buf, at + 1);
            memcpy(b2 + at + 1, bad[k], strlen(bad[k]));
            b2[at + 1 + strlen(bad[k])] = ' ';
            memcpy(b2 + at + 2 + strlen(bad[k]), buf + at + 1, len - at - 1);
            tmpfile_path("bad.asc", p, sizeof p);
            spit(p, b2, len + 1 + strlen(bad[k]));
            refused(p, NULL, TD_EFORMAT);
            free(b2);
        }
    }
    /* binary garbage in the data */
    {
        unsigned char *b2 = malloc(len);
        assert_non_null(b2);
        memcpy(b2, buf, len);
        for (size_t k = len / 3; k < len / 3 + 64; k++)
            b2[k] = (unsigned char)(k * 37 + 1);
        tmpfile_path("garbage.asc", p, sizeof p);
        spit(p, b2, len);
        refused(p, NULL, TD_EFORMAT);
        free(b2);
    }
    free(buf);

    tmpfile_path("hdr.asc", p, sizeof p);
    /* oversized: refused as too big before anything is allocated (under ASan a 40 GB
       allocation would abort the test) */
    spit_text(p, "ncols 100000\nnrows 100000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n");
    refused(p, NULL, TD_ETOOBIG);
    spit_text(p, "ncols 3000000000\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n");
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2.5\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n");
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize -1\n1 2 3 4\n");
    refused(p, NULL, TD_ERANGE);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize nan\n1 2 3 4\n");
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2 3 4\n"); /* no cellsize */
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2\nnrows 2\nncols 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n");
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 0\nxllcenter 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n");
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2\nnrows 2\ncolour blue\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n");
    refused(p, NULL, TD_EFORMAT);
    spit_text(p, "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 1e39\n");
    refused(p, NULL, TD_ERANGE); /* does not fit a float */

    /* limits from the options */
    fixture("volcano.asc", src, sizeof src);
    td_dem_opts_default(&o);
    o.limits.max_height = 86;
    refused(src, &o, TD_ETOOBIG);
    td_dem_opts_default(&o);
    o.limits.max_bytes = 61 * 87 * 4;
    refused(src, &o, TD_ETOOBIG);
}

/* ---- SRTM .hgt ---------------------------------------------------------------------- */

static void test_hgt(void **state)
{
    char p[512];
    td_grid *g;
    (void)state;
    fixture("N37W105.hgt", p, sizeof p);
    g = load_ok(p, NULL);
    /* east half of Trinidad (../shared/data/README.md): 1359 .. 4116 m, no voids */
    assert_int_equal(g->w, 1201);
    assert_int_equal(g->h, 1201);
    assert_true(g->zmin == 1359.0f && g->zmax == 4116.0f);
    assert_int_equal(g->voids, 0);
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT);
    assert_true(g->geo.x0 == -105.0 && g->geo.y0 == 37.0);
    assert_true(fabs(g->geo.dx - 1.0 / 1200.0) < 1e-15);
    /* 3" at 37.5 N, as trinidad/dem.json's spacing_m */
    assert_true(fabs(g->sx - 73.688) < 5e-4);
    assert_true(fabs(g->sy - 92.489) < 5e-4);
    assert_int_equal(g->tiles_x, 5);
    td_grid_free(g);
}

static void test_hgt_refusals(void **state)
{
    char src[512], p[512];
    size_t len;
    unsigned char *buf;
    td_grid *g;
    td_dem_opts o;
    (void)state;
    fixture("N37W105.hgt", src, sizeof src);
    buf = slurp(src, &len);
    assert_int_equal(len, 1201u * 1201u * 2u);

    tmpfile_path("N37W105.hgt", p, sizeof p);
    spit(p, buf, len - 1); /* truncated by one byte */
    refused(p, NULL, TD_EFORMAT);
    spit(p, buf, len / 2);
    refused(p, NULL, TD_EFORMAT);
    spit(p, "", 0);
    refused(p, NULL, TD_EFORMAT);

    /* voids (-32768) where the file says, rows flipped to south-based */
    buf[2 * 5] = 0x80; /* north row 0, column 5 */
    buf[2 * 5 + 1] = 0x00;
    buf[2 * (1200 * 1201 + 7)] = 0x80; /* south row, column 7 */
    buf[2 * (1200 * 1201 + 7) + 1] = 0x00;
    spit(p, buf, len);
    g = load_ok(p, NULL);
    assert_int_equal(g->voids, 2);
    assert_true(isnan(td_grid_at(g, 5, 1200)));
    assert_true(isnan(td_grid_at(g, 7, 0)));
    assert_false(isnan(td_grid_at(g, 6, 1200)));
    td_grid_free(g);

    /* corrupted: an impossible height (32767 m), and the whole file byte-swapped */
    buf[2 * 600000] = 0x7f;
    buf[2 * 600000 + 1] = 0xff;
    spit(p, buf, len);
    refused(p, NULL, TD_ERANGE);
    for (size_t k = 0; k + 1 < len; k += 2) {
        unsigned char t = buf[k];
        buf[k] = buf[k + 1];
        buf[k + 1] = t;
    }
    spit(p, buf, len);
    refused(p, NULL, TD_ERANGE);

    /* the name carries the place: no name, no georeference */
    tmpfile_path("tile.hgt", p, sizeof p);
    spit(p, buf, len);
    refused(p, NULL, TD_EFORMAT);
    tmpfile_path("N95W105.hgt", p, sizeof p);
    spit(p, buf, len);
    refused(p, NULL, TD_EFORMAT);
    free(buf);

    /* SRTM-1: 3601 x 3601, south/east names; all voids but one sample */
    {
        size_t n1 = 3601u * 3601u * 2u;
        unsigned char *b1 = malloc(n1);
        assert_non_null(b1);
        for (size_t k = 0; k < n1; k += 2) {
            b1[k] = 0x80;
            b1[k + 1] = 0x00;
        }
        b1[2 * (3601 * 3600 + 3600)] = 0x01; /* south-east sample: 256 + 2 m */
        b1[2 * (3601 * 3600 + 3600) + 1] = 0x02;
        tmpfile_path("s12e130.hgt", p, sizeof p);
        spit(p, b1, n1);
        free(b1);
        g = load_ok(p, NULL);
        assert_int_equal(g->w, 3601);
        assert_int_equal(g->voids, (int64_t)3601 * 3601 - 1);
        assert_true(g->zmin == 258.0f && g->zmax == 258.0f);
        assert_true(td_grid_at(g, 3600, 0) == 258.0f);
        assert_true(g->geo.x0 == 130.0 && g->geo.y0 == -12.0);
        assert_true(fabs(g->geo.dx - 1.0 / 3600.0) < 1e-15);
        assert_true(fabs(g->sx - 30.0) < 0.5 && fabs(g->sy - 30.7) < 0.2); /* 1" at 11.5 S */
        td_grid_free(g);
    }

    /* limits: a 1201 tile refused by a smaller configured limit */
    td_dem_opts_default(&o);
    o.limits.max_width = 1200;
    refused(src, &o, TD_ETOOBIG);
}

/* ---- raw float32 + JSON sidecar ------------------------------------------------------ */

static void test_f32_trinidad_crop(void **state)
{
    char p[512];
    td_grid *g, *h;
    (void)state;
    fixture("trinidad-crop.f32", p, sizeof p);
    g = load_ok(p, NULL);
    assert_int_equal(g->w, 200);
    assert_int_equal(g->h, 150);
    assert_true(g->zmin == 1676.0f && g->zmax == 1950.0f);
    assert_int_equal(g->voids, 0);
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT);
    /* origin: lon_west -106 + 1800 * dlon; south row = lat_north - 149 dlat */
    assert_true(fabs(g->geo.x0 - (-104.5)) < 1e-7);
    assert_true(fabs(g->geo.y0 - (38.0 - 549.0 / 1200.0)) < 1e-6);
    assert_true(fabs(g->sy - 92.489) < 5e-3);
    /* the crop is columns 600.., rows 400.. of N37W105.hgt: same heights, same places */
    fixture("N37W105.hgt", p, sizeof p);
    h = load_ok(p, NULL);
    for (int32_t r = 0; r < 150; r++)
        for (int32_t i = 0; i < 200; i++)
            assert_true(at_file_row(g, i, r) == at_file_row(h, 600 + i, 400 + r));
    assert_true(fabs(g->geo.x0 - (h->geo.x0 + 600 * h->geo.dx)) < 1e-7);
    td_grid_free(g);
    td_grid_free(h);
}

static void write_f32(const char *name, const float *v, size_t n, const char *sidecar_name,
                      const char *sidecar, char *p, size_t psz)
{
    char s[512];
    tmpfile_path(sidecar_name, s, sizeof s);
    spit_text(s, sidecar);
    tmpfile_path(name, p, psz);
    spit(p, v, n * sizeof(float));
}

static void test_f32_voids_and_refusals(void **state)
{
    char p[512], src[512];
    float v[12];
    td_grid *g;
    td_dem_opts o;
    (void)state;
    for (int k = 0; k < 12; k++)
        v[k] = (float)(100 + k);
    v[1] = -9999.0f;
    /* 4 x 3, numeric nodata, projected origin, spacing [sx, sy] */
    write_f32("a.f32", v, 12, "a.json",
              "{\"width\": 4, \"height\": 3, \"spacing_m\": [2, 3], \"nodata\": -9999,"
              " \"origin\": {\"x_ul\": 1000, \"y_ul\": 2000, \"crs\": \"EPSG:32613\"},"
              " \"min\": 0, \"source\": {\"anything\": true}}",
              p, sizeof p);
    g = load_ok(p, NULL);
    assert_int_equal(g->voids, 1);
    assert_true(isnan(at_file_row(g, 1, 0)));
    assert_true(at_file_row(g, 0, 0) == 100.0f);
    assert_true(td_grid_at(g, 3, 0) == 111.0f); /* last value of the file: south-east */
    assert_true(g->sx == 2.0 && g->sy == 3.0);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->geo.x0 == 1000.0 && g->geo.y0 == 2000.0 - 2 * 3.0);
    assert_string_equal(g->geo.crs, "EPSG:32613");
    td_grid_free(g);
    /* options override the sidecar's spacing */
    td_dem_opts_default(&o);
    o.spacing[0] = 5.0;
    g = load_ok(p, &o);
    assert_true(g->sx == 5.0 && g->sy == 5.0);
    td_grid_free(g);

    /* NaN samples: refused unless the sidecar declares NaN voids */
    v[1] = NAN;
    v[6] = NAN;
    write_f32("nan.f32", v, 12, "nan.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1, \"nodata\": null}",
              p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nan.f32", v, 12, "nan.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1, \"nodata\": \"nan\"}",
              p, sizeof p);
    g = load_ok(p, NULL);
    assert_int_equal(g->voids, 2);
    td_grid_free(g);
    v[1] = INFINITY;
    write_f32("inf.f32", v, 12, "inf.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1, \"nodata\": \"nan\"}",
              p, sizeof p);
    refused(p, NULL, TD_ERANGE);
    v[1] = 1.0f;
    v[6] = 1.0f;

    /* size mismatch: truncated and too long */
    write_f32("short.f32", v, 11, "short.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1}", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("long.f32", v, 12, "long.json", "{\"width\": 4, \"height\": 2, \"spacing_m\": 1}", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    /* oversized: a sidecar claiming 100000 x 100000 is too big, before reading */
    write_f32("huge.f32", v, 12, "huge.json", "{\"width\": 100000, \"height\": 100000, \"spacing_m\": 1}",
              p, sizeof p);
    refused(p, NULL, TD_ETOOBIG);
    /* non-numeric, missing, wrong or corrupted sidecar */
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": \"abc\", \"height\": 3, \"spacing_m\": 1}", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": \"20\"}", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": [1, -2]}", p, sizeof p);
    refused(p, NULL, TD_ERANGE);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4.5, \"height\": 3, \"spacing_m\": 1}", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1, \"nodata\": \"none\"}",
              p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3}", p, sizeof p);
    refused(p, NULL, TD_EINVAL); /* no spacing, no lon/lat origin */
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1, \"dtype\": \"int16\"}",
              p, sizeof p);
    refused(p, NULL, TD_EUNSUPPORTED);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"spacing_m\": 1, \"origin\": {\"lon_west\": 10}}",
              p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"width\": 4, \"spacing_m\": 1}", p, sizeof p);
    refused(p, NULL, TD_EFORMAT); /* duplicate key */
    write_f32("nn.f32", v, 12, "nn.json", "{\"width\": 4, \"height\": 3, \"spac", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    write_f32("nn.f32", v, 12, "nn.json", "[4, 3]", p, sizeof p);
    refused(p, NULL, TD_EFORMAT);
    tmpfile_path("alone.f32", p, sizeof p);
    spit(p, v, sizeof v);
    refused(p, NULL, TD_ENOTFOUND);

    /* the real crop, truncated and corrupted (its sidecar copied beside) */
    {
        size_t len, slen;
        unsigned char *buf, *side;
        fixture("trinidad-crop.json", src, sizeof src);
        side = slurp(src, &slen);
        fixture("trinidad-crop.f32", src, sizeof src);
        buf = slurp(src, &len);
        tmpfile_path("crop.json", p, sizeof p);
        spit(p, side, slen);
        tmpfile_path("crop.f32", p, sizeof p);
        spit(p, buf, len - 4);
        refused(p, NULL, TD_EFORMAT);
        memset(buf + len / 2, 0xff, 16); /* 0xffffffff is a NaN */
        spit(p, buf, len);
        refused(p, NULL, TD_EFORMAT);
        free(buf);
        free(side);
    }
}

/* ---- PNG ---------------------------------------------------------------------------- */

static void test_png_levi_rgbdiv(void **state)
{
    char p[512];
    td_grid *g;
    td_dem_opts o;
    (void)state;
    fixture("levi-topography.png", p, sizeof p);
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_RGB_DIV; /* divisor defaults to the Levi file's 11983 */
    o.spacing[0] = 20.0;
    g = load_ok(p, &o);
    /* levi/topography.reference.json */
    assert_int_equal(g->w, 400);
    assert_int_equal(g->h, 400);
    assert_true(fabs(g->zmin - 180.00100708007812) < 1e-4);
    assert_true(fabs(g->zmax - 530.6049194335938) < 1e-4);
    assert_true(fabs(grid_mean(g) - 227.7669677734375) < 1e-3);
    assert_int_equal(g->voids, 0);
    assert_true(g->sx == 20.0 && g->sy == 20.0);
    assert_int_equal(g->geo.kind, TD_GEO_NONE);
    td_grid_free(g);
}

/* The two re-encodings of Levi decode to the same heights within their quantisation. */
static void test_png_levi_reencoded(void **state)
{
    char p[512];
    td_grid *ref, *g;
    td_dem_opts o;
    double worst = 0.0;
    (void)state;
    fixture("levi-topography.png", p, sizeof p);
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_RGB_DIV;
    o.spacing[0] = 20.0;
    ref = load_ok(p, &o);

    fixture("levi-terrainrgb.png", p, sizeof p);
    o.encoding = TD_ENC_TERRAIN_RGB;
    g = load_ok(p, &o);
    assert_int_equal(g->w, 400);
    assert_int_equal(g->voids, 0);
    assert_true(fabs(g->zmin - 180.0) < 0.06 && fabs(g->zmax - 530.6) < 0.06);
    for (size_t k = 0; k < 400 * 400; k++)
        worst = fmax(worst, fabs((double)g->z[k] - ref->z[k]));
    assert_true(worst <= 0.05 + 1e-3); /* 0.1 m steps */
    td_grid_free(g);

    fixture("levi-terrarium.png", p, sizeof p);
    o.encoding = TD_ENC_TERRARIUM;
    g = load_ok(p, &o);
    worst = 0.0;
    for (size_t k = 0; k < 400 * 400; k++)
        worst = fmax(worst, fabs((double)g->z[k] - ref->z[k]));
    assert_true(worst <= 1.0 / 256.0 + 1e-3); /* 1/256 m steps */
    td_grid_free(g);

    /* the wrong encoding decodes without complaint to very wrong heights: this is why
       the encoding is never guessed */
    o.encoding = TD_ENC_TERRAIN_RGB;
    fixture("levi-terrarium.png", p, sizeof p);
    g = load_ok(p, &o);
    assert_true(fabs(g->zmax - ref->zmax) > 1000.0);
    td_grid_free(g);
    td_grid_free(ref);
}

static void test_png_gray16_trinidad_west(void **state)
{
    char p[512], q[512];
    td_grid *w, *e;
    td_dem_opts o;
    (void)state;
    fixture("trinidad-west-u16.png", p, sizeof p);
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_GRAY16;
    o.spacing[0] = 73.688;
    o.spacing[1] = 92.489;
    w = load_ok(p, &o);
    assert_int_equal(w->w, 1201);
    assert_int_equal(w->h, 1201);
    assert_true(w->zmin == 1951.0f && w->zmax == 4322.0f);
    assert_int_equal(w->voids, 0);
    assert_true(w->sx == 73.688 && w->sy == 92.489);
    /* with its east neighbour it is trinidad/dem.json: 2401 x 1201, 1359 .. 4322 m,
       no voids; the halves share column 1200 */
    fixture("N37W105.hgt", q, sizeof q);
    e = load_ok(q, NULL);
    assert_int_equal(w->w + e->w - 1, 2401);
    assert_int_equal(w->h, 1201);
    assert_true(fminf(w->zmin, e->zmin) == 1359.0f);
    assert_true(fmaxf(w->zmax, e->zmax) == 4322.0f);
    assert_int_equal(w->voids + e->voids, 0);
    for (int32_t j = 0; j < 1201; j++)
        assert_true(td_grid_at(w, 1200, j) == td_grid_at(e, 0, j));
    td_grid_free(e);
    td_grid_free(w);

    /* scale and offset (feet to metres, say), and a nodata raw value */
    o.scale = 0.5;
    o.offset = -100.0;
    o.given = TD_DEM_GIVEN_SCALE | TD_DEM_GIVEN_OFFSET;
    o.has_nodata = 1;
    o.nodata = 4322.0;
    w = load_ok(p, &o);
    assert_true(w->zmin == 1951.0f * 0.5f - 100.0f);
    assert_true(w->voids >= 1);
    assert_true(w->zmax < 4322.0f * 0.5f - 100.0f);
    td_grid_free(w);
}

static void test_png_sidecar_and_no_encoding(void **state)
{
    char src[512], p[512], s[512];
    size_t len;
    unsigned char *buf;
    td_grid *g;
    td_dem_opts o;
    (void)state;
    fixture("levi-topography.png", src, sizeof src);
    buf = slurp(src, &len);
    tmpfile_path("levi.png", p, sizeof p);
    spit(p, buf, len);
    free(buf);

    /* no encoding anywhere: refused, naming the flag and the sidecar */
    refused(p, NULL, TD_EINVAL);
    assert_int_equal(td_dem_recognised(p), 0);
    {
        td_err err = {0};
        td_grid *none = NULL;
        td_dem_load(p, NULL, &none, &err);
        assert_non_null(strstr(err.msg, "--encoding"));
        assert_non_null(strstr(err.msg, "levi.json"));
    }
    /* encoding without spacing: refused */
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_RGB_DIV;
    refused(p, &o, TD_EINVAL);

    /* the sidecar gives everything */
    tmpfile_path("levi.json", s, sizeof s);
    spit_text(s, "{\"encoding\": \"rgb-div\", \"divisor\": 11983, \"spacing_m\": 20}");
    assert_int_equal(td_dem_recognised(p), 1);
    g = load_ok(p, NULL);
    assert_true(fabs(g->zmax - 530.6049194335938) < 1e-4);
    assert_true(g->sx == 20.0);
    td_grid_free(g);
    /* an explicit option wins over the sidecar; an unset one does not */
    td_dem_opts_default(&o);
    o.divisor = 2 * 11983.0;
    g = load_ok(p, &o);
    assert_true(fabs(g->zmax - 530.6049194335938) < 1e-4);
    td_grid_free(g);
    o.given = TD_DEM_GIVEN_DIVISOR;
    g = load_ok(p, &o);
    assert_true(fabs(g->zmax - 530.6049194335938 / 2) < 1e-4);
    td_grid_free(g);

    /* lon/lat origin in a sidecar gives georeference and spacing */
    spit_text(s, "{\"encoding\": \"rgb-div\", \"origin\": {\"lon_west\": 24.8, \"lat_north\": 67.8,"
                 " \"dlon_deg\": 0.0005, \"dlat_deg\": 0.0002}}");
    g = load_ok(p, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT);
    assert_true(fabs(g->geo.y0 - (67.8 - 399 * 0.0002)) < 1e-9);
    assert_true(g->sx > 20.0 && g->sx < 22.0); /* 0.0005 deg at 67.76 N */
    assert_true(g->sy > 22.0 && g->sy < 23.0);
    td_grid_free(g);

    /* bad sidecars */
    spit_text(s, "{\"encoding\": \"guess\", \"spacing_m\": 20}");
    refused(p, NULL, TD_EFORMAT);
    spit_text(s, "{\"encoding\": \"rgb-div\", \"divisor\": \"abc\", \"spacing_m\": 20}");
    refused(p, NULL, TD_EFORMAT);
    spit_text(s, "{\"encoding\": \"rgb-div\", \"divisor\": 0, \"spacing_m\": 20}");
    refused(p, NULL, TD_ERANGE);
    spit_text(s, "{\"encoding\": \"gray16\", \"spacing_m\": 20}"); /* RGBA is not gray16 */
    refused(p, NULL, TD_EFORMAT);
    spit_text(s, "not json");
    refused(p, NULL, TD_EFORMAT);

    /* NaN parameters are refused, never turned into NaN heights */
    unlink(s);
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_RGB_DIV;
    o.spacing[0] = 20.0;
    o.divisor = NAN;
    o.given = TD_DEM_GIVEN_DIVISOR;
    refused(p, &o, TD_ERANGE);
    fixture("trinidad-west-u16.png", src, sizeof src);
    o.encoding = TD_ENC_GRAY16;
    o.scale = NAN;
    o.given = TD_DEM_GIVEN_SCALE;
    refused(src, &o, TD_ERANGE);
    o.scale = 1.0;
    o.has_nodata = 1;
    o.nodata = NAN;
    refused(src, &o, TD_ERANGE);
}

static void test_png_refusals(void **state)
{
    char src[512], p[512];
    size_t len, off;
    unsigned char *buf, *b2;
    td_dem_opts o;
    (void)state;
    td_dem_opts_default(&o);
    o.encoding = TD_ENC_TERRAIN_RGB;
    o.spacing[0] = 20.0;
    fixture("levi-terrainrgb.png", src, sizeof src);
    buf = slurp(src, &len);
    b2 = malloc(len);
    assert_non_null(b2);
    tmpfile_path("bad.png", p, sizeof p);

    /* truncated: at several places */
    {
        const size_t cuts[] = {4, 8, 20, 40, 200, len / 2, len - 13, len - 1};
        for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++) {
            spit(p, buf, cuts[k]);
            refused(p, &o, TD_EFORMAT);
        }
    }
    /* not a PNG */
    spit_text(p, "ncols 2\nnrows 2\n");
    refused(p, &o, TD_EFORMAT);

    /* corrupted image data: caught by the chunk CRC ... */
    off = png_chunk(buf, len, "IDAT");
    assert_true(off > 0);
    memcpy(b2, buf, len);
    for (size_t k = 0; k < 32; k++)
        b2[off + 8 + 100 + k] ^= 0x5a;
    spit(p, b2, len);
    refused(p, &o, TD_EFORMAT);
    /* ... and with a fixed-up CRC, by the decompressor */
    png_fix_crc(b2, off);
    spit(p, b2, len);
    refused(p, &o, TD_EFORMAT);

    /* oversized: an IHDR claiming 100000 x 100000 (valid CRC) is refused before any
       allocation */
    memcpy(b2, buf, len);
    off = png_chunk(b2, len, "IHDR");
    assert_int_equal(off, 8);
    put_be32(b2 + off + 8, 100000);
    put_be32(b2 + off + 12, 100000);
    png_fix_crc(b2, off);
    spit(p, b2, len);
    refused(p, &o, TD_ETOOBIG);
    /* zero width: invalid IHDR */
    put_be32(b2 + off + 8, 0);
    png_fix_crc(b2, off);
    spit(p, b2, len);
    refused(p, &o, TD_EFORMAT);
    /* a smaller height than the data: extra data is a format error or ignored, never a
       crash; larger: truncated image data */
    put_be32(b2 + off + 8, 400);
    put_be32(b2 + off + 12, 800);
    png_fix_crc(b2, off);
    spit(p, b2, len);
    refused(p, &o, TD_EFORMAT);

    /* limits from the options */
    fixture("levi-terrainrgb.png", src, sizeof src);
    o.limits.max_width = 399;
    refused(src, &o, TD_ETOOBIG);
    free(b2);
    free(buf);
}

/* Reads a whole PNG as libpng gives it (no transforms), for re-encoding. */
static unsigned char *png_pixels(const char *path, png_uint_32 *w, png_uint_32 *h, int *depth,
                                 int *ctype, size_t *rowbytes)
{
    FILE *f = fopen(path, "rb");
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    unsigned char *px;
    assert_non_null(f);
    png_init_io(png, f);
    png_read_info(png, info);
    png_get_IHDR(png, info, w, h, depth, ctype, NULL, NULL, NULL);
    *rowbytes = png_get_rowbytes(png, info);
    px = malloc(*rowbytes * *h);
    assert_non_null(px);
    for (png_uint_32 r = 0; r < *h; r++)
        png_read_row(png, px + r * *rowbytes, NULL);
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    return px;
}

typedef struct png_out {
    png_uint_32 w, h;
    int depth, ctype, interlace;
    size_t rowbytes;
    const unsigned char *px;
    const png_color *palette; /* palette images only */
    int npalette;
    const png_byte *trns; /* alpha per palette entry, or NULL */
    int ntrns;
} png_out;

static void png_write(const char *path, const png_out *o)
{
    FILE *f = fopen(path, "wb");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    png_bytepp rows = malloc(o->h * sizeof *rows);
    assert_non_null(f);
    assert_non_null(rows);
    for (png_uint_32 r = 0; r < o->h; r++)
        rows[r] = (png_bytep)o->px + r * o->rowbytes;
    png_init_io(png, f);
    png_set_IHDR(png, info, o->w, o->h, o->depth, o->ctype, o->interlace, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    if (o->palette)
        png_set_PLTE(png, info, o->palette, o->npalette);
    if (o->trns)
        png_set_tRNS(png, info, o->trns, o->ntrns, NULL);
    png_write_info(png, info);
    png_write_image(png, rows);
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    free(rows);
    assert_int_equal(fclose(f), 0);
}

/* The same pixels written with Adam7 interlacing decode to the same heights, for an RGB and
 * a 16-bit grayscale encoding. */
static void test_png_interlaced(void **state)
{
    const char *names[] = {"levi-terrainrgb.png", "trinidad-west-u16.png"};
    const td_dem_encoding encs[] = {TD_ENC_TERRAIN_RGB, TD_ENC_GRAY16};
    (void)state;
    for (int k = 0; k < 2; k++) {
        char src[512], p[512];
        png_out out = {0};
        unsigned char *px;
        td_grid *ref, *g;
        td_dem_opts o;
        td_dem_opts_default(&o);
        o.encoding = encs[k];
        o.spacing[0] = 20.0;
        fixture(names[k], src, sizeof src);
        ref = load_ok(src, &o);
        px = png_pixels(src, &out.w, &out.h, &out.depth, &out.ctype, &out.rowbytes);
        out.px = px;
        out.interlace = PNG_INTERLACE_ADAM7;
        tmpfile_path("adam7.png", p, sizeof p);
        png_write(p, &out);
        g = load_ok(p, &o);
        assert_int_equal(g->w, ref->w);
        assert_int_equal(g->h, ref->h);
        assert_memory_equal(g->z, ref->z, (size_t)g->w * (size_t)g->h * sizeof *g->z);
        assert_true(g->zmin == ref->zmin && g->zmax == ref->zmax);
        td_grid_free(g);

        /* truncated in the middle of its passes: refused, not half a grid */
        {
            size_t len;
            unsigned char *buf = slurp(p, &len);
            spit(p, buf, len * 3 / 5);
            refused(p, &o, TD_EFORMAT);
            free(buf);
        }
        unlink(p);
        free(px);
        td_grid_free(ref);
    }
}

/* A palette PNG (as optipng makes of a tile with few colours) is expanded to RGB; a palette
 * entry made transparent by tRNS is a void. 4-bit palette, 5 x 3, terrain-rgb. */
static void test_png_palette(void **state)
{
    /* terrain-rgb: m = -10000 + (R*65536 + G*256 + B) * 0.1 */
    const png_color pal[4] = {{0x01, 0x86, 0xa0}, {0x01, 0x87, 0x04}, {0x01, 0x90, 0x00}, {0, 0, 0}};
    const png_byte trns[4] = {255, 255, 255, 0};
    const double m[4] = {0.0, 10.0, 240.0, NAN}; /* 0x0186a0 = 100000; 0x018704 = 100100; 0x019000 = 102400 */
    const unsigned char idx[3][5] = {{0, 1, 2, 3, 0}, {1, 1, 1, 1, 1}, {2, 0, 2, 0, 2}};
    unsigned char px[3][3]; /* 4-bit: 5 pixels in 3 bytes per row */
    png_out out = {0};
    char p[512];
    td_grid *g;
    td_dem_opts o;
    (void)state;
    memset(px, 0, sizeof px);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 5; c++)
            px[r][c / 2] |= (unsigned char)(idx[r][c] << (c % 2 ? 0 : 4));
    out.w = 5;
    out.h = 3;
    out.depth = 4;
    out.ctype = PNG_COLOR_TYPE_PALETTE;
    out.rowbytes = 3;
    out.px = &px[0][0];
    out.palette = pal;
    out.npalette = 4;
    out.trns = trns;
    out.ntrns = 4;
    tmpfile_path("palette.png", p, sizeof p);
    for (int interlace = 0; interlace < 2; interlace++) {
        out.interlace = interlace ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE;
        png_write(p, &out);
        td_dem_opts_default(&o);
        o.encoding = TD_ENC_TERRAIN_RGB;
        o.spacing[0] = 30.0;
        g = load_ok(p, &o);
        assert_int_equal(g->w, 5);
        assert_int_equal(g->h, 3);
        assert_int_equal(g->voids, 1);
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 5; c++) {
                float z = g->z[(size_t)(2 - r) * 5 + (size_t)c]; /* south-based storage */
                double want = m[idx[r][c]];
                if (isnan(want))
                    assert_true(isnan(z));
                else
                    assert_true(fabs((double)z - want) < 1e-3);
            }
        }
        td_grid_free(g);
        /* gray16 needs 16-bit grayscale: a palette image is refused by name */
        o.encoding = TD_ENC_GRAY16;
        refused(p, &o, TD_EFORMAT);
    }
    unlink(p);
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

/* ---- memory follows the data (issue 15): tiny files claiming huge grids, decode buffers
 * in the budget, decompression bombs, a .prj that does not fit -------------------------- */

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
    const png_color pal[2] = {{1, 134, 160}, {1, 135, 4}};
    png_out out = {0};
    unsigned char *px = calloc((size_t)h, (w + 7) / 8);
    assert_non_null(px);
    out.w = w;
    out.h = h;
    out.depth = 1;
    out.ctype = PNG_COLOR_TYPE_PALETTE;
    out.interlace = interlace;
    out.rowbytes = (w + 7) / 8;
    out.px = px;
    out.palette = pal;
    out.npalette = 2;
    png_write(path, &out);
    free(px);
}

/* The .asc values as (float) strtod gives them, token by token: the loader's fast path
 * (demasc.c's asc_fast_value) must agree with it on 120,000 tokens: short decimals,
 * 20-digit ones as in picos ("2244.5900000000001455"), exact midpoints between floats
 * and the doubles next to them (the fast path must give up there), leading zeros, signs,
 * tiny fractions, and values a hair off NODATA. */
static void asc_token_of(uint64_t *st, int kind, char *buf, size_t n)
{
    uint64_t r;
    *st = *st * 6364136223846793005ULL + 1442695040888963407ULL;
    r = *st >> 11;
    if (kind == 0) {
        snprintf(buf, n, "%s%llu.%02llu", r & 1 ? "-" : "", (unsigned long long)(r % 5000),
                 (unsigned long long)(r >> 20) % 100);
    } else if (kind == 1) {
        snprintf(buf, n, "%.16f", (double)(r % 4000000) / 1000.0 + 1e-13 * (double)(r >> 40));
    } else if (kind <= 3) { /* a float midpoint, or the double just off it */
        float f = (float)(r % 3000000) / 997.0f;
        double mid = ((double)f + (double)nextafterf(f, INFINITY)) / 2.0;
        if (kind == 3)
            mid = nextafter(mid, (r >> 40) & 1 ? INFINITY : -INFINITY);
        snprintf(buf, n, "%.24f", mid);
    } else if (kind == 4) {
        snprintf(buf, n, "000%llu.000000%llu", (unsigned long long)(r % 100),
                 (unsigned long long)(r >> 30) % 1000000);
    } else if (kind == 5) {
        snprintf(buf, n, "0.%020llu", (unsigned long long)(r % 100000000000ULL));
    } else {
        snprintf(buf, n, "%.17g", -9999.0 + ((r & 3) == 0 ? 0.0 : ((r & 1) ? 1e-12 : -1e-13)));
    }
}

static void test_asc_values_as_strtod(void **state)
{
    enum { W = 300, H = 400 };
    char p[512], tok[64];
    uint64_t st = 12345;
    size_t cap = (size_t)W * H * 40 + 256, len = 0;
    char *text = malloc(cap);
    td_grid *g;
    (void)state;
    assert_non_null(text);
    len += (size_t)snprintf(text, cap, "ncols %d\nnrows %d\nxllcorner 0\nyllcorner 0\ncellsize 10\n"
                                       "NODATA_value -9999\n", W, H);
    for (int k = 0; k < W * H; k++) {
        asc_token_of(&st, k % 7, tok, sizeof tok);
        len += (size_t)snprintf(text + len, cap - len, "%s%c", tok, k % W == W - 1 ? '\n' : ' ');
    }
    tmpfile_path("strtod.asc", p, sizeof p);
    spit(p, text, len);
    g = load_ok(p, NULL);
    st = 12345;
    for (int k = 0; k < W * H; k++) {
        double v;
        float got = at_file_row(g, k % W, k / W);
        asc_token_of(&st, k % 7, tok, sizeof tok);
        v = strtod(tok, NULL);
        if (v == -9999.0)
            assert_true(isnan(got));
        else if (memcmp(&got, &(float){(float)v}, sizeof got) != 0)
            fail_msg("token %s: loaded %.9g, (float) strtod %.9g", tok, (double)got, (double)(float)v);
    }
    td_grid_free(g);
    free(text);
}

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
    tmpfile_path("claims.asc", p, sizeof p);
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
    g = load_ok(p, NULL);
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
    tmpfile_path("claims.png", p, sizeof p);
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
    tmpfile_path("bomb.png", p, sizeof p);
    tmpfile_path("bomb-adam7.png", q, sizeof q);
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
    a = load_ok(p, &o);
    b = load_ok(q, &o);
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
    tmpfile_path("crs.asc", a, sizeof a);
    tmpfile_path("crs.prj", prj, sizeof prj);

    spit(a, utm, strlen(utm));
    spit(prj, geog, strlen(geog));
    refused_with(a, NULL, TD_EFORMAT, prj, "says geographic", "is not degrees", NULL);
    spit(prj, proj, strlen(proj));
    g = load_ok(a, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->sx == 30.0);
    td_grid_free(g);

    spit(a, deg, strlen(deg));
    refused_with(a, NULL, TD_EFORMAT, prj, "says projected", "are degrees", NULL);
    spit(prj, geog, strlen(geog));
    g = load_ok(a, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_LONLAT);
    assert_true(g->sx > 70.0 && g->sx < 75.0); /* 3 arc-seconds at 37.25 N: about 73.7 m */
    td_grid_free(g);
    unlink(a);
    unlink(prj);
}

/* ---- dispatch, GDAL ----------------------------------------------------------------- */

static void test_dispatch(void **state)
{
    char p[512];
    const char *names[TD_ENC_COUNT] = {"none", "gray16", "terrain-rgb", "terrarium", "rgb-div"};
    td_dem_encoding e;
    td_dem_opts o;
    (void)state;
    for (int k = 0; k < TD_ENC_COUNT; k++) {
        assert_string_equal(td_dem_encoding_name((td_dem_encoding)k), names[k]);
        assert_int_equal(td_dem_encoding_parse(names[k], &e), TD_OK);
        assert_int_equal(e, k);
    }
    assert_int_equal(td_dem_encoding_parse("mapbox", &e), TD_EINVAL);
    td_dem_opts_default(&o);
    assert_int_equal(o.encoding, TD_ENC_NONE);
    assert_true(o.scale == 1.0 && o.offset == 0.0 && o.divisor == 11983.0);
    assert_int_equal(o.tile_log2, TD_TILE_LOG2_DEFAULT);
    assert_int_equal(o.limits.max_width, 65536);

    assert_true(td_dem_recognised("x/dem.f32"));
    assert_true(td_dem_recognised("x/volcano.ASC"));
    assert_true(td_dem_recognised("N37W105.hgt"));
    assert_false(td_dem_recognised("x/README.md"));
    assert_false(td_dem_recognised("x/dem.json"));
    assert_false(td_dem_recognised("x/orthophoto.png")); /* no sidecar */
    assert_int_equal(td_dem_recognised("x/dem.tif"), td_dem_have_gdal());

    tmpfile_path("missing.asc", p, sizeof p);
    refused(p, NULL, TD_ENOTFOUND);
    refused(tmpdir, NULL, TD_EINVAL); /* a directory */
    tmpfile_path("notes.txt", p, sizeof p);
    spit_text(p, "hello\n");
    refused(p, NULL, TD_OK); /* unsupported, or GDAL cannot open it */
    /* an extension that lies gets the loader's refusal */
    tmpfile_path("lie.asc", p, sizeof p);
    spit(p, "\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16);
    refused(p, NULL, TD_EFORMAT);
    tmpfile_path("tile.tif", p, sizeof p);
    spit_text(p, "II*\0garbage");
    refused(p, NULL, td_dem_have_gdal() ? TD_EFORMAT : TD_EUNSUPPORTED);
}

static void test_gdal_geotiff(void **state)
{
    (void)state;
#ifdef TERRAD_HAVE_GDAL
    char p[512], src[512];
    td_grid *ref, *g;
    GDALDriverH drv;
    GDALDatasetH ds;
    OGRSpatialReferenceH srs;
    float *row;
    double gt[6];

    fixture("volcano.asc", src, sizeof src);
    ref = load_ok(src, NULL);
    GDALAllRegister();
    drv = GDALGetDriverByName("GTiff");
    assert_non_null(drv);

    /* projected (UTM 60S), north-up, nodata -9999 at one sample */
    tmpfile_path("volcano.tif", p, sizeof p);
    ds = GDALCreate(drv, p, ref->w, ref->h, 1, GDT_Float32, NULL);
    assert_non_null(ds);
    gt[0] = 300000.0;
    gt[1] = 10.0;
    gt[2] = 0.0;
    gt[3] = 5920000.0;
    gt[4] = 0.0;
    gt[5] = -10.0;
    assert_int_equal(GDALSetGeoTransform(ds, gt), CE_None);
    srs = OSRNewSpatialReference(NULL);
    assert_int_equal(OSRImportFromEPSG(srs, 32760), OGRERR_NONE);
    assert_int_equal(GDALSetSpatialRef(ds, srs), CE_None);
    OSRDestroySpatialReference(srs);
    GDALSetRasterNoDataValue(GDALGetRasterBand(ds, 1), -9999.0);
    row = malloc((size_t)ref->w * sizeof *row);
    assert_non_null(row);
    for (int32_t r = 0; r < ref->h; r++) {
        for (int32_t i = 0; i < ref->w; i++)
            row[i] = at_file_row(ref, i, r);
        if (r == 3)
            row[4] = -9999.0f;
        assert_int_equal(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Write, 0, r, ref->w, 1, row, ref->w,
                                      1, GDT_Float32, 0, 0),
                         CE_None);
    }
    free(row);
    GDALClose(ds);

    g = load_ok(p, NULL);
    assert_int_equal(g->w, 61);
    assert_int_equal(g->h, 87);
    assert_int_equal(g->voids, 1);
    assert_true(isnan(at_file_row(g, 4, 3)));
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            if (!(i == 4 && j == g->h - 1 - 3))
                assert_true(td_grid_at(g, i, j) == td_grid_at(ref, i, j));
    assert_true(g->sx == 10.0 && g->sy == 10.0);
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->geo.x0 == 300005.0);
    assert_true(g->geo.y0 == 5920000.0 - 86.5 * 10.0);
    td_grid_free(g);

    /* truncated GeoTIFF: refused, never a crash */
    {
        size_t len;
        unsigned char *buf = slurp(p, &len);
        tmpfile_path("cut.tif", p, sizeof p);
        spit(p, buf, len / 2);
        refused(p, NULL, TD_OK);
        free(buf);
    }
    td_grid_free(ref);
#else
    skip();
#endif
}

/* ---- demutil: the loaders' shared helpers ---------------------------------------------- */

static td_grid *small_grid(int32_t w, int32_t h, const td_georef *geo)
{
    td_grid *g = NULL;
    td_dem_opts o;
    td_err err = {0};
    td_dem_opts_default(&o);
    assert_int_equal(td_demutil_create("x.f32", &o, w, h, 1.0, 2.0, geo, &g, &err), TD_OK);
    for (size_t k = 0; k < (size_t)w * (size_t)h; k++)
        g->z[k] = (float)k;
    return g;
}

static void test_demutil_rows_and_create(void **state)
{
    td_georef geo = {.kind = TD_GEO_PROJECTED, .x0 = 10, .y0 = 20, .dx = 1, .dy = 2, .crs = "c"};
    td_grid *g = small_grid(3, 4, &geo);
    td_grid *big = NULL;
    td_dem_opts o;
    td_err err = {0};
    (void)state;
    /* file row 0 is the north row, the grid's last */
    assert_ptr_equal(td_demutil_file_row(g, 0), g->z + 3 * 3);
    assert_ptr_equal(td_demutil_file_row(g, 3), g->z);
    assert_true(td_demutil_file_row(g, 1)[2] == td_grid_at(g, 2, 2));
    assert_int_equal(g->geo.kind, TD_GEO_PROJECTED);
    assert_true(g->geo.x0 == 10.0 && g->geo.dy == 2.0);
    assert_string_equal(g->geo.crs, "c");
    td_grid_free(g);
    g = small_grid(3, 4, NULL);
    assert_int_equal(g->geo.kind, TD_GEO_NONE);
    td_grid_free(g);
    /* a refusal names the file */
    td_dem_opts_default(&o);
    o.limits.max_width = 2;
    assert_int_equal(td_demutil_create("dir/x.f32", &o, 3, 4, 1, 1, NULL, &big, &err), TD_ETOOBIG);
    assert_null(big);
    assert_non_null(strstr(err.msg, "dir/x.f32: "));
}

static void test_demutil_open_and_read_row(void **state)
{
    char p[512];
    unsigned char buf[8];
    FILE *f = NULL;
    struct stat st;
    td_err err = {0};
    (void)state;
    tmpfile_path("none.bin", p, sizeof p);
    assert_int_equal(td_demutil_open(p, &f, &st, &err), TD_EIO);
    assert_null(f);
    assert_non_null(strstr(err.msg, ": cannot open ("));
    assert_non_null(strstr(err.msg, p));
    tmpfile_path("six.bin", p, sizeof p);
    spit(p, "abcdef", 6);
    assert_int_equal(td_demutil_open(p, &f, &st, &err), TD_OK);
    assert_non_null(f);
    assert_int_equal(st.st_size, 6);
    assert_int_equal(td_demutil_read_row(p, f, buf, 2, 2, 0, &err), TD_OK);
    assert_memory_equal(buf, "abcd", 4);
    /* two bytes left: row 1 of 4 bytes is short */
    assert_int_equal(td_demutil_read_row(p, f, buf, 2, 2, 1, &err), TD_EIO);
    assert_non_null(strstr(err.msg, "read failed at row 1 (file shrank while reading)"));
    fclose(f);
    f = NULL;
    assert_int_equal(td_demutil_open(p, &f, NULL, &err), TD_OK);
    fclose(f);
}

static void test_demutil_side_georef(void **state)
{
    td_demside sc;
    td_dem_opts o;
    td_err err = {0};
    double sx = 0, sy = 0, ex = 0, ey = 0;
    (void)state;
    td_dem_opts_default(&o);
    /* lon/lat: moved to the south row, spacing at the centre latitude */
    memset(&sc, 0, sizeof sc);
    sc.geo = (td_georef){.kind = TD_GEO_LONLAT, .x0 = -105, .y0 = 38, .dx = 0.5, .dy = 0.25};
    assert_int_equal(td_demutil_side_georef("x.f32", &o, &sc, 5, 5, &sx, &sy, &err), TD_OK);
    assert_true(sc.geo.y0 == 37.0 && sc.geo.x0 == -105.0 && sc.geo.dy == 0.25);
    td_grid_lonlat_spacing(37.5, 0.5, 0.25, &ex, &ey);
    assert_true(sx == ex && sy == ey);
    /* projected: the spacing becomes the step, then moved south */
    memset(&sc, 0, sizeof sc);
    sc.has_spacing = 1;
    sc.spacing[0] = 2.0;
    sc.spacing[1] = 3.0;
    sc.geo = (td_georef){.kind = TD_GEO_PROJECTED, .x0 = 1000, .y0 = 2000};
    assert_int_equal(td_demutil_side_georef("x.f32", &o, &sc, 4, 3, &sx, &sy, &err), TD_OK);
    assert_true(sx == 2.0 && sy == 3.0 && sc.geo.dx == 2.0 && sc.geo.dy == 3.0);
    assert_true(sc.geo.x0 == 1000.0 && sc.geo.y0 == 2000.0 - 2 * 3.0);
    /* the options win over the sidecar's spacing and set a projected step */
    memset(&sc, 0, sizeof sc);
    sc.geo = (td_georef){.kind = TD_GEO_PROJECTED, .x0 = 0, .y0 = 10};
    o.spacing[0] = 5.0;
    assert_int_equal(td_demutil_side_georef("x.f32", &o, &sc, 4, 3, &sx, &sy, &err), TD_OK);
    assert_true(sx == 5.0 && sy == 5.0 && sc.geo.dy == 5.0 && sc.geo.y0 == 0.0);
    /* no spacing anywhere: refused, the origin left as read */
    o.spacing[0] = 0.0;
    memset(&sc, 0, sizeof sc);
    sc.geo = (td_georef){.kind = TD_GEO_PROJECTED, .x0 = 0, .y0 = 10};
    assert_int_equal(td_demutil_side_georef("x.f32", &o, &sc, 4, 3, &sx, &sy, &err), TD_EINVAL);
    assert_true(sc.geo.y0 == 10.0);
    assert_non_null(strstr(err.msg, "x.f32: spacing unknown"));
}

static void test_demutil_f32_row(void **state)
{
    td_demutil_f32 raw = {.inf_refused = 1, .has_nodata = 1, .nodata = -9999.0f, .scale = 1.0,
                          .offset = -0.0, .max_abs = FLT_MAX};
    td_demutil_f32 scaled = {.nan_void = 1, .scale = 0.5, .offset = 10.0, .max_abs = 3.0e38};
    float row[5] = {-0.0f, 1.5f, -9999.0f, FLT_MAX, NAN};
    td_err err = {0};
    (void)state;
    snprintf(raw.nan_why, sizeof raw.nan_why, " (why)");
    /* as they are, -0.0 included; nodata is a void; a NaN is refused with the reason */
    assert_int_equal(td_demutil_f32_row("x.f32", &raw, row, 4, 0, &err), TD_OK);
    assert_true(row[0] == 0.0f && signbit(row[0]) && row[1] == 1.5f && isnan(row[2]) &&
                row[3] == FLT_MAX);
    /* the same rule with offset +0 (the rows with a void or a zero take a quick path of
       their own): -0.0 comes out +0.0, as v * 1 + 0 */
    raw.offset = 0.0;
    row[0] = -0.0f;
    row[2] = -9999.0f;
    assert_int_equal(td_demutil_f32_row("x.f32", &raw, row, 4, 0, &err), TD_OK);
    assert_true(row[0] == 0.0f && !signbit(row[0]) && row[1] == 1.5f && isnan(row[2]) && row[3] == FLT_MAX);
    raw.offset = -0.0;
    row[2] = 5.0f;
    assert_int_equal(td_demutil_f32_row("x.f32", &raw, row, 5, 7, &err), TD_EFORMAT);
    assert_string_equal(err.msg, "x.f32: NaN sample at column 4, row 7 (why)");
    /* infinities: refused before nodata when inf_refused */
    row[0] = INFINITY;
    raw.nodata = INFINITY;
    assert_int_equal(td_demutil_f32_row("x.f32", &raw, row, 1, 2, &err), TD_ERANGE);
    assert_string_equal(err.msg, "x.f32: infinite sample at column 0, row 2");
    /* scaled: NaN is a void, values scaled, a scaled value beyond max_abs refused */
    row[0] = 2.0f;
    row[1] = NAN;
    assert_int_equal(td_demutil_f32_row("x.tif", &scaled, row, 2, 0, &err), TD_OK);
    assert_true(row[0] == 11.0f && isnan(row[1]));
    row[0] = 3.0e38f;
    scaled.scale = 2.0;
    assert_int_equal(td_demutil_f32_row("x.tif", &scaled, row, 1, 3, &err), TD_ERANGE);
    assert_string_equal(err.msg, "x.tif: sample at column 0, row 3 is not finite");
}

static void test_demutil_deliver(void **state)
{
    td_grid *g = small_grid(3, 4, NULL);
    td_grid *out = (td_grid *)0x1;
    td_err err = {0};
    (void)state;
    /* success: finished (stats) and handed over */
    assert_int_equal(td_demutil_deliver("x.f32", TD_OK, g, &out, &err), TD_OK);
    assert_ptr_equal(out, g);
    assert_true(out->zmin == 0.0f && out->zmax == 11.0f && out->voids == 0);
    td_grid_free(out);
    /* an earlier failure: freed (ASan checks), NULL out, status kept */
    g = small_grid(3, 4, NULL);
    out = (td_grid *)0x1;
    td_err_set(&err, TD_EFORMAT, "x.f32: earlier");
    assert_int_equal(td_demutil_deliver("x.f32", TD_EFORMAT, g, &out, &err), TD_EFORMAT);
    assert_null(out);
    assert_string_equal(err.msg, "x.f32: earlier");
    out = (td_grid *)0x1;
    assert_int_equal(td_demutil_deliver("x.f32", TD_EIO, NULL, &out, &err), TD_EIO);
    assert_null(out);
    /* finish fails: the message names the file */
    g = small_grid(3, 4, NULL);
    g->z[5] = INFINITY;
    assert_int_equal(td_demutil_deliver("dir/x.f32", TD_OK, g, &out, &err), TD_ERANGE);
    assert_null(out);
    assert_non_null(strstr(err.msg, "dir/x.f32: infinite height"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_asc_volcano),
        cmocka_unit_test(test_asc_picos),
        cmocka_unit_test(test_asc_variants),
        cmocka_unit_test(test_asc_values_as_strtod),
        cmocka_unit_test(test_asc_refusals),
        cmocka_unit_test(test_hgt),
        cmocka_unit_test(test_hgt_refusals),
        cmocka_unit_test(test_f32_trinidad_crop),
        cmocka_unit_test(test_f32_voids_and_refusals),
        cmocka_unit_test(test_png_levi_rgbdiv),
        cmocka_unit_test(test_png_levi_reencoded),
        cmocka_unit_test(test_png_gray16_trinidad_west),
        cmocka_unit_test(test_png_sidecar_and_no_encoding),
        cmocka_unit_test(test_png_refusals),
        cmocka_unit_test(test_png_interlaced),
        cmocka_unit_test(test_png_palette),
        cmocka_unit_test(test_asc_header_claims_too_much),
        cmocka_unit_test(test_png_header_claims_too_much),
        cmocka_unit_test(test_png_bomb_budget),
        cmocka_unit_test(test_asc_prj_mismatch),
        cmocka_unit_test(test_dispatch),
        cmocka_unit_test(test_gdal_geotiff),
        cmocka_unit_test(test_demutil_rows_and_create),
        cmocka_unit_test(test_demutil_open_and_read_row),
        cmocka_unit_test(test_demutil_side_georef),
        cmocka_unit_test(test_demutil_f32_row),
        cmocka_unit_test(test_demutil_deliver),
    };
    return cmocka_run_group_tests(tests, group_setup, group_teardown);
}
