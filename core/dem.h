/* dem.h: loading DEM files into grids. One entry point picks the loader by the file's
 * extension (never by guessing an encoding from pixel values): raw float32 + JSON
 * sidecar (.f32 + .json), ESRI ASCII grid (.asc), SRTM (.hgt), PNG (.png, with an explicit
 * encoding), and anything else through GDAL when built with it.
 * Every loader checks sizes against the limits before allocating and refuses truncated,
 * oversized, inconsistent, non-numeric or NaN-laden input with a message naming the file
 * and the reason. */
#ifndef TD_DEM_H
#define TD_DEM_H

#include "grid.h"

#define TD_DEM_ENCODING_LIST(X)                                                \
    X(TD_ENC_NONE, "none")              /* not given */                        \
    X(TD_ENC_GRAY16, "gray16")          /* 16-bit gray: m = v*scale + offset */\
    X(TD_ENC_TERRAIN_RGB, "terrain-rgb") /* Mapbox: -10000 + (R*65536+G*256+B)*0.1 */ \
    X(TD_ENC_TERRARIUM, "terrarium")    /* R*256 + G + B/256 - 32768 */        \
    X(TD_ENC_RGB_DIV, "rgb-div")        /* (R*65536+G*256+B) / divisor */

typedef enum td_dem_encoding {
#define TD_X_ENUM(e, name) e,
    TD_DEM_ENCODING_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_ENC_COUNT
} td_dem_encoding;

typedef struct td_dem_opts {
    td_dem_encoding encoding; /* PNG only; required for PNG unless a sidecar gives it */
    double scale, offset;     /* gray16: metres = value*scale + offset (default 1, 0) */
    double divisor;           /* rgb-div (default 11983, the Levi file's) */
    double spacing[2];        /* metres; overrides/supplies spacing when > 0 */
    double nodata;            /* PNG: raw value meaning void when has_nodata */
    int has_nodata;
    int tile_log2;            /* 0: TD_TILE_LOG2_DEFAULT */
    td_grid_limits limits;
} td_dem_opts;

void td_dem_opts_default(td_dem_opts *o);
const char *td_dem_encoding_name(td_dem_encoding e);
td_status td_dem_encoding_parse(const char *name, td_dem_encoding *out);

/* Loads `path` into a finished grid (stats and tiles computed). */
td_status td_dem_load(const char *path, const td_dem_opts *opts, td_grid **out, td_err *err);

/* Non-zero if `path` names something td_dem_load recognises by its name (used to list a
 * data directory). */
int td_dem_recognised(const char *path);

#endif
