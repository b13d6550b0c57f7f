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

/* Level from the previous one (spacing doubles). */
static td_status halve(const td_grid *src, td_grid **out, td_err *err)
{
    td_status rc;
    int32_t w = (src->w - 1 + 1) / 2 + 1, h = (src->h - 1 + 1) / 2 + 1; /* ceil((n-1)/2) + 1 */
    td_grid *g = NULL;
    static const double wt[3] = {1.0, 2.0, 1.0};

    rc = td_grid_create(w, h, src->sx * 2.0, src->sy * 2.0, src->tile_log2, NULL, &g, err);
    if (rc)
        goto out;
    for (int32_t J = 0; J < h; J++) {
        for (int32_t I = 0; I < w; I++) {
            int32_t ci = 2 * I < src->w - 1 ? 2 * I : src->w - 1;
            int32_t cj = 2 * J < src->h - 1 ? 2 * J : src->h - 1;
            double sum = 0.0, wsum = 0.0;
            float v = NAN;
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
            g->z[(size_t)J * (size_t)w + (size_t)I] = v;
        }
    }
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
            td_grid_free(l->grid[k]);
        }
        free(l);
    }
}
