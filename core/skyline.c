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
#define TD_SKYLINE_LIFT 0.01 /* metres: the lowest eye above the (bilinear) ground */

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

/* The chosen surface's height below (x, y): the eye stands on it, not inside it (the
 * plane surface's cell is a box up to its highest corner, the triangles depart from the
 * bilinear patch). Bilinear for linear and bilinear; NaN outside or over a void. */
static double surface_ground(const td_grid *g, td_surface surf, double x, double y)
{
    double z = td_camera_ground(g, x, y);
    if (!isnan(z) && (surf == TD_SURFACE_PLANE || surf == TD_SURFACE_TRIANGLE)) {
        double fx = x / g->sx, fy = y / g->sy;
        int32_t i = fx >= g->w - 1 ? g->w - 2 : (int32_t)fx, j = fy >= g->h - 1 ? g->h - 2 : (int32_t)fy;
        double u = fx - i, t = fy - j;
        double z00 = td_grid_at(g, i, j), z10 = td_grid_at(g, i + 1, j), z01 = td_grid_at(g, i, j + 1),
               z11 = td_grid_at(g, i + 1, j + 1);
        if (surf == TD_SURFACE_PLANE) /* (a point on a cell edge: the higher cell's box would do too) */
            z = fmax(fmax(z00, z10), fmax(z01, z11));
        else if (u + t <= 1.0) /* split from (i+1, j) to (i, j+1): the south-west triangle */
            z = z00 + u * (z10 - z00) + t * (z01 - z00);
        else
            z = z11 + (1.0 - u) * (z01 - z11) + (1.0 - t) * (z10 - z11);
    }
    return z;
}

static td_status check_opts(const td_view *v, const td_skyline_opts *o, double *ground, td_err *err)
{
    td_status rc = TD_OK;
    *ground = surface_ground(v->grid, o->surface, o->x, o->y);
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
    /* an eye on the ground would start its rays on the surface: lift it by TD_SKYLINE_LIFT */
    virtual_scene(o, n, ground + fmax(o->height, TD_SKYLINE_LIFT), s);
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

/* ---- the sun against the skyline ------------------------------------------------------ */

/* The sun at t as seen (centre: geometric + refraction) and how far its upper limb is
 * above the skyline there (degrees; above the astronomical horizon where the skyline
 * has no terrain). */
static td_status sun_at(const td_skyline *s, double lat, double lon, double t, td_sun_sample *o, double *margin,
                        td_err *err)
{
    td_sun sun;
    td_status rc = td_solar_position(lat, lon, t, &sun, err);
    if (!rc) {
        o->t = t;
        o->azimuth = sun.azimuth_deg;
        o->elevation = sun.elevation_deg + sun.refraction_deg;
        o->skyline = td_skyline_elevation_at(s, sun.azimuth_deg);
        *margin = o->elevation + TD_SUN_RADIUS_DEG - (isnan(o->skyline) ? 0.0 : o->skyline);
        o->seen = *margin > 0.0;
    }
    return rc;
}

/* The instant in (a, b] where the sun's margin changes sign (seen at b: sb), to 1 s. */
static td_status refine(const td_skyline *s, double lat, double lon, double a, double b, int sb, double *t,
                        td_err *err)
{
    td_status rc = TD_OK;
    td_sun_sample smp;
    double m;
    while (!rc && b - a > 1.0) {
        double mid = 0.5 * (a + b);
        rc = sun_at(s, lat, lon, mid, &smp, &m, err);
        if (smp.seen == sb)
            b = mid;
        else
            a = mid;
    }
    *t = b;
    return rc;
}

/* Scans the day for the stretches the sun is seen (see skyline.h). */
static td_status scan_day(const td_skyline *s, double lat, double lon, td_skyline_sun *o, td_err *err)
{
    td_status rc = TD_OK;
    double t0 = o->noon_s - 43200.0, t1 = o->noon_s + 43200.0, m, prev_t = t0;
    td_sun_sample smp;
    int prev = 0, open = 0;
    o->rise_s = o->set_s = NAN;
    for (double t = t0; !rc && t <= t1; t += TD_SUN_SCAN_S) {
        double edge = t;
        rc = sun_at(s, lat, lon, t, &smp, &m, err);
        if (!rc && t > t0 && smp.seen != prev)
            rc = refine(s, lat, lon, prev_t, t, smp.seen, &edge, err);
        if (!rc && smp.seen && !prev && o->nint < TD_SUN_INTERVALS_MAX) {
            o->interval[o->nint][0] = edge;
            open = 1;
            if (t > t0 && isnan(o->rise_s))
                o->rise_s = edge;
        } else if (!rc && !smp.seen && prev && open) {
            o->interval[o->nint++][1] = edge;
            o->set_s = edge;
            open = 0;
        }
        prev = smp.seen;
        prev_t = t;
    }
    if (!rc && open)
        o->interval[o->nint++][1] = t1;
    for (int k = 0; k < o->nint; k++)
        o->seen_s += o->interval[k][1] - o->interval[k][0];
    return rc;
}

td_status td_skyline_sun_day(const td_skyline *s, double lat, double lon, double day_s, td_skyline_sun *out,
                         td_err *err)
{
    td_sun_day day;
    double m;
    memset(out, 0, sizeof *out);
    td_status rc = td_solar_day(lat, lon, day_s, &day, err);
    if (rc) {
        rc = td_err_field(err, rc, "observer", "%s", err->msg);
        goto out;
    }
    out->noon_s = day.noon_s;
    out->polar = day.polar;
    out->astro_rise_s = day.polar ? NAN : day.rise_s;
    out->astro_set_s = day.polar ? NAN : day.set_s;
    for (int k = 0; !rc && k < TD_SUN_PATH_MAX; k++)
        rc = sun_at(s, lat, lon, day.noon_s - 43200.0 + 300.0 * k, &out->path[out->npath++], &m, err);
    if (!rc)
        rc = scan_day(s, lat, lon, out, err);
out:
    return rc;
}
