/* gridedit.h: editing a grid's heights without touching the grid: a region and its new
 * heights are checked, then applied to a COPY (copy-on-write), so a grid that renders
 * are reading is never written. The server's PUT /v1/admin/datasets/{id}/heights and
 * `terrad render --edit` both call these, so the two give the same heights; a fuzz
 * target can call td_grid_edit_parse and td_grid_edit_decode on any bytes.
 *
 * A region is given as the API gives it: X, Y the column and row of its north-west
 * sample in the file's order (row 0 north), W x H samples; the body is W*H
 * little-endian float32 heights, row 0 the region's northern row, NaN a void. Inside,
 * rows are south-based (grid.h): file row y is grid row j = grid->h - 1 - y.
 *
 *   file rows (north first)          grid rows (south first)
 *   y     +-------+  body row 0      j = H-1-y       (the region's top)
 *         |region |                   ...
 *   y+h-1 +-------+  body row h-1    j = H-y-h       (its bottom)
 *
 * Touched tiles: every tile that holds one of the region's samples; tiles share their
 * edge samples, so an edit on a seam touches the tiles on both sides. */
#ifndef TD_GRIDEDIT_H
#define TD_GRIDEDIT_H

#include "grid.h"

/* The most samples one edit may carry by default (a 4096 x 4096 region, 64 MiB body). */
#define TD_GRID_EDIT_MAX_SAMPLES ((int64_t)1 << 24)

typedef struct td_grid_region {
    int32_t x, y; /* column and row (row 0 north) of the north-west sample */
    int32_t w, h; /* samples, >= 1 */
} td_grid_region;

/* Parses and checks the region's four decimal integers (the query's x, y, w, h) against
 * grid g: each present, an integer without sign or junk, the region inside the grid,
 * w*h at most max_samples (<= 0: TD_GRID_EDIT_MAX_SAMPLES). TD_EINVAL with err->field
 * "x", "y", "w" or "h" naming the one at fault; TD_ETOOBIG ("w") when too many samples. */
td_status td_grid_edit_parse(const td_grid *g, const char *x, const char *y, const char *w,
                             const char *h, int64_t max_samples, td_grid_region *out,
                             td_err *err);

/* Decodes the body of region r: exactly r->w * r->h little-endian float32, each finite
 * or NaN (a void; every NaN becomes the canonical quiet NaN). Returns a malloc'ed array
 * of w*h floats in the body's order (row 0 north). TD_EINVAL with field "body" for a
 * wrong length (saying the length expected) or an infinite sample (saying which). */
td_status td_grid_edit_decode(const td_grid_region *r, const void *body, size_t len,
                              float **out, td_err *err);

/* A new grid: a copy of g (heights, tiles, georeference) with the region's samples
 * replaced by z (w*h floats, row 0 north, as td_grid_edit_decode gives), its statistics
 * and tile ranges recomputed. g is only read. r must be inside g (td_grid_edit_parse). */
td_status td_grid_edit_apply(const td_grid *g, const td_grid_region *r, const float *z,
                             td_grid **out, td_err *err);

/* The tiles of g that hold a sample of r: a malloc'ed list of tile indices (row-major,
 * south first, as g->tiles), *n of them (at least one). */
td_status td_grid_edit_tiles(const td_grid *g, const td_grid_region *r, size_t **tiles,
                             size_t *n, td_err *err);

/* The region's current heights as a body: w*h little-endian float32 (4*w*h bytes into
 * out), row 0 north, voids as NaN: what GET .../heights answers, and what a client
 * changes and sends back. r must be inside g. */
void td_grid_edit_read(const td_grid *g, const td_grid_region *r, unsigned char *out);

/* Reads a file of w*h little-endian float32 (the same body as the API's) and applies it
 * at (x, y): what `terrad render --edit X,Y,W,H,FILE` does. Errors name the file. */
td_status td_grid_edit_file(const td_grid *g, const td_grid_region *r, const char *path,
                            td_grid **out, td_err *err);

#endif
