/* test_planes.c: unit tests of the parameter planes' build stages. The dilation
 * (td_planes_max3x3, the 3x3 maximum that turns the EDT's centre distances into
 * footprint gaps) against brute force: random arrays with holes (-inf) of every small
 * shape, one-cell and one-row arrays, the array's edges, and real tiles of a grid with
 * voids and partial edge tiles, where nothing beyond the tile may count. The cone bound
 * of the whole build is tested in test_trace.c. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "planes.h"
#include "trace.h"

static uint64_t next(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return *s >> 33;
}

/* The 3x3 maximum by definition: every neighbour inside the array, one by one. */
static float brute_max3x3(const float *h, int32_t nx, int32_t ny, int32_t x, int32_t y)
{
    float m = -INFINITY;
    for (int32_t dy = -1; dy <= 1; dy++)
        for (int32_t dx = -1; dx <= 1; dx++) {
            int32_t qx = x + dx, qy = y + dy;
            if (qx >= 0 && qx < nx && qy >= 0 && qy < ny && h[(size_t)qy * (size_t)nx + (size_t)qx] > m)
                m = h[(size_t)qy * (size_t)nx + (size_t)qx];
        }
    return m;
}

/* td_planes_max3x3 of h equals brute force everywhere, and {out >= z} is {h >= z}
 * dilated by one cell (8-neighbourhood) for every height z of h. */
static void check_against_brute(const float *h, int32_t nx, int32_t ny)
{
    size_t n = (size_t)nx * (size_t)ny;
    float *out = malloc(sizeof(float) * n);
    assert_non_null(out);
    td_planes_max3x3(h, nx, ny, out);
    for (int32_t y = 0; y < ny; y++)
        for (int32_t x = 0; x < nx; x++) {
            float want = brute_max3x3(h, nx, ny, x, y), got = out[(size_t)y * (size_t)nx + (size_t)x];
            if (!(got == want)) /* exact: a maximum is one of the inputs */
                fail_msg("%d x %d: out(%d, %d) = %g, brute force %g", (int)nx, (int)ny, (int)x, (int)y,
                         (double)got, (double)want);
        }
    for (size_t k = 0; k < n; k++) {
        float z = h[k];
        if (z == -INFINITY)
            continue;
        for (int32_t y = 0; y < ny; y++)
            for (int32_t x = 0; x < nx; x++) {
                int near = 0;
                for (int32_t dy = -1; dy <= 1; dy++)
                    for (int32_t dx = -1; dx <= 1; dx++) {
                        int32_t qx = x + dx, qy = y + dy;
                        near |= qx >= 0 && qx < nx && qy >= 0 && qy < ny &&
                                h[(size_t)qy * (size_t)nx + (size_t)qx] >= z;
                    }
                assert_int_equal(out[(size_t)y * (size_t)nx + (size_t)x] >= z, near);
            }
    }
    free(out);
}

static void test_max3x3_random(void **state)
{
    static const int32_t shapes[][2] = {{1, 1}, {1, 7}, {7, 1}, {2, 2}, {3, 2}, {2, 3}, {5, 3},
                                        {8, 8}, {13, 9}, {32, 17}, {1, 33}, {33, 1}};
    uint64_t s = 12345;
    (void)state;
    for (size_t i = 0; i < sizeof shapes / sizeof shapes[0]; i++) {
        int32_t nx = shapes[i][0], ny = shapes[i][1];
        for (int round = 0; round < 4; round++) {
            size_t n = (size_t)nx * (size_t)ny;
            float *h = malloc(sizeof(float) * n);
            assert_non_null(h);
            for (size_t k = 0; k < n; k++) {
                uint64_t r = next(&s);
                /* a quarter holes, some ties, negative heights too */
                h[k] = r % 4 == 0 ? -INFINITY : (float)((int64_t)(r % 41) - 10) * 0.5f;
            }
            check_against_brute(h, nx, ny);
            free(h);
        }
    }
}

static void test_max3x3_holes_and_edges(void **state)
{
    float h[4 * 3], out[4 * 3];
    (void)state;
    /* all holes stay holes */
    for (int k = 0; k < 12; k++)
        h[k] = -INFINITY;
    td_planes_max3x3(h, 4, 3, out);
    for (int k = 0; k < 12; k++)
        assert_true(out[k] == -INFINITY);
    /* one cell in a corner reaches its three neighbours and no further */
    h[0] = 5.0f;
    td_planes_max3x3(h, 4, 3, out);
    for (int32_t y = 0; y < 3; y++)
        for (int32_t x = 0; x < 4; x++)
            assert_true(out[y * 4 + x] == (x <= 1 && y <= 1 ? 5.0f : -INFINITY));
    /* one cell in the far corner, lower than a hole's neighbours: same, mirrored */
    h[0] = -INFINITY;
    h[11] = -3.0f;
    td_planes_max3x3(h, 4, 3, out);
    for (int32_t y = 0; y < 3; y++)
        for (int32_t x = 0; x < 4; x++)
            assert_true(out[y * 4 + x] == (x >= 2 && y >= 1 ? -3.0f : -INFINITY));
    /* a single cell is its own maximum */
    h[0] = 7.5f;
    td_planes_max3x3(h, 1, 1, out);
    assert_true(out[0] == 7.5f);
}

/* The cells' highest corners of real tiles: voids, partial east and north tiles, and a
 * spike just beyond a tile's edge that the whole grid's dilation would carry in. */
static void test_max3x3_tiles(void **state)
{
    td_grid *g = NULL;
    uint64_t s = 99;
    (void)state;
    /* 21 x 14 samples: 20 x 13 cells in tiles of 8: 3 x 2 tiles, the last column and row partial */
    assert_int_equal(td_grid_create(21, 14, 10.0, 12.0, 3, NULL, &g, NULL), TD_OK);
    for (int32_t k = 0; k < 21 * 14; k++)
        g->z[k] = (float)(next(&s) % 200);
    g->z[5 * 21 + 3] = NAN;
    g->z[5 * 21 + 4] = NAN;
    g->z[12 * 21 + 18] = NAN;
    /* samples are stored row 0 north; sample column 9 lies only under cells 8 and 9
     * (tile column 1): tile 0's cells end at sample column 8 */
    for (int32_t r = 0; r < 14; r++)
        g->z[r * 21 + 9] = 10000.0f;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    assert_int_equal(g->tiles_x, 3);
    assert_int_equal(g->tiles_y, 2);
    for (int32_t t = 0; t < g->tiles_x * g->tiles_y; t++) {
        const td_tile *tl = &g->tiles[t];
        size_t n = (size_t)tl->nx * (size_t)tl->ny;
        float *h = malloc(sizeof(float) * n), *out = malloc(sizeof(float) * n);
        assert_non_null(h);
        assert_non_null(out);
        td_grid_cell_max(g, tl, h);
        check_against_brute(h, tl->nx, tl->ny);
        td_planes_max3x3(h, tl->nx, tl->ny, out);
        if (t % g->tiles_x == 0) /* west tiles: the wall of 10000 is beyond their east edge */
            for (size_t k = 0; k < n; k++)
                assert_true(out[k] < 10000.0f);
        free(h);
        free(out);
    }
    assert_true(g->tiles[2].nx < 8); /* the east tiles are partial */
    assert_true(g->tiles[3].ny < 8); /* the north tiles too */
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_max3x3_random),
        cmocka_unit_test(test_max3x3_holes_and_edges),
        cmocka_unit_test(test_max3x3_tiles),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
