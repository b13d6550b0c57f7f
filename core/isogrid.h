/* isogrid.h: the isometric lattice (McGuire and Sibley 2004, "A heightfield on an
 * isometric grid"): a height field whose odd rows are slid east by half a column, so that
 * its triangles are (near) equilateral while tiles stay square; the lattice's surface is
 * piecewise linear over those triangles.
 *
 * Layout, in the dataset frame (x east, y north, metres), with column spacing a and row
 * spacing b:
 *
 *    row 3  O---O-------O-------O---O     odd rows: nx + 1 samples, at x = 0,
 *           |  / \     / \     / \  |       (c - 1/2) a for c = 1 .. nx-1, and (nx-1) a
 *    row 2  E-------E-------E-------E     even rows: nx samples at x = c a
 *           |  \ /     \ /     \ /  |     (the odd rows' end samples, on the border, are
 *    row 1  O---O-------O-------O---O      what keeps tiles square: the paper's "isosceles
 *           |  / \     / \     / \  |      triangles added to the rows' ends")
 *    row 0  E-------E-------E-------E     y = r b
 *
 * In the strip between rows r and r+1 (one even row E, one odd row O) the triangles are
 * numbered q = 0 .. 2nx-2 from west to east: q = 2c is "O-based" (O_c, O_c+1, E_c), q =
 * 2k+1 is "E-based" (E_k, E_k+1, O_k+1). In lattice coordinates u = x/a, Y = y/b every
 * edge lies on one of three families of lines, Y = n, u - Y/2 = n and u + Y/2 = n
 * (n integer), so the triangle holding a point is (r, q) = (floor Y, floor(u - Y/2) +
 * floor(u + Y/2) + 1), clipped to 0 <= u <= nx-1 (the border triangles are those cut in
 * half there). That is what the ray walk steps through: a three-family DDA.
 *
 * Row spacing: `square` takes b = a (the paper's square tiles: the lattice's rows and
 * columns fall on the square grid's, so a coarse level samples real grid points and has
 * the square level's extent and sample count, plus one sample per odd row);
 * `equilateral` takes b = a sqrt(3)/2 (equilateral triangles; the same density as a
 * square grid of spacing h needs a = h sqrt(2/sqrt 3)). docs/isometric.md measures both.
 *
 * Voids are NaN samples; a triangle with a void corner is a hole. Built lattices are
 * immutable and shared by threads without locks. Who calls it: the accuracy benchmark
 * (tests/bench/iso_accuracy.c), the oracle (tests/oracle/oracle_iso.c) and the unit
 * tests; core/lod.c builds isometric levels from it. */
#ifndef TD_ISOGRID_H
#define TD_ISOGRID_H

#include <math.h>
#include <stdint.h>

#include "grid.h"
#include "trace.h"

#define TD_ISO_ROWS_LIST(X)                                                    \
    X(TD_ISO_ROWS_SQUARE, "square")                                            \
    X(TD_ISO_ROWS_EQUILATERAL, "equilateral")

typedef enum td_iso_rows {
#define TD_X_ENUM(e, name) e,
    TD_ISO_ROWS_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_ISO_ROWS_COUNT
} td_iso_rows;

const char *td_iso_rows_name(td_iso_rows r);

/* Two-byte vertices (the paper's storage): the samples are cut into tiles of T x T
 * (rows r >> tile_log2, columns c >> tile_log2; an odd row's last sample belongs to the
 * last tile); each tile has an offset and a step, and each sample a 16-bit k, height =
 * offset + k * step of the sample's own tile. Every sample is stored once, so it decodes
 * to one height wherever triangles of two tiles share it (watertight). A tile is lossless
 * when all its heights are offset + k * step for the coarsest of the steps 2^4 .. 2^-16
 * and 1/10 .. 1/1000 that does it and its range fits 65534 steps; otherwise step = range /
 * 65534 and the error is at most step / 2 (max_err says what it was). */
typedef struct td_iso_packed {
    int32_t nx, ny;
    double a, b;
    int tile_log2;
    int32_t tiles_x, tiles_y;
    double *offset;   /* tiles_x * tiles_y */
    double *step;     /* tiles_x * tiles_y */
    uint16_t *k;      /* one per sample, in td_iso's order; 0xFFFF is a void */
    int32_t lossless; /* tiles decoded exactly */
    double max_err;   /* largest |decoded - original| over valid samples, metres */
    uint64_t bytes;   /* k, offsets and steps */
} td_iso_packed;

#define TD_ISO_BLOCK_LOG2 3 /* level-0 blocks of 8 x 8 rows and columns */
#define TD_ISO_BLEVELS 24    /* block levels at most (each doubles the block) */

typedef struct td_iso {
    int32_t nx, ny;   /* samples per even row (>= 2), rows (>= 2); odd rows hold nx + 1 */
    double a, b;      /* column and row spacing, metres */
    float *z;         /* row r starts at z + td_iso_row_offset(r); NULL when packed */
    td_iso_packed *packed; /* the samples as two-byte vertices (td_iso_pack_lattice), or NULL */
    float zmin, zmax; /* over valid samples; NaN if all are void */
    /* Block maxima (the walk's hierarchy, a max pyramid): at level k, block (i, j) is the
     * box x in [i S a, (i+1) S a], y in [j S b, (j+1) S b], S = 2^(TD_ISO_BLOCK_LOG2 + k);
     * bmax[k][j bw[k] + i] bounds every triangle over it (-inf if none is valid). The top
     * level has one block. */
    int blevels;
    int32_t bw[TD_ISO_BLEVELS], bh[TD_ISO_BLEVELS];
    float *bmax[TD_ISO_BLEVELS]; /* one allocation, at bmax[0] */
} td_iso;

/* A height function for td_iso_sample: returns z at (x, y), NaN for a void. */
typedef double (*td_iso_fn)(void *ctx, double x, double y);

static inline size_t td_iso_row_offset(int32_t nx, int32_t r)
{
    return (size_t)r * (size_t)nx + (size_t)(r / 2);
}

static inline int32_t td_iso_row_len(const td_iso *l, int32_t r) { return l->nx + (r & 1); }

/* The tile that stores sample (r, c) of a packed lattice, and sample i (row r, column c): offset + k step of its tile, NaN for a
 * void. The one decoder: every reader of a packed lattice sees these heights. */
static inline size_t td_iso_packed_tile(const td_iso_packed *p, int32_t r, int32_t c)
{
    int32_t tx = c >> p->tile_log2;
    return (size_t)(r >> p->tile_log2) * (size_t)p->tiles_x +
           (size_t)(tx < p->tiles_x ? tx : p->tiles_x - 1);
}

static inline float td_iso_packed_at(const td_iso_packed *p, int32_t r, int32_t c, size_t i)
{
    size_t ti = td_iso_packed_tile(p, r, c);
    uint16_t k = p->k[i];
    return k == 0xFFFF ? NAN : (float)(p->offset[ti] + k * p->step[ti]);
}

/* Sample c of row r: the float, or the packed vertex decoded. */
static inline float td_iso_at(const td_iso *l, int32_t r, int32_t c)
{
    size_t i = td_iso_row_offset(l->nx, r) + (size_t)c;
    return l->z ? l->z[i] : td_iso_packed_at(l->packed, r, c, i);
}

/* x of sample c in row r. */
double td_iso_x(const td_iso *l, int32_t r, int32_t c);

/* Allocates an nx x ny lattice (heights NaN) after checking sizes and overflow. */
td_status td_iso_create(int32_t nx, int32_t ny, double a, double b, td_iso **out, td_err *err);

/* Fills every sample from f, then td_iso_finish. */
void td_iso_sample(td_iso *l, td_iso_fn f, void *ctx);

/* zmin, zmax and the block maxima from the samples: call after writing l->z. */
void td_iso_finish(td_iso *l);

/* The lattice over grid g's extent (as much of it as whole rows and columns cover) with
 * the density of g subsampled every `step` samples: square rows a = step sx, b = step sy
 * (every sample on a grid node when step is even); equilateral a = step sqrt(2 sx sy /
 * sqrt 3), b = a sqrt(3)/2. Samples off the grid's nodes take its bilinear surface (void
 * where a corner that weighs is void). */
td_status td_iso_from_grid(const td_grid *g, int32_t step, td_iso_rows rows, td_iso **out,
                           td_err *err);

void td_iso_free(td_iso *l);

/* The triangle (r, q) holding (x, y), (x, y) clamped into the lattice. */
void td_iso_locate(const td_iso *l, double x, double y, int32_t *r, int32_t *q);

/* Corners of triangle (r, q) as (x, y, z) points. Returns 0 on a hole (a void corner). */
int td_iso_triangle(const td_iso *l, int32_t r, int32_t q, double v[3][3]);

/* Height and unit upward normal (n may be NULL) of the lattice's surface at (x, y)
 * (clamped into the lattice). Returns 0, leaving z and n alone, on a hole. */
int td_iso_eval(const td_iso *l, double x, double y, double *z, double n[3]);

/* The first point where ray r (validated) meets the lattice's triangles in [tmin, tmax]:
 * the walk visits the triangles the ray's ground track crosses, in order (a DDA over the
 * three line families), and solves each one's plane along the ray in double; it steps
 * over the largest block of the pyramid where the ray stays above the block's maximum
 * (a step too). The same
 * rules as td_trace: the surface is two-sided (a ray that starts on it hits at tmin, one
 * that starts below it where it first crosses it); holes are passed through. hit->ci, cj
 * hold the triangle (q, r); hit->method is TD_METHOD_INCREMENTAL. */
void td_iso_trace(const td_iso *l, const td_ray *r, td_hit *hit);

td_status td_iso_pack(const td_iso *l, int tile_log2, td_iso_packed **out, td_err *err);

/* The lattice a packed one decodes to. */
td_status td_iso_unpack(const td_iso_packed *p, td_iso **out, td_err *err);

void td_iso_packed_free(td_iso_packed *p);

/* The lattice l as the paper keeps it: packed (td_iso_pack, tiles of 2^tile_log2) and read
 * through its two-byte vertices, no floats: td_iso_at decodes, so the walk, td_iso_eval
 * and the block maxima all see the decoded heights (l->packed->max_err from l's). l is
 * left alone. */
td_status td_iso_pack_lattice(const td_iso *l, int tile_log2, td_iso **out, td_err *err);

/* Bytes a lattice holds: its samples (floats or packed vertices, tile offsets and steps)
 * and its block maxima. */
uint64_t td_iso_bytes(const td_iso *l);

#endif
