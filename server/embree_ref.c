/* embree_ref.c: the Embree 3 reference scene (see embree_ref.h).
 *
 * Layout: one triangle geometry; vertex (I, J) of the (possibly refined) lattice is
 * vertex I + J * VW, VW = n*(w-1) + 1; cell (i, j) sub-quad (a, b) gives triangles
 * SW = (I,J) (I+1,J) (I,J+1) and NE = (I+1,J) (I+1,J+1) (I,J+1) with I = n*i + a,
 * J = n*j + b: the same diagonal as terrad's (south-east to north-west). Refined vertices
 * on a cell edge are interpolated along that edge only, so a void cell next to a valid
 * one cannot leak NaN into the shared edge.
 *
 * Error bound of the refinement: on a sub-square of side 1/n (in cell units) the
 * bilinear patch differs from its linear interpolant only by the d*u*v term, and
 * u*v deviates from the plane through three corners of a triangle by at most
 * (1/n)^2 / 4; so |surface - mesh| <= |z00 - z10 - z01 + z11| / (4 n^2) per cell. */
#include "embree_ref.h"

#include <math.h>
#include <stdlib.h>

#include <embree3/rtcore.h>

struct td_embree {
    RTCDevice dev;
    RTCScene scene;
    double c[3];     /* local frame origin in the dataset frame */
    double lo[3], hi[3]; /* bounding box (dataset frame), padded */
    double bound;    /* refinement error bound, metres */
    size_t ntri;
};

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

td_status td_embree_build(const td_grid *g, int refine, td_embree **out, td_err *err)
{
    td_status rc = TD_OK;
    td_embree *e = NULL;
    RTCGeometry geom = NULL;
    size_t vw, vh, nv, ncell = 0, ntri, tmp;
    float *vb;
    unsigned *ib;

    *out = NULL;
    if (refine < 1 || refine > 64) {
        rc = td_err_set(err, TD_ERANGE, "embree: refinement %d is out of range (1 .. 64)", refine);
        goto out;
    }
    vw = (size_t)refine * (size_t)(g->w - 1) + 1;
    vh = (size_t)refine * (size_t)(g->h - 1) + 1;
    for (int32_t j = 0; j + 1 < g->h; j++)
        for (int32_t i = 0; i + 1 < g->w; i++)
            ncell += (size_t)cell_valid(g, i, j);
    if (!td_mul_size(vw, vh, &nv) || nv > 0xffffffffu ||
        !td_mul_size(ncell, (size_t)refine * (size_t)refine * 2, &ntri) || ntri > 0x7fffffffu ||
        !td_mul_size(ntri, 3 * sizeof(unsigned), &tmp)) {
        rc = td_err_set(err, TD_ETOOBIG, "embree: %d x %d grid refined %d times is too big",
                        (int)g->w, (int)g->h, refine);
        goto out;
    }
    e = calloc(1, sizeof *e);
    if (!e) {
        rc = td_err_set(err, TD_ENOMEM, "embree: out of memory");
        goto out;
    }
    e->ntri = ntri;
    e->c[0] = 0.5 * (g->w - 1) * g->sx;
    e->c[1] = 0.5 * (g->h - 1) * g->sy;
    e->c[2] = isnan(g->zmin) ? 0.0 : 0.5 * ((double)g->zmin + (double)g->zmax);
    e->lo[0] = -1.0;
    e->lo[1] = -1.0;
    e->hi[0] = (g->w - 1) * g->sx + 1.0;
    e->hi[1] = (g->h - 1) * g->sy + 1.0;
    e->lo[2] = isnan(g->zmin) ? 0.0 : (double)g->zmin - 1.0 - 1e-6 * fabs(g->zmin);
    e->hi[2] = isnan(g->zmax) ? 0.0 : (double)g->zmax + 1.0 + 1e-6 * fabs(g->zmax);
    e->dev = rtcNewDevice(NULL);
    if (!e->dev) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: rtcNewDevice failed");
        goto out;
    }
    e->scene = rtcNewScene(e->dev);
    rtcSetSceneFlags(e->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(e->scene, RTC_BUILD_QUALITY_HIGH);
    if (ntri > 0) {
        geom = rtcNewGeometry(e->dev, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
        vb = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                     3 * sizeof(float), nv);
        ib = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                     3 * sizeof(unsigned), ntri);
        if (!vb || !ib) {
            rc = td_err_set(err, TD_ENOMEM, "embree: out of memory for %zu triangles", ntri);
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
        size_t k = 0;
        for (int32_t j = 0; j + 1 < g->h; j++) {
            for (int32_t i = 0; i + 1 < g->w; i++) {
                if (!cell_valid(g, i, j))
                    continue;
                double d = sample(g, i, j) - sample(g, i + 1, j) - sample(g, i, j + 1) +
                           sample(g, i + 1, j + 1);
                if (refine > 1 && fabs(d) / (4.0 * refine * refine) > e->bound)
                    e->bound = fabs(d) / (4.0 * refine * refine);
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
        rtcCommitGeometry(geom);
        rtcAttachGeometry(e->scene, geom);
    }
    rtcCommitScene(e->scene);
    if (rtcGetDeviceError(e->dev) != RTC_ERROR_NONE) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "embree: scene build failed (error %d)",
                        (int)rtcGetDeviceError(e->dev));
        goto out;
    }
out:
    if (geom)
        rtcReleaseGeometry(geom);
    if (rc != TD_OK) {
        td_embree_free(e);
        e = NULL;
    }
    *out = e;
    return rc;
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

size_t td_embree_triangles(const td_embree *e) { return e->ntri; }

double td_embree_trace(const td_embree *e, const td_ray *r)
{
    double lo = r->tmin, hi = r->tmax, res = INFINITY;
    int ok = e->ntri > 0;
    for (int a = 0; a < 3 && ok; a++) {
        if (r->d[a] == 0.0) {
            ok = r->o[a] >= e->lo[a] && r->o[a] <= e->hi[a];
        } else {
            double ta = (e->lo[a] - r->o[a]) / r->d[a], tb = (e->hi[a] - r->o[a]) / r->d[a];
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
        double m = fmax(fabs(r->d[0]), fmax(fabs(r->d[1]), fabs(r->d[2])));
        double q[3] = {r->d[0] / m, r->d[1] / m, r->d[2] / m};
        double n = m * sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
        struct RTCRayHit rh;
        struct RTCIntersectContext ctx;
        rh.ray.org_x = (float)(r->o[0] + lo * r->d[0] - e->c[0]);
        rh.ray.org_y = (float)(r->o[1] + lo * r->d[1] - e->c[1]);
        rh.ray.org_z = (float)(r->o[2] + lo * r->d[2] - e->c[2]);
        rh.ray.dir_x = (float)(q[0] * (m / n));
        rh.ray.dir_y = (float)(q[1] * (m / n));
        rh.ray.dir_z = (float)(q[2] * (m / n));
        rh.ray.tnear = 0.0f;
        rh.ray.tfar = isfinite(hi) ? (float)((hi - lo) * n) : INFINITY;
        rh.ray.time = 0.0f;
        rh.ray.mask = 0xffffffffu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcInitIntersectContext(&ctx);
        rtcIntersect1(e->scene, &ctx, &rh);
        if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID)
            res = lo + (double)rh.ray.tfar / n;
    }
    return res;
}

void td_embree_trace_many(const td_embree *e, const td_ray *r, size_t n, double *t)
{
    for (size_t k = 0; k < n; k++)
        t[k] = td_embree_trace(e, &r[k]);
}
