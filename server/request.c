/* request.c: scene JSON / query parameters -> struct td_scene (see request.h).
 *
 * One validator walks the JSON tree with the path of the current field kept in a small
 * buffer, so every refusal names it. Query parameters are first turned into the same
 * tree (every value a string) and walked with `query` set, where the getters read
 * numbers and booleans from text; so the two entry points cannot disagree on a rule.
 *
 * jansson refuses NaN and Infinity (they are not JSON) and, with JSON_REJECT_DUPLICATES,
 * repeated keys, but only says where in the text: locate() re-scans the text up to that
 * offset and rebuilds the path of the key being read there, so those errors name the
 * field too. Numbers too large for a double (1e999) are refused by jansson the same
 * way. Rejected alternative: a JSON schema library (no Debian package fits, and the
 * messages would not name our fields the way the HTTP contract wants). */
#include "request.h"
#include "limit.h"
#include "lod.h"
#include "solar.h"

#include <ctype.h>
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The range of a field from the table of limits (core/limit.h): its min, and the
 * service's max for the fields td_request_limits does not hold. */
static double lim_min(td_limit id)
{
    return td_limit_get(id)->min;
}

static double lim_api(td_limit id)
{
    return td_limit_get(id)->api_max;
}

void td_request_limits_default(td_request_limits *lim)
{
    lim->max_width = (int32_t)lim_api(TD_LIMIT_WIDTH);
    lim->max_height = (int32_t)lim_api(TD_LIMIT_HEIGHT);
    lim->max_pixels = 16u << 20;
    lim->max_samples = (int)lim_api(TD_LIMIT_SAMPLES);
    lim->max_samples_total = 64u << 20;
    lim->max_ao_rays = (int)lim_api(TD_LIMIT_AO_RAYS);
    lim->max_pick = (int)lim_api(TD_LIMIT_PICK);
    lim->allow_paths = 0;
}

typedef struct pctx {
    const td_request_limits *lim;
    td_request_error *err;
    int query;
    int pick;  /* POST /v1/pick: image.format is pick unless the scene says otherwise */
    char path[128];
    size_t plen;
    td_status rc;
} pctx;

static int fail(pctx *p, td_status st, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

static int fail(pctx *p, td_status st, const char *fmt, ...)
{
    va_list ap;
    if (p->rc == TD_OK) {
        p->rc = st;
        if (p->err) {
            snprintf(p->err->field, sizeof p->err->field, "%s", p->path);
            va_start(ap, fmt);
            vsnprintf(p->err->message, sizeof p->err->message, fmt, ap);
            va_end(ap);
        }
    }
    return -1;
}

/* Appends `.key` (or `key` at the root) and returns the old length for pop(). */
static size_t push(pctx *p, const char *key)
{
    size_t old = p->plen;
    int n = snprintf(p->path + p->plen, sizeof p->path - p->plen, "%s%s", p->plen ? "." : "", key);
    if (n > 0)
        p->plen = strlen(p->path);
    return old;
}

static size_t push_index(pctx *p, size_t i)
{
    size_t old = p->plen;
    snprintf(p->path + p->plen, sizeof p->path - p->plen, "[%zu]", i);
    p->plen = strlen(p->path);
    return old;
}

static void pop(pctx *p, size_t old)
{
    p->plen = old;
    p->path[old] = 0;
}

static const char *type_name(const json_t *v)
{
    switch (json_typeof(v)) {
    case JSON_OBJECT: return "an object";
    case JSON_ARRAY: return "an array";
    case JSON_STRING: return "a string";
    case JSON_INTEGER: return "an integer";
    case JSON_REAL: return "a number";
    case JSON_TRUE:
    case JSON_FALSE: return "a boolean";
    default: return "null";
    }
}

/* Refuses keys of obj not in the NULL-terminated list. */
static int check_keys(pctx *p, json_t *obj, const char *const *allowed)
{
    const char *key;
    json_t *val;
    int rc = 0;
    json_object_foreach(obj, key, val) {
        int ok = 0;
        for (const char *const *a = allowed; *a && !ok; a++)
            ok = !strcmp(key, *a);
        if (!ok) {
            size_t old = push(p, key);
            rc = fail(p, TD_EINVAL, "unknown key");
            pop(p, old);
            break;
        }
    }
    return rc;
}

/* Value -> double, from a JSON number or (query) text. */
static int as_number(pctx *p, json_t *v, double *out)
{
    int rc = 0;
    if (json_is_number(v)) {
        *out = json_number_value(v);
    } else if (p->query && json_is_string(v)) {
        const char *s = json_string_value(v);
        char *end = NULL;
        errno = 0;
        *out = strtod(s, &end);
        if (!*s || isspace((unsigned char)*s) || *end || errno == ERANGE)
            rc = fail(p, TD_EFORMAT, "'%.40s' is not a number", s);
    } else {
        rc = fail(p, TD_EINVAL, "expected a number, got %s", type_name(v));
    }
    if (!rc && !isfinite(*out))
        rc = fail(p, TD_ERANGE, "must be a finite number");
    return rc;
}

static int num(pctx *p, json_t *parent, const char *key, double lo, double hi, double *out)
{
    int rc = 0;
    json_t *v = json_object_get(parent, key);
    if (v) {
        size_t old = push(p, key);
        double d = 0.0;
        rc = as_number(p, v, &d);
        if (!rc && !(d >= lo && d <= hi))
            rc = fail(p, TD_ERANGE, "%g is outside %g .. %g", d, lo, hi);
        if (!rc) {
            *out = d;
            rc = 1;
        }
        pop(p, old);
    }
    return rc;
}

static int integer(pctx *p, json_t *parent, const char *key, long long lo, long long hi,
                   long long *out)
{
    int rc = 0;
    json_t *v = json_object_get(parent, key);
    if (v) {
        size_t old = push(p, key);
        long long n = 0;
        if (json_is_integer(v)) {
            n = json_integer_value(v);
        } else if (p->query && json_is_string(v)) {
            const char *s = json_string_value(v);
            char *end = NULL;
            errno = 0;
            n = strtoll(s, &end, 10);
            if (!*s || isspace((unsigned char)*s) || *end || errno == ERANGE)
                rc = fail(p, TD_EFORMAT, "'%.40s' is not an integer", s);
        } else {
            rc = fail(p, TD_EINVAL, "expected an integer, got %s", type_name(v));
        }
        if (!rc && !(n >= lo && n <= hi))
            rc = fail(p, TD_ERANGE, "%lld is outside %lld .. %lld", n, lo, hi);
        if (!rc) {
            *out = n;
            rc = 1;
        }
        pop(p, old);
    }
    return rc;
}

static int as_bool(pctx *p, json_t *v, int *out)
{
    int rc = 0;
    if (json_is_boolean(v)) {
        *out = json_is_true(v);
    } else if (p->query && json_is_string(v)) {
        const char *s = json_string_value(v);
        if (!strcmp(s, "true") || !strcmp(s, "1"))
            *out = 1;
        else if (!strcmp(s, "false") || !strcmp(s, "0"))
            *out = 0;
        else
            rc = fail(p, TD_EFORMAT, "'%.40s' is not true or false", s);
    } else {
        rc = fail(p, TD_EINVAL, "expected a boolean, got %s", type_name(v));
    }
    return rc;
}

static int boolean(pctx *p, json_t *parent, const char *key, int *out)
{
    int rc = 0;
    json_t *v = json_object_get(parent, key);
    if (v) {
        size_t old = push(p, key);
        rc = as_bool(p, v, out);
        if (!rc)
            rc = 1;
        pop(p, old);
    }
    return rc;
}

static int string(pctx *p, json_t *parent, const char *key, const char **out)
{
    int rc = 0;
    json_t *v = json_object_get(parent, key);
    if (v) {
        size_t old = push(p, key);
        if (!json_is_string(v))
            rc = fail(p, TD_EINVAL, "expected a string, got %s", type_name(v));
        else if (strlen(json_string_value(v)) != json_string_length(v))
            rc = fail(p, TD_EFORMAT, "contains a NUL character");
        if (!rc) {
            *out = json_string_value(v);
            rc = 1;
        }
        pop(p, old);
    }
    return rc;
}

/* An object member: 0 absent, 1 present (an object), -1 error. */
static int object(pctx *p, json_t *parent, const char *key, json_t **out)
{
    int rc = 0;
    json_t *v = json_object_get(parent, key);
    if (v) {
        size_t old = push(p, key);
        if (!json_is_object(v))
            rc = fail(p, TD_EINVAL, "expected an object, got %s", type_name(v));
        else
            rc = 1;
        *out = v;
        pop(p, old);
    }
    return rc;
}

static int id_valid(const char *s)
{
    int ok = s[0] != 0 && s[0] != '.';
    for (const char *c = s; *c && ok; c++)
        ok = isalnum((unsigned char)*c) || *c == '_' || *c == '.' || *c == '-';
    return ok;
}

static int name_or_path(pctx *p, json_t *parent, const char *key, char *dst, size_t cap,
                        int required)
{
    const char *s = NULL;
    int rc = string(p, parent, key, &s);
    size_t old = push(p, key);
    if (rc == 0 && required)
        rc = fail(p, TD_EINVAL, "required");
    if (rc == 1) {
        if (!s[0])
            rc = fail(p, TD_EINVAL, "must not be empty");
        else if (strlen(s) >= cap)
            rc = fail(p, TD_ETOOBIG, "longer than %zu characters", cap - 1);
        else if (!p->lim->allow_paths && !id_valid(s))
            rc = fail(p, TD_EINVAL, "'%.40s' is not a valid id ([A-Za-z0-9_.-], not starting with '.')", s);
        else
            snprintf(dst, cap, "%s", s);
    }
    pop(p, old);
    return rc;
}

#define TD_ANGLE 360.0
#define TD_COORD 1e9

static int parse_position(pctx *p, json_t *pos, td_scene_camera *c)
{
    static const char *const keys[] = {"x", "y", "z", "lon", "lat", "alt", "agl", NULL};
    int rc = check_keys(p, pos, keys);
    int hx = 0, hy = 0, hz = 0, hlon = 0, hlat = 0, halt = 0, hagl = 0;
    if (!rc && (hx = num(p, pos, "x", -TD_COORD, TD_COORD, &c->x)) < 0)
        rc = -1;
    if (!rc && (hy = num(p, pos, "y", -TD_COORD, TD_COORD, &c->y)) < 0)
        rc = -1;
    if (!rc && (hz = num(p, pos, "z", -1e5, 1e8, &c->z)) < 0)
        rc = -1;
    if (!rc && (hlon = num(p, pos, "lon", -180.0, 180.0, &c->lon)) < 0)
        rc = -1;
    if (!rc && (hlat = num(p, pos, "lat", -90.0, 90.0, &c->lat)) < 0)
        rc = -1;
    if (!rc && (halt = num(p, pos, "alt", -1e5, 1e8, &c->alt)) < 0)
        rc = -1;
    if (!rc && (hagl = num(p, pos, "agl", 0.0, 1e8, &c->agl)) < 0)
        rc = -1;
    if (!rc) {
        int frame = hx || hy, geo = hlon || hlat;
        if (frame && geo)
            rc = fail(p, TD_EINVAL, "give either x, y or lon, lat, not both");
        else if (!frame && !geo)
            rc = fail(p, TD_EINVAL, "needs x, y (dataset frame) or lon, lat");
        else if (frame && !(hx && hy))
            rc = fail(p, TD_EINVAL, "needs both x and y");
        else if (geo && !(hlon && hlat))
            rc = fail(p, TD_EINVAL, "needs both lon and lat");
        else if ((hz != 0) + (halt != 0) + (hagl != 0) != 1)
            rc = fail(p, TD_EINVAL, "needs exactly one height: z, alt or agl");
        else if (frame && halt)
            rc = fail(p, TD_EINVAL, "alt goes with lon, lat; use z with x, y");
        else if (geo && hz)
            rc = fail(p, TD_EINVAL, "z goes with x, y; use alt with lon, lat");
        else if (frame)
            c->pos_kind = hz ? TD_POS_XYZ : TD_POS_XY_AGL;
        else
            c->pos_kind = halt ? TD_POS_LONLAT_ALT : TD_POS_LONLAT_AGL;
    }
    return rc;
}

static int parse_extent(pctx *p, json_t *cam, td_scene_camera *c)
{
    int rc = 0;
    json_t *v = json_object_get(cam, "extent");
    if (v) {
        size_t old = push(p, "extent");
        if (p->query && json_is_string(v)) {
            const char *s = json_string_value(v);
            double e[4];
            int used = 0;
            if (sscanf(s, "%lf,%lf,%lf,%lf%n", &e[0], &e[1], &e[2], &e[3], &used) != 4 ||
                s[used] != 0)
                rc = fail(p, TD_EFORMAT, "expected xmin,ymin,xmax,ymax");
            for (int k = 0; k < 4 && !rc; k++) {
                if (!isfinite(e[k]) || fabs(e[k]) > TD_COORD)
                    rc = fail(p, TD_ERANGE, "coordinates must be finite and within 1e9");
                c->extent[k] = e[k];
            }
        } else if (!json_is_array(v) || json_array_size(v) != 4) {
            rc = fail(p, TD_EINVAL, "expected an array [xmin, ymin, xmax, ymax]");
        } else {
            for (size_t k = 0; k < 4 && !rc; k++) {
                size_t o2 = push_index(p, k);
                double d = 0.0;
                rc = as_number(p, json_array_get(v, k), &d);
                if (!rc && fabs(d) > TD_COORD)
                    rc = fail(p, TD_ERANGE, "%g is outside -1e9 .. 1e9", d);
                c->extent[k] = d;
                pop(p, o2);
            }
        }
        if (!rc && !(c->extent[2] > c->extent[0] && c->extent[3] > c->extent[1]))
            rc = fail(p, TD_ERANGE, "xmax must exceed xmin and ymax ymin");
        pop(p, old);
    }
    return rc;
}

static int parse_camera(pctx *p, json_t *cam, td_scene_camera *c)
{
    static const char *const keys[] = {"position", "heading", "pitch", "roll", "fov", "fov_v",
                                       "projection", "tilt", "swing", "azimuth", "focal_mm",
                                       "pixel_mm", "extent", NULL};
    int rc = check_keys(p, cam, keys);
    json_t *pos = NULL;
    const char *proj = NULL;
    int r, pinhole = 0, photo = 0;
    if (!rc && (r = string(p, cam, "projection", &proj)) < 0)
        rc = -1;
    if (!rc && proj) {
        size_t old = push(p, "projection");
        if (td_projection_parse(proj, &c->projection))
            rc = fail(p, TD_EINVAL, "'%.40s' is not perspective, orthographic or cylindrical", proj);
        pop(p, old);
    }
    if (!rc && (r = object(p, cam, "position", &pos)) < 0)
        rc = -1;
    if (!rc && r == 1) {
        size_t old = push(p, "position");
        rc = parse_position(p, pos, c);
        pop(p, old);
    } else if (!rc && c->projection != TD_PROJ_ORTHOGRAPHIC) {
        size_t old = push(p, "position");
        rc = fail(p, TD_EINVAL, "required");
        pop(p, old);
    }
    struct {
        const char *key;
        double lo, hi;
        double *dst;
        int *flag;
    } nums[] = {
        {"heading", -TD_ANGLE, TD_ANGLE, &c->heading, &pinhole},
        {"pitch", -90.0, 90.0, &c->pitch, &pinhole},
        {"roll", -180.0, 180.0, &c->roll, &pinhole},
        /* a panorama (cylindrical) may go round: 360 degrees */
        {"fov", 0.01, c->projection == TD_PROJ_CYLINDRICAL ? 360.0 : 179.0, &c->fov, &pinhole},
        {"fov_v", 0.01, 170.0, &c->fov_v, &pinhole},
        {"tilt", 0.0, 180.0, &c->tilt, &photo},
        {"swing", -TD_ANGLE, TD_ANGLE, &c->swing, &photo},
        {"azimuth", -TD_ANGLE, TD_ANGLE, &c->azimuth, &photo},
        {"focal_mm", 0.001, 1e5, &c->focal_mm, &photo},
        {"pixel_mm", 1e-6, 100.0, &c->pixel_mm, &photo},
    };
    for (size_t i = 0; i < sizeof nums / sizeof nums[0] && !rc; i++) {
        r = num(p, cam, nums[i].key, nums[i].lo, nums[i].hi, nums[i].dst);
        if (r < 0)
            rc = -1;
        else if (r)
            *nums[i].flag = 1;
    }
    if (!rc && pinhole && photo)
        rc = fail(p, TD_EINVAL,
                  "heading/pitch/roll/fov and tilt/swing/azimuth/focal_mm/pixel_mm are two "
                  "cameras: give one");
    c->photogrammetric = photo;
    if (!rc)
        rc = parse_extent(p, cam, c);
    if (!rc && json_object_get(cam, "fov_v") && c->projection != TD_PROJ_CYLINDRICAL) {
        size_t old = push(p, "fov_v");
        rc = fail(p, TD_EINVAL, "only for projection cylindrical");
        pop(p, old);
    }
    if (!rc && json_object_get(cam, "extent") && c->projection != TD_PROJ_ORTHOGRAPHIC) {
        size_t old = push(p, "extent");
        rc = fail(p, TD_EINVAL, "only for projection orthographic");
        pop(p, old);
    }
    return rc;
}

static int parse_image(pctx *p, json_t *img, td_scene *s)
{
    static const char *const keys[] = {"width", "height", "format", "depth_scale", NULL};
    int rc = check_keys(p, img, keys);
    long long w = s->image.width, h = s->image.height;
    const char *fmt = NULL;
    if (!rc && integer(p, img, "width", (long long)lim_min(TD_LIMIT_WIDTH), p->lim->max_width,
                       &w) < 0)
        rc = -1;
    if (!rc && integer(p, img, "height", (long long)lim_min(TD_LIMIT_HEIGHT), p->lim->max_height,
                       &h) < 0)
        rc = -1;
    if (!rc && string(p, img, "format", &fmt) < 0)
        rc = -1;
    if (!rc && fmt) {
        size_t old = push(p, "format");
        if (td_format_parse(fmt, &s->image.format))
            rc = fail(p, TD_EINVAL, "'%.40s' is not png, depth16, depth32f or pick", fmt);
        pop(p, old);
    }
    if (!rc && num(p, img, "depth_scale", 1e-6, 1e6, &s->image.depth_scale) < 0)
        rc = -1;
    s->image.width = (int32_t)w;
    s->image.height = (int32_t)h;
    return rc;
}

static int parse_quality(pctx *p, json_t *q, td_scene *s)
{
    static const char *const keys[] = {"method", "surface", "samples", "lod", "lod_grid",
                                       "smooth_normals", NULL};
    int rc = check_keys(p, q, keys);
    const char *m = NULL, *sf = NULL, *lg = NULL;
    long long n = s->quality.samples;
    if (!rc && string(p, q, "method", &m) < 0)
        rc = -1;
    if (!rc && m) {
        size_t old = push(p, "method");
        if (td_method_parse(m, &s->quality.method))
            rc = fail(p, TD_EINVAL, "'%.40s' is not incremental, hierarchical, parametric, silhouette or auto", m);
        pop(p, old);
    }
    if (!rc && string(p, q, "surface", &sf) < 0)
        rc = -1;
    if (!rc && sf) {
        size_t old = push(p, "surface");
        if (td_surface_parse(sf, &s->quality.surface))
            rc = fail(p, TD_EINVAL, "'%.40s' is not plane, linear, triangle or bilinear", sf);
        pop(p, old);
    }
    if (!rc && integer(p, q, "samples", (long long)lim_min(TD_LIMIT_SAMPLES), p->lim->max_samples,
                       &n) < 0)
        rc = -1;
    s->quality.samples = (int)n;
    /* lod: true/false, or a number: pixels one coarse cell may span */
    if (!rc && json_is_number(json_object_get(q, "lod"))) {
        if (num(p, q, "lod", lim_min(TD_LIMIT_LOD_PIXELS), lim_api(TD_LIMIT_LOD_PIXELS),
                &s->quality.lod_pixels) < 0)
            rc = -1;
        s->quality.lod = 1;
    } else if (!rc && boolean(p, q, "lod", &s->quality.lod) < 0) {
        rc = -1;
    }
    if (!rc && string(p, q, "lod_grid", &lg) < 0)
        rc = -1;
    if (!rc && lg) {
        size_t old = push(p, "lod_grid");
        td_lod_grid g;
        if (td_lod_grid_parse(lg, &g))
            rc = fail(p, TD_EINVAL, "'%.40s' is not square or isometric", lg);
        else
            s->quality.lod_grid = (int)g;
        pop(p, old);
    }
    if (!rc && boolean(p, q, "smooth_normals", &s->quality.smooth_normals) < 0)
        rc = -1;
    return rc;
}

/* A member that is either a boolean or an object (object = on); *obj is the object. */
static int bool_or_object(pctx *p, json_t *parent, const char *key, int *on, json_t **obj)
{
    int rc = 0;
    json_t *v = json_object_get(parent, key);
    *obj = NULL;
    if (v) {
        size_t old = push(p, key);
        if (json_is_object(v)) {
            *on = 1;
            *obj = v;
        } else if (json_is_boolean(v) || (p->query && json_is_string(v))) {
            rc = as_bool(p, v, on);
        } else {
            rc = fail(p, TD_EINVAL, "expected a boolean or an object, got %s", type_name(v));
        }
        pop(p, old);
    }
    return rc;
}

/* An effect given as a boolean, or as an object (on) whose one key is a number in
 * [lo, hi], e.g. "haze": {"visibility_km": 80}. 0 or 1 as bool_or_object, -1 refused. */
static int switch_number(pctx *p, json_t *fx, const char *effect, int *on, const char *key,
                         double lo, double hi, double *value)
{
    json_t *o = NULL;
    int rc = bool_or_object(p, fx, effect, on, &o);
    if (rc >= 0 && o) {
        const char *const keys[] = {key, NULL};
        size_t old = push(p, effect);
        if (check_keys(p, o, keys) < 0 || num(p, o, key, lo, hi, value) < 0)
            rc = -1;
        pop(p, old);
    }
    return rc;
}

static int parse_effects(pctx *p, json_t *fx, td_scene *s)
{
    static const char *const keys[] = {"sun", "ambient", "shadows", "haze", "sky", "water",
                                       "ambient_occlusion", "curvature", "drape", NULL};
    td_scene_effects *e = &s->effects;
    int rc = check_keys(p, fx, keys);
    json_t *o = NULL;
    size_t old;
    int r;

    if (!rc && (r = object(p, fx, "sun", &o)) < 0)
        rc = -1;
    if (!rc && r == 1) {
        static const char *const k2[] = {"azimuth", "elevation", "time", NULL};
        const char *when = NULL;
        old = push(p, "sun");
        rc = check_keys(p, o, k2);
        if (!rc && (r = string(p, o, "time", &when)) < 0)
            rc = -1;
        if (!rc && when) {
            td_err te;
            size_t at = push(p, "time");
            if (json_object_get(o, "azimuth") || json_object_get(o, "elevation"))
                rc = fail(p, TD_EINVAL, "give either time or azimuth and elevation, not both");
            else if (td_solar_parse_time(when, "time", &e->sun_time_s, &te))
                rc = fail(p, TD_EFORMAT, "%s", te.msg + strlen("time: "));
            else
                e->sun_time = 1;
            pop(p, at);
        }
        if (!rc && num(p, o, "azimuth", -TD_ANGLE, TD_ANGLE, &e->sun_azimuth) < 0)
            rc = -1;
        if (!rc && num(p, o, "elevation", lim_min(TD_LIMIT_SUN_ELEVATION),
                       lim_api(TD_LIMIT_SUN_ELEVATION), &e->sun_elevation) < 0)
            rc = -1;
        pop(p, old);
    }
    if (!rc && num(p, fx, "ambient", lim_min(TD_LIMIT_AMBIENT), lim_api(TD_LIMIT_AMBIENT),
                   &e->ambient) < 0)
        rc = -1;
    if (!rc && boolean(p, fx, "shadows", &e->shadows) < 0)
        rc = -1;
    if (!rc && boolean(p, fx, "sky", &e->sky) < 0)
        rc = -1;
    if (!rc && (switch_number(p, fx, "haze", &e->haze, "visibility_km", lim_min(TD_LIMIT_HAZE_KM),
                              lim_api(TD_LIMIT_HAZE_KM), &e->haze_visibility_km) < 0 ||
                switch_number(p, fx, "water", &e->water, "level", -1e5, 1e5, &e->water_level) < 0 ||
                switch_number(p, fx, "curvature", &e->curvature, "k", lim_min(TD_LIMIT_CURVATURE_K),
                              lim_api(TD_LIMIT_CURVATURE_K), &e->curvature_k) < 0))
        rc = -1;
    /* ambient_occlusion: N, or {"rays": N, "radius": metres} */
    json_t *ao = json_object_get(fx, "ambient_occlusion");
    if (!rc && ao && json_is_object(ao)) {
        static const char *const k2[] = {"rays", "radius", NULL};
        long long n = 8;
        old = push(p, "ambient_occlusion");
        rc = check_keys(p, ao, k2);
        if (!rc && integer(p, ao, "rays", (long long)lim_min(TD_LIMIT_AO_RAYS),
                           p->lim->max_ao_rays, &n) < 0)
            rc = -1;
        if (!rc && num(p, ao, "radius", 0.001, 1e6, &e->ao_radius) < 0)
            rc = -1;
        e->ambient_occlusion = (int)n;
        pop(p, old);
    } else if (!rc && ao) {
        long long n = 0;
        if (integer(p, fx, "ambient_occlusion", (long long)lim_min(TD_LIMIT_AO_RAYS),
                    p->lim->max_ao_rays, &n) < 0)
            rc = -1;
        e->ambient_occlusion = (int)n;
    }
    if (!rc && json_object_get(fx, "drape") &&
        name_or_path(p, fx, "drape", e->drape, sizeof e->drape, 0) < 0)
        rc = -1;
    return rc;
}

static int pick_point(pctx *p, double x, double y, const td_scene *s, size_t i)
{
    int rc = 0;
    size_t old = push_index(p, i);
    if (!(x >= -0.5 && x <= s->image.width - 0.5 && y >= -0.5 && y <= s->image.height - 0.5))
        rc = fail(p, TD_ERANGE, "pixel (%g, %g) is outside the %d x %d image", x, y,
                  (int)s->image.width, (int)s->image.height);
    pop(p, old);
    return rc;
}

static int parse_pick(pctx *p, json_t *root, td_scene *s)
{
    int rc = 0;
    json_t *v = json_object_get(root, "pick");
    if (!v)
        goto out;
    size_t old = push(p, "pick");
    if (p->query && json_is_string(v)) {
        const char *c = json_string_value(v);
        while (*c && !rc) {
            double x, y;
            int used = 0;
            if (s->npick >= p->lim->max_pick || s->npick >= TD_SCENE_PICK_MAX)
                rc = fail(p, TD_ETOOBIG, "more than %d pixels", p->lim->max_pick);
            else if (sscanf(c, "%lf,%lf%n", &x, &y, &used) != 2 || !isfinite(x) || !isfinite(y))
                rc = fail(p, TD_EFORMAT, "expected x,y;x,y;...");
            else if (!(rc = pick_point(p, x, y, s, (size_t)s->npick))) {
                s->pick[s->npick][0] = x;
                s->pick[s->npick][1] = y;
                s->npick++;
                c += used;
                if (*c == ';')
                    c++;
                else if (*c)
                    rc = fail(p, TD_EFORMAT, "expected x,y;x,y;...");
            }
        }
    } else if (!json_is_array(v)) {
        rc = fail(p, TD_EINVAL, "expected an array of [x, y] pixels, got %s", type_name(v));
    } else if (json_array_size(v) > (size_t)p->lim->max_pick ||
               json_array_size(v) > TD_SCENE_PICK_MAX) {
        rc = fail(p, TD_ETOOBIG, "%zu pixels is more than %d", json_array_size(v), p->lim->max_pick);
    } else {
        for (size_t i = 0; i < json_array_size(v) && !rc; i++) {
            json_t *pt = json_array_get(v, i);
            size_t o2 = push_index(p, i);
            double xy[2] = {0.0, 0.0};
            if (!json_is_array(pt) || json_array_size(pt) != 2)
                rc = fail(p, TD_EINVAL, "expected [x, y]");
            for (size_t k = 0; k < 2 && !rc; k++) {
                size_t o3 = push_index(p, k);
                rc = as_number(p, json_array_get(pt, k), &xy[k]);
                pop(p, o3);
            }
            pop(p, o2);
            if (!rc)
                rc = pick_point(p, xy[0], xy[1], s, i);
            s->pick[i][0] = xy[0];
            s->pick[i][1] = xy[1];
        }
        s->npick = (int)json_array_size(v);
    }
    pop(p, old);
out:
    return rc;
}

/* An optional object member parsed by `parse` with the member's name on the field path:
 * 0 when absent, 1 when parsed, -1 (and the error recorded) when refused. */
static int member(pctx *p, json_t *root, const char *key,
                  int (*parse)(pctx *, json_t *, td_scene *), td_scene *s)
{
    json_t *o = NULL;
    int r = object(p, root, key, &o);
    if (r == 1) {
        size_t old = push(p, key);
        r = parse(p, o, s) < 0 ? -1 : 1;
        pop(p, old);
    }
    return r;
}

static td_status walk(pctx *p, json_t *root, td_scene *s)
{
    static const char *const keys[] = {"dataset", "camera", "image", "quality", "effects",
                                       "pick", NULL};
    json_t *o = NULL;
    size_t old;
    int r;

    td_scene_defaults(s);
    if (p->pick)
        s->image.format = TD_FORMAT_PICK;
    if (!json_is_object(root)) {
        fail(p, TD_EINVAL, "the scene must be a JSON object, got %s", type_name(root));
        goto out;
    }
    if (check_keys(p, root, keys) < 0)
        goto out;
    if (name_or_path(p, root, "dataset", s->dataset, sizeof s->dataset, 1) < 0)
        goto out;
    /* image first: pick pixels are checked against its size */
    if (member(p, root, "image", parse_image, s) < 0)
        goto out;
    if ((r = object(p, root, "camera", &o)) < 0)
        goto out;
    old = push(p, "camera");
    r = r == 1 ? parse_camera(p, o, &s->camera) : fail(p, TD_EINVAL, "required");
    pop(p, old);
    if (r < 0)
        goto out;
    /* a panorama sees far: curvature and refraction on unless effects.curvature says no */
    s->effects.curvature = s->camera.projection == TD_PROJ_CYLINDRICAL;
    if (member(p, root, "quality", parse_quality, s) < 0 ||
        member(p, root, "effects", parse_effects, s) < 0)
        goto out;
    if (parse_pick(p, root, s) < 0)
        goto out;

    /* whole-scene limits */
    uint64_t px = (uint64_t)s->image.width * (uint64_t)s->image.height;
    uint64_t n2 = (uint64_t)s->quality.samples * (uint64_t)s->quality.samples;
    if (px > p->lim->max_pixels) {
        old = push(p, "image");
        fail(p, TD_ETOOBIG, "%d x %d pixels exceeds the limit of %llu", (int)s->image.width,
             (int)s->image.height, (unsigned long long)p->lim->max_pixels);
        pop(p, old);
    } else if (px * n2 > p->lim->max_samples_total) {
        old = push(p, "quality");
        push(p, "samples");
        fail(p, TD_ETOOBIG, "%d x %d samples per pixel over %llu pixels exceeds the limit of %llu",
             s->quality.samples, s->quality.samples, (unsigned long long)px,
             (unsigned long long)p->lim->max_samples_total);
        pop(p, old);
    } else if (s->image.format == TD_FORMAT_PICK && s->npick == 0) {
        old = push(p, "pick");
        fail(p, TD_EINVAL, "format pick needs a list of pixels");
        pop(p, old);
    } else if (s->image.format != TD_FORMAT_PICK && s->npick > 0) {
        old = push(p, "pick");
        fail(p, TD_EINVAL, "pixels to pick need image.format pick");
        pop(p, old);
    }
out:
    return p->rc;
}

/* Path of the key being read at byte `pos` of a JSON text: a small scanner that tracks
 * objects, arrays, keys and indices (enough for jansson's error positions). */
static void locate(const char *s, size_t len, size_t pos, char *out, size_t cap)
{
    enum { MAXD = 16 };
    struct frame {
        int obj;
        int expect_key;
        size_t index;
        char key[48];
    } st[MAXD];
    int depth = 0;
    size_t i = 0;
    if (pos > len)
        pos = len;
    while (i < pos) {
        char ch = s[i];
        if (ch == '"') {
            char buf[48];
            size_t n = 0;
            i++;
            while (i < len && s[i] != '"') {
                if (s[i] == '\\' && i + 1 < len)
                    i++;
                if (n + 1 < sizeof buf)
                    buf[n++] = s[i];
                i++;
            }
            buf[n] = 0;
            if (depth > 0 && depth <= MAXD && st[depth - 1].obj && st[depth - 1].expect_key) {
                snprintf(st[depth - 1].key, sizeof st[depth - 1].key, "%s", buf);
                st[depth - 1].expect_key = 0;
            }
        } else if (ch == '{' || ch == '[') {
            if (depth < MAXD) {
                st[depth].obj = ch == '{';
                st[depth].expect_key = ch == '{';
                st[depth].index = 0;
                st[depth].key[0] = 0;
            }
            depth++;
        } else if (ch == '}' || ch == ']') {
            if (depth > 0)
                depth--;
        } else if (ch == ',' && depth > 0 && depth <= MAXD) {
            if (st[depth - 1].obj) {
                st[depth - 1].expect_key = 1;
                st[depth - 1].key[0] = 0;
            } else {
                st[depth - 1].index++;
            }
        }
        i++;
    }
    size_t n = 0;
    out[0] = 0;
    for (int d = 0; d < depth && d < MAXD; d++) {
        int w;
        if (st[d].obj) {
            if (!st[d].key[0])
                break;
            w = snprintf(out + n, cap - n, "%s%s", n ? "." : "", st[d].key);
        } else {
            w = snprintf(out + n, cap - n, "[%zu]", st[d].index);
        }
        if (w < 0 || (size_t)w >= cap - n)
            break;
        n += (size_t)w;
    }
}

static td_status parse_text(const char *body, size_t len, const td_request_limits *lim, int pick,
                            td_scene *out, td_request_error *err)
{
    pctx p;
    json_error_t je;
    td_request_limits dflt;
    json_t *root = NULL;

    memset(&p, 0, sizeof p);
    if (!lim) {
        td_request_limits_default(&dflt);
        lim = &dflt;
    }
    p.lim = lim;
    p.err = err;
    p.pick = pick;
    if (err)
        err->field[0] = err->message[0] = 0;
    root = json_loadb(body, len, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        int dup = strstr(je.text, "duplicate") != NULL;
        locate(body, len, (size_t)(je.position > 0 ? je.position : 0), p.path, sizeof p.path);
        p.plen = strlen(p.path);
        fail(&p, dup ? TD_EINVAL : TD_EFORMAT, "%s (line %d, column %d)", je.text, je.line,
             je.column);
        goto out;
    }
    walk(&p, root, out);
out:
    json_decref(root);
    return p.rc;
}

td_status td_request_parse_scene(const char *body, size_t len, const td_request_limits *lim,
                                 td_scene *out, td_request_error *err)
{
    return parse_text(body, len, lim, 0, out, err);
}

td_status td_request_parse_pick(const char *body, size_t len, const td_request_limits *lim,
                                td_scene *out, td_request_error *err)
{
    return parse_text(body, len, lim, 1, out, err);
}

td_status td_request_parse_query(const char *const *keys, const char *const *values, size_t n,
                                 const td_request_limits *lim, td_scene *out,
                                 td_request_error *err)
{
    pctx p;
    td_request_limits dflt;
    json_t *root = json_object();

    memset(&p, 0, sizeof p);
    if (!lim) {
        td_request_limits_default(&dflt);
        lim = &dflt;
    }
    p.lim = lim;
    p.err = err;
    p.query = 1;
    if (err)
        err->field[0] = err->message[0] = 0;
    if (!root) {
        fail(&p, TD_ENOMEM, "no memory");
        goto out;
    }
    for (size_t i = 0; i < n && !p.rc; i++) {
        const char *k = keys[i], *v = values[i] ? values[i] : "";
        json_t *node = root;
        char part[64];
        snprintf(p.path, sizeof p.path, "%s", k);
        p.plen = strlen(p.path);
        if (strlen(k) >= sizeof p.path || !*k) {
            fail(&p, TD_EINVAL, "bad parameter name");
            break;
        }
        /* walk/create the objects of the dotted path; the last part holds the value */
        const char *c = k;
        while (!p.rc) {
            const char *dot = strchr(c, '.');
            size_t l = dot ? (size_t)(dot - c) : strlen(c);
            if (l == 0 || l >= sizeof part) {
                fail(&p, TD_EINVAL, "bad parameter name");
                break;
            }
            memcpy(part, c, l);
            part[l] = 0;
            json_t *child = json_object_get(node, part);
            if (!dot) {
                if (child)
                    fail(&p, TD_EINVAL, "given twice");
                else if (json_object_set_new(node, part, json_string(v)))
                    fail(&p, TD_EFORMAT, "not valid UTF-8");
                break;
            }
            if (!child) {
                child = json_object();
                if (!child || json_object_set_new(node, part, child)) {
                    fail(&p, TD_ENOMEM, "no memory");
                    break;
                }
            } else if (!json_is_object(child)) {
                fail(&p, TD_EINVAL, "given both as a value and as an object");
                break;
            }
            node = child;
            c = dot + 1;
        }
    }
    if (!p.rc) {
        p.path[0] = 0;
        p.plen = 0;
        walk(&p, root, out);
    }
out:
    json_decref(root);
    return p.rc;
}
