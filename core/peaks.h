/* peaks.h: the summits of a DEM by topographic prominence (issue 19). server/pano.c
 * computes them once per dataset version (lazily, on the first POST /v1/peaks) and keeps
 * them; POST /v1/peaks lists those of at least P metres visible in a view (each checked
 * with a camera ray, td_peaks_visible).
 *
 * A summit is a sample higher than every sample it connects to without descending below
 * its key col; its prominence is its height above that col: the highest saddle on the
 * lowest route to higher ground. The highest sample of each connected (void-free)
 * region has no higher ground: its prominence is its height above the region's lowest
 * sample. Ties are broken by sample index, so a plateau has one summit (its first sample
 * in file order). The grid's edge is a barrier: a summit whose key col lies beyond the
 * DEM gets the prominence the DEM shows, a lower bound.
 *
 * Algorithm (the standard one, e.g. Kirmse and de Ferranti 2017's "prominence by flooding"
 * for a single DEM): samples sorted by height, highest first, join the union-find regions
 * of their processed 8-neighbours; when a sample joins two regions whose highest samples
 * differ, the lower of the two peaks has met higher ground and its key col is this
 * sample: prominence = peak - sample. Cost: O(N log N) for the sort (qsort of sample
 * indices by height) and O(N a(N)) for the union-find with path halving and union by
 * size; 12 bytes a sample while it runs (order, parent, region peak), 16 bytes a summit
 * kept. Measured on trinidad (2401 x 1201): see the README's API section. */
#ifndef TD_PEAKS_H
#define TD_PEAKS_H

#include <stddef.h>
#include <stdint.h>

#include "camera.h"
#include "grid.h"
#include "render.h"

typedef struct td_summit {
    int32_t i, j;      /* sample: column, south-based row */
    float z;           /* its height */
    float prominence;  /* metres above its key col */
    int32_t col_i, col_j; /* the key col's sample (-1, -1 for a region's highest) */
} td_summit;

typedef struct td_summits {
    size_t n;
    td_summit *s;      /* prominence > 0, highest prominence first */
    double build_ms;
} td_summits;

/* Every summit of g with prominence > 0. out is the caller's (td_summits_free). */
td_status td_summits_find(const td_grid *g, td_summits **out, td_err *err);
void td_summits_free(td_summits *s);

/* A summit seen in a view. */
typedef struct td_peak_seen {
    const td_summit *summit;
    double px, py;     /* pixel coordinates of the summit (camera.h) */
    double p[3];       /* the summit, dataset frame */
    double distance;   /* horizontal, metres from the eye */
} td_peak_seen;

/* The summits of at least min_prominence metres inside the view of scene s (any
 * projection; curvature as the scene says) and not hidden by terrain: a summit is seen
 * when the camera ray through its pixel (td_render_pick: the render's own ray, bent
 * where the render bends it) meets nothing before it, allowing the cells around the
 * summit (a ray aimed at a crest may touch the slope in front of it). At most max are
 * returned, highest prominence first; *n is how many. *rays counts the picks. */
td_status td_peaks_visible(const td_view *v, const td_scene *s, const td_summits *sum,
                           double min_prominence, td_peak_seen *out, size_t max, size_t *n,
                           uint64_t *rays, td_err *err);

#endif
