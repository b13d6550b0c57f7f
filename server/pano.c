/* pano.c: POST /v1/horizon and POST /v1/peaks (see pano.h, README's API section).
 * routes.c's table points here (two rows); the work is core/skyline.c's and core/peaks.c's.
 *
 * As the viewshed (viewshed.c): the handler parses and checks the body on the HTTP thread
 * (400 naming the field; the dataset resolved to a tile-store snapshot, 404 when
 * unknown), the work goes to the HTTP layer's worker queue (503 + Retry-After when
 * full); what needs the grid (lon/lat, an observer outside it, a sun without a lon/lat
 * georeference) is refused by the worker, still 400 with the field.
 *
 *   horizon body: {"dataset", "observer": {"x","y"} | {"lon","lat"}, "height" (1.7 m),
 *     "step_deg" (0.25), "max_distance", "curvature": true (default) | false | {"k"},
 *     "surface", "method", "sun": {"date": "YYYY-MM-DD"}}
 *   peaks body: a scene (as /v1/render) plus "min_prominence" (100 m) and "max_peaks"
 *     (100)
 *
 * Summits cache: one entry per dataset id and heights version (an edit makes a new
 * version and so a new entry), computed by the first /v1/peaks that needs it while the
 * cache's lock is held (a second request for the same dataset waits for it rather than
 * computing it twice), refcounted so a replaced entry is freed by its last user; freed at
 * exit. The summit lists are immutable once built. */
#include "pano.h"

#include <jansson.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "clock.h"
#include "peaks.h"
#include "render.h"
#include "request.h"
#include "skyline.h"
#include "tilestore.h"
#include "viewshed.h"

#define PANO_DEFAULT_HEIGHT 1.7
#define PANO_MAX_PEAKS 1000

/* ---- the summits cache ------------------------------------------------------------------ */

typedef struct pano_entry {
    char id[TD_SCENE_DATASET_MAX];
    uint64_t version;
    td_summits *s;
    int refs; /* the cache's own (while listed) + users */
    struct pano_entry *next;
} pano_entry;

static pthread_mutex_t cache_lock = PTHREAD_MUTEX_INITIALIZER;
static pano_entry *cache_head;
static int cache_atexit;

static void entry_unref(pano_entry *e)
{
    if (e && --e->refs == 0) {
        td_summits_free(e->s);
        free(e);
    }
}

static void cache_free(void)
{
    pthread_mutex_lock(&cache_lock);
    while (cache_head) {
        pano_entry *e = cache_head;
        cache_head = e->next;
        entry_unref(e);
    }
    pthread_mutex_unlock(&cache_lock);
}

/* The summits of the snapshot's heights: the cached entry, or computed now. *fresh says
 * which. The caller releases the entry (cache_release). */
static td_status cache_get(const char *id, const td_snapshot *snap, pano_entry **out, int *fresh, td_err *err)
{
    td_status rc = TD_OK;
    uint64_t ver = td_snapshot_version(snap, NULL);
    pano_entry **pp, *e;
    pthread_mutex_lock(&cache_lock);
    if (!cache_atexit)
        cache_atexit = atexit(cache_free) == 0;
    for (pp = &cache_head; *pp && strcmp((*pp)->id, id); pp = &(*pp)->next)
        ;
    e = *pp;
    *fresh = !e || e->version != ver;
    if (*fresh) {
        pano_entry *n = calloc(1, sizeof *n);
        rc = n ? td_summits_find(td_snapshot_view(snap)->grid, &n->s, err)
               : td_err_set(err, TD_ENOMEM, "out of memory");
        if (!rc) {
            snprintf(n->id, sizeof n->id, "%s", id);
            n->version = ver;
            n->refs = 1;
            n->next = e ? e->next : NULL;
            *pp = n; /* replaces an older version's entry */
            entry_unref(e);
            e = n;
        } else {
            free(n);
            e = NULL;
        }
    }
    if (e)
        e->refs++;
    pthread_mutex_unlock(&cache_lock);
    *out = e;
    return rc;
}

static void cache_release(pano_entry *e)
{
    pthread_mutex_lock(&cache_lock);
    entry_unref(e);
    pthread_mutex_unlock(&cache_lock);
}

/* ---- requests ----------------------------------------------------------------------------- */

typedef struct pano_req {
    int peaks;
    char dataset[TD_SCENE_DATASET_MAX];
    /* horizon */
    int geo, sun;
    double a, b; /* observer: x, y or lon, lat */
    double day_s;
    char date[16];
    td_skyline_opts o;
    /* peaks */
    double min_prominence;
    int max_peaks;
    td_scene scene;
} pano_req;

/* obj[key]: absent (0), a number in [lo, hi] into *out (1), or an error naming field. */
static int num_field(json_t *obj, const char *key, const char *field, double lo, double hi, double *out,
                     td_status *rc, td_err *err)
{
    json_t *v = *rc ? NULL : json_object_get(obj, key);
    if (v && !json_is_number(v))
        *rc = td_err_field(err, TD_EINVAL, field, "must be a number");
    else if (v && !(json_number_value(v) >= lo && json_number_value(v) <= hi))
        *rc = td_err_field(err, TD_ERANGE, field, "%g is outside %g .. %g", json_number_value(v), lo, hi);
    else if (v)
        *out = json_number_value(v);
    return v != NULL && !*rc;
}

/* The first key of obj not in allowed (NULL: none). */
static const char *stray_key(json_t *obj, const char *const *allowed)
{
    const char *key, *bad = NULL;
    json_t *val;
    json_object_foreach(obj, key, val) {
        int k = 0;
        while (allowed[k] && strcmp(key, allowed[k]))
            k++;
        if (!allowed[k] && !bad)
            bad = key;
    }
    (void)val;
    return bad;
}

static td_status parse_observer(json_t *root, pano_req *q, td_err *err)
{
    static const char *const keys[] = {"x", "y", "lon", "lat", NULL};
    json_t *ob = json_object_get(root, "observer");
    td_status rc = TD_OK;
    const char *bad = json_is_object(ob) ? stray_key(ob, keys) : NULL;
    if (!json_is_object(ob))
        rc = td_err_field(err, TD_EINVAL, "observer", "required: {\"x\", \"y\"} or {\"lon\", \"lat\"}");
    else if (bad)
        rc = td_err_field(err, TD_EINVAL, "observer", "unknown key '%.40s'", bad);
    int hx = num_field(ob, "x", "observer.x", -1e9, 1e9, &q->a, &rc, err);
    int hy = num_field(ob, "y", "observer.y", -1e9, 1e9, &q->b, &rc, err);
    int hlon = num_field(ob, "lon", "observer.lon", -180, 360, &q->a, &rc, err);
    int hlat = num_field(ob, "lat", "observer.lat", -90, 90, &q->b, &rc, err);
    if (!rc && !((hx && hy && !hlon && !hlat) || (hlon && hlat && !hx && !hy)))
        rc = td_err_field(err, TD_EINVAL, "observer", "give x, y (dataset frame, metres) or lon, lat");
    q->geo = hlon;
    return rc;
}

/* "curvature": true, false or {"k"}; "surface", "method"; "sun": {"date"}. */
static td_status parse_options(json_t *root, pano_req *q, td_err *err)
{
    json_t *c = json_object_get(root, "curvature"), *s = json_object_get(root, "surface"),
           *m = json_object_get(root, "method"), *sun = json_object_get(root, "sun");
    td_status rc = TD_OK;
    if (c && json_is_boolean(c)) {
        q->o.curvature = json_is_true(c);
    } else if (c && json_is_object(c) && !stray_key(c, (const char *const[]){"k", NULL})) {
        q->o.curvature = 1;
        num_field(c, "k", "curvature.k", td_limit_get(TD_LIMIT_CURVATURE_K)->min,
                  td_limit_get(TD_LIMIT_CURVATURE_K)->api_max, &q->o.k, &rc, err);
    } else if (c) {
        rc = td_err_field(err, TD_EINVAL, "curvature", "true, false or {\"k\": refraction coefficient}");
    }
    if (!rc && s && (!json_is_string(s) || td_surface_parse(json_string_value(s), &q->o.surface)))
        rc = td_err_field(err, TD_EINVAL, "surface", "one of plane, linear, triangle, bilinear");
    if (!rc && m && (!json_is_string(m) || td_method_parse(json_string_value(m), &q->o.method)))
        rc = td_err_field(err, TD_EINVAL, "method", "one of incremental, hierarchical, parametric, auto");
    if (!rc && sun) {
        json_t *d = json_is_object(sun) ? json_object_get(sun, "date") : NULL;
        if (!json_is_string(d) || stray_key(sun, (const char *const[]){"date", NULL}) ||
            json_string_length(d) != 10)
            rc = td_err_field(err, TD_EINVAL, "sun.date", "give {\"date\": \"YYYY-MM-DD\"}");
        else
            rc = td_solar_parse_time(json_string_value(d), "sun.date", &q->day_s, err);
        if (!rc)
            snprintf(q->date, sizeof q->date, "%s", json_string_value(d));
        q->sun = 1;
    }
    return rc;
}

static td_status parse_horizon(json_t *root, pano_req *q, td_err *err)
{
    static const char *const keys[] = {"dataset", "observer", "height", "step_deg", "max_distance",
                                       "curvature", "surface", "method", "sun", NULL};
    const char *bad = stray_key(root, keys);
    td_status rc = bad ? td_err_field(err, TD_EINVAL, bad, "unknown key") : TD_OK;
    td_skyline_opts_default(&q->o);
    q->o.height = PANO_DEFAULT_HEIGHT;
    if (!rc)
        rc = parse_observer(root, q, err);
    num_field(root, "height", "height", 0, 1e5, &q->o.height, &rc, err);
    num_field(root, "step_deg", "step_deg", TD_SKYLINE_STEP_MIN, TD_SKYLINE_STEP_MAX, &q->o.step_deg, &rc, err);
    num_field(root, "max_distance", "max_distance", 1e-3, 1e9, &q->o.max_distance, &rc, err);
    if (!rc)
        rc = parse_options(root, q, err);
    return rc;
}

/* The scene with the peaks' own keys taken out and handed to the scene parser. */
static td_status parse_peaks(json_t *root, const td_app *app, pano_req *q, td_err *err)
{
    td_request_limits lim;
    td_request_error re;
    double mx = 100;
    td_status rc = TD_OK;
    q->min_prominence = 100.0;
    num_field(root, "min_prominence", "min_prominence", 0, 1e4, &q->min_prominence, &rc, err);
    num_field(root, "max_peaks", "max_peaks", 1, PANO_MAX_PEAKS, &mx, &rc, err);
    q->max_peaks = (int)mx;
    json_object_del(root, "min_prominence");
    json_object_del(root, "max_peaks");
    char *text = rc ? NULL : json_dumps(root, JSON_COMPACT);
    if (!rc && !text)
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
    td_request_limits_default(&lim);
    lim.max_pixels = (uint64_t)app->cfg->max_pixels;
    lim.allow_paths = 0;
    memset(&re, 0, sizeof re);
    if (!rc && td_request_parse_scene(text, strlen(text), &lim, &q->scene, &re))
        rc = td_err_field(err, TD_EINVAL, re.field[0] ? re.field : "scene", "%s", re.message);
    free(text);
    return rc;
}

/* ---- answers ---------------------------------------------------------------------------- */

/* An instant as ISO 8601 UTC to the second; null for NaN. */
static json_t *iso_time(double t)
{
    char buf[32];
    struct tm tm;
    time_t s = (time_t)floor(t + 0.5);
    if (!isfinite(t) || !gmtime_r(&s, &tm))
        return json_null();
    strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return json_string(buf);
}

static json_t *real_or_null(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

/* lon, lat of a dataset-frame point (NaN, NaN without a lon/lat georeference). */
static void to_lonlat(const td_grid *g, double x, double y, double *lon, double *lat)
{
    int ok = g->geo.kind == TD_GEO_LONLAT;
    *lon = ok ? g->geo.x0 + x / g->sx * g->geo.dx : NAN;
    *lat = ok ? g->geo.y0 + y / g->sy * g->geo.dy : NAN;
}

static json_t *sun_answer(const pano_req *q, const td_skyline_sun *s)
{
    json_t *path = json_array(), *iv = json_array();
    for (int k = 0; k < s->npath; k++) {
        const td_sun_sample *p = &s->path[k];
        json_array_append_new(path, json_pack("{s:o,s:f,s:f,s:o,s:b}", "time", iso_time(p->t), "azimuth", p->azimuth,
                                              "elevation", p->elevation, "skyline", real_or_null(p->skyline), "seen",
                                              p->seen));
    }
    for (int k = 0; k < s->nint; k++)
        json_array_append_new(iv, json_pack("[o,o]", iso_time(s->interval[k][0]), iso_time(s->interval[k][1])));
    return json_pack("{s:s,s:o,s:i,s:{s:o,s:o,s:o},s:{s:o,s:o,s:o},s:f,s:o,s:o}", "date", q->date, "noon",
                     iso_time(s->noon_s), "polar", s->polar, "sunrise", "astronomical", iso_time(s->astro_rise_s),
                     "terrain", iso_time(s->rise_s), "delay_s", real_or_null(s->rise_s - s->astro_rise_s),
                     "sunset", "astronomical", iso_time(s->astro_set_s), "terrain", iso_time(s->set_s), "early_s",
                     real_or_null(s->astro_set_s - s->set_s), "seen_s", s->seen_s, "intervals", iv, "path", path);
}

static json_t *horizon_answer(const pano_req *q, const td_grid *g, const td_skyline *sk, double lon, double lat,
                              json_t *sun)
{
    json_t *pts = json_array();
    for (int k = 0; k < sk->n; k++) {
        const td_skyline_pt *p = &sk->pt[k];
        json_array_append_new(pts, isnan(p->elevation)
                                       ? json_pack("{s:f,s:n}", "azimuth", p->azimuth, "elevation")
                                       : json_pack("{s:f,s:f,s:f,s:{s:f,s:f,s:f}}", "azimuth", p->azimuth,
                                                   "elevation", p->elevation, "distance", p->distance, "point",
                                                   "x", p->p[0], "y", p->p[1], "z", p->p[2]));
    }
    (void)g;
    return json_pack("{s:s,s:{s:f,s:f,s:f,s:o,s:o},s:f,s:f,s:o,s:b,s:f,s:s,s:s,s:I,s:o,s:o?}", "dataset",
                     q->dataset, "observer", "x", sk->eye[0], "y", sk->eye[1], "z", sk->eye[2], "lon",
                     real_or_null(lon), "lat", real_or_null(lat), "height", q->o.height, "step_deg", sk->step_deg,
                     "max_distance", real_or_null(q->o.max_distance), "curvature", q->o.curvature, "k",
                     q->o.curvature ? q->o.k : 0.0, "surface", td_surface_name(q->o.surface), "method",
                     td_method_name(q->o.method), "rays", (json_int_t)sk->rays, "skyline", pts, "sun", sun);
}

static json_t *peaks_answer(const pano_req *q, const td_grid *g, const td_peak_seen *seen, size_t n,
                            const pano_entry *e, int fresh, uint64_t rays)
{
    json_t *list = json_array();
    size_t total = 0;
    while (total < e->s->n && e->s->s[total].prominence >= q->min_prominence)
        total++;
    for (size_t k = 0; k < n; k++) {
        const td_peak_seen *p = &seen[k];
        const td_summit *m = p->summit;
        double lon, lat;
        to_lonlat(g, p->p[0], p->p[1], &lon, &lat);
        json_array_append_new(
            list, json_pack("{s:f,s:f,s:f,s:f,s:f,s:f,s:f,s:o,s:o,s:o}", "px", p->px, "py", p->py, "x", p->p[0], "y",
                            p->p[1], "z", p->p[2], "distance", p->distance, "prominence", (double)m->prominence,
                            "lon", real_or_null(lon), "lat", real_or_null(lat), "col",
                            m->col_i < 0 ? json_null()
                                         : json_pack("{s:f,s:f}", "x", m->col_i * g->sx, "y", m->col_j * g->sy)));
    }
    return json_pack("{s:s,s:f,s:I,s:I,s:b,s:f,s:I,s:o}", "dataset", q->dataset, "min_prominence",
                     q->min_prominence, "summits", (json_int_t)total, "visible", (json_int_t)n, "cached", !fresh,
                     "summits_ms", e->s->build_ms, "rays", (json_int_t)rays, "peaks", list);
}

/* ---- the work ------------------------------------------------------------------------------ */

typedef struct pano_job {
    td_json_job h; /* first: app, snapshot, parse time (routes.h) */
    pano_req q;
} pano_job;

/* The observer in the dataset frame and its lon/lat (NaN without a lon/lat georeference). */
static td_status observer_at(const td_grid *g, pano_req *q, double *lon, double *lat, td_err *err)
{
    td_status rc = TD_OK;
    q->o.x = q->a, q->o.y = q->b;
    if (q->geo)
        rc = td_vs_from_lonlat(g, q->a, q->b, "observer", &q->o.x, &q->o.y, err);
    to_lonlat(g, q->o.x, q->o.y, lon, lat);
    if (!rc && q->sun && isnan(*lon))
        rc = td_err_field(err, TD_EUNSUPPORTED, "sun",
                          "the sun needs the observer's lon/lat: the dataset has no lon/lat georeference");
    return rc;
}

static td_status work_horizon(pano_job *j, td_http_req *hq, td_http_resp *r, td_err *e)
{
    const td_view *v = td_snapshot_view(j->h.snap);
    td_skyline sk = {0};
    td_skyline_sun *sun = NULL;
    json_t *sj = NULL;
    double lon, lat;
    td_status rc = observer_at(v->grid, &j->q, &lon, &lat, e);
    j->q.o.cancel = td_http_req_cancel(hq);
    if (!rc)
        rc = td_skyline_compute(v, &j->q.o, &sk, e);
    if (!rc && j->q.sun) {
        sun = malloc(sizeof *sun);
        rc = sun ? td_skyline_sun_day(&sk, lat, lon, j->q.day_s, sun, e) : td_err_set(e, TD_ENOMEM, "out of memory");
        if (!rc)
            sj = sun_answer(&j->q, sun);
    }
    if (!rc)
        td_routes_json(r, 200, horizon_answer(&j->q, v->grid, &sk, lon, lat, sj));
    else
        json_decref(sj);
    td_skyline_free(&sk);
    free(sun);
    return rc;
}

static td_status work_peaks(pano_job *j, td_http_resp *r, td_err *e)
{
    const td_view *v = td_snapshot_view(j->h.snap);
    pano_entry *ent = NULL;
    td_peak_seen *seen = calloc((size_t)j->q.max_peaks, sizeof *seen);
    size_t n = 0;
    uint64_t rays = 0;
    int fresh = 0;
    td_status rc = seen ? cache_get(j->q.dataset, j->h.snap, &ent, &fresh, e) : td_err_set(e, TD_ENOMEM, "out of memory");
    if (!rc)
        rc = td_peaks_visible(v, &j->q.scene, ent->s, j->q.min_prominence, seen, (size_t)j->q.max_peaks, &n, &rays, e);
    if (!rc)
        td_routes_json(r, 200, peaks_answer(&j->q, v->grid, seen, n, ent, fresh, rays));
    if (ent)
        cache_release(ent);
    free(seen);
    return rc;
}

static void pano_work(void *cls, td_http_req *hq, td_http_resp *r, int cancelled)
{
    pano_job *j = cls;
    td_err e = {0};
    td_status rc = TD_OK;
    double queue_ms = td_http_req_queue_wait(hq) * 1e3, t0 = td_clock_s();
    if (cancelled) {
        td_http_resp_header(r, "Retry-After", "1");
        td_routes_error(r, "stopping", NULL, "the server is stopping");
    } else {
        rc = j->q.peaks ? work_peaks(j, r, &e) : work_horizon(j, hq, r, &e);
        if (rc)
            td_routes_work_error(j->h.app, r, rc, &e, j->q.peaks ? "the summits" : "the horizon");
        else
            td_http_resp_header(r, "Cache-Control", "no-store");
    }
    td_http_resp_header(r, "Server-Timing", "parse;dur=%.3f, queue;dur=%.3f, trace;dur=%.3f", j->h.parse_ms, queue_ms,
                        1e3 * (td_clock_s() - t0));
    td_snapshot_release(j->h.snap);
    free(j);
}

/* td_routes_json_job's parse: the dataset, then the endpoint's fields. */
static td_status pano_parse(json_t *root, const char *dataset, td_json_job *job, td_err *err)
{
    pano_job *j = (pano_job *)job;
    pano_req *q = &j->q;
    snprintf(q->dataset, sizeof q->dataset, "%s", dataset);
    return q->peaks ? parse_peaks(root, j->h.app, q, err) : parse_horizon(root, q, err);
}

/* Parses on the HTTP thread, resolves the dataset, queues the work (or answers). */
static void pano_handle(td_app *app, td_http_req *hq, td_http_resp *r, int peaks)
{
    pano_job *j = calloc(1, sizeof *j);
    if (j)
        j->q.peaks = peaks;
    td_routes_json_job(app, hq, r, j ? &j->h : NULL, pano_parse, pano_work);
}

void td_horizon_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    pano_handle(app, q, r, 0);
}

void td_peaks_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    pano_handle(app, q, r, 1);
}
