/* camera.c: pinhole, photogrammetric and orthographic cameras (see camera.h).
 *
 * Frame of the pinhole camera, heading H clockwise from north, pitch P up, roll R:
 *   fwd   = (sin H cos P, cos H cos P, sin P)
 *   right0 = (cos H, -sin H, 0)          (horizontal, to the right of fwd)
 *   up0   = right0 x fwd
 *   right = cos R right0 - sin R up0     (positive roll banks right: the right edge
 *   up    = sin R right0 + cos R up0      of the image goes down)
 * A pixel's direction is fwd*f + right*(u - W/2) - up*(v - H/2) with u = px + 0.5,
 * v = py + 0.5 and f the focal length in pixels, normalised.
 *
 * The photogrammetric camera (Paglieroni and Petersen's tilt, swing, azimuth) is the
 * same frame with heading = azimuth, pitch = tilt - 90, roll = swing - 180 and
 * f = focal_mm / pixel_mm; its fov follows from f and the width.
 *
 * The cylindrical camera (camera.h) keeps the pinhole frame of its centre pixel in fwd,
 * right, up (for callers that want an axis); its rays and projections use the heading,
 * f_h, f_v and tan_top. */
#include "camera.h"

#include <math.h>
#include <string.h>

#include "simd.h"

#define TD_DEG (M_PI / 180.0)

double td_camera_ground(const td_grid *g, double x, double y)
{
    double h = NAN;
    double fx = x / g->sx, fy = y / g->sy;
    if (fx >= 0.0 && fy >= 0.0 && fx <= (double)(g->w - 1) && fy <= (double)(g->h - 1)) {
        int32_t i = (int32_t)fx, j = (int32_t)fy;
        if (i > g->w - 2)
            i = g->w - 2;
        if (j > g->h - 2)
            j = g->h - 2;
        double u = fx - i, v = fy - j;
        double z00 = td_grid_sample(g, i, j), z10 = td_grid_sample(g, i + 1, j);
        double z01 = td_grid_sample(g, i, j + 1), z11 = td_grid_sample(g, i + 1, j + 1);
        h = (1 - v) * ((1 - u) * z00 + u * z10) + v * ((1 - u) * z01 + u * z11);
    }
    return h;
}

static void cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static td_status resolve_position(const td_scene_camera *c, const td_grid *g, double p[3],
                                  td_err *err)
{
    td_status rc = TD_OK;
    double x = c->x, y = c->y;

    if (c->pos_kind == TD_POS_LONLAT_ALT || c->pos_kind == TD_POS_LONLAT_AGL) {
        if (g->geo.kind != TD_GEO_LONLAT) {
            rc = td_err_field(err, TD_EUNSUPPORTED, "camera.position.lon",
                              "the dataset has no lon/lat georeference; "
                              "give x, y in the dataset frame");
            goto out;
        }
        x = (c->lon - g->geo.x0) / g->geo.dx * g->sx;
        y = (c->lat - g->geo.y0) / g->geo.dy * g->sy;
    }
    p[0] = x;
    p[1] = y;
    if (c->pos_kind == TD_POS_XYZ) {
        p[2] = c->z;
    } else if (c->pos_kind == TD_POS_LONLAT_ALT) {
        p[2] = c->alt;
    } else {
        double ground = td_camera_ground(g, x, y);
        if (isnan(ground)) {
            rc = td_err_field(err, TD_ERANGE, "camera.position.agl",
                              "no ground below (%.1f, %.1f): outside the dataset or over a void",
                              x, y);
            goto out;
        }
        p[2] = ground + c->agl;
    }
    if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]))
        rc = td_err_field(err, TD_ERANGE, "camera.position", "not a finite point");
out:
    return rc;
}

/* The cylindrical camera's rows and columns (camera.h); the frame is set by the caller. */
static td_status setup_cylindrical(const td_scene_camera *c, td_camera *out, td_err *err)
{
    td_status rc = TD_OK;
    double fh = out->width / (c->fov * TD_DEG), P = c->pitch * TD_DEG, hv = 0.5 * c->fov_v * TD_DEG;
    if (c->photogrammetric || c->roll != 0.0)
        rc = td_err_field(err, TD_EINVAL, c->photogrammetric ? "camera.tilt" : "camera.roll",
                          "a cylindrical camera takes heading, pitch, fov (and fov_v), no roll");
    else if (!(c->fov > 0.0 && c->fov <= 360.0))
        rc = td_err_field(err, TD_ERANGE, "camera.fov", "%g is outside (0, 360] degrees", c->fov);
    else if (!isfinite(c->pitch) || !isfinite(c->heading))
        rc = td_err_field(err, TD_ERANGE, isfinite(c->pitch) ? "camera.heading" : "camera.pitch", "must be finite");
    else if (!(c->fov_v >= 0.0) || (c->fov_v > 0.0 && !(fabs(c->pitch) + c->fov_v * 0.5 < 89.0)))
        rc = td_err_field(err, TD_ERANGE, "camera.fov_v",
                          "pitch +- fov_v/2 (%g +- %g) must stay within 89 degrees of the horizon",
                          c->pitch, 0.5 * c->fov_v);
    if (rc)
        goto out;
    out->heading = c->heading * TD_DEG;
    out->focal_px = fh;
    if (c->fov_v > 0.0) {
        out->tan_top = tan(P + hv);
        out->fv_px = out->height / (tan(P + hv) - tan(P - hv));
    } else {
        out->fv_px = fh;
        out->tan_top = tan(P) + 0.5 * out->height / fh;
    }
    /* the vertical angle per pixel is cos^2(e) / f_v <= 1 / f_v */
    out->pixel_angle = 1.0 / fmax(fh, out->fv_px);
out:
    return rc;
}

/* Top-down, north up, over camera.extent (the whole grid when it is all zeros). */
static td_status setup_orthographic(const td_scene_camera *c, const td_grid *g, td_camera *out,
                                    td_err *err)
{
    td_status rc = TD_OK;
    double x0 = c->extent[0], y0 = c->extent[1], x1 = c->extent[2], y1 = c->extent[3];
    if (x0 == 0.0 && y0 == 0.0 && x1 == 0.0 && y1 == 0.0) {
        x1 = (g->w - 1) * g->sx;
        y1 = (g->h - 1) * g->sy;
    }
    if (!(x1 > x0) || !(y1 > y0) || !isfinite(x0 + x1 + y0 + y1)) {
        rc = td_err_field(err, TD_ERANGE, "camera.extent", "[%g, %g, %g, %g] is empty", x0, y0, x1, y1);
    } else {
        out->x0 = x0;
        out->y1 = y1;
        out->dx = (x1 - x0) / out->width;
        out->dy = (y1 - y0) / out->height;
        out->ztop = (isfinite(g->zmax) ? (double)g->zmax : 0.0) + 100.0;
        out->o[0] = 0.5 * (x0 + x1);
        out->o[1] = 0.5 * (y0 + y1);
        out->o[2] = out->ztop;
        out->fwd[2] = -1.0;
        out->right[0] = 1.0;
        out->up[1] = 1.0;
        out->pixel_angle = 0.0;
    }
    return rc;
}

td_status td_camera_setup(const td_scene_camera *c, int32_t width, int32_t height,
                          const td_grid *g, td_camera *out, td_err *err)
{
    td_status rc = TD_OK;
    memset(out, 0, sizeof *out);
    out->projection = c->projection;
    out->width = width;
    out->height = height;
    if (width < 1 || height < 1) {
        rc = td_err_field(err, TD_ERANGE, "image", "%d x %d pixels is empty", (int)width, (int)height);
        goto out;
    }
    if (c->projection == TD_PROJ_ORTHOGRAPHIC) {
        rc = setup_orthographic(c, g, out, err);
        goto out;
    }

    double heading = c->heading, pitch = c->pitch, roll = c->roll, f;
    if (c->projection == TD_PROJ_CYLINDRICAL) {
        rc = setup_cylindrical(c, out, err);
        if (rc)
            goto out;
        f = out->focal_px;
    } else if (c->photogrammetric) {
        heading = c->azimuth;
        pitch = c->tilt - 90.0;
        roll = c->swing - 180.0;
        f = c->focal_mm / c->pixel_mm;
        if (!(f > 0.0) || !isfinite(f)) {
            rc = td_err_field(err, TD_ERANGE, "camera.focal_mm",
                              "focal length / pixel size must be positive");
            goto out;
        }
    } else {
        if (!(c->fov > 0.0 && c->fov < 180.0)) {
            rc = td_err_field(err, TD_ERANGE, "camera.fov", "%g is outside (0, 180) degrees", c->fov);
            goto out;
        }
        f = 0.5 * width / tan(0.5 * c->fov * TD_DEG);
    }
    rc = resolve_position(c, g, out->o, err);
    if (rc)
        goto out;
    double H = heading * TD_DEG, P = pitch * TD_DEG, R = roll * TD_DEG;
    double r0[3] = {cos(H), -sin(H), 0.0}, u0[3];
    out->fwd[0] = sin(H) * cos(P);
    out->fwd[1] = cos(H) * cos(P);
    out->fwd[2] = sin(P);
    cross(r0, out->fwd, u0);
    for (int k = 0; k < 3; k++) {
        out->right[k] = cos(R) * r0[k] - sin(R) * u0[k];
        out->up[k] = sin(R) * r0[k] + cos(R) * u0[k];
    }
    if (c->projection != TD_PROJ_CYLINDRICAL) {
        out->focal_px = f;
        out->pixel_angle = 1.0 / f;
    }
out:
    return rc;
}

/* A panorama's azimuth (radians, clockwise from north) at pixel abscissa px, and its row
 * at ordinate py: the tangent of the elevation and 1 / sqrt(1 + te^2). td_camera_ray and
 * the rows of td_camera_cyl_dirs take them from here, so their rays have the same bits. */
static inline double cyl_azimuth(const td_camera *cam, double px)
{
    return cam->heading + (px + 0.5 - 0.5 * cam->width) / cam->focal_px;
}

static inline void cyl_row(const td_camera *cam, double py, double *te, double *inv)
{
    *te = cam->tan_top - (py + 0.5) / cam->fv_px;
    *inv = 1.0 / sqrt(1.0 + *te * *te);
}

void td_camera_ray(const td_camera *cam, double px, double py, td_ray *r)
{
    double u = px + 0.5, v = py + 0.5;
    if (cam->projection == TD_PROJ_ORTHOGRAPHIC) {
        r->o[0] = cam->x0 + u * cam->dx;
        r->o[1] = cam->y1 - v * cam->dy;
        r->o[2] = cam->ztop;
        r->d[0] = 0.0;
        r->d[1] = 0.0;
        r->d[2] = -1.0;
    } else if (cam->projection == TD_PROJ_CYLINDRICAL) {
        double az = cyl_azimuth(cam, px), te, inv;
        cyl_row(cam, py, &te, &inv);
        memcpy(r->o, cam->o, sizeof r->o);
        r->d[0] = sin(az) * inv;
        r->d[1] = cos(az) * inv;
        r->d[2] = te * inv;
    } else {
        /* fwd + (right*a - up*b) / f: bounded for any focal length (f*fwd + ... would
         * overflow when squared for a fov of 1e-150 degrees) */
        double a = (u - 0.5 * cam->width) / cam->focal_px, b = (v - 0.5 * cam->height) / cam->focal_px;
        double n2 = 0.0;
        for (int k = 0; k < 3; k++) {
            r->o[k] = cam->o[k];
            r->d[k] = cam->fwd[k] + cam->right[k] * a - cam->up[k] * b;
            n2 += r->d[k] * r->d[k];
        }
        double inv = 1.0 / sqrt(n2);
        for (int k = 0; k < 3; k++)
            r->d[k] *= inv;
    }
    r->tmin = 0.0;
    r->tmax = INFINITY;
}

void td_camera_abscissas(const td_camera *cam, const double *px, int n, double *ax)
{
    for (int k = 0; k < n; k++)
        ax[k] = (px[k] + 0.5 - 0.5 * cam->width) / cam->focal_px;
}

TD_ROW_CLONES
void td_camera_dirs(const td_camera *cam, double py, const double *ax, int n, double *dx,
                    double *dy, double *dz)
{
    /* td_camera_ray's perspective branch, term for term (no contraction: -ffp-contract=off) */
    const double b = (py + 0.5 - 0.5 * cam->height) / cam->focal_px;
    const double f0 = cam->fwd[0], f1 = cam->fwd[1], f2 = cam->fwd[2];
    const double r0 = cam->right[0], r1 = cam->right[1], r2 = cam->right[2];
    const double u0 = cam->up[0] * b, u1 = cam->up[1] * b, u2 = cam->up[2] * b;
    for (int k = 0; k < n; k++) {
        double a = ax[k];
        double x = f0 + r0 * a - u0, y = f1 + r1 * a - u1, z = f2 + r2 * a - u2;
        double inv = 1.0 / sqrt(x * x + y * y + z * z);
        dx[k] = x * inv;
        dy[k] = y * inv;
        dz[k] = z * inv;
    }
}

void td_camera_cyl_columns(const td_camera *cam, const double *px, int n, double *sa, double *ca)
{
    for (int k = 0; k < n; k++) {
        double az = cyl_azimuth(cam, px[k]);
        sa[k] = sin(az);
        ca[k] = cos(az);
    }
}

TD_ROW_CLONES
void td_camera_cyl_dirs(const td_camera *cam, double py, const double *sa, const double *ca, int n,
                        double *dx, double *dy, double *dz)
{
    double te, inv;
    cyl_row(cam, py, &te, &inv);
    for (int k = 0; k < n; k++) {
        dx[k] = sa[k] * inv;
        dy[k] = ca[k] * inv;
        dz[k] = te * inv;
    }
}

/* Is the image of the vertical direction s (+1 up, -1 down) in front of the camera and
 * within a pixel of the rectangle? */
static int vertical_inside(const td_camera *cam, double s, double px0, double py0, double px1,
                           double py1)
{
    double x = s * cam->right[2], y = s * cam->up[2], z = s * cam->fwd[2];
    int in = 0;
    if (z > 0.0) {
        double px = 0.5 * cam->width + cam->focal_px * x / z - 0.5;
        double py = 0.5 * cam->height - cam->focal_px * y / z - 0.5;
        in = px >= px0 - 1.0 && px <= px1 + 1.0 && py >= py0 - 1.0 && py <= py1 + 1.0;
    }
    return in;
}

int td_camera_azimuths_poly(const td_camera *cam, const double (*p)[2], int np, double *az0, double *az1)
{
    double bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
    for (int k = 0; k < np; k++) { /* the polygon's box: the vanishing point kept off it */
        bx0 = p[k][0] < bx0 ? p[k][0] : bx0, bx1 = p[k][0] > bx1 ? p[k][0] : bx1;
        by0 = p[k][1] < by0 ? p[k][1] : by0, by1 = p[k][1] > by1 ? p[k][1] : by1;
    }
    /* a panorama's azimuth follows px alone (its rays are never vertical): the box's
       columns less than pi apart, with a pixel's margin, for the extremes below to hold */
    int ok = np > 0 && (cam->projection == TD_PROJ_CYLINDRICAL
                            ? (bx1 - bx0 + 1.0) / cam->focal_px < M_PI
                            : cam->projection == TD_PROJ_PERSPECTIVE && !vertical_inside(cam, 1.0, bx0, by0, bx1, by1) &&
                                  !vertical_inside(cam, -1.0, bx0, by0, bx1, by1));
    double ref = 0.0, lo = 0.0, hi = 0.0;
    for (int k = 0; ok && k < np; k++) {
        td_ray r;
        td_camera_ray(cam, p[k][0], p[k][1], &r);
        double a = atan2(r.d[1], r.d[0]);
        if (k == 0)
            ref = a;
        a = remainder(a - ref, 2.0 * M_PI);
        lo = a < lo ? a : lo;
        hi = a > hi ? a : hi;
    }
    ok = ok && hi - lo < M_PI;
    *az0 = ref + lo;
    *az1 = ref + hi;
    return ok;
}

int td_camera_azimuths(const td_camera *cam, double px0, double py0, double px1, double py1,
                       double *az0, double *az1)
{
    const double p[4][2] = {{px0, py0}, {px1, py0}, {px0, py1}, {px1, py1}};
    return td_camera_azimuths_poly(cam, p, 4, az0, az1);
}

void td_camera_rising(const td_camera *cam, double px, double py, double vert[2])
{
    /* how a point in front of the pixel moves in the image as it rises */
    td_ray r;
    double p[3], q[3], a[2] = {0.0, 0.0}, b[2] = {0.0, -1.0};
    td_camera_ray(cam, px, py, &r);
    for (int k = 0; k < 3; k++)
        p[k] = q[k] = r.o[k] + r.d[k];
    q[2] += 1e-3;
    if (cam->projection == TD_PROJ_PERSPECTIVE && td_camera_project(cam, p, &a[0], &a[1]) &&
        td_camera_project(cam, q, &b[0], &b[1])) {
        b[0] -= a[0];
        b[1] -= a[1];
    }
    double len = hypot(b[0], b[1]);
    vert[0] = len > 0.0 ? b[0] / len : 0.0;
    vert[1] = len > 0.0 ? b[1] / len : -1.0;
}

int td_camera_project(const td_camera *cam, const double p[3], double *px, double *py)
{
    int ok = 1;
    if (cam->projection == TD_PROJ_ORTHOGRAPHIC) {
        *px = (p[0] - cam->x0) / cam->dx - 0.5;
        *py = (cam->y1 - p[1]) / cam->dy - 0.5;
    } else if (cam->projection == TD_PROJ_CYLINDRICAL) {
        double v[3] = {p[0] - cam->o[0], p[1] - cam->o[1], p[2] - cam->o[2]};
        double h = hypot(v[0], v[1]);
        ok = h > 0.0;
        if (ok) {
            double da = remainder(atan2(v[0], v[1]) - cam->heading, 2.0 * M_PI);
            *px = 0.5 * cam->width + da * cam->focal_px - 0.5;
            *py = cam->fv_px * (cam->tan_top - v[2] / h) - 0.5;
        }
    } else {
        double v[3] = {p[0] - cam->o[0], p[1] - cam->o[1], p[2] - cam->o[2]};
        double xc = v[0] * cam->right[0] + v[1] * cam->right[1] + v[2] * cam->right[2];
        double yc = v[0] * cam->up[0] + v[1] * cam->up[1] + v[2] * cam->up[2];
        double zc = v[0] * cam->fwd[0] + v[1] * cam->fwd[1] + v[2] * cam->fwd[2];
        if (zc <= 0.0) {
            ok = 0;
        } else {
            *px = 0.5 * cam->width + cam->focal_px * xc / zc - 0.5;
            *py = 0.5 * cam->height - cam->focal_px * yc / zc - 0.5;
        }
    }
    return ok;
}
