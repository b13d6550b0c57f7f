/* lod.c: builds the coarse levels of lod.h.
 *
 * Why a filtered subsample and not the max-mipmap: the max pyramid bounds the terrain
 * (right for skipping, wrong for display: far ridges would swell by up to a cell's
 * relief), while a subsample of the filtered heights keeps the coarse surface within the
 * terrain's own range and puts every coarse sample exactly over a base sample, so the
 * dataset frame and the georeference stay the same at every level. */
#include "lod.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const grid_names[] = {
#define TD_X_NAME(e, name) name,
    TD_LOD_GRID_LIST(TD_X_NAME)
#undef TD_X_NAME
};

td_status td_lod_grid_parse(const char *name, td_lod_grid *out)
{
    int i = td_name_index(grid_names, TD_LOD_GRID_COUNT, name);
    if (i >= 0)
        *out = (td_lod_grid)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

const char *td_lod_grid_name(td_lod_grid g)
{
    return (unsigned)g < TD_LOD_GRID_COUNT ? grid_names[g] : "?";
}

/* The 1-2-1 weighted mean of src's samples around node (ci, cj), clamped into src; void
 * where that node is void (voids around it do not count). */
static float filtered(const td_grid *src, int32_t ci, int32_t cj)
{
    static const double wt[3] = {1.0, 2.0, 1.0};
    double sum = 0.0, wsum = 0.0;
    float v = NAN;
    ci = ci < src->w - 1 ? ci : src->w - 1;
    cj = cj < src->h - 1 ? cj : src->h - 1;
    if (!isnan(td_grid_at(src, ci, cj))) {
        for (int dj = -1; dj <= 1; dj++) {
            for (int di = -1; di <= 1; di++) {
                int32_t i = ci + di, j = cj + dj;
                if (i < 0 || j < 0 || i >= src->w || j >= src->h)
                    continue;
                float z = td_grid_at(src, i, j);
                if (!isnan(z)) {
                    sum += wt[di + 1] * wt[dj + 1] * (double)z;
                    wsum += wt[di + 1] * wt[dj + 1];
                }
            }
        }
        v = (float)(sum / wsum);
    }
    return v;
}

/* Level from the previous one (spacing doubles). */
static td_status halve(const td_grid *src, td_grid **out, td_err *err)
{
    td_status rc;
    int32_t w = (src->w - 1 + 1) / 2 + 1, h = (src->h - 1 + 1) / 2 + 1; /* ceil((n-1)/2) + 1 */
    td_grid *g = NULL;

    rc = td_grid_create(w, h, src->sx * 2.0, src->sy * 2.0, src->tile_log2, NULL, &g, err);
    if (rc)
        goto out;
    for (int32_t J = 0; J < h; J++)
        for (int32_t I = 0; I < w; I++)
            g->z[(size_t)J * (size_t)w + (size_t)I] = filtered(src, 2 * I, 2 * J);
    g->geo = src->geo;
    g->geo.dx *= 2.0;
    g->geo.dy *= 2.0;
    rc = td_grid_finish(g, err);
out:
    if (rc) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}

/* The isometric twin of square level `sq` (made from `src` by halve): even rows at sq's
 * nodes, odd rows' samples between them (the finer level's odd nodes), filtered alike;
 * kept as two-byte vertices (the paper's storage, tiles of 2^TD_LOD_ISO_TILE_LOG2), which
 * the walk decodes: the floats are only the packing's input. */
static td_status iso_twin(const td_grid *src, const td_grid *sq, td_iso **out, td_err *err)
{
    td_iso *l = NULL;
    td_status rc = td_iso_create(sq->w, sq->h, sq->sx, sq->sy, &l, err);
    *out = NULL;
    if (rc)
        goto out;
    for (int32_t r = 0; r < l->ny; r++) {
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            /* node of src under sample (r, c): x = td_iso_x / src->sx, exact halves */
            int32_t i = !(r & 1) ? 2 * c : (c == 0 ? 0 : (c == l->nx ? 2 * (l->nx - 1) : 2 * c - 1));
            l->z[td_iso_row_offset(l->nx, r) + (size_t)c] = filtered(src, i, 2 * r);
        }
    }
    td_iso_finish(l);
    rc = td_iso_pack_lattice(l, TD_LOD_ISO_TILE_LOG2, out, err);
out:
    td_iso_free(l);
    return rc;
}

td_status td_lod_build(const td_grid *base, int levels, const td_accel_opts *o, td_lod **out,
                       td_err *err)
{
    td_status rc = TD_OK;
    td_lod *l = calloc(1, sizeof *l);
    const td_grid *prev = base;

    *out = NULL;
    if (!l) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for level of detail");
        goto out;
    }
    if (levels > TD_LOD_MAX)
        levels = TD_LOD_MAX;
    for (int k = 1; k <= levels && prev->w > 2 && prev->h > 2; k++) {
        td_accel_stats st;
        rc = halve(prev, &l->grid[k], err);
        if (rc)
            goto out;
        rc = td_accel_build(l->grid[k], o, &l->accel[k], &st, err);
        if (rc)
            goto out;
        l->view[k].grid = l->grid[k];
        l->view[k].accel = l->accel[k]->tiles;
        l->bytes += td_grid_bytes(l->grid[k]->w, l->grid[k]->h, l->grid[k]->tile_log2) +
                    st.maxmip_bytes + st.planes_bytes;
        l->levels = k;
        prev = l->grid[k];
    }
out:
    if (rc) {
        td_lod_free(l);
        l = NULL;
    }
    *out = l;
    return rc;
}

void td_lod_free(td_lod *l)
{
    if (l) {
        for (int k = 1; k <= TD_LOD_MAX; k++) {
            td_accel_free(l->accel[k]);
            td_iso_free(l->iso[k]);
            td_grid_free(l->grid[k]);
        }
        free(l);
    }
}

td_status td_lod_add_iso(td_lod *l, const td_grid *base, td_err *err)
{
    td_status rc = TD_OK;
    td_iso *iso[TD_LOD_MAX + 1] = {NULL};
    uint64_t bytes = 0;
    for (int k = 1; k <= l->levels && !rc; k++) {
        rc = iso_twin(k == 1 ? base : l->grid[k - 1], l->grid[k], &iso[k], err);
        if (!rc)
            bytes += td_iso_bytes(iso[k]);
    }
    for (int k = 1; k <= l->levels; k++) {
        if (rc) {
            td_iso_free(iso[k]);
        } else {
            td_iso_free(l->iso[k]);
            l->iso[k] = iso[k];
        }
    }
    if (!rc)
        l->bytes += bytes;
    return rc;
}

void td_lod_iso_trace(const td_lod *l, int level, const td_ray *r, td_hit *hit)
{
    const td_grid *g = l->grid[level];
    td_iso_trace(l->iso[level], r, hit);
    if (hit->t < INFINITY) {
        double fi = floor(hit->p[0] / g->sx), fj = floor(hit->p[1] / g->sy);
        hit->ci = !(fi >= 0.0) ? 0 : (fi > g->w - 2 ? g->w - 2 : (int32_t)fi);
        hit->cj = !(fj >= 0.0) ? 0 : (fj > g->h - 2 ? g->h - 2 : (int32_t)fj);
    }
}
