/* test_terrain.c: the procedural terrain generator (core/terrain.c): the same seed gives
 * the same heights, another seed others; the range is rescaled to [base, base + relief];
 * sizes, tiles and parameter checks. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "terrain.h"

static td_grid *gen(int32_t w, int32_t h, uint64_t seed, int tile_log2)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err err = {0};
    td_terrain_params_default(&p);
    p.width = w;
    p.height = h;
    p.seed = seed;
    assert_int_equal(td_terrain_generate(&p, tile_log2, &g, &err), TD_OK);
    assert_non_null(g);
    return g;
}

static void test_deterministic_by_seed(void **state)
{
    td_grid *a = gen(257, 129, 7, 8), *b = gen(257, 129, 7, 8), *c = gen(257, 129, 8, 8);
    size_t n = 257 * 129, differ = 0;
    (void)state;
    assert_memory_equal(a->z, b->z, n * sizeof(float));
    for (size_t k = 0; k < n; k++)
        differ += a->z[k] != c->z[k];
    assert_true(differ > n / 2);
    /* the tile size changes the tiling, not the heights */
    td_grid_free(b);
    b = gen(257, 129, 7, 4);
    assert_memory_equal(a->z, b->z, n * sizeof(float));
    td_grid_free(a);
    td_grid_free(b);
    td_grid_free(c);
}

static void test_range_and_sizes(void **state)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err err = {0};
    (void)state;
    td_terrain_params_default(&p);
    p.width = 300;
    p.height = 200;
    p.spacing = 12.5;
    p.base_m = 1000.0;
    p.relief_m = 800.0;
    assert_int_equal(td_terrain_generate(&p, 6, &g, &err), TD_OK);
    assert_int_equal(g->w, 300);
    assert_int_equal(g->h, 200);
    assert_true(g->sx == 12.5 && g->sy == 12.5);
    assert_int_equal(g->tiles_x, 5); /* 299 cells / 64 */
    assert_int_equal(g->tiles_y, 4); /* 199 cells / 64 */
    assert_int_equal(g->voids, 0);
    /* the extremes land exactly on base and base + relief */
    assert_true(g->zmin == 1000.0f);
    assert_true(g->zmax == 1800.0f);
    for (size_t k = 0; k < 300 * 200; k++)
        assert_true(g->z[k] >= g->zmin && g->z[k] <= g->zmax);
    td_grid_free(g);

    p.relief_m = 0.0; /* flat */
    assert_int_equal(td_terrain_generate(&p, 8, &g, &err), TD_OK);
    assert_true(g->zmin == 1000.0f && g->zmax == 1000.0f);
    td_grid_free(g);

    p.width = 8193; /* 2 .. 8192 */
    assert_int_equal(td_terrain_generate(&p, 8, &g, &err), TD_ERANGE);
    assert_null(g);
    p.width = 1;
    assert_int_equal(td_terrain_generate(&p, 8, &g, &err), TD_ERANGE);
    p.width = 100;
    p.octaves = 0;
    assert_int_equal(td_terrain_generate(&p, 8, &g, &err), TD_ERANGE);
    p.octaves = 4;
    p.ridge = 1.5;
    assert_int_equal(td_terrain_generate(&p, 8, &g, &err), TD_ERANGE);
    p.ridge = 0.5;
    p.spacing = 0.0;
    assert_int_equal(td_terrain_generate(&p, 8, &g, &err), TD_ERANGE);
    assert_null(g);
}

/* Not flat noise: neighbouring samples are correlated (a smooth field), and the relief
 * uses the whole range. */
static void test_looks_like_terrain(void **state)
{
    td_grid *g = gen(513, 513, 3, 8);
    double step = 0.0;
    size_t n = 0;
    (void)state;
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i + 1 < g->w; i++, n++)
            step += fabs((double)td_grid_at(g, i + 1, j) - td_grid_at(g, i, j));
    step /= (double)n;
    assert_true(step > 0.01);
    assert_true(step < 0.05 * (g->zmax - g->zmin)); /* far below white noise's ~1/3 */
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_deterministic_by_seed),
        cmocka_unit_test(test_range_and_sizes),
        cmocka_unit_test(test_looks_like_terrain),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
