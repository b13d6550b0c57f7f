/* demutil.h: pieces shared by the DEM loaders (internal to core/dem*.c): the JSON
 * sidecar, the resolution of spacing and georeference, opening a file and reading its
 * rows into their south-based place, the creation and finishing of a grid with messages
 * that name the file, and the lookup of a file's extension.
 * See dem.h for the sidecar keys and the precedence opts > sidecar > defaults.
 *
 * Every loader has the same shape: parse the header, sidecar or name, check the size against
 * the limits (td_demutil_check_limits) before allocating, resolve spacing and
 * georeference, create the grid (td_demutil_create), read the samples row by row
 * (td_demutil_file_row), and hand the grid over with td_demutil_deliver, its one exit. */
#ifndef TD_DEMUTIL_H
#define TD_DEMUTIL_H

#include <stdint.h>
#include <stdio.h>
#include <sys/stat.h>

#include "dem.h"

#define TD_DEMUTIL_PATH_MAX 4096

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
                                     sample until td_demutil_side_georef */
    char path[TD_DEMUTIL_PATH_MAX]; /* the sidecar's path, for messages */
} td_demside;

/* `<path without extension>.json` into out; 0 if it does not fit. */
int td_demutil_sidecar_path(const char *path, char *out, size_t outsz);

/* Reads the sidecar of `path` (data file). A missing sidecar is an error only when
 * `required`; otherwise sc->present = 0. `need_size` asks for width/height. */
td_status td_demutil_sidecar_read(const char *path, int required, int need_size, td_demside *sc,
                                  td_err *err);

/* Spacing in metres: opts->spacing if given, else `sidecar` (may be NULL or have none),
 * else from a lon/lat georef at its centre latitude; error naming `path` otherwise. */
td_status td_demutil_spacing(const char *path, const td_dem_opts *o, const td_demside *sc,
                             const td_georef *geo, int32_t w, int32_t h, double *sx, double *sy,
                             td_err *err);

/* The size checks of td_grid_create (dimensions and memory budget of o->limits), done
 * before anything else so a header claiming a huge grid is refused as too big. */
td_status td_demutil_check_limits(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                                  td_err *err);

/* The byte budget of o->limits for the grid together with `extra` bytes the loader holds
 * while filling it (decode buffers, named by `what` in the message), checked before the
 * grid is allocated: "path: grid of W x H samples (G bytes) and WHAT (E bytes) need T
 * bytes, over the budget of B". */
td_status td_demutil_check_budget(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                                  uint64_t extra, const char *what, td_err *err);

/* Spacing and georeference of a grid of w x h samples described by a sidecar: sc->geo
 * arrives as read (y0 the north row, a projected origin without its step) and leaves in
 * grid.h's south-west convention, a projected origin taking the spacing as its step. */
td_status td_demutil_side_georef(const char *path, const td_dem_opts *o, td_demside *sc,
                                 int32_t w, int32_t h, double *sx, double *sy, td_err *err);

/* td_grid_create with the opts' limits and tile size, then geo (may be NULL) copied into
 * the grid; the message names `path`. */
td_status td_demutil_create(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                            double sx, double sy, const td_georef *geo, td_grid **out,
                            td_err *err);

/* Where file row r (row 0 = north, as files store them) lives in the grid's south-based
 * rows (grid.h). */
float *td_demutil_file_row(const td_grid *g, int32_t r);

/* fopen(path, "rb") into *f and, when st is not NULL, fstat into *st. On failure the
 * message is "path: cannot open (reason)"; *f may then be open (fstat failed), and the
 * caller closes it as on every other path. */
td_status td_demutil_open(const char *path, FILE **f, struct stat *st, td_err *err);

/* fread of n items of `size` bytes into dst, file row r; a short read is an error naming
 * the row, and whether the file failed or shrank since its size was checked. */
td_status td_demutil_read_row(const char *path, FILE *f, void *dst, size_t size, size_t n,
                              int32_t r, td_err *err);

/* How a loader of float32 samples (demraw.c, demgdal.c) turns them into heights, in this
 * order: a NaN is a void when nan_void, else refused (the message ends with nan_why); an
 * infinity is refused when inf_refused; a sample equal to nodata (when has_nodata) becomes
 * a void; any other becomes sample*scale + offset, refused as not finite beyond max_abs.
 * scale 1 and offset -0.0 leave every sample as it is, -0.0 included (x + -0.0 == x). */
typedef struct td_demutil_f32 {
    int nan_void;
    char nan_why[TD_DEMUTIL_PATH_MAX + 64]; /* room for a sidecar's path */
    int inf_refused;
    int has_nodata;
    float nodata;
    double scale, offset, max_abs;
} td_demutil_f32;

/* Applies p to the w samples of file row r in place (columns and row in the messages). */
td_status td_demutil_f32_row(const char *path, const td_demutil_f32 *p, float *row, int32_t w,
                             int32_t r, td_err *err);

/* The one exit of a loader: when rc is TD_OK, td_grid_finish (stats and tiles; its
 * message names `path`); if that or anything before failed, g is freed. *out gets the
 * finished grid or NULL; returns the status. g may be NULL when rc is not TD_OK. */
td_status td_demutil_deliver(const char *path, td_status rc, td_grid *g, td_grid **out,
                             td_err *err);

/* Lower-case extension of path without the dot ("" if none) into out (at most 15 chars). */
void td_demutil_ext(const char *path, char *out, size_t outsz);

/* The file name part of path. */
const char *td_demutil_basename(const char *path);

/* Strict number parsing: the whole token must be a finite decimal number (no "nan",
 * "inf", hex, or trailing characters). Returns 1 on success. */
int td_demutil_parse_double(const char *tok, double *out);

#endif
