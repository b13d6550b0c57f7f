/* request.h: scene JSON (POST /v1/render, `terrad render`) or query parameters
 * (GET /v1/render) -> struct td_scene, in one pure function each: no I/O, no globals,
 * no logging. Every refusal names the field's path (`camera.fov`, `pick[2][0]`, or ""
 * for the body as a whole) and says why: malformed JSON, duplicate keys, unknown keys,
 * wrong types, NaN or infinity, out-of-range values, an image over the limits.
 *
 * Statuses: TD_EFORMAT (not JSON / not a number), TD_EINVAL (unknown key, wrong type,
 * duplicate key, unknown name), TD_ERANGE (out of range), TD_ETOOBIG (image or sample
 * count over the limits), TD_EUNSUPPORTED (level of detail). The HTTP layer answers
 * all of them with 400. */
#ifndef TD_REQUEST_H
#define TD_REQUEST_H

#include <stddef.h>
#include <stdint.h>

#include "scene.h"

/* Defaults of the members that core/limit.h has a row for: the row's api_max (a caller
 * may raise them up to its max, what td_render accepts); the other ranges of scene
 * fields are the table's, not settable here. */
typedef struct td_request_limits {
    int32_t max_width, max_height; /* pixels per side */
    uint64_t max_pixels;           /* width * height (default 16 Mpx) */
    int max_samples;               /* n of n x n supersampling */
    uint64_t max_samples_total;    /* width * height * n * n (default 64 M) */
    int max_ao_rays;
    int max_pick;                  /* pixels in one pick (<= TD_SCENE_PICK_MAX) */
    int allow_paths;               /* dataset and drape may be file paths (CLI); else they
                                      must be ids: [A-Za-z0-9_.-], not starting with '.' */
} td_request_limits;

typedef struct td_request_error {
    char field[128];   /* path of the field at fault, "" for the body */
    char message[256];
} td_request_error;

void td_request_limits_default(td_request_limits *lim);

/* Parses a JSON scene of len bytes (need not be NUL-terminated). On success *out holds
 * the scene (defaults for what is absent); on failure err says where and why and *out
 * is unspecified. */
td_status td_request_parse_scene(const char *body, size_t len, const td_request_limits *lim,
                                 td_scene *out, td_request_error *err);

/* The body of POST /v1/pick: the same scene, whose image.format is pick unless the body
 * names another (which the caller then refuses or serves as it sees fit). */
td_status td_request_parse_pick(const char *body, size_t len, const td_request_limits *lim,
                                td_scene *out, td_request_error *err);

/* The same scene from query parameters: each key is the dotted path of a JSON field
 * (`dataset`, `camera.position.x`, `camera.heading`, `image.width`, `effects.shadows`,
 * `effects.haze.visibility_km`, `camera.extent=x0,y0,x1,y1`, `pick=x,y;x,y`), values
 * are text and are read as the field's type. A repeated key is refused. */
td_status td_request_parse_query(const char *const *keys, const char *const *values, size_t n,
                                 const td_request_limits *lim, td_scene *out,
                                 td_request_error *err);

#endif
