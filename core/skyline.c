/* skyline.c: the skyline of an observer by bisection on camera rays (see skyline.h).
 * Called by server/pano.c (POST /v1/horizon, and POST /v1/peaks does not need it).
 *
 * The virtual panorama: a cylindrical camera (camera.h) at the eye with one column an
 * azimuth (W = n, fov = n * step, the centre of column k at azimuth k * step) and rows
 * from -85 to +85 degrees, tall enough that a row is 1/64 of an azimuth step at the
 * horizon (the render bends its rays in chords within a quarter of its pixel angle:
 * render.c; here that is 1/256 of a step, 0.7 m at 40 km for a step of 0.25 degrees). Per column the bisection keeps the row lo
 * whose ray hits (within max_distance) and the row hi whose ray does not; every round
 * picks the middle rows of all columns still open, in batches of TD_SCENE_PICK_MAX
 * through td_render_pick, until hi and lo are 1e-6 rows apart. The skyline's point is
 * lo's hit: just under the grazing ray, the first terrain it meets is the crest that
 * forms the skyline. */
#include "skyline.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "limit.h"
#include "render.h"

#define TD_DEG (M_PI / 180.0)
#define TD_SKYLINE_TOL 1e-6 /* rows */

void td_skyline_opts_default(td_skyline_opts *o)
{
    memset(o, 0, sizeof *o);
    o->step_deg = 0.25;
    o->max_distance = INFINITY;
    o->curvature = 1;
    o->k = 0.13;
    o->surface = TD_SURFACE_BILINEAR;
    o->method = TD_METHOD_AUTO;
}

static td_status check_opts(const td_view *v, const td_skyline_opts *o, double *ground, td_err *err)
{
    td_status rc = TD_OK;
    *ground = td_camera_ground(v->grid, o->x, o->y);
    if (!(o->step_deg >= TD_SKYLINE_STEP_MIN && o->step_deg <= TD_SKYLINE_STEP_MAX))
        rc = td_err_field(err, TD_ERANGE, "step_deg", "%g is outside %g .. %g degrees", o->step_deg,
                          TD_SKYLINE_STEP_MIN, TD_SKYLINE_STEP_MAX);
    else if (!(o->max_distance > 0.0))
        rc = td_err_field(err, TD_ERANGE, "max_distance", "must be > 0 m (leave it out for no limit)");
    else if (!(o->height >= 0.0 && o->height <= 1e5))
        rc = td_err_field(err, TD_ERANGE, "height", "%g is outside 0 .. 100000 m", o->height);
    else if (o->curvature && td_limit_check(TD_LIMIT_CURVATURE_K, o->k, err))
        rc = td_err_field(err, TD_ERANGE, "curvature.k", "%g is outside %g .. %g", o->k,
                          td_limit_get(TD_LIMIT_CURVATURE_K)->min, td_limit_get(TD_LIMIT_CURVATURE_K)->max);
    else if (isnan(*ground))
        rc = td_err_field(err, TD_ERANGE, "observer", "(%.1f, %.1f) is outside the dataset or over a void",
                          o->x, o->y);
    return rc;
}

/* The virtual panorama's scene (see the top of the file). */
static void virtual_scene(const td_skyline_opts *o, int n, double z, td_scene *s)
{
    double step_rad = o->step_deg * TD_DEG;
    td_scene_defaults(s);
    s->dataset[0] = '-';
    s->camera.projection = TD_PROJ_CYLINDRICAL;
    s->camera.x = o->x;
    s->camera.y = o->y;
    s->camera.z = z;
    s->camera.fov = n * o->step_deg;
    s->camera.heading = (0.5 * n - 0.5) * o->step_deg;
    s->camera.fov_v = 170.0;
    s->image.width = n;
    s->image.height = (int32_t)ceil(64.0 / step_rad * 2.0 * tan(85.0 * TD_DEG));
    s->image.format = TD_FORMAT_PICK;
    s->quality.method = o->method;
    s->quality.surface = o->surface;
    s->effects.curvature = o->curvature;
    s->effects.curvature_k = o->k;
}

/* Does pick pk count: a hit within max_distance of the eye? */
static int counts(const td_pick *pk, const double eye[3], double max_distance)
{
    return pk->hit && hypot(pk->p[0] - eye[0], pk->p[1] - eye[1]) <= max_distance;
}

/* One round: picks row mid of every open column (lo - hi > tol, or not yet tried: the
 * first round tries the bottom row, the second the top), narrows lo/hi and keeps lo's
 * pick. Returns how many columns were open. */
static td_status bisect_round(const td_view *v, td_scene *s, int round, const td_skyline_opts *o,
                              const double eye[3], double *lo, double *hi, td_pick *best, td_pick *buf,
                              int *open, td_err *err)
{
    td_status rc = TD_OK;
    int n = s->image.width, col[TD_SCENE_PICK_MAX];
    double bottom = s->image.height - 0.5;
    *open = 0;
    for (int k0 = 0; k0 < n && !rc;) {
        s->npick = 0;
        for (; k0 < n && s->npick < TD_SCENE_PICK_MAX; k0++) {
            double mid = round == 0 ? bottom : round == 1 ? -0.5 : 0.5 * (lo[k0] + hi[k0]);
            if (round > 0 && (isnan(lo[k0]) || lo[k0] - hi[k0] <= TD_SKYLINE_TOL))
                continue;
            col[s->npick] = k0;
            s->pick[s->npick][0] = k0;
            s->pick[s->npick][1] = mid;
            s->npick++;
        }
        if (s->npick == 0)
            break;
        *open += s->npick;
        rc = td_render_pick(v, s, buf, NULL, err);
        for (int i = 0; i < s->npick && !rc; i++) {
            int k = col[i], hit = counts(&buf[i], eye, o->max_distance);
            double row = s->pick[i][1];
            if (hit) {
                lo[k] = row;
                best[k] = buf[i];
                if (round == 1)
                    hi[k] = row; /* above 85 degrees: saturated, done */
            } else if (round == 0) {
                lo[k] = NAN; /* nothing even below: no terrain this way */
            } else {
                hi[k] = row;
            }
        }
    }
    return rc;
}

td_status td_skyline_compute(const td_view *v, const td_skyline_opts *o, td_skyline *out, td_err *err)
{
    td_status rc;
    double ground;
    td_scene *s = NULL;
    td_camera cam;
    td_pick *best = NULL, *buf = NULL;
    double *lo = NULL, *hi = NULL;
    memset(out, 0, sizeof *out);
    rc = check_opts(v, o, &ground, err);
    if (rc)
        goto out;
    int n = (int)floor(360.0 / o->step_deg + 1e-9);
    s = malloc(sizeof *s);
    out->pt = calloc((size_t)n, sizeof *out->pt);
    best = calloc((size_t)n, sizeof *best);
    buf = calloc(TD_SCENE_PICK_MAX, sizeof *buf);
    lo = calloc((size_t)n, sizeof *lo);
    hi = calloc((size_t)n, sizeof *hi);
    if (!s || !out->pt || !best || !buf || !lo || !hi) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a skyline of %d azimuths", n);
        goto out;
    }
    out->n = n;
    out->step_deg = o->step_deg;
    virtual_scene(o, n, ground + o->height, s);
    rc = td_camera_setup(&s->camera, s->image.width, s->image.height, v->grid, &cam, err);
    memcpy(out->eye, cam.o, sizeof out->eye);
    for (int k = 0; k < n; k++)
        hi[k] = -0.5;
    for (int round = 0, open = 1; !rc && open; round++) {
        if (o->cancel && atomic_load(o->cancel))
            rc = td_err_set(err, TD_ECANCELED, "the skyline was cancelled");
        else
            rc = bisect_round(v, s, round, o, out->eye, lo, hi, best, buf, &open, err);
        out->rays += (uint64_t)open;
    }
    for (int k = 0; !rc && k < n; k++) {
        td_skyline_pt *p = &out->pt[k];
        p->azimuth = k * o->step_deg;
        p->elevation = p->distance = NAN;
        if (!isnan(lo[k])) {
            double te = cam.tan_top - (lo[k] + 0.5) / cam.fv_px;
            p->elevation = atan(te) / TD_DEG;
            memcpy(p->p, best[k].p, sizeof p->p);
            p->distance = hypot(p->p[0] - out->eye[0], p->p[1] - out->eye[1]);
        }
    }
out:
    if (rc)
        td_skyline_free(out);
    free(s);
    free(best);
    free(buf);
    free(lo);
    free(hi);
    return rc;
}

double td_skyline_elevation_at(const td_skyline *s, double azimuth)
{
    double a = fmod(azimuth, 360.0), e = NAN;
    if (a < 0.0)
        a += 360.0;
    if (s->n > 0 && isfinite(a)) {
        double f = a / s->step_deg;
        int k0 = (int)floor(f) % s->n;
        int k1 = (k0 + 1) % s->n;
        /* the gap over north is shorter when the step does not divide 360 */
        double gap = k1 == 0 ? 360.0 - k0 * s->step_deg : s->step_deg;
        double u = (a - k0 * s->step_deg) / gap;
        e = (1.0 - u) * s->pt[k0].elevation + u * s->pt[k1].elevation;
    }
    return e;
}

void td_skyline_free(td_skyline *s)
{
    if (s) {
        free(s->pt);
        s->pt = NULL;
        s->n = 0;
    }
}
