/* skyline.h: the skyline seen from an observer, azimuth by azimuth (issue 19): for each
 * azimuth the elevation angle of the highest terrain the eye sees, the distance to the
 * point that forms it and that point. POST /v1/horizon (server/pano.c) answers with it,
 * and the sun's rise and set behind the terrain are read against it.
 *
 * Exact on the chosen surface by construction: the skyline at azimuth a is the supremum
 * of the elevations whose camera ray (straight, or bent by curvature and refraction as
 * the render bends it) meets the terrain within max_distance. That set is an interval
 * from -90 degrees up (a ray below one that hits is below the terrain where the upper
 * one meets it, so it met the terrain before), so a bisection on the elevation finds its
 * top to 1e-6 of a pixel of the virtual panorama below. The rays are td_render_pick's on
 * a cylindrical camera with one column an azimuth (camera.h), so a rendered panorama of
 * the same eye, surface and curvature shows the same skyline: the render traces the
 * same rays by the same code. Cost: 32 rays an azimuth (1440 azimuths at 0.25 degrees:
 * 46,080 rays, each a walk over the grid); no per-dataset structure. Rejected: a sweep
 * of the grid's cells by azimuth (needs each surface's profile along a line, four more
 * exact solvers to keep in step with the tracer's). */
#ifndef TD_SKYLINE_H
#define TD_SKYLINE_H

#include <stdatomic.h>

#include "trace.h"

/* the finest azimuth step (degrees) and the coarsest */
#define TD_SKYLINE_STEP_MIN 0.05
#define TD_SKYLINE_STEP_MAX 10.0

typedef struct td_skyline_opts {
    double x, y;            /* observer, dataset frame */
    double height;          /* eye above the ground, metres */
    double step_deg;        /* azimuth step (default 0.25) */
    double max_distance;    /* horizontal, metres (default +inf: the whole grid) */
    int curvature;          /* earth curvature and refraction (default on) */
    double k;               /* refraction coefficient (default 0.13) */
    td_surface surface;     /* default bilinear */
    td_method method;       /* default auto */
    const atomic_int *cancel; /* polled between rounds; non-zero -> TD_ECANCELED */
} td_skyline_opts;

typedef struct td_skyline_pt {
    double azimuth;         /* degrees clockwise from north, k * step */
    double elevation;       /* degrees above the eye's horizontal; NaN: no terrain */
    double distance;        /* horizontal, metres, to the point that forms it */
    double p[3];            /* that point, dataset frame */
} td_skyline_pt;

typedef struct td_skyline {
    int n;                  /* azimuths: floor(360 / step) */
    double step_deg;
    double eye[3];          /* dataset frame */
    td_skyline_pt *pt;      /* n, azimuth k * step_deg */
    uint64_t rays;
} td_skyline;

void td_skyline_opts_default(td_skyline_opts *o);

/* Computes the skyline. Errors name the field: observer (outside the grid, over a void),
 * step_deg, max_distance, curvature.k. out is the caller's (td_skyline_free). */
td_status td_skyline_compute(const td_view *v, const td_skyline_opts *o, td_skyline *out, td_err *err);

/* The skyline's elevation at any azimuth (degrees), linear between the two azimuths
 * around it (wrapping at 360); NaN where either has no terrain. */
double td_skyline_elevation_at(const td_skyline *s, double azimuth);

void td_skyline_free(td_skyline *s);

#endif
