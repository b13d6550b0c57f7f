/* scene.c: names of the scene's variant lists and the defaults of every field
 * (the values DESIGN.md's scene JSON gets when a key is absent). */
#include "scene.h"

#include <string.h>

static const char *const td_position_names[] = {
#define TD_X_NAME(e, name) name,
    TD_POSITION_LIST(TD_X_NAME)
#undef TD_X_NAME
};

static const char *const td_projection_names[] = {
#define TD_X_NAME(e, name) name,
    TD_PROJECTION_LIST(TD_X_NAME)
#undef TD_X_NAME
};

static const char *const td_format_names[] = {
#define TD_X_NAME(e, name) name,
    TD_FORMAT_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_position_kind_name(td_position_kind k)
{
    return (unsigned)k < TD_POS_COUNT ? td_position_names[k] : "unknown";
}

const char *td_projection_name(td_projection p)
{
    return (unsigned)p < TD_PROJ_COUNT ? td_projection_names[p] : "unknown";
}

const char *td_format_name(td_format f)
{
    return (unsigned)f < TD_FORMAT_COUNT ? td_format_names[f] : "unknown";
}

td_status td_projection_parse(const char *name, td_projection *out)
{
    int i = td_name_index(td_projection_names, TD_PROJ_COUNT, name);
    if (i >= 0)
        *out = (td_projection)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

td_status td_format_parse(const char *name, td_format *out)
{
    int i = td_name_index(td_format_names, TD_FORMAT_COUNT, name);
    if (i >= 0)
        *out = (td_format)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

void td_scene_defaults(td_scene *s)
{
    memset(s, 0, sizeof *s);
    s->camera.pos_kind = TD_POS_XYZ;
    s->camera.projection = TD_PROJ_PERSPECTIVE;
    s->camera.heading = 0.0;
    s->camera.pitch = 0.0;
    s->camera.roll = 0.0;
    s->camera.fov = 60.0;
    s->camera.swing = 180.0;
    s->camera.tilt = 90.0;
    s->camera.focal_mm = 150.0;
    s->camera.pixel_mm = 0.01;
    s->image.width = 640;
    s->image.height = 480;
    s->image.format = TD_FORMAT_PNG;
    s->image.depth_scale = 0.0;
    s->quality.method = TD_METHOD_AUTO;
    s->quality.surface = TD_SURFACE_BILINEAR;
    s->quality.samples = 1;
    s->quality.lod = 0;
    s->quality.lod_pixels = 1.0;
    s->quality.lod_grid = 0; /* TD_LOD_GRID_SQUARE: docs/isometric.md */
    s->quality.smooth_normals = 0;
    s->effects.sun_azimuth = 315.0;
    s->effects.sun_elevation = 45.0;
    s->effects.ambient = 0.25;
    s->effects.haze_visibility_km = 80.0;
    s->effects.water_level = 0.0;
    s->effects.ao_radius = 0.0;
    s->effects.curvature_k = 0.13;
}
