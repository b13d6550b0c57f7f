/* trace.h: rays against the height field, with three methods over four surfaces.
 *
 * Methods and surfaces come from one X-macro table each (enum, name). A trace sees the
 * grid and, per tile, whatever acceleration is resident (a view): `incremental` needs
 * nothing, `hierarchical` uses a tile's max-mipmap where present, `parametric` its
 * parameter planes; both fall back to the incremental walk in tiles that lack them.
 * `silhouette` needs nothing either: it is a camera-ray method (silhouette.h: the render
 * builds a partition of its view and starts each camera ray with td_trace_from); every
 * walk it makes, and any ray traced with it here, is the incremental walk (a hit reports
 * `incremental`). `auto` picks per tile from what is resident.
 *
 * Rays are given in the dataset frame in double precision; the walk re-bases them per
 * tile. Surfaces are two-sided: the hit is the first t in [tmin, tmax] where the ray
 * meets the surface (touching counts; a ray that starts on or below the surface hits at
 * once: `tmin` for the triangle, linear and bilinear surfaces when it starts exactly on
 * them, the first crossing when it starts below; the plane surface is a solid column,
 * so an origin inside it hits at tmin). Cells with a void corner are holes.
 *
 * Where a ray runs exactly along a grid line (x = i*sx or y = j*sy), the triangle,
 * linear and bilinear surfaces of the two cells agree on the shared edge, so either cell
 * gives the same hit. The plane surface's columns do not agree there: they are
 * half-open, [i*sx, (i+1)*sx) x [j*sy, (j+1)*sy) (closed on the grid's east and north
 * edges), so such a ray sees the column east (north) of the line, and a vertical ray
 * through a sample sees the column north-east of it. A ray through a sample point
 * crosses diagonally between the two cells that meet there and touches the other two
 * only at that point; a touch there (measure zero) may be reported or not. */
#ifndef TD_TRACE_H
#define TD_TRACE_H

#include "grid.h"

#define TD_METHOD_LIST(X)                                                      \
    X(TD_METHOD_INCREMENTAL, "incremental")                                    \
    X(TD_METHOD_HIERARCHICAL, "hierarchical")                                  \
    X(TD_METHOD_PARAMETRIC, "parametric")                                      \
    X(TD_METHOD_SILHOUETTE, "silhouette")                                      \
    X(TD_METHOD_AUTO, "auto")

#define TD_SURFACE_LIST(X)                                                     \
    X(TD_SURFACE_PLANE, "plane")                                               \
    X(TD_SURFACE_LINEAR, "linear")                                             \
    X(TD_SURFACE_TRIANGLE, "triangle")                                         \
    X(TD_SURFACE_BILINEAR, "bilinear")

typedef enum td_method {
#define TD_X_ENUM(e, name) e,
    TD_METHOD_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_METHOD_COUNT
} td_method;

typedef enum td_surface {
#define TD_X_ENUM(e, name) e,
    TD_SURFACE_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_SURFACE_COUNT
} td_surface;

const char *td_method_name(td_method m);
const char *td_surface_name(td_surface s);
/* Parse a name; return TD_EINVAL (and leave *out) for an unknown one. */
td_status td_method_parse(const char *name, td_method *out);
td_status td_surface_parse(const char *name, td_surface *out);

typedef struct td_maxmip td_maxmip; /* one tile's max pyramid (maxmip.h) */
typedef struct td_sunlit td_sunlit; /* heights surely in the sun (sunlit.h) */
typedef struct td_planes td_planes; /* one tile's parameter planes (planes.h) */

/* What is resident for one tile; either pointer may be NULL. */
typedef struct td_tile_accel {
    const td_maxmip *maxmip;
    const td_planes *planes;
} td_tile_accel;

/* What one trace sees: the grid and, optionally, one td_tile_accel per tile
 * (grid->tiles_x * grid->tiles_y entries, same order as grid->tiles). */
typedef struct td_view {
    const td_grid *grid;
    const td_tile_accel *accel; /* may be NULL: no acceleration resident */
} td_view;

typedef struct td_ray {
    double o[3];      /* origin, dataset frame, metres */
    double d[3];      /* direction, need not be unit length, not zero */
    double tmin, tmax; /* search interval in units of d; tmax may be +inf */
} td_ray;

typedef struct td_hit {
    double t;          /* +inf for a miss */
    double p[3];       /* hit point o + t*d (dataset frame), valid on a hit */
    float n[3];        /* unit normal of the surface that was hit, facing up (n[2] >= 0) */
    int32_t ci, cj;    /* the cell hit (column, south-based row) */
    uint32_t steps;    /* steps the tracer took for this ray */
    td_method method;  /* method used in the tile where the ray ended */
} td_hit;

/* Refuses NaN or inf in origin or direction, a zero direction or one whose components
 * are all below 2^-900 (hit distances in its units would overflow), or a NaN/negative
 * interval, with a message naming the component. */
td_status td_ray_validate(const td_ray *r, td_err *err);

/* Traces one validated ray. Never allocates; thread-safe for a shared view. */
void td_trace(const td_view *v, td_method m, td_surface s, const td_ray *r, td_hit *hit);

/* td_trace for a ray the caller knows meets nothing before t_clear (units of d; e.g. from
 * a horizon.h bound): the walk starts at the boundary of the cell the ray is in at
 * t_clear, so the hit is td_trace's, bit for bit, in fewer steps. A t_clear past the
 * search's end is a miss; t_clear <= tmin changes nothing. */
void td_trace_from(const td_view *v, td_method m, td_surface s, const td_ray *r, double t_clear,
                   td_hit *hit);

/* A fan: camera rays from one origin, as arrays (a packet of four or eight loads each as
 * one vector): ray k's direction (dx[k], dy[k], dz[k]) and where it may start, t_clear[k]
 * (td_trace_from's; +inf: a miss known without tracing). At most TD_FAN_MAX rays; the
 * TD_FAN_PAD slots past them are td_trace_fan's (a last short packet's padding). */
#define TD_FAN_MAX 64
#define TD_FAN_PAD 7
typedef struct td_fan {
    double dx[TD_FAN_MAX + TD_FAN_PAD], dy[TD_FAN_MAX + TD_FAN_PAD], dz[TD_FAN_MAX + TD_FAN_PAD];
    double t_clear[TD_FAN_MAX + TD_FAN_PAD];
} td_fan;

/* A fan's hits, as arrays (stored a vector at a time from the packets): ray k's td_hit
 * fields (t, p = (px, py, pz), n = (nx, ny, nz), ci, cj, steps, method), and zb[k], the
 * bilinear surface's height at its x, y in its cell (td_grid_bilinear_cell's value bit
 * for bit: what the render's height error compares with; NaN for a miss or a void cell).
 * td_fan_hit reads one back as a td_hit. */
typedef struct td_fan_hits {
    double t[TD_FAN_MAX + TD_FAN_PAD], px[TD_FAN_MAX + TD_FAN_PAD], py[TD_FAN_MAX + TD_FAN_PAD];
    double pz[TD_FAN_MAX + TD_FAN_PAD], zb[TD_FAN_MAX + TD_FAN_PAD];
    float nx[TD_FAN_MAX + TD_FAN_PAD], ny[TD_FAN_MAX + TD_FAN_PAD], nz[TD_FAN_MAX + TD_FAN_PAD];
    int32_t ci[TD_FAN_MAX + TD_FAN_PAD], cj[TD_FAN_MAX + TD_FAN_PAD];
    uint32_t steps[TD_FAN_MAX + TD_FAN_PAD];
    int32_t method[TD_FAN_MAX + TD_FAN_PAD]; /* a td_method */
} td_fan_hits;

/* The lanes of the ray packets that walk fans and shadow rays together (td_trace_fan,
 * td_occluded_par): 8 where the build has the AVX-512 instance and the processor runs it,
 * else 4. td_trace_set_lanes(4 or 8) makes this process use that width where it can (the
 * tests hold both to the scalar walk; the benchmark compares them), 0 goes back to the
 * processor's choice; it returns the width now used. Both widths give the same answers,
 * bit for bit. */
int td_trace_lanes(void);
int td_trace_set_lanes(int lanes);

/* td_trace_from for the first n (<= TD_FAN_MAX) rays of fan f from origin o, each over
 * [0, +inf): the camera rays of a render, which share the walk's setup of the grid and
 * the origin. Ray k's hit (td_fan_hit(h, k, ..)) is the one td_trace_from gives it, bit for
 * bit. Writes f's padding slots. */
void td_trace_fan(const td_view *v, td_method m, td_surface s, const double o[3], int n, td_fan *f,
                  td_fan_hits *h);

/* Ray k's hit of a traced fan as td_trace_from writes one (every other byte zero). */
void td_fan_hit(const td_fan_hits *h, int k, td_hit *out);

/* Whether the ray meets the surface in [tmin, tmax] (td_trace's hit is finite), for rays
 * that leave the surface (shadow and ambient-occlusion rays): it climbs the max-mipmap
 * from small blocks up, and computes no hit point or normal. A shadow ray (direction the
 * sun's of lit, which may be NULL, or the sun's azimuth and at least its slope: a chord of
 * a bent shadow ray) also ends, unoccluded, where it rises above lit's bound (sunlit.h).
 * Adds its steps to *steps. */
int td_occluded(const td_view *v, td_method m, td_surface s, const td_ray *r,
                const td_sunlit *lit, uint32_t *steps);

/* Whether the point p (dataset frame, over the grid) stands above lit's bound (sunlit.h)
 * by the walk's margin, the test td_occluded makes at each cell: then a ray from p toward
 * the sun, or along the sun's azimuth and at least as steep, meets no terrain. 0 without
 * a bound or off the grid. */
int td_sunlit_clear(const td_grid *g, const td_sunlit *lit, const double p[3]);

/* td_occluded for n parallel rays over [0, +inf): from o[k] along d (the shadow rays of a
 * render, which share the walk's setup of the grid and the direction; with a sun bound,
 * four at a time through their first cells). hit[k] is what td_occluded says of ray k.
 * Adds their steps to *steps (with the bound, the cells the packets walked and then the
 * one-ray walks' steps: not td_occluded's count). */
void td_occluded_par(const td_view *v, td_method m, td_surface s, const double d[3], int n,
                     const double (*o)[3], const td_sunlit *lit, uint8_t *hit, uint32_t *steps);

/* An upper bound of every surface over the cells [i0, i1] x [j0, j1] (clamped to the
 * grid; -inf if no cell is left or all are holes): the highest corner, read from at
 * most 16 samples or max-mipmap blocks per tile it touches (a tile's zmax where neither
 * is small enough). */
double td_view_max(const td_view *v, int32_t i0, int32_t i1, int32_t j0, int32_t j1);

/* The cell column (or row) of coordinate x, given inv = 1 / spacing, saturated to
 * [-1, 2^31 - 2] (NaN gives -1): td_view_max's arguments from a box that may reach far off
 * the grid (horizon bins, beams). */
static inline int32_t td_view_cell(double x, double inv)
{
    double c = x * inv;
    return !(c >= 0.0) ? -1 : (c > 2147483646.0 ? 2147483646 : (int32_t)c);
}

/* Surface height at (x, y) in the dataset frame inside cell (ci, cj), NaN on a hole
 * (the `linear` surface has no height of its own: it is evaluated as bilinear here). */
double td_surface_height(const td_grid *g, td_surface s, int32_t ci, int32_t cj, double x, double y);

#endif
