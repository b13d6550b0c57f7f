/* embree_ref.c: Embree 3 scenes of a height field (see embree_ref.h), for the oracle
 * tests and `terrad bench`.
 *
 * Layout. Vertex (I, J) of the (possibly refined) lattice is vertex I + J * VW,
 * VW = n*(w-1) + 1, at (I*sx/n, J*sy/n, z) minus the grid's centre (void samples get
 * z = 0; no primitive uses them). Triangle mesh: cell (i, j) sub-quad (a, b) gives
 * triangles SW = (I,J) (I+1,J) (I,J+1) and NE = (I+1,J) (I+1,J+1) (I,J+1) with
 * I = n*i + a, J = n*j + b: the same diagonal as terrad's (south-east to north-west).
 * Refined vertices on a cell edge are interpolated along that edge only, so a void cell
 * next to a valid one cannot leak NaN into the shared edge.
 * GRID geometry (n = 1 only): RTCGrid records over the same vertex buffer (stride = grid
 * width); Embree splits each grid quad (v0 = (x,y), v1 = (x+1,y), v2 = (x+1,y+1),
 * v3 = (x,y+1)) into (v0,v1,v3) and (v2,v3,v1), the same diagonal v1-v3. A tile without
 * a void cell becomes one record; a tile with voids one record per run of valid cells in
 * each cell row, so holes stay holes.
 *
 * Error bound of the refinement: on a sub-square of side 1/n (in cell units) the
 * bilinear patch differs from its linear interpolant only by the d*u*v term, and
 * u*v deviates from the plane through three corners of a triangle by at most
 * (1/n)^2 / 4; so |surface - mesh| <= |z00 - z10 - z01 + z11| / (4 n^2) per cell.
 *
 * Memory: rtcSetDeviceMemoryMonitorFunction counts every byte Embree allocates on the
 * device (BVH nodes, primitive blocks, the buffers of rtcSetNewGeometryBuffer).
 *
 * Rays are prepared (clipped and converted in double) apart from tracing, so the
 * benchmark can time Embree at its best, on rays already in its native form. */
#include "embree_ref.h"
#include "clock.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>

#include <embree3/rtcore.h>

static const char *const geom_names[] = {
#define TD_X_NAME(e, name) name,
    TD_EMBREE_GEOM_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_embree_geom_name(td_embree_geom g)
{
    return (unsigned)g < TD_EMBREE_GEOM_COUNT ? geom_names[g] : "unknown";
}

struct td_embree {
    RTCDevice dev;
    RTCScene scene;
    double c[3];         /* local frame origin in the dataset frame */
    double lo[3], hi[3]; /* bounding box (dataset frame), padded */
    double bound;        /* refinement error bound, metres */
    size_t prims;
    _Atomic int64_t cur, peak;
};

static bool monitor(void *ptr, ssize_t bytes, bool post)
{
    td_embree *e = ptr;
    (void)post;
    int64_t now = atomic_fetch_add(&e->cur, (int64_t)bytes) + (int64_t)bytes;
    int64_t pk = atomic_load(&e->peak);
    while (now > pk && !atomic_compare_exchange_weak(&e->peak, &pk, now)) {
    }
    return true;
}

static double sample(const td_grid *g, int32_t i, int32_t j) { return (double)td_grid_at(g, i, j); }

/* Height of refined lattice vertex (I, J) for refinement n. */
static double vertex_height(const td_grid *g, int n, int64_t I, int64_t J)
{
    int32_t i = (int32_t)(I / n), j = (int32_t)(J / n);
    int a = (int)(I % n), b = (int)(J % n);
    double u = (double)a / n, v = (double)b / n, h;
    if (a == 0 && b == 0)
        h = sample(g, i, j);
    else if (a == 0)
        h = (1.0 - v) * sample(g, i, j) + v * sample(g, i, j + 1);
    else if (b == 0)
        h = (1.0 - u) * sample(g, i, j) + u * sample(g, i + 1, j);
    else
        h = (1.0 - u) * (1.0 - v) * sample(g, i, j) + u * (1.0 - v) * sample(g, i + 1, j) +
            (1.0 - u) * v * sample(g, i, j + 1) + u * v * sample(g, i + 1, j + 1);
    return h;
}

static int cell_valid(const td_grid *g, int32_t i, int32_t j)
{
    return !(isnan(td_grid_at(g, i, j)) || isnan(td_grid_at(g, i + 1, j)) ||
             isnan(td_grid_at(g, i, j + 1)) || isnan(td_grid_at(g, i + 1, j + 1)));
}

/* Counts (fill = NULL) or writes the GRID records. */
static size_t grid_records(const td_grid *g, struct RTCGrid *fill)
{
    size_t k = 0;
    for (int32_t ty = 0; ty < g->tiles_y; ty++) {
        for (int32_t tx = 0; tx < g->tiles_x; tx++) {
            const td_tile *t = &g->tiles[(size_t)ty * (size_t)g->tiles_x + (size_t)tx];
            int whole = 1;
            for (int32_t j = t->j0; j < t->j0 + t->ny && whole; j++)
                for (int32_t i = t->i0; i < t->i0 + t->nx && whole; i++)
                    whole = cell_valid(g, i, j);
            if (whole) {
                if (fill) {
                    fill[k].startVertexID = (unsigned)((size_t)t->j0 * (size_t)g->w + (size_t)t->i0);
                    fill[k].stride = (unsigned)g->w;
                    fill[k].width = (unsigned short)(t->nx + 1);
                    fill[k].height = (unsigned short)(t->ny + 1);
                }
                k++;
                continue;
            }
            for (int32_t j = t->j0; j < t->j0 + t->ny; j++) {
                int32_t i = t->i0, iend = t->i0 + t->nx;
                while (i < iend) {
                    int32_t a;
                    while (i < iend && !cell_valid(g, i, j))
                        i++;
                    a = i;
                    while (i < iend && cell_valid(g, i, j))
                        i++;
                    if (i > a) {
                        if (fill) {
                            fill[k].startVertexID = (unsigned)((size_t)j * (size_t)g->w + (size_t)a);
                            fill[k].stride = (unsigned)g->w;
                            fill[k].width = (unsigned short)(i - a + 1);
                            fill[k].height = 2;
                        }
                        k++;
                    }
                }
            }
        }
    }
    return k;
}

/* Index buffer of the triangle mesh (see the top of the file); returns the bound. */
static double mesh_indices(const td_grid *g, int refine, size_t vw, unsigned *ib)
{
    size_t k = 0;
    double bound = 0.0;
    for (int32_t j = 0; j + 1 < g->h; j++) {
        for (int32_t i = 0; i + 1 < g->w; i++) {
            if (!cell_valid(g, i, j))
                continue;
            double d = sample(g, i, j) - sample(g, i + 1, j) - sample(g, i, j + 1) + sample(g, i + 1, j + 1);
            if (refine > 1 && fabs(d) / (4.0 * refine * refine) > bound)
                bound = fabs(d) / (4.0 * refine * refine);
            for (int b = 0; b < refine; b++) {
                for (int a = 0; a < refine; a++) {
                    unsigned I = (unsigned)(refine * i + a), J = (unsigned)(refine * j + b);
                    unsigned v00 = J * (unsigned)vw + I, v10 = v00 + 1;
                    unsigned v01 = v00 + (unsigned)vw, v11 = v01 + 1;
                    ib[k++] = v00, ib[k++] = v10, ib[k++] = v01;
                    ib[k++] = v10, ib[k++] = v11, ib[k++] = v01;
                }
            }
        }
    }
    return bound;
}

/* e's device (`threads` build threads, 0 all; its memory counted by monitor) and its
 * empty robust, high-quality scene. */
static td_status scene_open(td_embree *e, int threads, td_err *err)
{
    td_status rc = TD_OK;
    char cfg[64];
    snprintf(cfg, sizeof cfg, "threads=%d,verbose=0", threads > 0 ? threads : 0);
    e->dev = rtcNewDevice(cfg);
    if (!e->dev) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: rtcNewDevice(\"%s\") failed", cfg);
    } else {
        rtcSetDeviceMemoryMonitorFunction(e->dev, monitor, e);
        e->scene = rtcNewScene(e->dev);
        rtcSetSceneFlags(e->scene, RTC_SCENE_FLAG_ROBUST);
        rtcSetSceneBuildQuality(e->scene, RTC_BUILD_QUALITY_HIGH);
    }
    return rc;
}

void td_embree_opts_default(td_embree_opts *o)
{
    o->geom = TD_EMBREE_TRIANGLES;
    o->refine = 1;
    o->threads = 0;
}

td_status td_embree_build_opts(const td_grid *g, const td_embree_opts *o, td_embree **out,
                               td_embree_stats *st, td_err *err)
{
    td_status rc = TD_OK;
    td_embree *e = NULL;
    RTCGeometry gm = NULL;
    td_embree_stats stats;
    const int refine = o->refine;
    size_t vw, vh, nv, ncell = 0, nprim = 0, tmp;
    double t0;

    *out = NULL;
    memset(&stats, 0, sizeof stats);
    if (refine < 1 || refine > 64 || (o->geom == TD_EMBREE_GRID && refine != 1) ||
        (unsigned)o->geom >= TD_EMBREE_GEOM_COUNT) {
        rc = td_err_set(err, TD_ERANGE, "embree: refinement %d is out of range (1 .. 64, 1 for GRID)", refine);
        goto out;
    }
    vw = (size_t)refine * (size_t)(g->w - 1) + 1;
    vh = (size_t)refine * (size_t)(g->h - 1) + 1;
    for (int32_t j = 0; j + 1 < g->h; j++)
        for (int32_t i = 0; i + 1 < g->w; i++)
            ncell += (size_t)cell_valid(g, i, j);
    if (!td_mul_size(vw, vh, &nv) || nv > 0xffffffffu ||
        !td_mul_size(ncell, (size_t)refine * (size_t)refine * 2, &tmp) || tmp > 0x7fffffffu ||
        !td_mul_size(tmp, 3 * sizeof(unsigned), &tmp) || g->tile_log2 > 14) {
        rc = td_err_set(err, TD_ETOOBIG, "embree: %d x %d grid refined %d times is too big",
                        (int)g->w, (int)g->h, refine);
        goto out;
    }
    e = calloc(1, sizeof *e);
    if (!e) {
        rc = td_err_set(err, TD_ENOMEM, "embree: out of memory");
        goto out;
    }
    e->c[0] = 0.5 * (g->w - 1) * g->sx;
    e->c[1] = 0.5 * (g->h - 1) * g->sy;
    e->c[2] = isnan(g->zmin) ? 0.0 : 0.5 * ((double)g->zmin + (double)g->zmax);
    e->lo[0] = -1.0;
    e->lo[1] = -1.0;
    e->hi[0] = (g->w - 1) * g->sx + 1.0;
    e->hi[1] = (g->h - 1) * g->sy + 1.0;
    e->lo[2] = isnan(g->zmin) ? 0.0 : (double)g->zmin - 1.0 - 1e-6 * fabs(g->zmin);
    e->hi[2] = isnan(g->zmax) ? 0.0 : (double)g->zmax + 1.0 + 1e-6 * fabs(g->zmax);
    rc = scene_open(e, o->threads, err);
    if (rc)
        goto out;
    t0 = td_clock_s();
    if (ncell > 0) {
        float *vb;
        gm = rtcNewGeometry(e->dev, o->geom == TD_EMBREE_GRID ? RTC_GEOMETRY_TYPE_GRID
                                                              : RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetGeometryBuildQuality(gm, RTC_BUILD_QUALITY_HIGH);
        vb = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                     3 * sizeof(float), nv);
        if (!vb) {
            rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu vertices", nv);
            goto out;
        }
        for (size_t J = 0; J < vh; J++) {
            for (size_t I = 0; I < vw; I++) {
                float *p = vb + 3 * (J * vw + I);
                double h = vertex_height(g, refine, (int64_t)I, (int64_t)J);
                p[0] = (float)((double)I * g->sx / refine - e->c[0]);
                p[1] = (float)((double)J * g->sy / refine - e->c[1]);
                p[2] = (float)(isnan(h) ? 0.0 : h - e->c[2]);
            }
        }
        if (o->geom == TD_EMBREE_GRID) {
            struct RTCGrid *gb;
            nprim = grid_records(g, NULL);
            gb = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_GRID, 0, RTC_FORMAT_GRID,
                                         sizeof(struct RTCGrid), nprim);
            if (!gb) {
                rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu grids", nprim);
                goto out;
            }
            grid_records(g, gb);
        } else {
            unsigned *ib;
            nprim = 2 * ncell * (size_t)refine * (size_t)refine;
            ib = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                         3 * sizeof(unsigned), nprim);
            if (!ib) {
                rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu triangles", nprim);
                goto out;
            }
            e->bound = mesh_indices(g, refine, vw, ib);
        }
        rtcCommitGeometry(gm);
        rtcAttachGeometry(e->scene, gm);
        rtcReleaseGeometry(gm);
        gm = NULL;
    }
    rtcCommitScene(e->scene);
    stats.build_seconds = td_clock_s() - t0;
    if (rtcGetDeviceError(e->dev) != RTC_ERROR_NONE) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: scene build failed (error %d)",
                        (int)rtcGetDeviceError(e->dev));
        goto out;
    }
    e->prims = nprim;
    stats.bytes = atomic_load(&e->cur);
    stats.peak_bytes = atomic_load(&e->peak);
    stats.primitives = nprim;
out:
    if (gm)
        rtcReleaseGeometry(gm);
    if (rc != TD_OK) {
        td_embree_free(e);
        e = NULL;
    }
    if (st)
        *st = stats;
    *out = e;
    return rc;
}

td_status td_embree_build_mesh(const double *v, size_t nv, const uint32_t *tri, size_t nt,
                               td_embree **out, td_err *err)
{
    td_status rc = TD_OK;
    td_embree *e = calloc(1, sizeof *e);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    RTCGeometry gm = NULL;
    float *vb;
    unsigned *ib;

    *out = NULL;
    if (!e || nv > 0xffffffffu || nt > 0x7fffffffu / 3) {
        rc = td_err_set(err, e ? TD_ETOOBIG : TD_ENOMEM, "embree: a mesh of %zu vertices, %zu triangles", nv, nt);
        goto out;
    }
    for (size_t k = 0; k < nv; k++)
        for (int a = 0; a < 3 && !isnan(v[3 * k + 2]); a++) {
            lo[a] = fmin(lo[a], v[3 * k + a]);
            hi[a] = fmax(hi[a], v[3 * k + a]);
        }
    for (int a = 0; a < 3; a++) { /* the box padded as a grid's (td_embree_build_opts) */
        double pad = a < 2 ? 1.0 : 1.0 + 1e-6 * fmax(fabs(lo[a]), fabs(hi[a]));
        lo[a] = isfinite(lo[a]) ? lo[a] : 0.0;
        hi[a] = isfinite(hi[a]) ? hi[a] : 0.0;
        e->c[a] = 0.5 * (lo[a] + hi[a]);
        e->lo[a] = lo[a] - pad;
        e->hi[a] = hi[a] + pad;
    }
    rc = scene_open(e, 0, err);
    if (rc || nt == 0)
        goto commit;
    gm = rtcNewGeometry(e->dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(gm, RTC_BUILD_QUALITY_HIGH);
    vb = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), nv);
    ib = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), nt);
    if (!vb || !ib) {
        rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu triangles", nt);
        goto out;
    }
    for (size_t k = 0; k < nv; k++)
        for (int a = 0; a < 3; a++)
            vb[3 * k + a] = (float)(isnan(v[3 * k + 2]) ? 0.0 : v[3 * k + a] - e->c[a]);
    for (size_t k = 0; k < 3 * nt; k++)
        ib[k] = tri[k];
    rtcCommitGeometry(gm);
    rtcAttachGeometry(e->scene, gm);
    rtcReleaseGeometry(gm);
    gm = NULL;
    e->prims = nt;
commit:
    if (!rc)
        rtcCommitScene(e->scene);
    if (!rc && rtcGetDeviceError(e->dev) != RTC_ERROR_NONE)
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: mesh build failed (error %d)",
                        (int)rtcGetDeviceError(e->dev));
out:
    if (gm)
        rtcReleaseGeometry(gm);
    if (rc) {
        td_embree_free(e);
        e = NULL;
    }
    *out = e;
    return rc;
}

td_status td_embree_build(const td_grid *g, int refine, td_embree **out, td_err *err)
{
    td_embree_opts o;
    td_embree_opts_default(&o);
    o.refine = refine;
    return td_embree_build_opts(g, &o, out, NULL, err);
}

void td_embree_free(td_embree *e)
{
    if (e) {
        if (e->scene)
            rtcReleaseScene(e->scene);
        if (e->dev)
            rtcReleaseDevice(e->dev);
        free(e);
    }
}

double td_embree_refine_bound(const td_embree *e) { return e->bound; }

size_t td_embree_triangles(const td_embree *e) { return e->prims; }

void td_embree_prepare(const td_embree *e, const td_ray *r, size_t n, td_embree_ray *out)
{
    for (size_t k = 0; k < n; k++) {
        const td_ray *q = &r[k];
        td_embree_ray *p = &out[k];
        double lo = q->tmin, hi = q->tmax;
        int ok = e->prims > 0;
        memset(p, 0, sizeof *p);
        for (int a = 0; a < 3 && ok; a++) {
            if (q->d[a] == 0.0) {
                ok = q->o[a] >= e->lo[a] && q->o[a] <= e->hi[a];
            } else {
                double ta = (e->lo[a] - q->o[a]) / q->d[a], tb = (e->hi[a] - q->o[a]) / q->d[a];
                if (ta > tb) {
                    double x = ta;
                    ta = tb;
                    tb = x;
                }
                lo = ta > lo ? ta : lo;
                hi = tb < hi ? tb : hi;
            }
        }
        if (ok && lo <= hi) {
            /* |d| without overflow or underflow for huge or denormal components */
            double m = fmax(fabs(q->d[0]), fmax(fabs(q->d[1]), fabs(q->d[2])));
            double u[3] = {q->d[0] / m, q->d[1] / m, q->d[2] / m};
            double nn = m * sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
            for (int a = 0; a < 3; a++) {
                p->o[a] = (float)(q->o[a] + lo * q->d[a] - e->c[a]);
                p->d[a] = (float)(u[a] * (m / nn));
            }
            p->tfar = isfinite(hi) ? (float)((hi - lo) * nn) : INFINITY;
            p->lo = lo;
            p->n = nn;
            p->valid = 1;
        }
    }
}

void td_embree_trace1(const td_embree *e, const td_embree_ray *r, size_t n, double *t)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t k = 0; k < n; k++) {
        const td_embree_ray *p = &r[k];
        struct RTCRayHit rh;
        t[k] = INFINITY;
        if (!p->valid)
            continue;
        rh.ray.org_x = p->o[0];
        rh.ray.org_y = p->o[1];
        rh.ray.org_z = p->o[2];
        rh.ray.dir_x = p->d[0];
        rh.ray.dir_y = p->d[1];
        rh.ray.dir_z = p->d[2];
        rh.ray.tnear = 0.0f;
        rh.ray.tfar = p->tfar;
        rh.ray.time = 0.0f;
        rh.ray.mask = 0xffffffffu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(e->scene, &ctx, &rh);
        if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID)
            t[k] = p->lo + (double)rh.ray.tfar / p->n;
    }
}

/* One 16-wide packet of prepared rays into an RTCRay16 (slots past m repeat ray 0 and are
 * masked off); returns whether any slot is valid. */
static int fill_ray16(const td_embree_ray *r, size_t m, struct RTCRay16 *ray, int valid[16])
{
    int any = 0;
    for (size_t l = 0; l < 16; l++) {
        const td_embree_ray *p = &r[l < m ? l : 0];
        valid[l] = l < m && p->valid ? -1 : 0;
        any |= valid[l];
        ray->org_x[l] = p->o[0];
        ray->org_y[l] = p->o[1];
        ray->org_z[l] = p->o[2];
        ray->dir_x[l] = p->d[0];
        ray->dir_y[l] = p->d[1];
        ray->dir_z[l] = p->d[2];
        ray->tnear[l] = 0.0f;
        ray->tfar[l] = p->tfar;
        ray->time[l] = 0.0f;
        ray->mask[l] = 0xffffffffu;
        ray->id[l] = (unsigned)l;
        ray->flags[l] = 0;
    }
    return any;
}

void td_embree_trace16(const td_embree *e, const td_embree_ray *r, size_t n, double *t)
{
    struct RTCIntersectContext ctx;
    struct RTCRayHit16 rh __attribute__((aligned(64)));
    int valid[16] __attribute__((aligned(64)));
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    for (size_t k0 = 0; k0 < n; k0 += 16) {
        size_t m = n - k0 < 16 ? n - k0 : 16;
        for (size_t l = 0; l < 16; l++) {
            rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
        }
        if (fill_ray16(r + k0, m, &rh.ray, valid))
            rtcIntersect16(valid, e->scene, &ctx, &rh);
        for (size_t l = 0; l < m; l++)
            t[k0 + l] = valid[l] && rh.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID
                            ? r[k0 + l].lo + (double)rh.ray.tfar[l] / r[k0 + l].n
                            : INFINITY;
    }
}

void td_embree_occluded16(const td_embree *e, const td_embree_ray *r, size_t n, uint8_t *occ)
{
    struct RTCIntersectContext ctx;
    struct RTCRay16 ray __attribute__((aligned(64)));
    int valid[16] __attribute__((aligned(64)));
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    for (size_t k0 = 0; k0 < n; k0 += 16) {
        size_t m = n - k0 < 16 ? n - k0 : 16;
        if (fill_ray16(r + k0, m, &ray, valid))
            rtcOccluded16(valid, e->scene, &ctx, &ray);
        /* rtcOccluded16 sets tfar to -inf where the ray is blocked */
        for (size_t l = 0; l < m; l++)
            occ[k0 + l] = valid[l] && ray.tfar[l] < 0.0f;
    }
}

double td_embree_trace(const td_embree *e, const td_ray *r)
{
    td_embree_ray p;
    double t;
    td_embree_prepare(e, r, 1, &p);
    td_embree_trace1(e, &p, 1, &t);
    return t;
}

void td_embree_trace_many(const td_embree *e, const td_ray *r, size_t n, double *t)
{
    for (size_t k = 0; k < n; k++)
        t[k] = td_embree_trace(e, &r[k]);
}
