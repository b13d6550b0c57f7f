/* camera.h: turning a scene camera into rays, and points back into pixels.
 *
 * Pixel coordinates: (px, py) with px to the right and py down; integer values are
 * pixel centres (pixel (0, 0) spans [-0.5, 0.5) x [-0.5, 0.5)), so round(px), round(py)
 * name the pixel a point falls in. td_camera_ray and td_camera_project use the same
 * convention, which makes project -> pick a round trip.
 *
 * Rays are set up in double precision relative to the camera: origin = the camera's
 * position (perspective, cylindrical) or a point on the top plane above the pixel
 * (orthographic), unit direction, so t is in metres.
 *
 * Cylindrical (panorama): the image is the unrolled inside of a vertical cylinder around
 * the eye. Column u = px + 0.5 looks at azimuth heading + (u - W/2) / f_h (radians,
 * clockwise from north; f_h = W / fov in pixels per radian, fov up to 360 degrees); row
 * v = py + 0.5 looks at the elevation e with tan e = tan_top - v / f_v. Without fov_v,
 * f_v = f_h (square pixels at the horizon) and the centre row looks at the pitch; with
 * fov_v the rows span pitch - fov_v/2 .. pitch + fov_v/2. Verticals stay vertical and
 * every column is one azimuth, so a skyline is one row per column. Roll is refused. At
 * 360 degrees the seam (azimuth heading +- 180) is the left edge of pixel 0 and the right
 * edge of pixel W-1; td_camera_project maps an azimuth to heading - 180 .. heading + 180. */
#ifndef TD_CAMERA_H
#define TD_CAMERA_H

#include "scene.h"

typedef struct td_camera {
    td_projection projection;
    int32_t width, height;
    /* perspective */
    double o[3];                     /* position, dataset frame */
    double fwd[3], right[3], up[3];  /* orthonormal camera frame */
    double focal_px;                 /* focal length in pixels */
    double pixel_angle;              /* radians per pixel at the image centre */
    /* cylindrical (focal_px = f_h above) */
    double heading;                  /* radians, azimuth of the centre column */
    double fv_px, tan_top;           /* rows: tan e = tan_top - v / fv_px */
    /* orthographic: top-down, north up */
    double x0, y1;                   /* west and north edges of the extent */
    double dx, dy;                   /* metres per pixel */
    double ztop;                     /* height of the ray origins */
} td_camera;

/* Resolves the position (lon/lat needs a lon/lat georeference; agl samples the grid
 * below) and builds the frame. Errors name the scene field (e.g. `camera.position.lon`). */
td_status td_camera_setup(const td_scene_camera *c, int32_t width, int32_t height,
                          const td_grid *g, td_camera *out, td_err *err);

/* The ray through pixel coordinates (px, py); tmin = 0, tmax = +inf. */
void td_camera_ray(const td_camera *cam, double px, double py, td_ray *r);

/* The image-plane abscissas of pixel columns px[k], k < n, of a perspective camera:
 * ax[k] = (px[k] + 0.5 - width / 2) / focal_px, td_camera_ray's first step. Rows share
 * them: a block computes its columns' once. */
void td_camera_abscissas(const td_camera *cam, const double *px, int n, double *ax);

/* The unit directions of the rays through pixels (px[k], py), k < n, of a perspective
 * camera, from their abscissas ax[k] (td_camera_abscissas), the same bits as
 * td_camera_ray's, into dx, dy, dz (the rays start at cam->o). One loop over a row that
 * the compiler vectorises: the render's camera rays come a sample row at a time. */
void td_camera_dirs(const td_camera *cam, double py, const double *ax, int n, double *dx,
                    double *dy, double *dz);

/* A cylindrical camera's columns: the sine and cosine of the azimuth of the column through
 * px[k], k < n, into sa[k] and ca[k] (td_camera_ray's). Rows share them, as they share
 * td_camera_abscissas'. */
void td_camera_cyl_columns(const td_camera *cam, const double *px, int n, double *sa, double *ca);

/* The unit directions of a cylindrical camera's rays through pixels (px[k], py), k < n,
 * from their columns' (td_camera_cyl_columns), the same bits as td_camera_ray's, into dx,
 * dy, dz (the rays start at cam->o): one sine and cosine a column, not one a sample. */
void td_camera_cyl_dirs(const td_camera *cam, double py, const double *sa, const double *ca, int n,
                        double *dx, double *dy, double *dz);

/* Bounds the azimuths (atan2(d_y, d_x), radians) of the rays through the rectangle of
 * pixel coordinates [px0, px1] x [py0, py1]: [*az0, *az1], az1 - az0 < pi. The rays of
 * one azimuth pass through one half-line from the image of the vertical (the vanishing
 * point of verticals), so over a rectangle that does not hold that point the extremes are
 * at its corners (a cylindrical camera's azimuth follows the column alone). Returns 0
 * (nothing bounded) when it does hold it (with a pixel's margin), for an orthographic
 * camera, or when the corners span pi or more. */
int td_camera_azimuths(const td_camera *cam, double px0, double py0, double px1, double py1,
                       double *az0, double *az1);

/* The same for the convex polygon of pixel coordinates p[0 .. np) (its extremes are at
 * its vertices); the vanishing point is kept off the polygon's bounding box. */
int td_camera_azimuths_poly(const td_camera *cam, const double (*p)[2], int np, double *az0, double *az1);

/* The image direction (unit; px right, py down) in which a point seen at pixel (px, py)
 * moves as it rises: elevation grows that way along the pixel's vanishing-point line.
 * Straight up the image (0, -1) where no direction follows (orthographic camera). */
void td_camera_rising(const td_camera *cam, double px, double py, double vert[2]);

/* Projects p (dataset frame) to pixel coordinates; returns 0 when p is behind the
 * camera (perspective) or straight above or below the eye (cylindrical) and leaves px, py unset, 1 otherwise (the point may still be
 * outside the image). */
int td_camera_project(const td_camera *cam, const double p[3], double *px, double *py);

/* Ground height below (x, y): bilinear over the grid's samples, NaN outside the grid
 * or over a void. */
double td_camera_ground(const td_grid *g, double x, double y);

#endif
