/* reference.h: independent double-precision references for the four surfaces, and the
 * judge that settles a tracer's answer against them.
 *
 * The reference shares nothing with core/trace.c but the grid and the ray record: it
 * enumerates every cell whose closed footprint the ray's ground track touches (with a
 * small margin), in ray order, and solves each cell's surface exactly in double:
 * piecewise linear along the ray for `triangle` (split at the diagonal) and `linear`,
 * the quadratic of the patch for `bilinear`, a closed box for `plane`. Besides the first
 * exact hit it reports a tolerance band of half-width eps (metres, vertical):
 *   t_near   first t where the ray comes within eps of the surface;
 *   t_strict first t where the ray has definitely crossed it (from more than eps on one
 *            side to more than eps on the other; for `plane`, entered the box shrunk by
 *            eps).
 * Any answer in [t_near, t_strict] whose point lies within eps of the surface is
 * consistent with the surface up to eps ("a tie"); a miss is consistent iff t_strict is
 * +inf. That is what settles touches at ridge heights, rays through vertices and grazing
 * rays where float32 rounding decides hit or miss. */
#ifndef TD_REFERENCE_H
#define TD_REFERENCE_H

#include <stdint.h>

#include "trace.h"

typedef struct td_ref_hit {
    double t;          /* first exact hit, +inf for a miss */
    int32_t ci, cj;    /* its cell (-1 on a miss) */
    double t_near;     /* see above; +inf if never within eps */
    double t_strict;   /* see above; +inf if never definitely crossed */
    uint64_t cells;    /* cells examined */
} td_ref_hit;

/* Traces r (validated, tmin finite) over g for surface s with band half-width eps >= 0. */
void td_ref_trace(const td_grid *g, td_surface s, const td_ray *r, double eps, td_ref_hit *out);

/* Non-zero if the point o + t*d of ray r lies within eps (vertically, or for `plane`
 * within eps of a box's boundary) of surface s. */
int td_ref_point_near(const td_grid *g, td_surface s, const td_ray *r, double t, double eps);

/* The height of r's point at t over surface s (metres; negative: under it), in the cell
 * holding the point's ground position: for `linear` the chord of the ray's line through
 * that cell. NaN for `plane` and over a hole (nothing to be under). The viewshed rule's
 * "starts under the surface" (docs/viewshed.md), judged without core/viewshed.c. */
double td_ref_gap(const td_grid *g, td_surface s, const td_ray *r, double t);

/* Tolerance in metres on a hit point: 1 mm plus float32 rounding of its coordinates. */
double td_ref_tol(const double p[3]);

/* Largest height difference per metre between neighbouring samples (for turning a point
 * tolerance into a vertical one). */
double td_ref_max_slope(const td_grid *g);

typedef enum td_ref_verdict {
    TD_REF_AGREE = 0, /* within tolerance of the exact hit (or both miss) */
    TD_REF_TIE,       /* not the exact hit, but inside the eps band (see above) */
    TD_REF_WRONG      /* neither */
} td_ref_verdict;

/* Judges answer t (+inf = miss) for ray r against ref (computed with band eps). */
td_ref_verdict td_ref_judge(const td_grid *g, td_surface s, const td_ray *r,
                            const td_ref_hit *ref, double t, double eps);

/* Distance in metres between the points of r at t1 and t2 (both finite). */
double td_ref_dist(const td_ray *r, double t1, double t2);

#endif
