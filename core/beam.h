/* beam.h: the height above which no ray of a descending beam can meet the terrain.
 *
 * A conservative beam per pixel block (after Reshetov et al.'s entry-point search), for
 * the camera rays the horizon (horizon.h) cannot bound: blocks whose rays fan out over
 * more than a quarter turn of azimuth, around the vanishing point of the verticals, as
 * when looking steeply down. Take rays from one eye E whose directions lie in the convex
 * cone of nd corner directions d_k, all descending (d_k,z < 0). On any such ray the point
 * at height Z is a convex combination of the corner rays' points at height Z,
 *
 *     P_k(Z) = E + (E_z - Z) / (-d_k,z) * d_k,
 *
 * (the weights are lambda_k d_k,z / d_z for d = sum lambda_k d_k) and P_k is linear in Z,
 * so every point of every ray of the beam with a height in [Z_lo, Z_hi] lies over the box
 * of the 2 nd points P_k(Z_lo), P_k(Z_hi). Start from Z_hi = min(E_z, the grid's highest
 * sample) and Z_lo = its lowest; while the highest corner M of any cell under the box
 * (td_view_max, plus the walk's zeps) is below Z_hi, no ray point between M and Z_hi can
 * be on or under the terrain (no surface rises above its cell's highest corner), so
 * Z_hi = M and again, up to TD_BEAM_ROUNDS times, never below Z_lo. After the first round
 * the box is taken over a band [Z_hi - b, Z_hi] only (its points P_k over the band's two
 * heights): the rays' points in the band lie over that smaller box, so its highest corner
 * M bounds them the same way; a band whose box holds nothing as high as its bottom is
 * crossed freely (Z_hi drops to its bottom, the next band twice as deep). b starts at
 * TD_BEAM_BAND_CELLS cells of horizontal run of the beam's shallowest corner, so a band's
 * box reaches about that far past the beam's footprint where the whole range's box
 * reached (Z_hi - Z_lo) times the run: on trinidad's straight-down bench view, steps per
 * camera ray 3.10 -> 2.63 and primary-stage instructions 334.3 -> 323.1 M (callgrind,
 * triangle); picos's 348.6 -> 343.4 M. Z_hi never goes below Z_lo: the solid surfaces'
 * walls (the height plane's columns) reach below the lowest sample, so a ray that passes
 * under every cell may still meet one from the side. A ray of the beam then meets nothing
 * before it descends to Z_hi: render.c starts it at t = (E_z - Z_hi) / (-d_z) (less a
 * relative 1e-12) with td_trace_from, which returns td_trace's hit bit for bit. An eye
 * below Z_lo gets its own height (the rays start at the eye).
 *
 * Margins: the box is padded by a relative 1e-9 and 1e-6 m (the rays' directions are
 * computed to about 1e-16), the bound by zeps. A beam with a corner not descending, or
 * a view without a finite height, gets no bound (+inf: the rays start at the eye). */
#ifndef TD_BEAM_H
#define TD_BEAM_H

#include <stdint.h>

#include "trace.h"

#define TD_BEAM_ROUNDS 6 /* box-and-bound rounds a beam takes at most */
#define TD_BEAM_BAND_CELLS 2.0 /* how far a band's box reaches past the footprint */

/* The height Z_hi for the beam from eye o over corner directions d[0 .. nd) (see above);
 * adds to *steps one for each bound taken. */
double td_beam_floor(const td_view *v, const double o[3], const double (*d)[3], int nd, uint32_t *steps);

#endif
