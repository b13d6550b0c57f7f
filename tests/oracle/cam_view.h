/* cam_view.h: a camera view placed in a grid's own frame, and the depth render of it the
 * oracle's camera checks judge (oracle.c --cameras, oracle_lod.c). */
#ifndef TD_CAM_VIEW_H
#define TD_CAM_VIEW_H

#include <string.h>

#include "render.h"

typedef struct cam_view {
    const char *name;
    double fx, fy, agl, heading, pitch, roll, fov, sun_az, sun_el;
} cam_view;

/* The scene of view cv over g: the defaults, the camera at fx, fy (fractions of g's
 * extent), agl metres over the highest sample (a negative agl puts it below the crests,
 * at the lowest sample plus a quarter of the relief), a w x h depth32f image, method m,
 * surface sf and the view's sun. */
static inline void cam_view_scene(const cam_view *cv, const td_grid *g, int w, int h, td_method m,
                                  td_surface sf, td_scene *sc)
{
    td_scene_defaults(sc);
    sc->camera.x = cv->fx * (g->w - 1) * g->sx;
    sc->camera.y = cv->fy * (g->h - 1) * g->sy;
    sc->camera.z = cv->agl < 0.0 ? g->zmin + 0.25 * (g->zmax - g->zmin) : g->zmax + cv->agl;
    sc->camera.heading = cv->heading, sc->camera.pitch = cv->pitch, sc->camera.roll = cv->roll;
    sc->camera.fov = cv->fov;
    sc->image.width = w, sc->image.height = h, sc->image.format = TD_FORMAT_DEPTH32F;
    sc->quality.method = m, sc->quality.surface = sf;
    sc->effects.sun_azimuth = cv->sun_az, sc->effects.sun_elevation = cv->sun_el;
}

/* Renders sc with the coherence devices of o on (into *on) and off (TD_RENDER_OFF_CAMERA,
 * into *off) and sets up its camera; non-zero on an error (in err). */
static inline int cam_view_render(const td_view *v, const td_scene *sc, const td_render_opts *o,
                                  td_render_result *on, td_render_result *off, td_camera *cam,
                                  td_err *err)
{
    td_render_opts plain = *o;
    plain.off = TD_RENDER_OFF_CAMERA;
    memset(on, 0, sizeof *on), memset(off, 0, sizeof *off);
    return td_render(v, sc, o, on, err) || td_render(v, sc, &plain, off, err) ||
           td_camera_setup(&sc->camera, sc->image.width, sc->image.height, v->grid, cam, err);
}

/* Whether pixel k has the same depth, bit for bit, with the devices on and off, and (for a
 * method other than auto) as auto's. */
static inline int cam_view_same(const td_render_result *on, const td_render_result *off,
                                const float *auto_depth, td_method m, int k)
{
    return !memcmp(&on->depth[k], &off->depth[k], sizeof(float)) &&
           (m == TD_METHOD_AUTO || !memcmp(&on->depth[k], &auto_depth[k], sizeof(float)));
}

#endif
