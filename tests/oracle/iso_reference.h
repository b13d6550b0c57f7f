/* iso_reference.h: an independent double-precision reference for rays against the
 * isometric lattice of core/isogrid.h, and the judge that settles td_iso_trace's answer
 * against it (the lattice's counterpart of reference.h).
 *
 * It shares with core/isogrid.c only the lattice record (sizes, spacings, samples): the
 * vertex positions are rebuilt from the paper's description (even rows at c a, odd rows
 * at 0, (c - 1/2) a, (nx - 1) a), each row strip is triangulated by merging its two rows'
 * vertices west to east (ties to the even row), and every triangle of every strip the
 * ray's ground track may touch is clipped against the ray's line by its three edges and
 * solved along the ray with barycentric heights. No DDA, no point location.
 *
 * The surface is two-sided (isogrid.h): the exact hit is the first t where the ray meets
 * a valid triangle. Band of half-width eps (metres, vertical), as reference.h: t_near is
 * the first t where the ray comes within eps of the surface, t_strict the first where it
 * has definitely crossed it (from more than eps on one side to more than eps on the other,
 * over valid triangles whose interior the ray's ground track enters, without a hole
 * between: a ray running along a hole's border only touches the surface, as in
 * reference.h). Any answer in [t_near, t_strict] whose point is within eps of the surface
 * (a point a rounding outside the lattice's border counts as on it) is a tie; a miss is
 * consistent iff t_strict is +inf. */
#ifndef TD_ISO_REFERENCE_H
#define TD_ISO_REFERENCE_H

#include "isogrid.h"

typedef struct td_iso_ref_hit {
    double t;        /* first exact hit, +inf if none */
    double t_near;   /* see above, +inf if never */
    double t_strict; /* see above, +inf if never */
    uint64_t triangles; /* triangles clipped */
} td_iso_ref_hit;

void td_iso_ref_trace(const td_iso *l, const td_ray *r, double eps, td_iso_ref_hit *out);

/* Height of the lattice's surface at (x, y) by the reference's own triangulation (NaN
 * outside the lattice or on a hole). */
double td_iso_ref_height(const td_iso *l, double x, double y);

typedef enum td_iso_ref_verdict { TD_ISO_REF_AGREE = 0, TD_ISO_REF_TIE, TD_ISO_REF_WRONG } td_iso_ref_verdict;

/* Judges answer t (+inf = miss): agree within 1 mm plus float32 rounding of the point,
 * tie inside the band, else wrong. */
td_iso_ref_verdict td_iso_ref_judge(const td_iso *l, const td_ray *r, const td_iso_ref_hit *ref,
                                    double t, double eps);

#endif
