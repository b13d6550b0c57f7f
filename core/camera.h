/* camera.h: turning a scene camera into rays, and points back into pixels.
 *
 * Pixel coordinates: (px, py) with px to the right and py down; integer values are
 * pixel centres (pixel (0, 0) spans [-0.5, 0.5) x [-0.5, 0.5)), so round(px), round(py)
 * name the pixel a point falls in. td_camera_ray and td_camera_project use the same
 * convention, which makes project -> pick a round trip.
 *
 * Rays are set up in double precision relative to the camera: origin = the camera's
 * position (perspective) or a point on the top plane above the pixel (orthographic),
 * unit direction, so t is in metres. */
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

/* Bounds the azimuths (atan2(d_y, d_x), radians) of the rays through the rectangle of
 * pixel coordinates [px0, px1] x [py0, py1]: [*az0, *az1], az1 - az0 < pi. The rays of
 * one azimuth pass through one half-line from the image of the vertical (the vanishing
 * point of verticals), so over a rectangle that does not hold that point the extremes are
 * at its corners. Returns 0 (nothing bounded) when it does hold it (with a pixel's
 * margin), for an orthographic camera, or when the corners span pi or more. */
int td_camera_azimuths(const td_camera *cam, double px0, double py0, double px1, double py1,
                       double *az0, double *az1);

/* The image direction (unit; px right, py down) in which a point seen at pixel (px, py)
 * moves as it rises: elevation grows that way along the pixel's vanishing-point line.
 * Straight up the image (0, -1) where no direction follows (orthographic camera). */
void td_camera_rising(const td_camera *cam, double px, double py, double vert[2]);

/* Projects p (dataset frame) to pixel coordinates; returns 0 when p is behind the
 * camera (perspective) and leaves px, py unset, 1 otherwise (the point may still be
 * outside the image). */
int td_camera_project(const td_camera *cam, const double p[3], double *px, double *py);

/* Ground height below (x, y): bilinear over the grid's samples, NaN outside the grid
 * or over a void. */
double td_camera_ground(const td_grid *g, double x, double y);

#endif
