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

#include "solar.h"
#include "trace.h"

/* the finest azimuth step (degrees) and the coarsest */
#define TD_SKYLINE_STEP_MIN 0.05
#define TD_SKYLINE_STEP_MAX 10.0

typedef struct td_skyline_opts {
    double x, y;            /* observer, dataset frame */
    double height;          /* eye above the chosen surface (plane: the cell's box; triangle:
                               its triangle; else bilinear), metres; at least 1 cm is used */
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

/* The sun against the skyline over one day (solar.h's NOAA position). The day is the
 * solar day around the solar noon of the UTC date that contains day_s: noon - 12 h to
 * noon + 12 h, so a place far from Greenwich gets its own morning and evening. The sun
 * counts as seen when its upper limb (centre + 0.2667 degrees, as seen: geometric +
 * refraction) is above the skyline at its azimuth, where the skyline has no terrain
 * above the astronomical horizon (the almanac's rule: the upper limb at 0 degrees).
 * Rises and sets are found every TD_SUN_SCAN_S and refined by bisection to 1 s. */
#define TD_SUN_PATH_MAX 289     /* path samples: every 5 minutes over the day, both ends */
#define TD_SUN_INTERVALS_MAX 16 /* stretches of the day the sun is seen */
#define TD_SUN_SCAN_S 60.0
#define TD_SUN_RADIUS_DEG 0.2667

typedef struct td_sun_sample {
    double t;               /* unix seconds */
    double azimuth;         /* degrees */
    double elevation;       /* the centre as seen (geometric + refraction), degrees */
    double skyline;         /* the skyline's elevation at that azimuth (NaN: none) */
    int seen;
} td_sun_sample;

typedef struct td_skyline_sun {
    double noon_s;          /* solar noon */
    double astro_rise_s, astro_set_s; /* almanac sunrise, sunset (solar.h); polar: NaN */
    int polar;              /* +1 up all day, -1 down all day (astronomically), else 0 */
    double rise_s, set_s;   /* the first time the sun clears the skyline and the last it
                               goes behind it; NaN when it does not (seen all day: rise
                               and set are NaN, seen_s the whole day) */
    double seen_s;          /* seconds of the day the sun is seen */
    int nint;               /* stretches seen: [start, end] each (day ends included) */
    double interval[TD_SUN_INTERVALS_MAX][2];
    int npath;
    td_sun_sample path[TD_SUN_PATH_MAX];
} td_skyline_sun;

/* Errors name "sun.date" (not a date), "observer" (lat/lon out of range). */
td_status td_skyline_sun_day(const td_skyline *s, double lat, double lon, double day_s, td_skyline_sun *out,
                         td_err *err);

#endif
