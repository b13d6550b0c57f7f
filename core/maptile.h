/* maptile.h: one Web Mercator map tile's pixels from their ground positions: heights in
 * an RGB encoding for web maps' elevation sources, or the terrain shaded from above with
 * cast shadows.
 *
 * Callers: server/maps.c (GET /v1/maps/...), the map benchmark, the tests. The positions
 * come from mercator.h (td_merc_positions: each pixel centre in the dataset frame); this
 * module knows nothing of projections.
 *
 * Each pixel is the dataset at its position on the level of detail that fits the pixel
 * (lod.h: the coarsest level whose cells are no larger than the pixel's footprint times
 * lod_pixels; the full grid when lod_pixels is 0 or no levels are given):
 *   terrain-rgb  height = -10000 + (R * 65536 + G * 256 + B) * 0.1  (Mapbox), rounded to
 *                the nearest 0.1 m;
 *   terrarium    height = R * 256 + G + B / 256 - 32768  (Mapzen/Tilezen), rounded to the
 *                nearest 1/256 m;
 *     the height is the surface's (td_surface_height) at the position; where there is no
 *     data (outside the grid, a void) the pixel encodes 0 m with alpha 0 (what MapLibre
 *     assumes beyond a source's bounds, so no wall at the edge);
 *   shaded       a ray straight down at the position (td_trace, the request's method and
 *                surface: the same hit as an orthographic render's), then, with shadows,
 *                one ray toward the sun from the hit (td_occluded, with the sun bound of
 *                sunlit.h on the full grid); grey = 255 * (a + (1 - a) * max(0, n.sun) *
 *                lit), a the ambient term, alpha 255; no data: transparent (0, 0, 0, 0).
 *                Linear in n.sun, as gdaldem hillshade's 255 * n.sun. */
#ifndef TD_MAPTILE_H
#define TD_MAPTILE_H

#include <stdint.h>

#include "lod.h"
#include "sunlit.h"
#include "trace.h"

#define TD_MAPSTYLE_LIST(X)                                                    \
    X(TD_MAPSTYLE_SHADED, "shaded")                                            \
    X(TD_MAPSTYLE_TERRAIN_RGB, "terrain-rgb")                                  \
    X(TD_MAPSTYLE_TERRARIUM, "terrarium")

typedef enum td_mapstyle {
#define TD_X_ENUM(e, name) e,
    TD_MAPSTYLE_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_MAPSTYLE_COUNT
} td_mapstyle;

const char *td_mapstyle_name(td_mapstyle s);
/* TD_EINVAL (and *out left) for an unknown name. */
td_status td_mapstyle_parse(const char *name, td_mapstyle *out);

typedef struct td_maptile_spec {
    td_mapstyle style;
    td_surface surface; /* default bilinear */
    td_method method;   /* default auto */
    double sun[3];      /* unit, toward the sun (shaded) */
    int shadows;        /* shaded: trace a ray toward the sun from each lit face */
    double ambient;     /* shaded: 0 .. 1 */
    double lod_pixels;  /* pixels one coarse cell may span; 0: the full grid always */
} td_maptile_spec;

typedef struct td_maptile_stats {
    uint64_t pixels_with_data;
    uint64_t primary_rays, shadow_rays, steps;
    int level; /* the level of detail used */
} td_maptile_stats;

void td_maptile_spec_default(td_maptile_spec *s);

/* The level of detail for pixels of foot_m metres (see the top of the file). */
int td_maptile_level(const td_grid *base, const td_lod *lod, double foot_m, double lod_pixels);

/* Fills rgba (px * px * 4, rows from the north) from xy (td_merc_positions). v is the
 * full grid's view, lod its levels (may be NULL), lit the full grid's sun bound for
 * s->sun (may be NULL). rays (NULL, or 2 * px * px slots) receives each shaded pixel's
 * vertical ray [2k] and shadow ray [2k + 1] (tmax -1 where there is none), for tracing the
 * same rays with a reference (the oracle test). */
td_status td_maptile_render(const td_view *v, const td_lod *lod, const td_sunlit *lit,
                            const td_maptile_spec *s, const double *xy, int px, double foot_m,
                            uint8_t *rgba, td_ray *rays, td_maptile_stats *st, td_err *err);

/* The heights the encodings decode to (for tests): NaN where alpha is 0. */
double td_maptile_decode(td_mapstyle style, const uint8_t px[4]);

#endif
