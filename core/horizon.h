/* horizon.h: where the rays of a wedge from one eye may start: a conservative horizon.
 *
 * Vertical ray coherence (Qu et al.; Lee and Shin; Cohen-Or et al.), made exact for rays
 * that do not share a vertical plane. Take camera rays from the eye E whose azimuths lie
 * in a wedge [az0, az1]. Cut the wedge into bins by horizontal distance from E; for bin k,
 * covering distances [d_k, d_k+1), bound the elevation (as a tangent) of every terrain
 * point in it from above:
 *
 *     e_k = (M_k - E_z) / d_k      (M_k >= E_z)      e_k = (M_k - E_z) / d_k+1   (else)
 *
 * where M_k is the highest corner of any cell that meets the bin's bounding box
 * (td_view_max: at most 16 samples or max-mipmap blocks a tile). A ray of elevation
 * tangent e is at height E_z + d e at horizontal distance d, so it cannot meet the
 * terrain in a bin with
 * e_k < e: it meets nothing before the first bin whose running maximum P_k = max e_j
 * (j <= k) reaches e, and nothing at all if no bin does. That holds for every surface
 * (each is bounded by its cell's highest corner) and every ray of the wedge, in any
 * vertical plane inside it; no ray is resampled or moved. td_trace_from then starts the
 * ray at that bin's near edge and returns td_trace's hit, bit for bit.
 *
 * The bins are built lazily, near to far, as rays ask for them: a ray above everything
 * built so far extends the list until a bin reaches it (or the grid ends, or no terrain
 * left could: a miss). Where a whole stretch stays below the asking ray, one bin of up to
 * 2^L cells covers it (bounded at max-mipmap level L); elsewhere a bin is about as deep as
 * the wedge is wide, and at least a cell. Rays asked for in increasing elevation (bottom
 * to top of an upright image) therefore reuse the bins below them: the cost is about
 * one walk along the wedge, shared by all its rays.
 *
 * The margins: every bound gets the walk's zeps on the height and a relative 1e-12 on the
 * tangent, and the wedge is widened by 1e-9 rad, far above the rounding of the rays'
 * directions and of the bins' corners. Rays of a wedge wider than pi/2, or too steep for
 * a tangent (|d_xy| tiny), get no bound (0). */
#ifndef TD_HORIZON_H
#define TD_HORIZON_H

#include <math.h>

#include "trace.h"

#define TD_HORIZON_BINS 1024 /* bins a wedge keeps; past them rays start at the last one */

typedef struct td_horizon {
    const td_view *v;
    double ex, ey, ez;            /* the eye */
    double az0, az1;              /* the wedge, radians, az0 <= az1 < az0 + pi/2 */
    double c0[2], c1[2];          /* unit directions of its two sides */
    int axis[4];                  /* axis directions (+x, +y, -x, -y) inside the wedge */
    double cell;                  /* min(sx, sy) */
    double isx, isy;              /* 1/sx, 1/sy */
    double width;                 /* the wedge's angular width (bins at least this deep, relative) */
    double zeps;                  /* height margin */
    double dmax;                  /* farthest grid point from the eye */
    double ztop;                  /* highest sample of the grid */
    int lev;                      /* next coarse bin tried: 2^lev cells deep */
    int n;                        /* bins built */
    int last;                     /* the bin the last ray started in */
    int done;                     /* the bins reach the grid's far side */
    double d[TD_HORIZON_BINS + 1]; /* bin k covers [d[k], d[k+1]) */
    double p[TD_HORIZON_BINS];    /* running maximum of the bins' elevation bounds */
} td_horizon;

/* Sets up a wedge of rays from eye o with azimuths (atan2(dy, dx)) in [az0, az1]. Returns
 * 0 (and the wedge gives no bound) if the wedge is wider than pi/2. */
int td_horizon_begin(td_horizon *h, const td_view *v, const double o[3], double az0, double az1);

/* td_horizon_clear's part that builds bins: for a ray of elevation bound e_lo above every
 * bin built so far (h->n 0, or p[n - 1] < e_lo). */
double td_horizon_extend(td_horizon *h, double e_lo, uint32_t *steps);

/* The horizontal distance from the eye before which a ray of the wedge with elevation
 * tangent e (d_z / |d_xy|) meets nothing: 0 if nothing is known, +inf if it meets nothing
 * at all. Builds bins as needed, adding one to *steps for each. Inline: most rays of a
 * wedge find their bin among those built (the primary stage calls it for every ray). */
static inline double td_horizon_clear(td_horizon *h, double e, uint32_t *steps)
{
    double at = 0.0;
    const double e_lo = e - 1e-12 * (1.0 + fabs(e));
    if (!h->v || !(e_lo > -INFINITY)) {
        at = 0.0;
    } else if (h->n > 0 && h->p[h->n - 1] >= e_lo) {
        /* the first bin whose running maximum reaches e: near the last one asked for,
           since rays come in rising elevation */
        int k = h->last < h->n ? h->last : h->n - 1;
        while (k > 0 && h->p[k - 1] >= e_lo)
            k--;
        while (h->p[k] < e_lo)
            k++;
        h->last = k;
        at = h->d[k];
    } else {
        at = td_horizon_extend(h, e_lo, steps);
    }
    return at;
}

#endif
