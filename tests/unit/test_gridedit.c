/* test_gridedit.c: heights edits (core/gridedit.c): the region's parameters refused
 * with the field at fault, the body's length and values checked, little-endian decoding,
 * the copy-on-write (the original grid untouched, the copy equal to a grid built from
 * scratch with the same heights), north-first rows landing on the right south-based
 * rows, the touched tiles against a brute-force scan, and the file form of
 * `terrad render --edit`. */
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

#include "gridedit.h"

static td_grid *make_grid(int32_t w, int32_t h, int tile_log2)
{
    td_grid *g = NULL;
    td_err err = {0};
    assert_int_equal(td_grid_create(w, h, 10.0, 20.0, tile_log2, NULL, &g, &err), TD_OK);
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++)
            g->z[(size_t)j * (size_t)w + (size_t)i] = (float)(100 + (i * 7 + j * 13) % 50);
    g->z[3] = NAN;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    return g;
}

/* w*h little-endian float32 */
static unsigned char *le_body(const float *z, size_t n)
{
    unsigned char *b = malloc(n * 4);
    for (size_t k = 0; k < n; k++) {
        uint32_t u;
        memcpy(&u, &z[k], 4);
        for (int i = 0; i < 4; i++)
            b[4 * k + (size_t)i] = (unsigned char)(u >> (8 * i));
    }
    return b;
}

static void expect_field(const char *x, const char *y, const char *w, const char *h, int64_t max,
                         td_status st, const char *field)
{
    td_grid *g = make_grid(13, 9, 2);
    td_grid_region r = {-1, -1, -1, -1};
    td_err err = {0};
    assert_int_equal(td_grid_edit_parse(g, x, y, w, h, max, &r, &err), st);
    assert_string_equal(err.field, field);
    assert_int_equal(r.x, -1); /* untouched on failure */
    td_grid_free(g);
}

static void test_parse_refuses_with_the_field(void **state)
{
    (void)state;
    expect_field(NULL, "0", "1", "1", 0, TD_EINVAL, "x");
    expect_field("0", "", "1", "1", 0, TD_EINVAL, "y");
    expect_field("0", "0", "-1", "1", 0, TD_EINVAL, "w");
    expect_field("0", "0", "1", "1e2", 0, TD_EINVAL, "h");
    expect_field("+1", "0", "1", "1", 0, TD_EINVAL, "x");
    expect_field(" 1", "0", "1", "1", 0, TD_EINVAL, "x");
    expect_field("99999999999", "0", "1", "1", 0, TD_EINVAL, "x");
    expect_field("13", "0", "1", "1", 0, TD_EINVAL, "x");  /* columns 0 .. 12 */
    expect_field("0", "9", "1", "1", 0, TD_EINVAL, "y");   /* rows 0 .. 8 */
    expect_field("0", "0", "0", "1", 0, TD_EINVAL, "w");
    expect_field("10", "0", "4", "1", 0, TD_EINVAL, "w");  /* 10 + 4 > 13 */
    expect_field("0", "5", "1", "5", 0, TD_EINVAL, "h");   /* 5 + 5 > 9 */
    expect_field("0", "0", "2147483647", "1", 0, TD_EINVAL, "w");
    expect_field("0", "0", "5", "5", 24, TD_ETOOBIG, "w"); /* 25 samples over 24 */
}

static void test_parse_accepts_the_whole_grid(void **state)
{
    td_grid *g = make_grid(13, 9, 2);
    td_grid_region r;
    td_err err = {0};
    (void)state;
    assert_int_equal(td_grid_edit_parse(g, "0", "0", "13", "9", 0, &r, &err), TD_OK);
    assert_int_equal(r.x, 0);
    assert_int_equal(r.w, 13);
    assert_int_equal(r.h, 9);
    assert_int_equal(td_grid_edit_parse(g, "12", "008", "1", "1", 1, &r, &err), TD_OK);
    assert_int_equal(r.x, 12);
    assert_int_equal(r.y, 8);
    td_grid_free(g);
}

static void test_decode(void **state)
{
    td_grid_region r = {0, 0, 2, 2};
    /* 1.5f, NaN with payload, -0.25f, 1e6f, little-endian */
    const unsigned char body[16] = {0x00, 0x00, 0xc0, 0x3f, 0x01, 0x00, 0xc0, 0x7f,
                                    0x00, 0x00, 0x80, 0xbe, 0x00, 0x24, 0x74, 0x49};
    unsigned char bad[16];
    float *z = NULL;
    td_err err = {0};
    (void)state;
    assert_int_equal(td_grid_edit_decode(&r, body, sizeof body, &z, &err), TD_OK);
    assert_true(z[0] == 1.5f);
    assert_true(isnan(z[1]));
    assert_true(z[2] == -0.25f);
    assert_true(z[3] == 1e6f);
    free(z);
    z = NULL;
    /* wrong length: one byte short, one byte over, nothing */
    assert_int_equal(td_grid_edit_decode(&r, body, 15, &z, &err), TD_EINVAL);
    assert_string_equal(err.field, "body");
    assert_non_null(strstr(err.msg, "16 bytes"));
    assert_int_equal(td_grid_edit_decode(&r, body, 17, &z, &err), TD_EINVAL);
    assert_int_equal(td_grid_edit_decode(&r, body, 0, &z, &err), TD_EINVAL);
    assert_null(z);
    /* +inf in sample 2 (row 1, column 0) */
    memcpy(bad, body, sizeof bad);
    bad[8] = 0x00, bad[9] = 0x00, bad[10] = 0x80, bad[11] = 0x7f;
    assert_int_equal(td_grid_edit_decode(&r, bad, sizeof bad, &z, &err), TD_EINVAL);
    assert_string_equal(err.field, "body");
    assert_non_null(strstr(err.msg, "sample 2 (row 1, column 0) is +inf"));
    bad[11] = 0xff; /* -inf */
    assert_int_equal(td_grid_edit_decode(&r, bad, sizeof bad, &z, &err), TD_EINVAL);
    assert_non_null(strstr(err.msg, "-inf"));
    assert_null(z);
}

/* The copy holds the region's heights where the file's rows say, everything else as g,
 * and statistics and tiles equal to a grid finished from scratch with those heights. */
static void test_apply_copy_on_write(void **state)
{
    td_grid *g = make_grid(13, 9, 2), *c = NULL, *ref = NULL;
    td_grid_region r = {3, 2, 4, 3}; /* columns 3..6, file rows 2..4 = grid rows 6..4 */
    float z[12], *before = malloc(13 * 9 * sizeof(float));
    td_err err = {0};
    (void)state;
    memcpy(before, g->z, 13 * 9 * sizeof(float));
    for (int k = 0; k < 12; k++)
        z[k] = 1000.0f + (float)k;
    z[5] = NAN;
    assert_int_equal(td_grid_edit_apply(g, &r, z, &c, &err), TD_OK);
    assert_memory_equal(g->z, before, 13 * 9 * sizeof(float)); /* g is only read */
    /* body row 0 is file row 2 = grid row 9-1-2 = 6; row 2 is grid row 4 */
    assert_true(td_grid_at(c, 3, 6) == 1000.0f);
    assert_true(td_grid_at(c, 6, 6) == 1003.0f);
    assert_true(isnan(td_grid_at(c, 4, 5)));
    assert_true(td_grid_at(c, 6, 4) == 1011.0f);
    assert_true(td_grid_at(c, 2, 6) == td_grid_at(g, 2, 6));
    assert_true(td_grid_at(c, 3, 3) == td_grid_at(g, 3, 3));
    assert_int_equal(c->voids, g->voids + 1);
    assert_true(c->zmax == 1011.0f);
    assert_true(c->geo.kind == g->geo.kind && c->sx == g->sx && c->sy == g->sy);
    /* the same as a grid built from scratch with the copy's heights */
    assert_int_equal(td_grid_create(13, 9, 10.0, 20.0, 2, NULL, &ref, &err), TD_OK);
    memcpy(ref->z, c->z, 13 * 9 * sizeof(float));
    assert_int_equal(td_grid_finish(ref, &err), TD_OK);
    assert_true(ref->zmin == c->zmin && ref->zmax == c->zmax && ref->voids == c->voids);
    assert_memory_equal(ref->tiles, c->tiles, sizeof(td_tile) * (size_t)(c->tiles_x * c->tiles_y));
    /* read back as a body: the same bytes as the body that wrote it */
    {
        unsigned char *want = le_body(z, 12), got[48];
        td_grid_edit_read(c, &r, got);
        assert_memory_equal(got, want, 48);
        free(want);
    }
    free(before);
    td_grid_free(ref);
    td_grid_free(c);
    td_grid_free(g);
}

/* Every tile holding a sample of the region, and no other, for every region of a small
 * grid with 4-cell tiles (seams at columns and rows 4, 8). */
static void test_tiles_brute_force(void **state)
{
    td_grid *g = make_grid(13, 10, 2);
    td_err err = {0};
    (void)state;
    for (int32_t y = 0; y < g->h; y++)
        for (int32_t x = 0; x < g->w; x++)
            for (int32_t h = 1; y + h <= g->h; h += 2)
                for (int32_t w = 1; x + w <= g->w; w += 3) {
                    td_grid_region r = {x, y, w, h};
                    size_t *tiles = NULL, n = 0, want = 0;
                    assert_int_equal(td_grid_edit_tiles(g, &r, &tiles, &n, &err), TD_OK);
                    for (size_t t = 0; t < (size_t)(g->tiles_x * g->tiles_y); t++) {
                        const td_tile *tl = &g->tiles[t];
                        int32_t jlo = g->h - y - h, jhi = g->h - 1 - y;
                        int holds = tl->i0 <= x + w - 1 && x <= tl->i0 + tl->nx &&
                                    tl->j0 <= jhi && jlo <= tl->j0 + tl->ny;
                        int listed = 0;
                        for (size_t k = 0; k < n; k++)
                            listed |= tiles[k] == t;
                        assert_int_equal(holds, listed);
                        want += (size_t)holds;
                    }
                    assert_int_equal(n, want);
                    free(tiles);
                }
    td_grid_free(g);
}

static void test_edit_file(void **state)
{
    td_grid *g = make_grid(13, 9, 2), *a = NULL, *b = NULL;
    td_grid_region r = {12, 7, 1, 2};
    float z[2] = {5.0f, NAN};
    unsigned char *body = le_body(z, 2);
    char path[] = "/tmp/test_gridedit_XXXXXX";
    int fd = mkstemp(path);
    float *dz = NULL;
    td_err err = {0};
    (void)state;
    assert_true(fd >= 0);
    assert_int_equal(write(fd, body, 8), 8);
    close(fd);
    assert_int_equal(td_grid_edit_file(g, &r, path, &a, &err), TD_OK);
    assert_int_equal(td_grid_edit_decode(&r, body, 8, &dz, &err), TD_OK);
    assert_int_equal(td_grid_edit_apply(g, &r, dz, &b, &err), TD_OK);
    assert_memory_equal(a->z, b->z, 13 * 9 * sizeof(float));
    assert_true(td_grid_at(a, 12, 1) == 5.0f);
    assert_true(isnan(td_grid_at(a, 12, 0)));
    td_grid_free(a);
    a = NULL;
    /* a region the file is too short for: the file and the body named */
    r.h = 3;
    r.y = 6;
    assert_int_equal(td_grid_edit_file(g, &r, path, &a, &err), TD_EINVAL);
    assert_null(a);
    assert_string_equal(err.field, "body");
    assert_non_null(strstr(err.msg, path));
    assert_int_equal(td_grid_edit_file(g, &r, "/nonexistent/x.f32", &a, &err), TD_EIO);
    unlink(path);
    free(dz);
    free(body);
    td_grid_free(b);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_parse_refuses_with_the_field),
        cmocka_unit_test(test_parse_accepts_the_whole_grid),
        cmocka_unit_test(test_decode),
        cmocka_unit_test(test_apply_copy_on_write),
        cmocka_unit_test(test_tiles_brute_force),
        cmocka_unit_test(test_edit_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
