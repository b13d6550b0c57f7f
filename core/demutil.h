/* demutil.h: pieces shared by the DEM loaders (internal to core/dem*.c): the JSON
 * sidecar, the resolution of spacing and georeference, the creation and finishing of a
 * grid with messages that name the file, and the lookup of a file's extension.
 * See dem.h for the sidecar keys and the precedence opts > sidecar > defaults. */
#ifndef TD_DEMUTIL_H
#define TD_DEMUTIL_H

#include <stdint.h>

#include "dem.h"

typedef enum td_demutil_nodata {
    TD_NODATA_ABSENT = 0, /* key not present */
    TD_NODATA_NULL,       /* "nodata": null: the file has no voids */
    TD_NODATA_VALUE,      /* "nodata": number */
    TD_NODATA_NAN         /* "nodata": "nan": NaN samples are voids (.f32) */
} td_demutil_nodata;

/* What a sidecar says; every field is optional, has_* tells which were present. */
typedef struct td_demside {
    int present;                  /* the sidecar file exists and was parsed */
    int has_size;
    int32_t width, height;
    int has_spacing;
    double spacing[2];
    td_demutil_nodata nodata_kind;
    double nodata;
    td_dem_encoding encoding;     /* TD_ENC_NONE when absent */
    int has_scale, has_offset, has_divisor;
    double scale, offset, divisor;
    td_georef geo;                /* kind NONE when no origin; x0/y0 of the NORTH-west
                                     sample until td_demutil_georef_finish */
    char path[4096];              /* the sidecar's path, for messages */
} td_demside;

/* `<path without extension>.json` into out; 0 if it does not fit. */
int td_demutil_sidecar_path(const char *path, char *out, size_t outsz);

/* Reads the sidecar of `path` (data file). A missing sidecar is an error only when
 * `required`; otherwise sc->present = 0. `need_size` asks for width/height. */
td_status td_demutil_sidecar_read(const char *path, int required, int need_size, td_demside *sc,
                                  td_err *err);

/* Turns a georef whose y0 is the north row (as files store it) into grid.h's south-west
 * convention, for a grid of h rows. */
void td_demutil_georef_from_north(td_georef *geo, int32_t h);

/* Spacing in metres: opts->spacing if given, else `sidecar` (may be NULL or have none),
 * else from a lon/lat georef at its centre latitude; error naming `path` otherwise. */
td_status td_demutil_spacing(const char *path, const td_dem_opts *o, const td_demside *sc,
                             const td_georef *geo, int32_t w, int32_t h, double *sx, double *sy,
                             td_err *err);

/* The size checks of td_grid_create (dimensions and memory budget of o->limits), done
 * before anything else so a header claiming a huge grid is refused as too big. */
td_status td_demutil_check_limits(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                                  td_err *err);

/* td_grid_create with the opts' limits and tile size; the message names `path`. */
td_status td_demutil_create(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                            double sx, double sy, td_grid **out, td_err *err);

/* td_grid_finish; the message names `path`. */
td_status td_demutil_finish(const char *path, td_grid *g, td_err *err);

/* Lower-case extension of path without the dot ("" if none) into out (at most 15 chars). */
void td_demutil_ext(const char *path, char *out, size_t outsz);

/* The file name part of path. */
const char *td_demutil_basename(const char *path);

/* Strict number parsing: the whole token must be a finite decimal number (no "nan",
 * "inf", hex, or trailing characters). Returns 1 on success. */
int td_demutil_parse_double(const char *tok, double *out);

#endif
