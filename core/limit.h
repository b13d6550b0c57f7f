/* limit.h: the ranges of a scene's numeric fields, written once. The request parser
 * (server/request.c: what the HTTP service and `terrad render` accept) and td_render's
 * own check (core/render.c: what core accepts from any caller, the benchmark and the tile
 * routes included) both read them here, so the two cannot drift apart again (they had:
 * samples at most 4 against 8, AO rays 64 against 1024).
 *
 * Columns: id, JSON path (the `field` of a refusal), min, api_max, max.
 *   min      the smallest value either accepts.
 *   api_max  the HTTP service's largest (td_request_limits_default). For the fields a
 *            td_request_limits member can move (image size, samples, AO rays, pick
 *            count), a caller may raise it up to max: `terrad render` does for samples,
 *            AO rays and picks; `--max-samples` only lowers it.
 *   max      the largest td_render / td_render_pick accept. Above api_max only where a
 *            core caller needs more than the service allows (the CLI's 8 x 8 samples,
 *            1024 AO rays, 1024 picks; images up to 65536 a side for the library); for
 *            the other rows the two are equal on purpose.
 * The values are those docs/api.md and the README describe (samples capped at 4 by the
 * parser, lod 0.25 .. 64 pixels, ...) and those request.c and render.c held before.
 *
 * Not here: the camera's fields (heading, pitch, fov, position, extent) are ranges of
 * the parser alone; td_camera_setup checks only what its arithmetic needs (fov in
 * (0, 180), a finite position). Pixel and sample totals (max_pixels,
 * max_samples_total) are the service's budget, set per deployment (request.h). */
#ifndef TD_LIMIT_H
#define TD_LIMIT_H

#include "scene.h"
#include "status.h"

#define TD_LIMIT_LIST(X)                                                                  \
    X(TD_LIMIT_WIDTH, "image.width", 1, 4096, 65536)                                      \
    X(TD_LIMIT_HEIGHT, "image.height", 1, 4096, 65536)                                    \
    X(TD_LIMIT_SAMPLES, "quality.samples", 1, 4, 8)                                       \
    X(TD_LIMIT_LOD_PIXELS, "quality.lod", 0.25, 64, 64)                                   \
    X(TD_LIMIT_AO_RAYS, "effects.ambient_occlusion", 0, 64, 1024)                         \
    X(TD_LIMIT_AMBIENT, "effects.ambient", 0, 1, 1)                                       \
    X(TD_LIMIT_SUN_ELEVATION, "effects.sun.elevation", -90, 90, 90)                       \
    X(TD_LIMIT_HAZE_KM, "effects.haze.visibility_km", 0.01, 10000, 10000)                 \
    X(TD_LIMIT_CURVATURE_K, "effects.curvature.k", -0.99, 0.99, 0.99)                     \
    X(TD_LIMIT_PICK, "pick", 0, 256, TD_SCENE_PICK_MAX)

typedef enum td_limit {
#define TD_X_ENUM(id, path, min, api_max, max) id,
    TD_LIMIT_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_LIMIT_COUNT
} td_limit;

typedef struct td_limit_row {
    const char *path;
    double min, api_max, max;
} td_limit_row;

/* The row of a limit (NULL for an id outside the table). */
const td_limit_row *td_limit_get(td_limit id);

/* Core's check: TD_OK if min <= v <= max, else TD_ERANGE with the field set to the row's
 * path and a message "PATH: V is outside MIN .. MAX". NaN is outside. */
td_status td_limit_check(td_limit id, double v, td_err *err);

#endif
