/* silhouette.h: Sakalauskas' silhouette partitioning, made exact: where each camera ray of
 * one view may first meet the terrain, from the heights alone (no max-mipmap, no planes).
 *
 * Sakalauskas (WSCG 2007) slices the height field into rows ordered away from the eye and,
 * per screen column x, keeps the silhouette S_{v<=a}(x) of the rows up to a: the highest
 * image row the terrain in them reaches. It never falls as a grows (his eq. 2), and a pixel
 * above it sees nothing in those rows (eq. 1), so a binary search over a finds the row a
 * pixel sees with a fixed number of reads; he builds it every frame, for terrain that
 * changes every frame (erosion). Here the same structure only bounds: it says before
 * which distance a ray meets nothing, and td_trace_from walks the exact surface from
 * there, so the hit is the incremental walk's, bit for bit.
 *
 *   fan      the camera rays whose horizontal direction is dominated by one axis
 *            direction (+x, +y, -x, -y: |d_x| >= |d_y| picks x); four at most, one for
 *            each quadrant the image's azimuths reach (all four when the vanishing point
 *            of verticals is inside the image, e.g. looking straight down)
 *   strip    the cells between two consecutive sample lines across that axis (a column
 *            of cells for x), taken from the eye's strip outward to the grid's edge
 *   wedge    the paper's screen column: the fan's rays with slope m = d_cross / d_along in
 *            [m0 + k dm, m0 + (k+1) dm], about 4 pixels' angle wide (wedges are uniform in
 *            m; at most one wedge per 4 image columns over all fans; silhouette.c)
 *
 * For wedge k and strip s, every ray of the wedge crosses the strip between along-
 * distances q_n and q_f from the eye, at cross positions inside [e_c + min(q m),
 * e_c + max(q m)]: a range of cells of the strip. Every surface of a cell lies under its
 * highest corner, so with M the highest corner of those cells (voids dropped) a ray of
 * elevation tangent e (d_z / |d_xy|) can meet the strip only if
 *
 *     e <= B = (M - E_z) / d_n     (M >= E_z)      e <= B = (M - E_z) / d_f   (else)
 *
 * with d_n = q_n sqrt(1 + min m^2) and d_f = q_f sqrt(1 + max m^2) the nearest and
 * farthest horizontal distance of the crossing over the wedge. The running maximum
 * P_s = max(B_0 .. B_s) is the exact form of S_{v<=a}(x): non-decreasing in s, so a binary
 * search finds the first strip with P_s >= e; the ray meets nothing before that strip's
 * near line (t_clear), and nothing at all if no strip reaches e. Margins: M gets the
 * walk's height margin (trace.c's zeps), B a relative 1e-12, and P is stored as a float
 * rounded up; t_clear is shortened by a relative 1e-12. A ray whose slope falls outside
 * its fan's wedges, or with no horizontal part, gets no bound (0: the walk from its start).
 *
 * Cost: the build reads, per strip, the two sample lines over the fan's cross range once
 * and takes each wedge's maximum over its cells (entries = wedges x strips, counted as
 * steps); a ray costs a binary search (log2 strips probes, each a step) and then the walk
 * from t_clear. Nothing is kept between renders. Callers: render.c, per perspective
 * render with method `silhouette` (or `auto` over tiles mostly without max-mipmaps). */
#ifndef TD_SILHOUETTE_H
#define TD_SILHOUETTE_H

#include "camera.h"
#include "trace.h"

#define TD_SILH_FANS 4

/* One quadrant of horizontal directions: strips along `axis` taken in direction `sign`. */
typedef struct td_silh_fan {
    int axis;       /* 0: the rays' x dominates (strips are columns of cells); 1: y (rows) */
    int sign;       /* +1 or -1: the direction the strips are taken in from the eye */
    int32_t first;  /* cell index along the axis of the strip nearest the eye */
    int32_t ns;     /* strips from there to the grid's edge (0: every ray of the fan misses) */
    int32_t nw;     /* wedges (0: no fan here, its rays get no bound) */
    double m0, dm, idm; /* wedge k covers slopes [m0 + k dm, m0 + (k+1) dm]; idm = 1/dm */
    double ea;      /* the eye's coordinate along the axis, metres */
    double sa;      /* sample spacing along the axis, metres */
    float *p;       /* nw * ns: wedge k's running maxima P_s at p[k * ns + s] */
} td_silh_fan;

typedef struct td_silhouette {
    double eye[3];
    td_silh_fan fan[TD_SILH_FANS]; /* +x, +y, -x, -y */
    uint64_t entries;              /* P_s built, over all fans (the build's steps) */
    size_t bytes;
} td_silhouette;

/* Builds the partition of a perspective camera's rays over grid g, with up to `threads`
 * threads (<= 1: the caller's only). *out is NULL (TD_OK) for a camera it does not handle
 * (orthographic) or a grid without valid samples. */
td_status td_silhouette_build(const td_grid *g, const td_camera *cam, int threads, td_silhouette **out,
                              td_err *err);

/* For a ray from the camera's eye with direction d (any length): the t (units of d)
 * before which it meets nothing; 0 if the partition says nothing for it, +inf if it meets
 * nothing at all. Adds its binary search's probes to *steps. Thread-safe. */
double td_silhouette_clear(const td_silhouette *s, const double d[3], uint32_t *steps);

void td_silhouette_free(td_silhouette *s);

#endif
