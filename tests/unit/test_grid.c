/* test_grid.c: the height field (core/grid.c): size and limit checks before allocation,
 * checked arithmetic, tiles that share their edge samples, per-tile zmin/zmax against a
 * brute-force scan, voids, and the lon/lat spacing of the Trinidad grid. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "grid.h"
#include "terrain.h"

static td_grid *make_grid(int32_t w, int32_t h, int tile_log2)
{
    td_grid *g = NULL;
    td_err err = {0};
    assert_int_equal(td_grid_create(w, h, 10.0, 10.0, tile_log2, NULL, &g, &err), TD_OK);
    assert_non_null(g);
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++)
            g->z[(size_t)j * (size_t)w + (size_t)i] = (float)(100 + (i * 7 + j * 13) % 50);
    return g;
}

static void test_create_refuses_bad_sizes(void **state)
{
    td_grid *g = (td_grid *)0x1;
    td_err err = {0};
    td_grid_limits lim;
    (void)state;

    assert_int_equal(td_grid_create(1, 10, 1, 1, 8, NULL, &g, &err), TD_EFORMAT);
    assert_null(g);
    assert_int_equal(td_grid_create(10, -5, 1, 1, 8, NULL, &g, &err), TD_EFORMAT);
    assert_null(g);
    /* default limit 65536 x 65536, checked before anything is allocated */
    assert_int_equal(td_grid_create(65537, 2, 1, 1, 8, NULL, &g, &err), TD_ETOOBIG);
    assert_null(g);
    assert_non_null(strstr(err.msg, "65537"));
    assert_int_equal(td_grid_create(100000, 100000, 1, 1, 8, NULL, &g, &err), TD_ETOOBIG);
    assert_null(g);

    td_grid_limits_default(&lim);
    assert_int_equal(lim.max_width, 65536);
    assert_int_equal(lim.max_height, 65536);
    lim.max_width = 100;
    assert_int_equal(td_grid_create(101, 50, 1, 1, 8, &lim, &g, &err), TD_ETOOBIG);
    assert_int_equal(td_grid_create(100, 50, 1, 1, 8, &lim, &g, &err), TD_OK);
    td_grid_free(g);
    /* memory budget: 100 x 50 floats alone are 20000 bytes */
    lim.max_bytes = 20000;
    assert_int_equal(td_grid_create(100, 50, 1, 1, 8, &lim, &g, &err), TD_ETOOBIG);
    assert_null(g);
    assert_non_null(strstr(err.msg, "budget"));
    lim.max_bytes = td_grid_bytes(100, 50, 8);
    assert_int_equal(td_grid_create(100, 50, 1, 1, 8, &lim, &g, &err), TD_OK);
    td_grid_free(g);

    /* spacing and tile size */
    assert_int_equal(td_grid_create(10, 10, 0.0, 1, 8, NULL, &g, &err), TD_ERANGE);
    assert_int_equal(td_grid_create(10, 10, 1, NAN, 8, NULL, &g, &err), TD_ERANGE);
    assert_int_equal(td_grid_create(10, 10, 1, INFINITY, 8, NULL, &g, &err), TD_ERANGE);
    assert_int_equal(td_grid_create(10, 10, 1, 1, 0, NULL, &g, &err), TD_ERANGE);
    assert_int_equal(td_grid_create(10, 10, 1, 1, 17, NULL, &g, &err), TD_ERANGE);
    assert_null(g);
}

static void test_checked_arithmetic(void **state)
{
    size_t out = 7;
    (void)state;
    assert_int_equal(td_mul_size(SIZE_MAX / 2 + 1, 2, &out), 0);
    assert_int_equal(out, 7); /* untouched on overflow */
    assert_int_equal(td_mul_size(SIZE_MAX, 0, &out), 1);
    assert_int_equal(out, 0);
    assert_int_equal(td_mul_size(65536, 65536, &out), 1);
    assert_int_equal(out, (size_t)65536 * 65536);
    assert_int_equal(td_add_size(SIZE_MAX, 1, &out), 0);
    assert_int_equal(td_add_size(SIZE_MAX - 1, 1, &out), 1);
    assert_true(out == SIZE_MAX);
    /* bytes: heights + tile records + the grid record; 0 for impossible sizes */
    assert_true(td_grid_bytes(1, 10, 8) == 0);
    assert_true(td_grid_bytes(10, 10, 0) == 0);
    assert_true(td_grid_bytes(257, 257, 8) == 257u * 257u * 4u + 1u * sizeof(td_tile) + sizeof(td_grid));
    assert_true(td_grid_bytes(258, 257, 8) == 258u * 257u * 4u + 2u * sizeof(td_tile) + sizeof(td_grid));
    assert_true(td_grid_bytes(65536, 65536, 8) > (uint64_t)65536 * 65536 * 4);
}

/* Tiles of T cells: tile (tx, ty) covers cells [tx*T, tx*T+T) and samples up to tx*T+T. */
static void test_tile_layout(void **state)
{
    td_err err = {0};
    td_grid *g = make_grid(1000, 700, 8);
    (void)state;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_int_equal(td_grid_tile_size(g), 256);
    assert_int_equal(g->tiles_x, 4); /* 999 cells */
    assert_int_equal(g->tiles_y, 3); /* 699 cells */
    for (int32_t ty = 0; ty < g->tiles_y; ty++) {
        for (int32_t tx = 0; tx < g->tiles_x; tx++) {
            const td_tile *t = &g->tiles[ty * g->tiles_x + tx];
            assert_int_equal(t->i0, tx * 256);
            assert_int_equal(t->j0, ty * 256);
            assert_int_equal(t->nx, tx < 3 ? 256 : 999 - 768);
            assert_int_equal(t->ny, ty < 2 ? 256 : 699 - 512);
        }
    }
    /* O(1) cell lookup: the owner of a cell contains it */
    for (int32_t cj = 0; cj < 699; cj += 37) {
        for (int32_t ci = 0; ci < 999; ci += 41) {
            const td_tile *t = td_grid_tile_of_cell(g, ci, cj);
            assert_true(ci >= t->i0 && ci < t->i0 + t->nx);
            assert_true(cj >= t->j0 && cj < t->j0 + t->ny);
        }
    }
    assert_ptr_equal(td_grid_tile_of_cell(g, 998, 698), &g->tiles[11]);
    assert_ptr_equal(td_grid_tile_of_cell(g, 255, 256), &g->tiles[4]);
    assert_true(td_grid_at(g, 5, 3) == g->z[3 * 1000 + 5]);
    td_grid_free(g);
}

/* A spike on a shared edge sample raises the zmax of every tile that shares it. */
static void test_tiles_share_edges(void **state)
{
    td_err err = {0};
    td_grid *g = make_grid(600, 600, 8); /* 3 x 3 tiles */
    (void)state;
    g->z[(size_t)10 * 600 + 256] = 5000.0f;   /* column 256: edge of tiles 0 and 1 */
    g->z[(size_t)512 * 600 + 512] = 6000.0f;  /* corner of tiles 4, 5, 7, 8 */
    g->z[(size_t)300 * 600 + 100] = -50.0f;   /* interior of tile 3 */
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_true(g->tiles[0].zmax == 5000.0f);
    assert_true(g->tiles[1].zmax == 5000.0f);
    assert_true(g->tiles[2].zmax < 200.0f);
    assert_true(g->tiles[4].zmax == 6000.0f);
    assert_true(g->tiles[5].zmax == 6000.0f);
    assert_true(g->tiles[7].zmax == 6000.0f);
    assert_true(g->tiles[8].zmax == 6000.0f);
    assert_true(g->tiles[6].zmax < 200.0f);
    assert_true(g->tiles[3].zmin == -50.0f);
    assert_true(g->tiles[0].zmin >= 100.0f);
    assert_true(g->zmin == -50.0f);
    assert_true(g->zmax == 6000.0f);
    td_grid_free(g);
}

/* Per-tile bounds equal a brute-force scan over each tile's samples, edges included. */
static void test_tile_bounds_brute_force(void **state)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err err = {0};
    (void)state;
    td_terrain_params_default(&p);
    p.width = 301;
    p.height = 170;
    p.seed = 42;
    assert_int_equal(td_terrain_generate(&p, 5, &g, &err), TD_OK); /* 32-cell tiles */
    assert_int_equal(g->tiles_x, 10);
    assert_int_equal(g->tiles_y, 6);
    for (int32_t k = 0; k < g->tiles_x * g->tiles_y; k++) {
        const td_tile *t = &g->tiles[k];
        float lo = INFINITY, hi = -INFINITY;
        for (int32_t j = t->j0; j <= t->j0 + t->ny; j++)
            for (int32_t i = t->i0; i <= t->i0 + t->nx; i++) {
                float v = td_grid_at(g, i, j);
                lo = fminf(lo, v);
                hi = fmaxf(hi, v);
            }
        assert_true(t->zmin == lo);
        assert_true(t->zmax == hi);
        assert_true(t->zmin >= g->zmin && t->zmax <= g->zmax);
    }
    td_grid_free(g);
}

static void test_voids(void **state)
{
    td_err err = {0};
    td_grid *g = make_grid(40, 30, 3); /* 8-cell tiles: 5 x 4 */
    (void)state;
    /* void the whole first tile (samples 0..8 x 0..8) and one more sample elsewhere */
    for (int32_t j = 0; j <= 8; j++)
        for (int32_t i = 0; i <= 8; i++)
            g->z[j * 40 + i] = NAN;
    g->z[20 * 40 + 20] = NAN;
    g->z[25 * 40 + 30] = 10.0f;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_int_equal(g->voids, 81 + 1);
    assert_true(g->tiles[0].zmin == INFINITY);
    assert_true(g->tiles[0].zmax == -INFINITY);
    assert_true(isfinite(g->tiles[1].zmin)); /* shares column 8 (void) but has others */
    assert_true(g->zmin == 10.0f);
    assert_true(g->zmax == 149.0f);
    for (size_t k = 0; k < 40 * 30; k++)
        g->z[k] = NAN;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_int_equal(g->voids, 1200);
    assert_true(isnan(g->zmin) && isnan(g->zmax));
    g->z[77] = INFINITY;
    assert_int_equal(td_grid_finish(g, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "infinite"));
    td_grid_free(g);
    td_grid_free(NULL);
}

/* td_grid_finish's ranges (vectorised over integer keys) keep the scalar scan's answers
 * exactly: a minimum or maximum of zero gets the sign of the first zero in scan order
 * (south row first), tile by tile and for the grid; negative heights order below positive
 * ones; the first infinite sample is the one named. */
static void test_finish_signed_zeros(void **state)
{
    td_err err = {0};
    td_grid *g = make_grid(20, 12, 3); /* 8-cell tiles: 3 x 2 */
    (void)state;
    for (size_t k = 0; k < 20 * 12; k++)
        g->z[k] = 5.0f;
    g->z[1] = -0.0f; /* tile 0: -0 first, then +0 */
    g->z[2] = 0.0f;
    g->z[10] = 0.0f; /* tile 1: +0 first (column 10), then -0 */
    g->z[20 + 11] = -0.0f;
    g->z[5 * 20 + 19] = -7.5f; /* tile 2's lowest, and the grid's */
    g->z[11 * 20 + 3] = 9.25f; /* tile 3's highest, and the grid's */
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_true(g->tiles[0].zmin == 0.0f && signbit(g->tiles[0].zmin));
    assert_true(g->tiles[1].zmin == 0.0f && !signbit(g->tiles[1].zmin));
    assert_true(g->tiles[2].zmin == -7.5f && g->tiles[2].zmax == 5.0f);
    assert_true(g->tiles[3].zmax == 9.25f && g->tiles[3].zmin == 5.0f);
    assert_true(g->zmin == -7.5f && g->zmax == 9.25f);
    for (size_t k = 0; k < 20 * 12; k++) /* a grid whose highest sample is zero */
        g->z[k] = k % 7 == 0 ? 0.0f : -(float)(k % 7);
    g->z[3] = -0.0f;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_true(g->zmax == 0.0f && !signbit(g->zmax)); /* z[0] = +0 comes first */
    g->z[0] = -0.0f;
    assert_int_equal(td_grid_finish(g, &err), TD_OK);
    assert_true(g->zmax == 0.0f && signbit(g->zmax));
    assert_true(g->zmin == -6.0f);
    g->z[4 * 20 + 9] = -INFINITY;
    g->z[7 * 20 + 2] = INFINITY;
    assert_int_equal(td_grid_finish(g, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "column 9, row 7 from the north")); /* rows: 12 - 1 - 4 */
    td_grid_free(g);
}

/* The Trinidad grid: 3 arc-seconds at its centre latitude 37.5 N is 73.688 m x 92.489 m
 * (the values in its dem.json). */
static void test_lonlat_spacing(void **state)
{
    double sx = 0, sy = 0;
    (void)state;
    td_grid_lonlat_spacing(37.5, 1.0 / 1200.0, 1.0 / 1200.0, &sx, &sy);
    assert_true(fabs(sx - 73.688) < 5e-4);
    assert_true(fabs(sy - 92.489) < 5e-4);
    /* equator: one degree of longitude is 111319.49 m on WGS84 */
    td_grid_lonlat_spacing(0.0, 1.0, 1.0, &sx, &sy);
    assert_true(fabs(sx - 111319.49) < 0.01);
    assert_true(fabs(sy - 110574.28) < 0.01);
    /* poles: longitude spacing shrinks to nothing */
    td_grid_lonlat_spacing(90.0, 1.0, 1.0, &sx, &sy);
    assert_true(fabs(sx) < 1e-6);
    assert_true(sy > 111000.0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_create_refuses_bad_sizes),
        cmocka_unit_test(test_checked_arithmetic),
        cmocka_unit_test(test_tile_layout),
        cmocka_unit_test(test_tiles_share_edges),
        cmocka_unit_test(test_tile_bounds_brute_force),
        cmocka_unit_test(test_voids),
        cmocka_unit_test(test_finish_signed_zeros),
        cmocka_unit_test(test_lonlat_spacing),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
