/* peaks.c: summits by prominence (union-find over samples sorted by height) and their
 * visibility in a view (a camera ray each). See peaks.h for the definitions, the
 * algorithm and its cost. Called by server/pano.c.
 *
 * Layout while finding (N = w * h samples, voids left out of `order`):
 *   order[N]   sample indices, highest first (ties: lower index first), sorted as
 *              (height, index) pairs (8 bytes a sample during the sort)
 *   parent[N]  union-find parent, -1 while the sample is not yet processed
 *   top[N]     for a root: its region's highest sample (its peak); size in `size`
 * A summit is recorded when its region meets a region with a higher peak. */
#include "peaks.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "effects.h"

typedef struct find_ctx {
    const float *z;
    int32_t *parent, *top, *size;
} find_ctx;

/* A sample for the sort (qsort has no context argument: the height travels along). */
typedef struct zi {
    float z;
    int32_t i;
} zi;

/* Highest first; equal heights by index. */
static int by_height(const void *a, const void *b)
{
    const zi *x = a, *y = b;
    return x->z > y->z ? -1 : x->z < y->z ? 1 : (x->i > y->i) - (x->i < y->i);
}

/* Is sample a higher than b in the sort's order? */
static int higher(const float *z, int32_t a, int32_t b)
{
    return z[a] > z[b] || (z[a] == z[b] && a < b);
}

static int32_t root_of(int32_t *parent, int32_t x)
{
    while (parent[x] != x) {
        parent[x] = parent[parent[x]]; /* path halving */
        x = parent[x];
    }
    return x;
}

/* Joins the regions of c and n (n processed); records the lower peak as a summit with
 * its key col at c. */
static td_status join(find_ctx *f, const td_grid *g, int32_t c, int32_t n, td_summit **list, size_t *count,
                      size_t *cap)
{
    td_status rc = TD_OK;
    int32_t a = root_of(f->parent, c), b = root_of(f->parent, n);
    if (a != b) {
        int32_t pa = f->top[a], pb = f->top[b], low = higher(f->z, pa, pb) ? pb : pa;
        if (f->z[low] > f->z[c]) { /* a lone sample (or a flat) joining higher ground is no summit */
            if (*count == *cap) {
                size_t nc = *cap ? 2 * *cap : 1024;
                td_summit *nl = realloc(*list, nc * sizeof *nl);
                if (!nl)
                    rc = TD_ENOMEM;
                else
                    *list = nl, *cap = nc;
            }
            if (!rc) {
                td_summit *s = &(*list)[(*count)++];
                s->i = low % g->w, s->j = low / g->w, s->z = f->z[low];
                s->prominence = f->z[low] - f->z[c];
                s->col_i = c % g->w, s->col_j = c / g->w;
            }
        }
        if (f->size[a] < f->size[b]) {
            int32_t t = a;
            a = b, b = t;
        }
        f->parent[b] = a;
        f->size[a] += f->size[b];
        f->top[a] = higher(f->z, pa, pb) ? pa : pb;
    }
    return rc;
}

static int by_prominence(const void *a, const void *b)
{
    const td_summit *x = a, *y = b;
    int64_t kx = (int64_t)x->j << 32 | (uint32_t)x->i, ky = (int64_t)y->j << 32 | (uint32_t)y->i;
    if (x->prominence != y->prominence)
        return x->prominence > y->prominence ? -1 : 1;
    return (kx > ky) - (kx < ky);
}

/* The regions' highest samples (never joined to higher ground): prominence above the
 * region's lowest sample, which is the last of it processed. */
static td_status add_roots(find_ctx *f, const td_grid *g, const int32_t *order, size_t nv, td_summit **list,
                           size_t *count, size_t *cap)
{
    td_status rc = TD_OK;
    for (size_t k = nv; k-- > 0 && !rc;) {
        int32_t c = order[k], r = root_of(f->parent, c);
        if (f->top[r] < 0)
            continue; /* this region's summit is recorded */
        int32_t peak = f->top[r];
        f->top[r] = -1;
        if (f->z[peak] > f->z[c]) {
            if (*count == *cap) {
                size_t nc = *cap ? 2 * *cap : 16;
                td_summit *nl = realloc(*list, nc * sizeof *nl);
                if (!nl) {
                    rc = TD_ENOMEM;
                    break;
                }
                *list = nl, *cap = nc;
            }
            td_summit *s = &(*list)[(*count)++];
            s->i = peak % g->w, s->j = peak / g->w, s->z = f->z[peak];
            s->prominence = f->z[peak] - f->z[c];
            s->col_i = s->col_j = -1;
        }
    }
    return rc;
}

/* The flood: every valid sample, highest first, joins its processed 8-neighbours. */
static td_status flood(find_ctx *f, const td_grid *g, const int32_t *order, size_t nv, td_summit **list,
                       size_t *count, size_t *cap)
{
    td_status rc = TD_OK;
    for (size_t k = 0; k < nv && !rc; k++) {
        int32_t c = order[k], ci = c % g->w, cj = c / g->w;
        f->parent[c] = c, f->top[c] = c, f->size[c] = 1;
        for (int dj = -1; dj <= 1 && !rc; dj++)
            for (int di = -1; di <= 1 && !rc; di++) {
                int32_t ni = ci + di, nj = cj + dj;
                if ((di || dj) && ni >= 0 && nj >= 0 && ni < g->w && nj < g->h &&
                    f->parent[nj * g->w + ni] >= 0)
                    rc = join(f, g, c, nj * g->w + ni, list, count, cap);
            }
    }
    return rc;
}

td_status td_summits_find(const td_grid *g, td_summits **out, td_err *err)
{
    td_status rc = TD_OK;
    double t0 = td_clock_s();
    size_t n = (size_t)g->w * (size_t)g->h, nv = 0, count = 0, cap = 0;
    find_ctx f = {g->z, NULL, NULL, NULL};
    int32_t *order = NULL;
    zi *sorted = NULL;
    td_summit *list = NULL;
    td_summits *res = calloc(1, sizeof *res);
    *out = NULL;
    if (n > (size_t)INT32_MAX) {
        rc = td_err_set(err, TD_ETOOBIG, "%d x %d samples: too many for the summit search", (int)g->w, (int)g->h);
        goto out;
    }
    order = malloc(n * sizeof *order);
    sorted = malloc(n * sizeof *sorted);
    f.parent = malloc(n * sizeof *f.parent);
    f.top = malloc(n * sizeof *f.top);
    f.size = malloc(n * sizeof *f.size);
    if (!res || !order || !sorted || !f.parent || !f.top || !f.size) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the summits of a %d x %d grid", (int)g->w, (int)g->h);
        goto out;
    }
    for (size_t k = 0; k < n; k++) {
        f.parent[k] = -1;
        if (!isnan(g->z[k]))
            sorted[nv++] = (zi){g->z[k], (int32_t)k};
    }
    qsort(sorted, nv, sizeof *sorted, by_height);
    for (size_t k = 0; k < nv; k++)
        order[k] = sorted[k].i;
    free(sorted);
    sorted = NULL;
    rc = flood(&f, g, order, nv, &list, &count, &cap);
    if (!rc)
        rc = add_roots(&f, g, order, nv, &list, &count, &cap);
    if (rc) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the summits of a %d x %d grid", (int)g->w, (int)g->h);
        goto out;
    }
    qsort(list, count, sizeof *list, by_prominence);
    res->n = count;
    res->s = list;
    list = NULL;
    res->build_ms = 1e3 * (td_clock_s() - t0);
    *out = res;
    res = NULL;
out:
    free(order);
    free(sorted);
    free(f.parent);
    free(f.top);
    free(f.size);
    free(list);
    td_summits_free(res);
    return rc;
}

void td_summits_free(td_summits *s)
{
    if (s) {
        free(s->s);
        free(s);
    }
}

/* One camera ray through pixel (px, py) of scene s (its pick list is ours); *bent when
 * the render bent it. */
static td_status pick_at(const td_view *v, td_scene *s, double px, double py, td_pick *pk, int *bent,
                         td_err *err)
{
    td_render_stats st;
    s->npick = 1;
    s->pick[0][0] = px;
    s->pick[0][1] = py;
    td_status rc = td_render_pick(v, s, pk, &st, err);
    *bent = st.curved_rays > 0;
    return rc;
}

/* Is summit point P, at horizontal distance d, seen along the camera's ray through it?
 * With curvature the ray through P's apparent place (P lowered by a*d^2) is bent up
 * through P; if the render does not bend that ray, the straight ray through P is it. */
static td_status seen(const td_view *v, td_scene *s, const td_camera *cam, const double P[3], double d,
                      td_peak_seen *o, int *vis, uint64_t *rays, td_err *err)
{
    td_status rc = TD_OK;
    td_pick pk;
    int bent = 0, in;
    double a = s->effects.curvature ? (1.0 - s->effects.curvature_k) / (2.0 * TD_EARTH_RADIUS_M) : 0.0;
    double Q[3] = {P[0], P[1], P[2] - a * d * d};
    *vis = 0;
    in = td_camera_project(cam, Q, &o->px, &o->py);
    if (in && a > 0.0) {
        rc = pick_at(v, s, o->px, o->py, &pk, &bent, err);
        ++*rays;
        if (!rc && !bent)
            in = td_camera_project(cam, P, &o->px, &o->py);
    }
    in = in && o->px >= -0.5 && o->px < cam->width - 0.5 && o->py >= -0.5 && o->py < cam->height - 0.5;
    if (!rc && in && !bent) {
        rc = pick_at(v, s, o->px, o->py, &pk, &bent, err);
        ++*rays;
    }
    if (!rc && in) {
        double tol = 1.5 * hypot(v->grid->sx, v->grid->sy);
        *vis = !pk.hit || hypot(pk.p[0] - cam->o[0], pk.p[1] - cam->o[1]) >= d - tol;
    }
    return rc;
}

td_status td_peaks_visible(const td_view *v, const td_scene *s, const td_summits *sum,
                           double min_prominence, td_peak_seen *out, size_t max, size_t *n,
                           uint64_t *rays, td_err *err)
{
    td_status rc;
    td_camera cam;
    td_scene *sc = malloc(sizeof *sc);
    const td_grid *g = v->grid;
    *n = 0;
    *rays = 0;
    if (!sc) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
        goto out;
    }
    *sc = *s;
    sc->image.format = TD_FORMAT_PICK;
    rc = td_camera_setup(&sc->camera, s->image.width, s->image.height, g, &cam, err);
    for (size_t k = 0; !rc && k < sum->n && *n < max && sum->s[k].prominence >= min_prominence; k++) {
        const td_summit *m = &sum->s[k];
        td_peak_seen *o = &out[*n];
        int vis = 0;
        o->p[0] = m->i * g->sx, o->p[1] = m->j * g->sy, o->p[2] = m->z;
        o->distance = hypot(o->p[0] - cam.o[0], o->p[1] - cam.o[1]);
        o->summit = m;
        if (cam.projection == TD_PROJ_ORTHOGRAPHIC) {
            vis = td_camera_project(&cam, o->p, &o->px, &o->py) && o->px >= -0.5 && o->py >= -0.5 &&
                  o->px < cam.width - 0.5 && o->py < cam.height - 0.5; /* from above every summit is seen */
            o->distance = cam.o[2] - o->p[2];
        } else {
            rc = seen(v, sc, &cam, o->p, o->distance, o, &vis, rays, err);
        }
        *n += vis;
    }
out:
    free(sc);
    return rc;
}
