/* viewshed.c: POST /v1/viewshed and POST /v1/los (docs/api.md), and the answers that
 * `terrad viewshed` shares with them. routes.c's table points here (two rows); the
 * computation is core/viewshed.c's.
 *
 * As a render: the handler parses and checks the body on the HTTP thread (400 naming
 * the field; the dataset resolved to a tile-store snapshot, 404 when unknown), then the
 * work goes to the HTTP layer's worker queue (503 + Retry-After when full) and polls the
 * worker's cancel flag (--render-timeout). What needs the grid (lon/lat, an observer
 * outside the grid or over a void) is refused by the worker, still with a 400 and the
 * field. One thread a viewshed: the workers use the cores.
 *
 *   viewshed body: {"dataset", "observer": {"x","y"} | {"lon","lat"}, or "observers":
 *     [...], "height", "target_height", "max_distance", "curvature": true | {"k"},
 *     "surface", "method", "format": "png" | "json"}
 *   los body: {"dataset", "from": {"x","y" | "lon","lat", "height"}, "to": {...},
 *     "curvature", "surface", "method"} */
#include "viewshed_api.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "limit.h"
#include "bigalloc.h"

/* ---- answers -------------------------------------------------------------------------- */

td_status td_vs_encode(const td_grid *g, int nobs, uint8_t *counts, td_buf *out, td_err *err)
{
    if (nobs == 1)
        td_viewshed_gray(counts, (size_t)g->w * (size_t)g->h, counts);
    return td_image_encode_gray8(counts, g->w, g->h, out, err);
}

json_t *td_vs_answer(const char *dataset, const td_grid *g, const td_viewshed_opts *o,
                     const td_viewshed_stats *st, const uint8_t *counts)
{
    json_t *seen_by = json_array(), *obs = json_array();
    uint64_t hist[TD_VS_MAX_OBSERVERS + 1] = {0};
    size_t n = (size_t)g->w * (size_t)g->h;
    if (o->nobs == 1) { /* the counts are 0 or 1: st has them (no pass over the picture) */
        hist[1] = st->visible;
        hist[0] = st->inside - st->visible;
    }
    for (size_t k = 0; k < n && o->nobs > 1; k++)
        if (counts[k] != TD_VS_OUTSIDE)
            hist[counts[k]]++;
    for (int k = 0; k <= o->nobs; k++)
        json_array_append_new(seen_by, json_integer((json_int_t)hist[k]));
    for (int k = 0; k < o->nobs; k++)
        json_array_append_new(obs, json_pack("{s:f,s:f}", "x", o->obs[k].x, "y", o->obs[k].y));
    return json_pack("{s:s,s:i,s:i,s:o,s:f,s:f,s:o?,s:b,s:f,s:s,s:s,s:I,s:I,s:I,s:I,s:I,s:f,s:f,"
                     "s:o,s:I,s:I,s:I,s:f,s:{s:f,s:f},s:i}",
                     "dataset", dataset, "grid_width", (int)g->w, "grid_height", (int)g->h, "observers", obs,
                     "eye_height", o->height, "target_height", o->target_height, "max_distance",
                     isfinite(o->max_distance) ? json_real(o->max_distance) : NULL, "curvature",
                     o->curvature, "k", o->curvature ? o->k : 0.0, "surface", td_surface_name(o->surface),
                     "method", td_method_name(o->method), "samples", (json_int_t)st->samples,
                     "inside", (json_int_t)st->inside, "visible", (json_int_t)st->visible, "hidden",
                     (json_int_t)(st->inside - st->visible), "outside",
                     (json_int_t)(st->samples - st->inside), "visible_fraction",
                     st->inside ? (double)st->visible / (double)st->inside : 0.0, "visible_area_m2",
                     st->visible_area_m2, "seen_by", seen_by, "swept", (json_int_t)st->swept, "rays",
                     (json_int_t)st->rays, "steps",
                     (json_int_t)st->steps, "mean_steps", st->rays ? (double)st->steps / (double)st->rays : 0.0,
                     "timings_ms", "setup", st->setup_ms, "trace", st->trace_ms, "threads", st->threads);
}

static json_t *point3(const double p[3])
{
    return json_pack("{s:f,s:f,s:f}", "x", p[0], "y", p[1], "z", p[2]);
}

json_t *td_los_answer(const char *dataset, const td_los_opts *o, const td_los_result *r)
{
    json_t *prof = json_array();
    json_t *block = r->visible ? json_null()
                               : json_pack("{s:o,s:f,s:f}", "point", point3(r->block), "distance",
                                           r->block_s, "distance_3d", r->block_dist);
    for (int k = 0; k < r->nprofile; k++) {
        const td_los_point *p = &r->profile[k];
        json_array_append_new(prof, json_pack("[f,o,f]", p->s, isnan(p->ground) ? json_null() : json_real(p->ground),
                                              p->line));
    }
    return json_pack("{s:s,s:b,s:o,s:o,s:f,s:o,s:b,s:f,s:s,s:s,s:i,s:o}", "dataset", dataset, "visible",
                     r->visible, "from", point3(r->eye_a), "to", point3(r->eye_b), "distance", r->distance,
                     "blocked_at", block, "curvature", o->curvature, "k", o->curvature ? o->k : 0.0,
                     "surface", td_surface_name(o->surface), "method", td_method_name(o->method), "steps",
                     (int)r->steps, "profile", prof);
}

/* ---- requests ------------------------------------------------------------------------- */

/* A point of a request: x, y in the dataset frame, or lon, lat to resolve on the grid. */
typedef struct vs_pt {
    double a, b, h;
    int geo;
    char field[24];
} vs_pt;

typedef struct vs_req {
    int los;
    int json; /* format */
    char dataset[TD_SCENE_DATASET_MAX];
    vs_pt pts[TD_VS_MAX_OBSERVERS];
    int npts;
    td_viewshed_opts o; /* height, target_height, max_distance, curvature, k, surface, method */
} vs_req;

/* Refuses keys of obj not in allowed, naming prefix + key. */
static td_status keys_known(json_t *obj, const char *const *allowed, const char *prefix, td_err *err)
{
    td_status rc = TD_OK;
    const char *key;
    json_t *val;
    json_object_foreach(obj, key, val) {
        int ok = 0;
        for (int k = 0; allowed[k] && !ok; k++)
            ok = !strcmp(key, allowed[k]);
        if (!ok && !rc) {
            char f[64];
            snprintf(f, sizeof f, "%s%.40s", prefix, key);
            rc = td_err_field(err, TD_EINVAL, f, "unknown key");
        }
    }
    (void)val;
    return rc;
}

/* obj[key] as a number in [lo, hi] (absent: *out unchanged, *had 0). */
static td_status number(json_t *obj, const char *key, const char *field, double lo, double hi,
                        double *out, int *had, td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(obj, key);
    if (had)
        *had = v != NULL;
    if (v && !json_is_number(v))
        rc = td_err_field(err, TD_EINVAL, field, "must be a number");
    else if (v && !(json_number_value(v) >= lo && json_number_value(v) <= hi))
        rc = td_err_field(err, TD_ERANGE, field, "%g is outside %g .. %g", json_number_value(v), lo, hi);
    else if (v)
        *out = json_number_value(v);
    return rc;
}

/* {"x","y"} or {"lon","lat"} (and "height" in a line of sight's ends) at field. */
static td_status parse_pt(json_t *v, const char *field, int with_height, vs_pt *p, td_err *err)
{
    static const char *const keys[] = {"x", "y", "lon", "lat", "height", NULL};
    const td_limit_row *hr = td_vs_limit_get(TD_VS_LIMIT_HEIGHT);
    char f[64];
    int hx = 0, hy = 0, hlon = 0, hlat = 0;
    td_status rc = TD_OK;
    snprintf(p->field, sizeof p->field, "%s", field);
    snprintf(f, sizeof f, "%s.", field);
    if (!json_is_object(v))
        rc = td_err_field(err, TD_EINVAL, field, "must be an object {\"x\", \"y\"} or {\"lon\", \"lat\"}");
    if (!rc)
        rc = keys_known(v, with_height ? keys : (const char *const[]){"x", "y", "lon", "lat", NULL}, f, err);
    if (!rc)
        rc = number(v, "x", field, -1e9, 1e9, &p->a, &hx, err);
    if (!rc)
        rc = number(v, "y", field, -1e9, 1e9, &p->b, &hy, err);
    if (!rc && !hx && !hy)
        rc = number(v, "lon", field, -180, 180, &p->a, &hlon, err);
    if (!rc && !hx && !hy)
        rc = number(v, "lat", field, -90, 90, &p->b, &hlat, err);
    snprintf(f, sizeof f, "%s.height", field);
    if (!rc && with_height)
        rc = number(v, "height", f, hr->min, hr->api_max, &p->h, NULL, err);
    if (!rc && (hx || hy) && (json_object_get(v, "lon") || json_object_get(v, "lat")))
        rc = td_err_field(err, TD_EINVAL, field, "give x, y or lon, lat, not both");
    if (!rc && !((hx && hy) || (hlon && hlat)))
        rc = td_err_field(err, TD_EINVAL, field, "give x, y (dataset frame, metres) or lon, lat");
    p->geo = hlon;
    return rc;
}

/* "curvature": true, false or {"k": ...}; "surface", "method". */
static td_status parse_quality(json_t *root, td_viewshed_opts *o, td_err *err)
{
    const td_limit_row *kr = td_limit_get(TD_LIMIT_CURVATURE_K);
    json_t *c = json_object_get(root, "curvature"), *s = json_object_get(root, "surface"),
           *m = json_object_get(root, "method");
    td_status rc = TD_OK;
    if (c && json_is_boolean(c))
        o->curvature = json_is_true(c);
    else if (c && json_is_object(c)) {
        o->curvature = 1;
        rc = keys_known(c, (const char *const[]){"k", NULL}, "curvature.", err);
        if (!rc)
            rc = number(c, "k", "curvature.k", kr->min, kr->api_max, &o->k, NULL, err);
    } else if (c)
        rc = td_err_field(err, TD_EINVAL, "curvature", "true, false or {\"k\": refraction coefficient}");
    if (!rc && s && (!json_is_string(s) || td_surface_parse(json_string_value(s), &o->surface)))
        rc = td_err_field(err, TD_EINVAL, "surface", "one of plane, linear, triangle, bilinear");
    if (!rc && m && (!json_is_string(m) || td_method_parse(json_string_value(m), &o->method)))
        rc = td_err_field(err, TD_EINVAL, "method", "one of incremental, hierarchical, parametric, auto");
    return rc;
}

/* "observer" or "observers": [...] */
static td_status parse_observers(json_t *root, vs_req *q, td_err *err)
{
    json_t *one = json_object_get(root, "observer"), *many = json_object_get(root, "observers");
    const td_limit_row *lr = td_vs_limit_get(TD_VS_LIMIT_OBSERVERS);
    td_status rc = TD_OK;
    char f[32];
    if (one && many)
        rc = td_err_field(err, TD_EINVAL, "observers", "give observer or observers, not both");
    else if (one)
        rc = parse_pt(one, "observer", 0, &q->pts[0], err);
    else if (!many || !json_is_array(many) || json_array_size(many) < 1)
        rc = td_err_field(err, TD_EINVAL, many ? "observers" : "observer",
                          "required: {\"x\", \"y\"} (or \"observers\": [...], at least one)");
    else if (json_array_size(many) > (size_t)lr->api_max)
        rc = td_err_field(err, TD_ETOOBIG, "observers", "%zu observers: at most %g", json_array_size(many),
                          lr->api_max);
    q->npts = one ? 1 : (int)json_array_size(many);
    for (int k = 0; !rc && !one && k < q->npts; k++) {
        snprintf(f, sizeof f, "observers[%d]", k);
        rc = parse_pt(json_array_get(many, (size_t)k), f, 0, &q->pts[k], err);
    }
    return rc;
}

/* The viewshed body's own fields (dataset and the quality ones are common). */
static td_status parse_viewshed(json_t *root, vs_req *q, td_err *err)
{
    static const char *const keys[] = {"dataset", "observer", "observers", "height", "target_height",
                                       "max_distance", "curvature", "surface", "method", "format", NULL};
    const td_limit_row *hr = td_vs_limit_get(TD_VS_LIMIT_HEIGHT), *tr = td_vs_limit_get(TD_VS_LIMIT_TARGET_HEIGHT);
    json_t *fmt = json_object_get(root, "format");
    int had = 0;
    td_status rc = keys_known(root, keys, "", err);
    if (!rc)
        rc = parse_observers(root, q, err);
    if (!rc)
        rc = number(root, "height", "height", hr->min, hr->api_max, &q->o.height, &had, err);
    if (!rc && !had)
        rc = td_err_field(err, TD_EINVAL, "height", "required: the eye's height above the ground, metres");
    if (!rc)
        rc = number(root, "target_height", "target_height", tr->min, tr->api_max, &q->o.target_height, NULL, err);
    if (!rc)
        rc = number(root, "max_distance", "max_distance", 0, 1e9, &q->o.max_distance, NULL, err);
    if (!rc && !(q->o.max_distance > 0))
        rc = td_err_field(err, TD_ERANGE, "max_distance", "must be > 0 m (leave it out for no limit)");
    if (!rc && fmt && !(json_is_string(fmt) && (!strcmp(json_string_value(fmt), "png") ||
                                                !strcmp(json_string_value(fmt), "json"))))
        rc = td_err_field(err, TD_EINVAL, "format", "png or json");
    q->json = fmt && json_is_string(fmt) && !strcmp(json_string_value(fmt), "json");
    return rc;
}

static td_status parse_los(json_t *root, vs_req *q, td_err *err)
{
    static const char *const keys[] = {"dataset", "from", "to", "curvature", "surface", "method", NULL};
    td_status rc = keys_known(root, keys, "", err);
    q->npts = 2;
    if (!rc)
        rc = parse_pt(json_object_get(root, "from"), "from", 1, &q->pts[0], err);
    if (!rc)
        rc = parse_pt(json_object_get(root, "to"), "to", 1, &q->pts[1], err);
    return rc;
}

/* ---- the work --------------------------------------------------------------------------- */

typedef struct vs_job {
    td_json_job h; /* first: app, snapshot, parse time (routes.h) */
    vs_req q;
} vs_job;

/* The request's points in the dataset frame (lon/lat resolved on the grid). */
static td_status resolve(const td_grid *g, vs_req *q, td_vs_point *out, td_err *err)
{
    td_status rc = TD_OK;
    for (int k = 0; k < q->npts && !rc; k++) {
        out[k].x = q->pts[k].a;
        out[k].y = q->pts[k].b;
        if (q->pts[k].geo)
            rc = td_vs_from_lonlat(g, q->pts[k].a, q->pts[k].b, q->pts[k].field, &out[k].x, &out[k].y, err);
    }
    return rc;
}

/* A viewshed on the worker: PNG or JSON, and the stages' times in *st. */
static td_status work_viewshed(vs_job *j, td_http_req *hq, td_http_resp *r, td_viewshed_stats *st,
                               double *encode_ms, td_err *e)
{
    const td_view *v = td_snapshot_view(j->h.snap);
    td_vs_point *pts = calloc((size_t)j->q.npts, sizeof *pts);
    uint8_t *counts = td_bigalloc_scratch((size_t)v->grid->w * (size_t)v->grid->h); /* written whole next */
    td_buf png = {0};
    td_status rc = TD_OK;
    double t;
    if (!pts || !counts) {
        rc = td_err_set(e, TD_ENOMEM, "out of memory for the viewshed of a %d x %d grid", (int)v->grid->w,
                        (int)v->grid->h);
        goto out;
    }
    rc = resolve(v->grid, &j->q, pts, e);
    j->q.o.obs = pts;
    j->q.o.nobs = j->q.npts;
    j->q.o.threads = 1; /* one viewshed per worker; the workers use the cores */
    j->q.o.cancel = td_http_req_cancel(hq);
    if (!rc)
        rc = td_viewshed(v, &j->q.o, counts, st, e);
    if (rc)
        goto out;
    t = td_clock_s();
    if (j->q.json) {
        td_routes_json(r, 200, td_vs_answer(j->q.dataset, v->grid, &j->q.o, st, counts));
    } else {
        rc = td_vs_encode(v->grid, j->q.o.nobs, counts, &png, e);
        if (rc)
            goto out;
        r->status = 200;
        td_http_resp_take(r, png.data, png.len, "image/png");
        png.data = NULL;
        td_http_resp_header(r, "X-Terrad-Visible", "%llu", (unsigned long long)st->visible);
        td_http_resp_header(r, "X-Terrad-Visible-Area", "%.1f", st->visible_area_m2);
    }
    *encode_ms = 1e3 * (td_clock_s() - t);
out:
    j->q.o.obs = NULL;
    td_buf_free(&png);
    free(counts);
    free(pts);
    return rc;
}

static td_status work_los(vs_job *j, td_http_resp *r, td_err *e)
{
    const td_view *v = td_snapshot_view(j->h.snap);
    td_los_result *res = malloc(sizeof *res);
    td_vs_point pts[2];
    td_los_opts o;
    td_status rc = TD_OK;
    if (!res) {
        rc = td_err_set(e, TD_ENOMEM, "out of memory");
        goto out;
    }
    td_los_opts_default(&o);
    o.curvature = j->q.o.curvature;
    o.k = j->q.o.k;
    o.surface = j->q.o.surface;
    o.method = j->q.o.method;
    rc = resolve(v->grid, &j->q, pts, e);
    o.a = pts[0];
    o.b = pts[1];
    o.height_a = j->q.pts[0].h;
    o.height_b = j->q.pts[1].h;
    if (!rc)
        rc = td_los(v, &o, res, e);
    if (!rc)
        td_routes_json(r, 200, td_los_answer(j->q.dataset, &o, res));
out:
    free(res);
    return rc;
}

static void vs_work(void *cls, td_http_req *hq, td_http_resp *r, int cancelled)
{
    vs_job *j = cls;
    td_viewshed_stats st;
    td_err e = {0};
    td_status rc = TD_OK;
    double queue_ms = td_http_req_queue_wait(hq) * 1e3, t0 = td_clock_s(), encode_ms = 0;

    memset(&st, 0, sizeof st);
    if (cancelled) {
        td_http_resp_header(r, "Retry-After", "1");
        td_routes_error(r, "stopping", NULL, "the server is stopping");
        goto out;
    }
    rc = j->q.los ? work_los(j, r, &e) : work_viewshed(j, hq, r, &st, &encode_ms, &e);
    if (rc)
        td_routes_work_error(j->h.app, r, rc, &e, "the viewshed");
    else
        td_http_resp_header(r, "Cache-Control", "no-store");
out:
    if (j->q.los)
        td_http_resp_header(r, "Server-Timing", "parse;dur=%.3f, queue;dur=%.3f, trace;dur=%.3f", j->h.parse_ms,
                            queue_ms, 1e3 * (td_clock_s() - t0));
    else
        td_http_resp_header(r, "Server-Timing",
                            "parse;dur=%.3f, queue;dur=%.3f, setup;dur=%.3f, trace;dur=%.3f, encode;dur=%.3f",
                            j->h.parse_ms, queue_ms, st.setup_ms, st.trace_ms, encode_ms);
    td_snapshot_release(j->h.snap);
    free(j);
}

/* td_routes_json_job's parse: the dataset, then the endpoint's fields. */
static td_status vs_parse(json_t *root, const char *dataset, td_json_job *job, td_err *err)
{
    vs_req *q = &((vs_job *)job)->q;
    td_status rc;
    snprintf(q->dataset, sizeof q->dataset, "%s", dataset);
    rc = parse_quality(root, &q->o, err);
    if (!rc)
        rc = q->los ? parse_los(root, q, err) : parse_viewshed(root, q, err);
    return rc;
}

/* Parses on the HTTP thread, resolves the dataset, queues the work (or answers). */
static void vs_handle(td_app *app, td_http_req *hq, td_http_resp *r, int los)
{
    vs_job *j = calloc(1, sizeof *j);
    if (j) {
        j->q.los = los;
        td_viewshed_opts_default(&j->q.o);
    }
    td_routes_json_job(app, hq, r, j ? &j->h : NULL, vs_parse, vs_work);
}

void td_vs_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    vs_handle(app, q, r, 0);
}

void td_los_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    vs_handle(app, q, r, 1);
}
