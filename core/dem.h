/* dem.h: loading DEM files into grids. One entry point picks the loader by the file's
 * extension (never by guessing an encoding from pixel values): raw float32 + JSON
 * sidecar (.f32 + .json), ESRI ASCII grid (.asc), SRTM (.hgt), PNG (.png, with an explicit
 * encoding), and anything else through GDAL when built with it.
 * Every loader checks sizes against the limits before allocating and refuses truncated,
 * oversized, inconsistent, non-numeric or NaN-laden input with a message naming the file
 * and the reason.
 *
 * Precedence of parameters: an explicit option (opts, e.g. from command-line flags) wins
 * over the JSON sidecar beside the file, which wins over the defaults. For scale, offset
 * and divisor, whose defaults are real numbers, "explicit" means the matching bit is set
 * in opts->given (TD_DEM_GIVEN_*); encoding, spacing and nodata are explicit when set
 * (encoding != TD_ENC_NONE, spacing > 0, has_nodata).
 *
 * Sidecar `<name>.json` (beside `<name>.f32` or `<name>.png`; keys other than these are
 * ignored, so a descriptive JSON with min/max/source is fine):
 *   width, height          integers (.f32 only, required there)
 *   spacing_m              number, or [sx, sy], metres
 *   nodata                 number, null (no voids), or "nan" (.f32: NaN samples are voids)
 *   encoding, scale, offset, divisor   PNG only, as in td_dem_opts
 *   dtype, byte_order      if present must be "float32" and "little" (.f32)
 *   origin                 optional object: lon_west, lat_north, dlon_deg, dlat_deg
 *                          (lon/lat of the north-west sample, degrees per sample), or
 *                          x_ul, y_ul (projected coordinates of the north-west sample),
 *                          and crs (free text) */
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
    unsigned given;           /* TD_DEM_GIVEN_* bits: scale/offset/divisor set explicitly */
} td_dem_opts;

#define TD_DEM_GIVEN_SCALE 1u
#define TD_DEM_GIVEN_OFFSET 2u
#define TD_DEM_GIVEN_DIVISOR 4u

void td_dem_opts_default(td_dem_opts *o);
const char *td_dem_encoding_name(td_dem_encoding e);
td_status td_dem_encoding_parse(const char *name, td_dem_encoding *out);

/* Loads `path` into a finished grid (stats and tiles computed). */
td_status td_dem_load(const char *path, const td_dem_opts *opts, td_grid **out, td_err *err);

/* Non-zero if `path` names something td_dem_load recognises by its name (used to list a
 * data directory). A .png counts only when its `<name>.json` sidecar exists (a PNG without
 * one needs an explicit encoding, and is more likely an image such as an orthophoto). */
int td_dem_recognised(const char *path);

/* Non-zero when the build has the GDAL loader (GeoTIFF and other raster formats). */
int td_dem_have_gdal(void);

#endif
