/* bench_embree.c: Embree scenes for `terrad bench` (see bench_embree.h).
 *
 * Layout. Vertices: one float3 per grid sample, (i*sx, j*sy, z) minus the grid's centre
 * (void samples get z = 0; no primitive uses them). Triangle mesh: per valid cell
 * (i, j) the triangles (i,j) (i+1,j) (i,j+1) and (i+1,j) (i+1,j+1) (i,j+1), terrad's
 * south-east to north-west diagonal. GRID geometry: RTCGrid records over the same
 * vertex buffer (stride = grid width); Embree splits each grid quad (v0 = (x,y),
 * v1 = (x+1,y), v2 = (x+1,y+1), v3 = (x,y+1)) into (v0,v1,v3) and (v2,v3,v1), the same
 * diagonal v1-v3. A tile of terrad's grid without a void cell becomes one record; a
 * tile with voids becomes one record per run of valid cells in each cell row, so holes
 * stay holes. The benchmark checks both scenes against terrad's triangle surface on
 * every ray it times (agreement column of the report).
 *
 * Memory: rtcSetDeviceMemoryMonitorFunction counts every byte Embree allocates on the
 * device (BVH nodes, primitive blocks, and the buffers made by rtcSetNewGeometryBuffer);
 * resident = the count after rtcCommitScene and the geometry's release.
 *
 * Alternative rejected: timing td_embree_trace of embree_ref.c. It clips and converts
 * each ray in double inside the call, which adds a constant per ray that Embree's users
 * would not pay; the oracle needs that for exactness, the yardstick should be Embree at
 * its best. */
#include "bench_embree.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>

#include <embree3/rtcore.h>

static const char *const geom_names[] = {
#define TD_X_NAME(e, name) name,
    TD_BENCH_EMBREE_GEOM_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_bench_embree_geom_name(td_bench_embree_geom g)
{
    return (unsigned)g < TD_BENCH_EMBREE_GEOM_COUNT ? geom_names[g] : "unknown";
}

struct td_bench_embree {
    RTCDevice dev;
    RTCScene scene;
    double c[3];         /* local frame origin, dataset frame */
    double lo[3], hi[3]; /* box, dataset frame, padded */
    size_t prims;
    _Atomic int64_t cur, peak;
};

static bool monitor(void *ptr, ssize_t bytes, bool post)
{
    td_bench_embree *e = ptr;
    (void)post;
    int64_t now = atomic_fetch_add(&e->cur, (int64_t)bytes) + (int64_t)bytes;
    int64_t pk = atomic_load(&e->peak);
    while (now > pk && !atomic_compare_exchange_weak(&e->peak, &pk, now)) {
    }
    return true;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
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

td_status td_bench_embree_build(const td_grid *g, td_bench_embree_geom geom, int threads,
                                td_bench_embree **out, td_bench_embree_stats *st, td_err *err)
{
    td_status rc = TD_OK;
    td_bench_embree *e = NULL;
    RTCGeometry gm = NULL;
    size_t nv, ncell = 0, nprim = 0, tmp;
    char cfg[64];
    double t0;

    *out = NULL;
    memset(st, 0, sizeof *st);
    if (!td_mul_size((size_t)g->w, (size_t)g->h, &nv) || nv > 0xffffffffu ||
        !td_mul_size(nv, 2 * 3 * sizeof(unsigned), &tmp) || g->tile_log2 > 14) {
        rc = td_err_set(err, TD_ETOOBIG, "embree: %d x %d grid is too big for the benchmark scene",
                        (int)g->w, (int)g->h);
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
    snprintf(cfg, sizeof cfg, "threads=%d,verbose=0", threads > 0 ? threads : 0);
    e->dev = rtcNewDevice(cfg);
    if (!e->dev) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: rtcNewDevice(\"%s\") failed", cfg);
        goto out;
    }
    rtcSetDeviceMemoryMonitorFunction(e->dev, monitor, e);

    t0 = now_s();
    e->scene = rtcNewScene(e->dev);
    rtcSetSceneFlags(e->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(e->scene, RTC_BUILD_QUALITY_HIGH);
    for (int32_t j = 0; j + 1 < g->h; j++)
        for (int32_t i = 0; i + 1 < g->w; i++)
            ncell += (size_t)cell_valid(g, i, j);
    if (ncell > 0) {
        float *vb;
        gm = rtcNewGeometry(e->dev, geom == TD_BENCH_EMBREE_GRID ? RTC_GEOMETRY_TYPE_GRID
                                                                 : RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetGeometryBuildQuality(gm, RTC_BUILD_QUALITY_HIGH);
        vb = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                     3 * sizeof(float), nv);
        if (!vb) {
            rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu vertices", nv);
            goto out;
        }
        for (int32_t j = 0; j < g->h; j++) {
            for (int32_t i = 0; i < g->w; i++) {
                float *p = vb + 3 * ((size_t)j * (size_t)g->w + (size_t)i);
                double h = td_grid_at(g, i, j);
                p[0] = (float)((double)i * g->sx - e->c[0]);
                p[1] = (float)((double)j * g->sy - e->c[1]);
                p[2] = (float)(isnan(h) ? 0.0 : h - e->c[2]);
            }
        }
        if (geom == TD_BENCH_EMBREE_GRID) {
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
            size_t k = 0;
            nprim = 2 * ncell;
            ib = rtcSetNewGeometryBuffer(gm, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                         3 * sizeof(unsigned), nprim);
            if (!ib) {
                rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu triangles", nprim);
                goto out;
            }
            for (int32_t j = 0; j + 1 < g->h; j++) {
                for (int32_t i = 0; i + 1 < g->w; i++) {
                    if (!cell_valid(g, i, j))
                        continue;
                    unsigned v00 = (unsigned)j * (unsigned)g->w + (unsigned)i, v10 = v00 + 1;
                    unsigned v01 = v00 + (unsigned)g->w, v11 = v01 + 1;
                    ib[k++] = v00, ib[k++] = v10, ib[k++] = v01;
                    ib[k++] = v10, ib[k++] = v11, ib[k++] = v01;
                }
            }
        }
        rtcCommitGeometry(gm);
        rtcAttachGeometry(e->scene, gm);
        rtcReleaseGeometry(gm);
        gm = NULL;
    }
    rtcCommitScene(e->scene);
    st->build_seconds = now_s() - t0;
    if (rtcGetDeviceError(e->dev) != RTC_ERROR_NONE) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: scene build failed (error %d)",
                        (int)rtcGetDeviceError(e->dev));
        goto out;
    }
    e->prims = nprim;
    st->bytes = atomic_load(&e->cur);
    st->peak_bytes = atomic_load(&e->peak);
    st->primitives = nprim;
out:
    if (gm)
        rtcReleaseGeometry(gm);
    if (rc != TD_OK) {
        td_bench_embree_free(e);
        e = NULL;
    }
    *out = e;
    return rc;
}

void td_bench_embree_free(td_bench_embree *e)
{
    if (e) {
        if (e->scene)
            rtcReleaseScene(e->scene);
        if (e->dev)
            rtcReleaseDevice(e->dev);
        free(e);
    }
}

void td_bench_embree_prepare(const td_bench_embree *e, const td_ray *r, size_t n,
                             td_bench_eray *out)
{
    for (size_t k = 0; k < n; k++) {
        const td_ray *q = &r[k];
        td_bench_eray *p = &out[k];
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

void td_bench_embree_trace1(const td_bench_embree *e, const td_bench_eray *r, size_t n, double *t)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t k = 0; k < n; k++) {
        const td_bench_eray *p = &r[k];
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
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(e->scene, &ctx, &rh);
        if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID)
            t[k] = p->lo + (double)rh.ray.tfar / p->n;
    }
}

void td_bench_embree_trace16(const td_bench_embree *e, const td_bench_eray *r, size_t n, double *t)
{
    struct RTCIntersectContext ctx;
    struct RTCRayHit16 rh __attribute__((aligned(64)));
    int valid[16] __attribute__((aligned(64)));
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    for (size_t k0 = 0; k0 < n; k0 += 16) {
        size_t m = n - k0 < 16 ? n - k0 : 16;
        int any = 0;
        for (size_t l = 0; l < 16; l++) {
            const td_bench_eray *p = &r[k0 + (l < m ? l : 0)];
            valid[l] = l < m && p->valid ? -1 : 0;
            any |= valid[l];
            rh.ray.org_x[l] = p->o[0];
            rh.ray.org_y[l] = p->o[1];
            rh.ray.org_z[l] = p->o[2];
            rh.ray.dir_x[l] = p->d[0];
            rh.ray.dir_y[l] = p->d[1];
            rh.ray.dir_z[l] = p->d[2];
            rh.ray.tnear[l] = 0.0f;
            rh.ray.tfar[l] = p->tfar;
            rh.ray.time[l] = 0.0f;
            rh.ray.mask[l] = 0xffffffffu;
            rh.ray.id[l] = (unsigned)l;
            rh.ray.flags[l] = 0;
            rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
        }
        if (any)
            rtcIntersect16(valid, e->scene, &ctx, &rh);
        for (size_t l = 0; l < m; l++)
            t[k0 + l] = valid[l] && rh.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID
                            ? r[k0 + l].lo + (double)rh.ray.tfar[l] / r[k0 + l].n
                            : INFINITY;
    }
}
