/* terrain.h: a seeded procedural terrain generator (fBm of gradient noise with ridged
 * octaves) for tests and benchmarks. Same seed and parameters, same heights, on every
 * machine: integer hashing, no libc rand. */
#ifndef TD_TERRAIN_H
#define TD_TERRAIN_H

#include "grid.h"

typedef struct td_terrain_params {
    int32_t width, height; /* samples, 2 .. 8192 */
    double spacing;        /* metres, > 0 */
    uint64_t seed;
    int octaves;           /* 1 .. 16 */
    double feature_m;      /* wavelength of the first octave, metres */
    double relief_m;       /* height range, metres (0 gives flat terrain at base_m) */
    double base_m;         /* lowest height */
    double ridge;          /* 0 = smooth fBm, 1 = fully ridged */
} td_terrain_params;

void td_terrain_params_default(td_terrain_params *p);

/* Builds a grid (tile size 2^tile_log2) filled with procedural heights. */
td_status td_terrain_generate(const td_terrain_params *p, int tile_log2, td_grid **out, td_err *err);

#endif
