/* terrain_fixture.h: procedural terrain for the unit tests that need a relief (test_beam.c,
 * test_sunlit.c, test_trace.c). Include after cmocka.h. */
#ifndef TERRAIN_FIXTURE_H
#define TERRAIN_FIXTURE_H

#include "terrain.h"

/* Procedural terrain of w x h samples at `spacing` metres from `seed`, tiles of
 * 2^tile_log2 cells. */
static inline td_grid *terrain_seeded(int32_t w, int32_t h, double spacing, uint64_t seed, int tile_log2)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_terrain_params_default(&p);
    p.width = w;
    p.height = h;
    p.spacing = spacing;
    p.seed = seed;
    assert_int_equal(td_terrain_generate(&p, tile_log2, &g, NULL), TD_OK);
    return g;
}

/* The same from td_terrain_params_default's seed. */
static inline td_grid *terrain(int32_t w, int32_t h, double spacing, int tile_log2)
{
    td_terrain_params p;
    td_terrain_params_default(&p);
    return terrain_seeded(w, h, spacing, p.seed, tile_log2);
}

#endif
