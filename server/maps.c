/* maps.c: GET /v1/maps/{dataset}/{style}/{z}/{x}/{y}.png and /v1/maps/{dataset}/{style}.json
 * (maps.h; issue 17).
 *
 * A tile request is checked on the HTTP thread (path, style, query, the dataset's map,
 * the tile against the dataset's Web Mercator bounds, If-None-Match), then traced on a
 * render worker: the pixel positions (td_merc_positions), the sun bound for shadows on
 * the full grid (sunlit.h; the dataset keeps it for the next tiles with the same sun,
 * td_snapshot_sunlit), the pixels (td_maptile_render), the PNG. The sun of ?time= is
 * NOAA's (core/solar.h) at the dataset's centre, turned into the dataset frame by the
 * CRS's meridian convergence (td_merc_proj_grid_north), as ?azimuth= is.
 *
 * ETag: a hash of the style, the canonical parameters, the tile and the dataset's shape,
 * then the heights version (as /v1/tiles' tags), so an edit changes every tag. */
#include "maps.h"

#include <ctype.h>
#include <limits.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "hash.h"
#include "image.h"
#include "maptile.h"
#include "mercator.h"
#include "scene.h"
#include "solar.h"
#include "static.h"
#include "sunlit.h"

/* One dataset's map: its transformations (cloned per tile) or why it has none. */
typedef struct map_entry {
    char id[TD_SCENE_DATASET_MAX];
    td_merc_proj *proj; /* NULL: no map, msg says why */
    char msg[300];
} map_entry;

struct td_maps {
    pthread_mutex_t mu;
    map_entry *e;
    size_t n, cap;
};

td_maps *td_maps_create(void)
{
    td_maps *m = calloc(1, sizeof *m);
    if (m)
        pthread_mutex_init(&m->mu, NULL);
    return m;
}

void td_maps_free(td_maps *m)
{
    if (!m)
        return;
    for (size_t i = 0; i < m->n; i++)
        td_merc_proj_free(m->e[i].proj);
    free(m->e);
    pthread_mutex_destroy(&m->mu);
    free(m);
}

/* What a handler needs of a dataset's map. */
typedef struct map_info {
    double ll[4], merc[4], centre[2], grid_north;
    char name[128];
} map_info;

/* The dataset's map entry, made on first use (under the lock: made once). */
static map_entry *entry_get(td_maps *m, const td_dataset_info *di)
{
    map_entry *e = NULL;
    for (size_t i = 0; i < m->n && !e; i++)
        if (!strcmp(m->e[i].id, di->id))
            e = &m->e[i];
    if (!e && m->n == m->cap) {
        size_t cap = m->cap ? 2 * m->cap : 8;
        map_entry *ne = realloc(m->e, cap * sizeof *ne);
        if (!ne)
            return NULL;
        m->e = ne;
        m->cap = cap;
    }
    if (!e) {
        char path[4096];
        td_err err = {0};
        e = &m->e[m->n++];
        memset(e, 0, sizeof *e);
        snprintf(e->id, sizeof e->id, "%s", di->id);
        snprintf(path, sizeof path, "%s/%s", di->dir ? di->dir : ".", di->file ? di->file : "");
        if (td_merc_proj_create(di->file ? path : NULL, di->grid, &e->proj, &err))
            snprintf(e->msg, sizeof e->msg, "dataset '%.60s' has no map: %.200s", di->id, err.msg);
    }
    return e;
}

/* The dataset's map (info) and, when clone is not NULL, a copy of its transformations for
 * this thread. 0, or -1 with the reason in msg. */
static int map_lookup(td_maps *m, const td_dataset_info *di, map_info *info, td_merc_proj **clone,
                      char *msg, size_t n)
{
    int rc = -1;
    map_entry *e;
    td_err err = {0};
    pthread_mutex_lock(&m->mu);
    e = entry_get(m, di);
    if (!e) {
        snprintf(msg, n, "out of memory");
    } else if (!e->proj) {
        snprintf(msg, n, "%s", e->msg);
    } else if (clone && td_merc_proj_clone(e->proj, clone, &err)) {
        snprintf(msg, n, "%.290s", err.msg);
    } else {
        td_merc_proj_bounds(e->proj, info->ll, info->merc, info->centre);
        info->grid_north = td_merc_proj_grid_north(e->proj);
        snprintf(info->name, sizeof info->name, "%s", td_merc_proj_name(e->proj));
        rc = 0;
    }
    pthread_mutex_unlock(&m->mu);
    return rc;
}

int td_maps_centre(td_maps *m, const td_dataset_info *di, double centre[2], double *grid_north, char *msg,
                   size_t n)
{
    map_info info;
    int rc = map_lookup(m, di, &info, NULL, msg, n);
    if (rc == 0) {
        centre[0] = info.centre[0];
        centre[1] = info.centre[1];
        *grid_north = info.grid_north;
    }
    return rc;
}

/* --- query parameters ----------------------------------------------------------------- */

static const struct {
    const char *name;
    int shaded_only;
} map_params[] = {
#define TD_X_ROW(e, name, shaded_only) {name, shaded_only},
    TD_MAPS_PARAM_LIST(TD_X_ROW)
#undef TD_X_ROW
};

/* One parameter into mq; 0, or -1 with the error. */
static int add_param(td_maps_query *mq, td_mapstyle style, const char *key, const char *value)
{
    int k = -1;
    for (int i = 0; i < TD_MAPS_PARAM_COUNT && k < 0; i++)
        if (!strcmp(key, map_params[i].name))
            k = i;
    if (k < 0 || (map_params[k].shaded_only && style != TD_MAPSTYLE_SHADED)) {
        snprintf(mq->field, sizeof mq->field, "%.31s", key);
        snprintf(mq->msg, sizeof mq->msg, "%.40s: not a parameter of %s tiles (they take %s)", key,
                 td_mapstyle_name(style),
                 style == TD_MAPSTYLE_SHADED ? "azimuth, elevation, time, shadows, ambient, method, surface, lod"
                                             : "surface, lod");
        return -1;
    }
    if (mq->value[k] || !value) {
        snprintf(mq->field, sizeof mq->field, "%s", map_params[k].name);
        snprintf(mq->msg, sizeof mq->msg, "%s: give it once, with a value", map_params[k].name);
        return -1;
    }
    mq->value[k] = value;
    return 0;
}

/* A number in [lo, hi] from the parameter k, or an error; 0 when fine. */
static int num_param(td_maps_query *mq, int k, double lo, double hi, double *out)
{
    char *end = NULL;
    double v;
    errno = 0;
    v = strtod(mq->value[k], &end);
    if (errno || end == mq->value[k] || *end || !isfinite(v) || v < lo || v > hi) {
        snprintf(mq->field, sizeof mq->field, "%s", map_params[k].name);
        snprintf(mq->msg, sizeof mq->msg, "%s: a number in [%g, %g]", map_params[k].name, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

static int set_error(td_maps_query *mq, const char *field, const char *msg)
{
    snprintf(mq->field, sizeof mq->field, "%s", field);
    snprintf(mq->msg, sizeof mq->msg, "%.290s", msg);
    return -1;
}

/* The sun: ?time= (NOAA's position at the dataset's centre) or ?azimuth=&elevation=
 * (default 315, 45); into the spec in the dataset frame. */
static int sun_params(td_maps_query *mq, const double centre[2], double grid_north)
{
    td_err e = {0};
    td_sun sun;
    mq->azimuth = 315.0;
    mq->elevation = 45.0;
    mq->time_s = NAN;
    if (mq->value[TD_MAPS_P_TIME] && (mq->value[TD_MAPS_P_AZIMUTH] || mq->value[TD_MAPS_P_ELEVATION]))
        return set_error(mq, "time", "time: give either time or azimuth and elevation, not both");
    if (mq->value[TD_MAPS_P_TIME]) {
        if (td_solar_parse_time(mq->value[TD_MAPS_P_TIME], "time", &mq->time_s, &e) ||
            td_solar_position(centre[1], centre[0], mq->time_s, &sun, &e))
            return set_error(mq, "time", e.msg);
        mq->azimuth = sun.azimuth_deg;
        mq->elevation = sun.elevation_deg;
    }
    if ((mq->value[TD_MAPS_P_AZIMUTH] && num_param(mq, TD_MAPS_P_AZIMUTH, 0.0, 360.0, &mq->azimuth)) ||
        (mq->value[TD_MAPS_P_ELEVATION] && num_param(mq, TD_MAPS_P_ELEVATION, -90.0, 90.0, &mq->elevation)))
        return -1;
    td_solar_direction(mq->azimuth + grid_north, mq->elevation, mq->spec.sun);
    return 0;
}

int td_maps_parse_query(const char *const *keys, const char *const *values, size_t n, td_mapstyle style,
                        const double centre[2], double grid_north, td_maps_query *mq)
{
    memset(mq, 0, sizeof *mq);
    td_maptile_spec_default(&mq->spec);
    mq->spec.style = style;
    for (size_t i = 0; i < n; i++)
        if (add_param(mq, style, keys[i], values[i]))
            return -1;
    if (mq->value[TD_MAPS_P_SURFACE] && td_surface_parse(mq->value[TD_MAPS_P_SURFACE], &mq->spec.surface))
        return set_error(mq, "surface", "surface: plane, linear, triangle or bilinear");
    if (mq->value[TD_MAPS_P_METHOD] && td_method_parse(mq->value[TD_MAPS_P_METHOD], &mq->spec.method))
        return set_error(mq, "method", "method: incremental, hierarchical, parametric, silhouette or auto");
    if (mq->value[TD_MAPS_P_SHADOWS]) {
        const char *v = mq->value[TD_MAPS_P_SHADOWS];
        if (strcmp(v, "true") && strcmp(v, "false") && strcmp(v, "1") && strcmp(v, "0"))
            return set_error(mq, "shadows", "shadows: true or false");
        mq->spec.shadows = !strcmp(v, "true") || !strcmp(v, "1");
    }
    if ((mq->value[TD_MAPS_P_AMBIENT] && num_param(mq, TD_MAPS_P_AMBIENT, 0.0, 1.0, &mq->spec.ambient)) ||
        (mq->value[TD_MAPS_P_LOD] && num_param(mq, TD_MAPS_P_LOD, 0.0, 64.0, &mq->spec.lod_pixels)))
        return -1;
    if (style == TD_MAPSTYLE_SHADED && sun_params(mq, centre, grid_north))
        return -1;
    snprintf(mq->canon, sizeof mq->canon, "%s;s=%d;m=%d;lod=%.17g;sun=%.17g,%.17g,%.17g;sh=%d;a=%.17g",
             td_mapstyle_name(style), (int)mq->spec.surface, (int)mq->spec.method, mq->spec.lod_pixels,
             mq->spec.sun[0], mq->spec.sun[1], mq->spec.sun[2], mq->spec.shadows, mq->spec.ambient);
    return 0;
}

/* The request's query into td_maps_parse_query (at most 32 parameters). */
typedef struct q_args {
    const char *keys[32], *values[32];
    size_t n;
    int overflow;
} q_args;

static int collect(void *cls, const char *key, const char *value)
{
    q_args *a = cls;
    if (a->n == 32) {
        a->overflow = 1;
        return 1;
    }
    a->keys[a->n] = key;
    a->values[a->n++] = value;
    return 0;
}

static int parse_query(td_http_req *q, td_mapstyle style, const map_info *mi, td_maps_query *mq)
{
    q_args a;
    memset(&a, 0, sizeof a);
    td_http_req_query_each(q, collect, &a);
    if (a.overflow) {
        memset(mq, 0, sizeof *mq);
        snprintf(mq->msg, sizeof mq->msg, "more than 32 query parameters");
        return -1;
    }
    return td_maps_parse_query(a.keys, a.values, a.n, style, mi->centre, mi->grid_north, mq);
}

/* --- tiles ------------------------------------------------------------------------------- */

typedef struct map_job {
    td_app *app;
    td_snapshot *snap;
    td_maps_query mq;
    size_t idx; /* the dataset */
    int z, px;
    int32_t x, y;
    char etag[96];
    double parse_ms;
} map_job;

/* The PNG of a tile; 0, or -1 with the answer in r (404 when the tile holds no data). */
static int tile_png(map_job *j, td_merc_proj *proj, td_http_resp *r, td_buf *png, td_maptile_stats *st,
                    double ms[3])
{
    const td_view *v = td_snapshot_view(j->snap);
    const td_lod *lod = td_snapshot_lod(j->snap);
    size_t n = (size_t)j->px * (size_t)j->px;
    double *xy = malloc(2 * n * sizeof *xy), foot = 0.0, t0 = td_clock_s();
    uint8_t *rgba = malloc(4 * n);
    const td_sunlit *lit = NULL; /* held by the snapshot */
    td_err e = {0};
    int exact = 0, rc = -1, level, kept = 0;
    if (!xy || !rgba) {
        td_routes_error(r, "internal", NULL, "out of memory");
        goto out;
    }
    if (td_merc_positions(proj, j->z, j->x, j->y, j->px, xy, &exact, &foot, &e)) {
        td_routes_error(r, "internal", NULL, e.msg);
        goto out;
    }
    ms[0] = (td_clock_s() - t0) * 1e3;
    t0 = td_clock_s();
    level = td_maptile_level(v->grid, lod, foot, j->mq.spec.lod_pixels);
    if (j->mq.spec.style == TD_MAPSTYLE_SHADED && j->mq.spec.shadows && level == 0 &&
        td_snapshot_sunlit(j->snap, j->mq.spec.sun, &lit, &kept, &e)) {
        td_routes_error(r, "internal", NULL, e.msg);
        goto out;
    }
    if (td_maptile_render(v, lod, lit, &j->mq.spec, xy, j->px, foot, rgba, NULL, st, &e)) {
        td_routes_error(r, "bad_request", NULL, e.msg);
        goto out;
    }
    ms[1] = (td_clock_s() - t0) * 1e3;
    t0 = td_clock_s();
    if (!st->pixels_with_data) {
        td_routes_error(r, "not_found", NULL, "the tile holds no data of the dataset");
        goto out;
    }
    if (td_image_encode_rgba(rgba, j->px, j->px, png, &e)) {
        td_routes_error(r, "internal", NULL, e.msg);
        goto out;
    }
    ms[2] = (td_clock_s() - t0) * 1e3;
    rc = 0;
out:
    free(xy);
    free(rgba);
    return rc;
}

static void tile_work(void *cls, td_http_req *q, td_http_resp *r, int cancelled)
{
    map_job *j = cls;
    td_dataset_info di;
    map_info mi;
    td_merc_proj *proj = NULL;
    td_maptile_stats st;
    td_buf png = {0};
    double ms[3] = {0, 0, 0}, queue_ms = td_http_req_queue_wait(q) * 1e3, t0 = td_clock_s();
    char msg[300];
    memset(&st, 0, sizeof st);
    if (cancelled) {
        td_http_resp_header(r, "Retry-After", "1");
        td_routes_error(r, "stopping", NULL, "the server is stopping");
        goto out;
    }
    td_store_info(j->app->store, j->idx, &di);
    if (map_lookup(j->app->maps, &di, &mi, &proj, msg, sizeof msg)) {
        td_routes_error(r, "internal", NULL, msg);
        goto out;
    }
    if (tile_png(j, proj, r, &png, &st, ms))
        goto out;
    r->status = 200;
    td_http_resp_take(r, png.data, png.len, "image/png");
    png.data = NULL;
    td_http_resp_header(r, "ETag", "%s", j->etag);
    td_http_resp_header(r, "Cache-Control", "public, max-age=86400");
    td_http_resp_header(r, "X-Terrad-Method", "%s", td_method_name(j->mq.spec.method));
    td_http_resp_header(r, "X-Terrad-Surface", "%s", td_surface_name(j->mq.spec.surface));
    td_http_resp_header(r, "X-Terrad-Rays", "%llu", (unsigned long long)(st.primary_rays + st.shadow_rays));
    td_http_resp_header(r, "X-Terrad-Steps", "%llu", (unsigned long long)st.steps);
    td_http_resp_header(r, "X-Terrad-Level", "%d", st.level);
    td_metrics_render(j->app->metrics, j->mq.spec.method, td_clock_s() - t0, st.primary_rays + st.shadow_rays,
                      st.steps);
out:
    td_http_resp_header(r, "Server-Timing", "parse;dur=%.3f, queue;dur=%.3f, positions;dur=%.3f, trace;dur=%.3f, "
                        "encode;dur=%.3f", j->parse_ms, queue_ms, ms[0], ms[1], ms[2]);
    td_buf_free(&png);
    td_merc_proj_free(proj);
    td_snapshot_release(j->snap);
    free(j);
}

/* The tile's ETag: its place, style and parameters, the dataset's shape, then the heights
 * version of the snapshot. */
static void tile_etag(map_job *j, const td_dataset_info *di)
{
    uint64_t chain = 0, ver = td_snapshot_version(j->snap, &chain);
    double shape[6] = {(double)di->grid->w, (double)di->grid->h, di->grid->sx, di->grid->sy,
                       (double)di->grid->zmin, (double)di->grid->zmax};
    int32_t place[4] = {j->z, j->x, j->y, j->px};
    uint64_t h = td_fnv1a(TD_FNV1A_INIT, j->mq.canon, strlen(j->mq.canon));
    h = td_fnv1a(h, shape, sizeof shape);
    h = td_fnv1a(h, place, sizeof place);
    snprintf(j->etag, sizeof j->etag, "\"m%016llx-v%llu.%08llx\"", (unsigned long long)h, (unsigned long long)ver,
             (unsigned long long)(chain & 0xffffffffu));
}

/* {y}.png or {y}@2x.png: the row and the tile's size in pixels; 0 when not such a name. */
static int tile_name(char *s, int *px)
{
    size_t l = strlen(s);
    if (l < 5 || strcmp(s + l - 4, ".png"))
        return 0;
    s[l - 4] = '\0';
    *px = 256;
    if (l > 7 && !strcmp(s + l - 7, "@2x")) {
        s[l - 7] = '\0';
        *px = 512;
    }
    return 1;
}

/* 1 when the tile's box meets the dataset's Web Mercator box. */
static int tile_meets(const map_info *mi, int z, long x, long y)
{
    double b[4];
    td_merc_tile_bounds(z, (int32_t)x, (int32_t)y, b);
    return b[0] <= mi->merc[2] && b[2] >= mi->merc[0] && b[1] <= mi->merc[3] && b[3] >= mi->merc[1];
}

/* The dataset and style of a map path: 0, or -1 answered (404). */
static int dataset_style(td_app *app, td_http_resp *r, const char *id, const char *style_name, long *idx,
                         td_mapstyle *style, td_dataset_info *di, map_info *mi)
{
    char msg[300];
    *idx = td_store_find(app->store, id);
    if (*idx < 0) {
        snprintf(msg, sizeof msg, "unknown dataset '%.100s'", id);
        td_routes_error(r, "unknown_dataset", "dataset", msg);
        return -1;
    }
    if (td_mapstyle_parse(style_name, style)) {
        snprintf(msg, sizeof msg, "unknown style '%.60s': shaded, terrain-rgb or terrarium", style_name);
        td_routes_error(r, "not_found", "style", msg);
        return -1;
    }
    td_store_info(app->store, (size_t)*idx, di);
    if (map_lookup(app->maps, di, mi, NULL, msg, sizeof msg)) {
        td_routes_error(r, "not_found", "dataset", msg);
        return -1;
    }
    return 0;
}

/* GET /v1/maps/{dataset}/{style}/{z}/{x}/{y}.png */
void td_maps_tile_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    map_job *j = calloc(1, sizeof *j);
    td_dataset_info di;
    map_info mi;
    td_mapstyle style;
    long idx, z, x, y;
    int px = 256;
    char msg[300];
    td_err e = {0};
    double t0 = td_clock_s();

    if (!j) {
        td_routes_error(r, "internal", NULL, "out of memory");
        goto out;
    }
    if (!tile_name(seg[4], &px)) {
        td_routes_error(r, "not_found", NULL, "map tile paths end in {y}.png or {y}@2x.png");
        goto out;
    }
    if (dataset_style(app, r, seg[0], seg[1], &idx, &style, &di, &mi))
        goto out;
    if (!td_routes_parse_uint(seg[2], TD_MERC_MAX_ZOOM, &z)) {
        td_routes_error(r, "bad_request", "z", "z: an integer zoom in [0, 24]");
        goto out;
    }
    if (!td_routes_parse_uint(seg[3], (1L << z) - 1, &x) || !td_routes_parse_uint(seg[4], (1L << z) - 1, &y)) {
        snprintf(msg, sizeof msg, "no tile %.20s/%.20s at zoom %ld (x and y in [0, %ld])", seg[3], seg[4], z,
                 (1L << z) - 1);
        td_routes_error(r, "not_found", NULL, msg);
        goto out;
    }
    if (parse_query(q, style, &mi, &j->mq)) {
        td_routes_error(r, "bad_request", j->mq.field[0] ? j->mq.field : NULL, j->mq.msg);
        goto out;
    }
    if (!tile_meets(&mi, (int)z, x, y)) {
        snprintf(msg, sizeof msg, "tile %ld/%ld/%ld is outside dataset '%s'", z, x, y, di.id);
        td_routes_error(r, "not_found", NULL, msg);
        goto out;
    }
    if (td_store_acquire(app->store, di.id, &j->snap, &e)) {
        td_routes_error(r, "unknown_dataset", "dataset", e.msg);
        goto out;
    }
    j->app = app;
    j->idx = (size_t)idx;
    j->z = (int)z;
    j->x = (int32_t)x;
    j->y = (int32_t)y;
    j->px = px;
    tile_etag(j, &di);
    {
        const char *inm = td_http_req_header(q, "If-None-Match");
        if (inm && (strstr(inm, j->etag) || !strcmp(inm, "*"))) {
            r->status = 304;
            td_http_resp_header(r, "ETag", "%s", j->etag);
            td_http_resp_header(r, "Cache-Control", "public, max-age=86400");
            goto out;
        }
    }
    j->parse_ms = (td_clock_s() - t0) * 1e3;
    if (td_http_defer(q, tile_work, j) == 0) {
        j = NULL; /* the worker frees it */
    } else {
        snprintf(msg, sizeof msg, "the render queue is full (%ld running, %ld waiting); retry later",
                 app->cfg->render_workers, app->cfg->queue);
        td_http_resp_header(r, "Retry-After", "1");
        td_routes_error(r, atomic_load(&app->ready) ? "busy" : "stopping", NULL, msg);
    }
out:
    if (j) {
        td_snapshot_release(j->snap);
        free(j);
    }
}

/* --- TileJSON ---------------------------------------------------------------------------- */

/* The origin the client reached: X-Forwarded-Proto/-Host (a proxy in front), else Host;
 * only the characters of a host name, an address and a port. 0 when there is none. */
static int base_url(td_app *app, td_http_req *q, char *out, size_t n)
{
    const char *proto = td_http_req_header(q, "X-Forwarded-Proto");
    const char *host = td_http_req_header(q, "X-Forwarded-Host");
    if (!host)
        host = td_http_req_header(q, "Host");
    if (!host || !*host || strlen(host) > 255 || host[strspn(host, "abcdefghijklmnopqrstuvwxyz"
                                                                  "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-:[]")])
        host = app->cfg->listen;
    if (!proto || (strcmp(proto, "https") && strcmp(proto, "http")))
        proto = "http";
    return snprintf(out, n, "%s://%s", proto, host) < (int)n;
}

/* Appends the parameters as given, percent-encoded, to the tiles template. */
static void append_query(const td_maps_query *mq, char *out, size_t n)
{
    size_t l = strlen(out);
    char sep = '?';
    for (int k = 0; k < TD_MAPS_PARAM_COUNT; k++) {
        if (!mq->value[k])
            continue;
        l += (size_t)snprintf(out + l, l < n ? n - l : 0, "%c%s=", sep, map_params[k].name);
        sep = '&';
        for (const unsigned char *p = (const unsigned char *)mq->value[k]; *p && l + 4 < n; p++)
            l += isalnum(*p) || strchr("-_.~:", *p) ? (size_t)snprintf(out + l, n - l, "%c", *p)
                                                   : (size_t)snprintf(out + l, n - l, "%%%02X", *p);
    }
}

/* GET /v1/maps/{dataset}/{style}.json */
void td_maps_tilejson_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    td_dataset_info di;
    map_info mi;
    td_maps_query mq;
    td_mapstyle style;
    long idx;
    size_t l = strlen(seg[1]);
    char tiles[2048], base[300];
    json_t *j;
    int maxzoom;

    if (l < 6 || strcmp(seg[1] + l - 5, ".json")) {
        td_routes_error(r, "not_found", NULL, "TileJSON paths are /v1/maps/{dataset}/{style}.json");
        return;
    }
    seg[1][l - 5] = '\0';
    if (dataset_style(app, r, seg[0], seg[1], &idx, &style, &di, &mi))
        return;
    if (parse_query(q, style, &mi, &mq)) {
        td_routes_error(r, "bad_request", mq.field[0] ? mq.field : NULL, mq.msg);
        return;
    }
    base_url(app, q, base, sizeof base);
    snprintf(tiles, sizeof tiles, "%s/v1/maps/%s/%s/{z}/{x}/{y}.png", base, di.id, td_mapstyle_name(style));
    append_query(&mq, tiles, sizeof tiles);
    maxzoom = td_merc_zoom_for(di.grid->sx < di.grid->sy ? di.grid->sx : di.grid->sy, mi.centre[1]);
    j = json_pack("{s:s, s:s, s:s, s:s, s:[s], s:i, s:i, s:[f,f,f,f], s:[f,f,i], s:s, s:s, s:s}", "tilejson",
                  "3.0.0", "name", di.id, "scheme", "xyz", "version", "1.0.0", "tiles", tiles, "minzoom", 0,
                  "maxzoom", maxzoom, "bounds", mi.ll[0], mi.ll[1], mi.ll[2], mi.ll[3], "center", mi.centre[0],
                  mi.centre[1], maxzoom > 3 ? maxzoom - 3 : 0, "attribution",
                  "Heights: see /v1/datasets; shading ray-traced by terrad", "description",
                  style == TD_MAPSTYLE_SHADED ? "top-down ray-traced shading with cast shadows"
                                              : "heights encoded for raster-dem sources",
                  "crs", mi.name);
    if (j && style != TD_MAPSTYLE_SHADED)
        json_object_set_new(j, "encoding", json_string(style == TD_MAPSTYLE_TERRAIN_RGB ? "mapbox" : "terrarium"));
    if (j) {
        char ver[40];
        snprintf(ver, sizeof ver, "1.0.%llu", (unsigned long long)di.version);
        json_object_set_new(j, "version", json_string(ver));
        if (style == TD_MAPSTYLE_SHADED)
            json_object_set_new(j, "sun", json_pack("{s:f, s:f}", "azimuth", mq.azimuth, "elevation", mq.elevation));
    }
    td_http_resp_header(r, "Cache-Control", "public, max-age=300");
    td_routes_json(r, 200, j);
}

/* --- MapLibre GL JS for the web map page ------------------------------------------------ */

void td_maps_vendor_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    char dist[PATH_MAX + 64], root[PATH_MAX];
    td_err e = {0};
    (void)seg;
    snprintf(dist, sizeof dist, "%s/node_modules/maplibre-gl/dist", app->web_dir);
    if (!app->web_dir[0] || !realpath(dist, root))
        root[0] = '\0';
    if (td_static_serve(root, td_http_req_path(q) + strlen(TD_MAPS_VENDOR_PREFIX), 1, r, &e))
        td_routes_error(r, "not_found", NULL, e.msg);
}
