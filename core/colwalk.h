/* colwalk.h: the camera rays of one vertical plane through the eye, traced together
 * (issue 12: vertical ray coherence, after Qu et al. and Lee and Shin, exact per ray).
 *
 * With the camera upright and level (pitch 0, roll 0: its up vector is the world's z), or
 * cylindrical (a panorama, at any pitch), the rays of one image column share their
 * horizontal direction h, so they lie in one vertical plane through the eye E, and each is
 * E + s (h, e) in the horizontal distance s, with its own slope e. In that plane a ray above a lower one cannot meet the terrain before the
 * distance at which the lower one met it (it is above the lower one at every s > 0, and the
 * lower one was above the surface up to its hit). So the rays of a column are taken from the
 * lowest up along one walk of the plane's cells: in each cell the surface along the line
 * (its height where the line enters and leaves the cell, and, on the triangle surface,
 * where it crosses the cell's diagonal) is computed once, and each ray is tested against it
 * from the cell where the ray below it hit. A ray's test in a cell is its own exact
 * intersection with the surface there (trace.c's rules: the first point at or under the
 * surface; the plane's wall where the ray enters under the top; the bilinear patch's
 * quadratic along the line), and cells with a void corner are holes the rays pass through.
 * Boxes of cells (the max-mipmap's 8 x 8 blocks, or a tile without one) that the lowest
 * unfinished ray passes over by the walk's margin are crossed in one step, and once that
 * ray rises above the grid's highest sample, it and every ray above it miss. A column's
 * walk may start where a horizon (horizon.h) says its lowest ray meets nothing before:
 * the render cuts its image into blocks, and the rays of an upper block start far out.
 *
 * The answers are the exact walk's to the rounding of the line's parameter (the hits'
 * distances agree to about 1e-12 of the distance); where a ray only touches the surface,
 * within that rounding, hit or miss may differ from td_trace's, and the oracle tests judge
 * those by the double reference as they judge Embree's. td_colwalk_ok says when the device
 * applies: the eye over the grid, above every corner of the cells around it, so that every
 * ray starts above every surface. A ray can only get under the surface through a hole (a
 * void cell it passes through, and a cell beyond it entered below its surface); the rays
 * above such a ray may then meet the terrain before it does, so they are left to the
 * caller (NaN). */
#ifndef TD_COLWALK_H
#define TD_COLWALK_H

#include <stdint.h>

#include "trace.h"

/* One eye's column walks: what every column of a view shares. */
typedef struct td_colwalk {
    const td_view *v;
    td_surface sf;
    double o[3];       /* the eye, dataset frame */
    double U, V;       /* the eye in cells */
    double zmax;       /* the grid's highest sample */
    double zeps;       /* the walk's margin (trace.c's) */
} td_colwalk;

/* What td_colwalk_trace found for one ray. */
typedef struct td_colhit {
    double s;       /* horizontal distance from the eye to the hit; +inf: a miss; NaN: not
                       known (a ray below it passed under the surface through a hole: the
                       caller traces it alone) */
    double zb;      /* the bilinear surface's height at the hit's x, y (the height error's
                       reference, as td_trace_fan's zb) */
    float n[3];     /* the unit normal there, facing up, as td_trace records it (the plane's
                       top or the wall the ray came through; the other surfaces' gradient) */
    int32_t ci, cj; /* the cell hit */
} td_colhit;

/* Sets up *cw for rays from o over view v and surface sf; returns 0 when the device does
 * not apply (o not strictly inside the grid, or not above every corner of the cells around
 * it by the walk's margin, or a void among them): those rays take the plain walk. */
int td_colwalk_init(td_colwalk *cw, const td_view *v, td_surface sf, const double o[3]);

/* Traces the n rays from the eye whose horizontal direction is (hx, hy) (unit length),
 * given by their slopes e[k] = d_z / |d_xy| in non-decreasing order, into hit[k], from
 * the horizontal distance s0 on: the lowest ray (e[0]) meets nothing before s0 (0, or a
 * horizon's bound, horizon.h; +inf: every ray misses). Returns the steps taken (cells and
 * boxes), shared by the n rays. */
uint32_t td_colwalk_trace(const td_colwalk *cw, double hx, double hy, double s0, int n,
                          const double *e, td_colhit *hit);

#endif
