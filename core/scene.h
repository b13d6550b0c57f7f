/* scene.h: what one render is asked to do: camera, image, quality and the effects,
 * as a plain struct with defaults. server/request.c fills it from scene JSON (or query
 * parameters); core/render.c reads it. Nothing here allocates: a scene is a value that
 * can be copied, compared and hashed (the server's ETag).
 *
 * Frame: the dataset frame of grid.h (x east, y north, z up, metres). Angles in degrees:
 * heading/azimuth clockwise from north, pitch positive looks up, roll positive banks the
 * camera to the right (the horizon turns anticlockwise in the image), fov horizontal.
 *
 * Variant lists (camera kind, position kind, projection, image format) are X-macro
 * tables so enum, name and JSON spelling cannot drift apart. */
#ifndef TD_SCENE_H
#define TD_SCENE_H

#include <stdint.h>

#include "trace.h"

#define TD_POSITION_LIST(X)                                                    \
    X(TD_POS_XYZ, "xyz")       /* x, y, z in the dataset frame */              \
    X(TD_POS_LONLAT_ALT, "lonlat-alt") /* lon, lat (degrees), alt (metres) */  \
    X(TD_POS_LONLAT_AGL, "lonlat-agl") /* lon, lat, metres above ground */     \
    X(TD_POS_XY_AGL, "xy-agl")  /* x, y in the frame, metres above ground */

#define TD_PROJECTION_LIST(X)                                                  \
    X(TD_PROJ_PERSPECTIVE, "perspective")                                      \
    X(TD_PROJ_ORTHOGRAPHIC, "orthographic")                                    \
    X(TD_PROJ_CYLINDRICAL, "cylindrical") /* panorama: fov up to 360 (camera.h) */

#define TD_FORMAT_LIST(X)                                                      \
    X(TD_FORMAT_PNG, "png")         /* RGBA8 PNG */                            \
    X(TD_FORMAT_DEPTH16, "depth16") /* 16-bit gray PNG, distance / depth_scale */ \
    X(TD_FORMAT_DEPTH32F, "depth32f") /* raw float32 LE distance, +inf = miss */ \
    X(TD_FORMAT_PICK, "pick")       /* JSON: the terrain point at given pixels */

typedef enum td_position_kind {
#define TD_X_ENUM(e, name) e,
    TD_POSITION_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_POS_COUNT
} td_position_kind;

typedef enum td_projection {
#define TD_X_ENUM(e, name) e,
    TD_PROJECTION_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_PROJ_COUNT
} td_projection;

typedef enum td_format {
#define TD_X_ENUM(e, name) e,
    TD_FORMAT_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_FORMAT_COUNT
} td_format;

const char *td_position_kind_name(td_position_kind k);
const char *td_projection_name(td_projection p);
const char *td_format_name(td_format f);
td_status td_projection_parse(const char *name, td_projection *out);
td_status td_format_parse(const char *name, td_format *out);

#define TD_SCENE_DATASET_MAX 256
#define TD_SCENE_PATH_MAX 512
#define TD_SCENE_PICK_MAX 1024

typedef struct td_scene_camera {
    td_position_kind pos_kind;
    double x, y, z;         /* TD_POS_XYZ (z), TD_POS_XY_AGL (x, y) */
    double lon, lat;        /* TD_POS_LONLAT_* */
    double alt, agl;        /* metres; alt absolute, agl above the ground below */
    td_projection projection;
    /* pinhole */
    double heading, pitch, roll, fov;
    /* cylindrical: the vertical field of view, degrees (0 = from the image's aspect,
     * square pixels at the horizon) */
    double fov_v;
    /* Paglieroni's photogrammetric camera, when `photogrammetric` is set: tilt is the
     * angle of the optical axis from the nadir (0 looks straight down, 90 at the
     * horizon), azimuth the optical axis' heading, swing the rotation about the axis
     * (180 = no roll: the nadir falls straight below the principal point), focal length
     * and pixel pitch in millimetres. */
    int photogrammetric;
    double tilt, swing, azimuth, focal_mm, pixel_mm;
    /* orthographic (top-down, north up): the extent in the dataset frame; all four
     * zero means the whole grid. */
    double extent[4]; /* xmin, ymin, xmax, ymax */
} td_scene_camera;

typedef struct td_scene_image {
    int32_t width, height;
    td_format format;
    double depth_scale; /* depth16: metres per unit; 0 = chosen from the deepest hit */
} td_scene_image;

typedef struct td_scene_quality {
    td_method method;
    td_surface surface;
    int samples;        /* n: n x n supersampling, 1 .. 8 */
    int lod;            /* level of detail on (render.c; needs td_render_opts.lod) */
    double lod_pixels;  /* with lod: pixels one coarse cell may span (default 1) */
    int lod_grid;       /* with lod: td_lod_grid (lod.h) of the coarse levels (default square) */
    int smooth_normals; /* vertex normals interpolated across the cell */
} td_scene_quality;

typedef struct td_scene_effects {
    double sun_azimuth, sun_elevation; /* always used by shading (default 315, 45) */
    int sun_time;                      /* effects.sun.time given: whoever renders turns it into
                                          sun_azimuth and sun_elevation at the dataset's centre
                                          (td_solar_in_grid) before td_render */
    double sun_time_s;                 /* that instant, seconds since 1970 UTC */
    double ambient;                    /* ambient light 0 .. 1 (default 0.25) */
    int shadows;
    int haze;
    double haze_visibility_km;         /* meteorological visibility at the lowest ground */
    int sky;
    int water;
    double water_level;                /* metres, dataset frame z */
    int ambient_occlusion;             /* N hemisphere rays per hit; 0 = off */
    double ao_radius;                  /* metres; 0 = 16 cells */
    int curvature;
    double curvature_k;                /* refraction coefficient (default 0.13) */
    char drape[TD_SCENE_PATH_MAX];     /* texture drape PNG path; empty = hypsometric tint */
} td_scene_effects;

typedef struct td_scene {
    char dataset[TD_SCENE_DATASET_MAX];
    td_scene_camera camera;
    td_scene_image image;
    td_scene_quality quality;
    td_scene_effects effects;
    int npick;                          /* pixels asked for by format "pick" */
    double pick[TD_SCENE_PICK_MAX][2];  /* pixel x, y (integers are pixel centres) */
} td_scene;

/* Fills every field with its default (camera at the origin, looking north, 640 x 480
 * PNG, auto method, bilinear surface, no effect). */
void td_scene_defaults(td_scene *s);

#endif
