/* grid.h: the height field, its dataset frame, georeference and tiles.
 *
 * A grid is W x H float heights with spacing sx, sy in metres (they may differ, as on
 * lon/lat grids). Storage is row-major with SOUTH-based rows, so sample (i, j) sits at
 * (i*sx, j*sy, z[j*W + i]) in the dataset frame (x east, y north); loaders flip the
 * file's north-first rows as they read. A void (nodata) sample is NaN; a cell with a
 * void corner is a hole.
 *
 *        j = H-1  +----+----+----+      tiles of T x T cells share their edge samples:
 *                 |    |    |    |      tile (tx, ty) covers cells i in [tx*T, tx*T+T)
 *        j = 1    +----+----+----+      and samples i in [tx*T, tx*T+T] (clamped), so
 *                 |cell|    |    |      the surface is watertight across seams.
 *        j = 0    +----+----+----+
 *               i = 0    1    2   W-1
 *
 * Built grids are immutable and shared by threads without locks. */
#ifndef TD_GRID_H
#define TD_GRID_H

#include <stdint.h>
#include <stddef.h>

#include "status.h"

#define TD_TILE_LOG2_DEFAULT 8 /* T = 256 cells */

typedef enum td_geo_kind {
    TD_GEO_NONE = 0,  /* local metres only */
    TD_GEO_LONLAT,    /* x0, y0 in degrees; dx, dy in degrees per sample */
    TD_GEO_PROJECTED  /* x0, y0 in projected units (easting/northing); dx, dy per sample */
} td_geo_kind;

/* Georeference of sample (0, 0), the south-west sample, kept in double precision. */
typedef struct td_georef {
    td_geo_kind kind;
    double x0, y0; /* lon/lat or easting/northing of sample (0, 0) */
    double dx, dy; /* georeferenced step per sample, east and north (both > 0) */
    char crs[96];  /* free text, may be empty */
} td_georef;

typedef struct td_tile {
    int32_t i0, j0;   /* first cell of the tile (also its first sample) */
    int32_t nx, ny;   /* cells in the tile: T, or fewer on the east/north edge */
    float zmin, zmax; /* over the valid samples of the tile, edges included;
                         +inf/-inf if the tile has none */
} td_tile;

typedef struct td_grid_limits {
    int32_t max_width, max_height; /* default 65536 each */
    uint64_t max_bytes;            /* heights + tile records; 0 = no budget (default 4 GiB) */
} td_grid_limits;

/* Where the samples of cell corners are (the render path's one accessor, td_grid_corner):
 * the samples are kept in blocks of B x B cells, (B+1) x (B+1) samples each (the edge
 * samples shared with the neighbours duplicated), so the four corners of any cell are in
 * one block: sample (i, j) of block (i >> log2, j >> log2) is at
 *   base + ((j >> log2) * blocks_x + (i >> log2)) * block_floats
 *        + (j & mask) * stride + (i & mask)
 * and the cell's other corners at +1, +stride, +stride+1. An in-memory grid is one block
 * (log2 30, mask all ones, stride w: the row-major address of z), which td_grid_corner
 * takes directly (one predicted branch: the branchless formula for both cost 10-13% more
 * instructions on two render views, the branch 2-3%, callgrind); a prepared
 * grid's blocked file (prepared.h, B = 32 by default) has log2 5, stride 33, and a block row
 * for every 32 cells plus one where the last sample starts a block (every sample, not only every
 * cell corner, is addressable). */
typedef struct td_corners {
    const float *base;
    size_t blocks_x;     /* blocks along a row */
    size_t block_floats; /* floats from one block to the next */
    size_t stride;       /* floats from one sample row of a block to the next */
    uint32_t mask;       /* B - 1 */
    int log2;            /* log2 B */
} td_corners;

#define TD_CORNERS_FLAT_LOG2 30 /* one block: any index of an int32 grid < 2^30 */

typedef struct td_grid {
    int32_t w, h;      /* samples */
    double sx, sy;     /* spacing in metres */
    float *z;          /* w*h heights, south-based rows, NaN = void */
    int tile_log2;     /* T = 1 << tile_log2 cells */
    int32_t tiles_x, tiles_y;
    td_tile *tiles;    /* tiles_x * tiles_y, row-major, south first */
    float zmin, zmax;  /* over valid samples; NaN if all are void */
    int64_t voids;     /* void samples */
    td_georef geo;
    void *map;         /* when z is a read-only file mapping (prepared.h): its base, which
                          td_grid_free unmaps instead of freeing z; NULL otherwise */
    size_t map_bytes;
    td_corners cz;     /* where the render path reads samples (td_grid_corner): z itself,
                          or a prepared grid's blocked copy of it */
    void *bmap;        /* that blocked copy's file mapping (unmapped by td_grid_free), or NULL */
    size_t bmap_bytes;
} td_grid;

void td_grid_limits_default(td_grid_limits *lim);

/* Bytes a w x h grid would take resident (heights and tile records), or 0 on overflow. */
uint64_t td_grid_bytes(int32_t w, int32_t h, int tile_log2);

/* Allocates a w x h grid (heights uninitialised) after checking size, overflow and the
 * limits (lim may be NULL for the defaults). Nothing is allocated when a check fails.
 * Fill g->z (south-based rows), then call td_grid_finish. */
td_status td_grid_create(int32_t w, int32_t h, double sx, double sy, int tile_log2,
                         const td_grid_limits *lim, td_grid **out, td_err *err);

/* Floats as int32 keys in the same order (-0 just below +0), so that the lowest and highest
 * of a run are integer reductions, which vectorise where float ones (NaN rules) do not:
 * td_grid_keys takes the keys of z[0 .. n) whose magnitude's bits are at most `most` into
 * *lo and *hi (start them at INT32_MAX and INT32_MIN: those stay for none), and
 * td_grid_key_float turns a key back into its float. */
#define TD_KEYS_VALID 0x7f800000u  /* every value but NaN (a void) */
#define TD_KEYS_FINITE 0x7f7fffffu /* the finite values */
void td_grid_keys(const float *z, size_t n, uint32_t most, int32_t *lo, int32_t *hi);
float td_grid_key_float(int32_t k);

/* Computes zmin/zmax, void count and the tile records. Refuses +-inf heights. */
td_status td_grid_finish(td_grid *g, td_err *err);

void td_grid_free(td_grid *g);

/* O(1) lookups. */
static inline float td_grid_at(const td_grid *g, int32_t i, int32_t j)
{
    return g->z[(size_t)j * (size_t)g->w + (size_t)i];
}

/* Sample (i, j) through g->cz (any 0 <= i < w, 0 <= j < h): a cell (i, j)'s corners
 * are p[0], p[1], p[stride], p[stride + 1] for p = td_grid_corner(&g->cz, i, j). The
 * tracers, the hit shading and the tiles' acceleration builds read heights this way (so a
 * prepared grid's render touches its blocked pages only); td_grid_at reads z, row-major. */
static inline const float *td_grid_corner(const td_corners *c, int32_t i, int32_t j)
{
    if (__builtin_expect(c->log2 == TD_CORNERS_FLAT_LOG2, 1))
        return c->base + (size_t)j * c->stride + (size_t)i;
    return c->base +
           ((size_t)(j >> c->log2) * c->blocks_x + (size_t)(i >> c->log2)) * c->block_floats +
           (size_t)((uint32_t)j & c->mask) * c->stride + (size_t)((uint32_t)i & c->mask);
}

/* Of n samples (i, j), (i + 1, j) .. along a row, how many from the first are
 * contiguous at td_grid_corner(c, i, j) (all n in an in-memory grid; up to the block's
 * east edge in a blocked one). */
static inline int32_t td_grid_run(const td_corners *c, int32_t i, int32_t n)
{
    int64_t left = (int64_t)c->mask + 2 - (int64_t)((uint32_t)i & c->mask);
    return left < n ? (int32_t)left : n;
}

static inline float td_grid_sample(const td_grid *g, int32_t i, int32_t j)
{
    return *td_grid_corner(&g->cz, i, j);
}

/* g->cz as the row-major address of g->z (what td_grid_create sets). */
void td_grid_corners_flat(td_grid *g);

static inline int32_t td_grid_tile_size(const td_grid *g) { return (int32_t)1 << g->tile_log2; }

/* The tile that owns cell (ci, cj); 0 <= ci < w-1, 0 <= cj < h-1. */
static inline const td_tile *td_grid_tile_of_cell(const td_grid *g, int32_t ci, int32_t cj)
{
    return &g->tiles[(size_t)(cj >> g->tile_log2) * (size_t)g->tiles_x +
                     (size_t)(ci >> g->tile_log2)];
}

/* The tiles tx0..tx1 x ty0..ty1 (inclusive, inside the grid) as a malloc'ed list of tile
 * indices, row-major, south first (as g->tiles); *n of them. */
td_status td_grid_tile_range(const td_grid *g, int32_t tx0, int32_t tx1, int32_t ty0, int32_t ty1,
                             size_t **tiles, size_t *n, td_err *err);

/* The bilinear surface of cell (ci, cj) at (x, y) in the dataset frame (clamped to the
 * cell): the exact surface the others are measured against. Its unit normal goes to n
 * unless n is NULL. Returns 0, leaving z and n alone, where a corner is a void. */
int td_grid_bilinear_cell(const td_grid *g, int32_t ci, int32_t cj, double x, double y, double *z,
                          double n[3]);

/* The same at (x, y) in whichever cell holds it (the grid's border cells beyond it). */
int td_grid_bilinear(const td_grid *g, double x, double y, double *z, double n[3]);

/* Per cell of tile t, the highest of its four corners (which bounds every surface), or
 * -inf for a hole (a void corner). out holds t->nx * t->ny floats, row-major, south first. */
void td_grid_cell_max(const td_grid *g, const td_tile *t, float *out);

/* Spacing in metres of a lon/lat grid at latitude lat_deg on the WGS84 ellipsoid
 * (radii of curvature in the prime vertical and the meridian). */
void td_grid_lonlat_spacing(double lat_deg, double dlon_deg, double dlat_deg, double *sx,
                            double *sy);

#endif
