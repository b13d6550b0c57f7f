/* gridedit.c: heights edits as copy-on-write of a grid (see gridedit.h). Called by the
 * tile store (server/tilestore.c, td_store_edit) for PUT .../heights and by `terrad
 * render --edit`. Every check happens before anything is allocated or copied, so a bad
 * region or body changes nothing.
 *
 * The copy is the whole height array (memcpy) and td_grid_finish over it: one pass over
 * W*H floats. Rejected: copying only the touched tiles' samples, which needs heights
 * stored per tile, and so every tracer's indexing changed, for a saving the benchmark
 * in README puts at a few milliseconds on the demo grids. */
#include "gridedit.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* One of the region's integers: digits only, 0 .. INT32_MAX. */
static td_status parse_one(const char *s, const char *field, int32_t *out, td_err *err)
{
    td_status rc = TD_OK;
    char *end = NULL;
    long long v = 0;

    if (!s || !*s) {
        rc = td_err_field(err, TD_EINVAL, field, "missing (the region is ?x=&y=&w=&h=)");
        goto out;
    }
    for (const char *p = s; *p; p++)
        if (*p < '0' || *p > '9') {
            rc = td_err_field(err, TD_EINVAL, field, "'%.40s' is not a non-negative integer", s);
            goto out;
        }
    errno = 0;
    v = strtoll(s, &end, 10);
    if (errno || *end || v > INT32_MAX) {
        rc = td_err_field(err, TD_EINVAL, field, "'%.40s' is out of range", s);
        goto out;
    }
    *out = (int32_t)v;
out:
    return rc;
}

td_status td_grid_edit_parse(const td_grid *g, const char *x, const char *y, const char *w,
                             const char *h, int64_t max_samples, td_grid_region *out,
                             td_err *err)
{
    td_status rc;
    td_grid_region r = {0, 0, 0, 0};

    if (max_samples <= 0)
        max_samples = TD_GRID_EDIT_MAX_SAMPLES;
    rc = parse_one(x, "x", &r.x, err);
    if (!rc)
        rc = parse_one(y, "y", &r.y, err);
    if (!rc)
        rc = parse_one(w, "w", &r.w, err);
    if (!rc)
        rc = parse_one(h, "h", &r.h, err);
    if (rc)
        goto out;
    if (r.x >= g->w) {
        rc = td_err_field(err, TD_EINVAL, "x", "column %d is outside the grid (columns 0 .. %d)",
                          (int)r.x, (int)g->w - 1);
    } else if (r.y >= g->h) {
        rc = td_err_field(err, TD_EINVAL, "y", "row %d is outside the grid (rows 0 .. %d, 0 north)",
                          (int)r.y, (int)g->h - 1);
    } else if (r.w < 1 || r.w > g->w - r.x) {
        rc = td_err_field(err, TD_EINVAL, "w", "%d columns from column %d leave the grid (%d columns)",
                          (int)r.w, (int)r.x, (int)g->w);
    } else if (r.h < 1 || r.h > g->h - r.y) {
        rc = td_err_field(err, TD_EINVAL, "h", "%d rows from row %d leave the grid (%d rows)",
                          (int)r.h, (int)r.y, (int)g->h);
    } else if ((int64_t)r.w * r.h > max_samples) {
        rc = td_err_field(err, TD_ETOOBIG, "w", "%d x %d samples are more than one edit may carry (%lld)",
                          (int)r.w, (int)r.h, (long long)max_samples);
    }
    if (!rc)
        *out = r;
out:
    return rc;
}

td_status td_grid_edit_decode(const td_grid_region *r, const void *body, size_t len,
                              float **out, td_err *err)
{
    td_status rc = TD_OK;
    size_t n = 0, bytes = 0;
    const unsigned char *b = body;
    float *z = NULL;

    *out = NULL;
    if (r->w < 1 || r->h < 1 || !td_mul_size((size_t)r->w, (size_t)r->h, &n) ||
        !td_mul_size(n, 4, &bytes)) {
        rc = td_err_field(err, TD_EINVAL, "w", "%d x %d is not a region", (int)r->w, (int)r->h);
        goto out;
    }
    if (len != bytes) {
        rc = td_err_field(err, TD_EINVAL, "body", "%zu bytes, but %d x %d float32 samples are %zu bytes",
                          len, (int)r->w, (int)r->h, bytes);
        goto out;
    }
    z = malloc(bytes ? bytes : 1);
    if (!z) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %zu samples", n);
        goto out;
    }
    for (size_t k = 0; k < n; k++) {
        uint32_t u = (uint32_t)b[4 * k] | (uint32_t)b[4 * k + 1] << 8 |
                     (uint32_t)b[4 * k + 2] << 16 | (uint32_t)b[4 * k + 3] << 24;
        float v;
        memcpy(&v, &u, sizeof v);
        if (isinf(v)) {
            rc = td_err_field(err, TD_EINVAL, "body", "sample %zu (row %zu, column %zu) is %s; "
                              "heights are finite, or NaN for a void", k, k / (size_t)r->w,
                              k % (size_t)r->w, v > 0 ? "+inf" : "-inf");
            goto out;
        }
        z[k] = isnan(v) ? NAN : v;
    }
    *out = z;
    z = NULL;
out:
    free(z);
    return rc;
}

td_status td_grid_edit_apply(const td_grid *g, const td_grid_region *r, const float *z,
                             td_grid **out, td_err *err)
{
    td_status rc;
    td_grid_limits lim = {g->w, g->h, 0}; /* the copy is g's size: g passed its limits */
    td_grid *c = NULL;

    *out = NULL;
    rc = td_grid_create(g->w, g->h, g->sx, g->sy, g->tile_log2, &lim, &c, err);
    if (rc)
        goto out;
    c->geo = g->geo;
    memcpy(c->z, g->z, (size_t)g->w * (size_t)g->h * sizeof(float));
    for (int32_t row = 0; row < r->h; row++) {
        int32_t j = g->h - 1 - (r->y + row);
        memcpy(c->z + (size_t)j * (size_t)g->w + (size_t)r->x, z + (size_t)row * (size_t)r->w,
               (size_t)r->w * sizeof(float));
    }
    rc = td_grid_finish(c, err);
    if (rc)
        goto out;
    *out = c;
    c = NULL;
out:
    td_grid_free(c);
    return rc;
}

void td_grid_edit_read(const td_grid *g, const td_grid_region *r, unsigned char *out)
{
    for (int32_t row = 0; row < r->h; row++) {
        const float *src = g->z + (size_t)(g->h - 1 - (r->y + row)) * (size_t)g->w + (size_t)r->x;
        for (int32_t col = 0; col < r->w; col++) {
            uint32_t u;
            memcpy(&u, &src[col], sizeof u);
            for (int b = 0; b < 4; b++)
                *out++ = (unsigned char)(u >> (8 * b));
        }
    }
}

/* The tiles along one axis holding samples lo .. hi: tile t holds samples t*T .. t*T+T. */
static void tile_span(int32_t lo, int32_t hi, int32_t T, int32_t ntiles, int32_t *t0, int32_t *t1)
{
    int32_t a = (lo + T - 1) / T - 1, b = hi / T;
    *t0 = a < 0 ? 0 : a;
    *t1 = b > ntiles - 1 ? ntiles - 1 : b;
}

td_status td_grid_edit_tiles(const td_grid *g, const td_grid_region *r, size_t **tiles,
                             size_t *n, td_err *err)
{
    int32_t T = td_grid_tile_size(g), tx0, tx1, ty0, ty1;

    tile_span(r->x, r->x + r->w - 1, T, g->tiles_x, &tx0, &tx1);
    tile_span(g->h - r->y - r->h, g->h - 1 - r->y, T, g->tiles_y, &ty0, &ty1);
    return td_grid_tile_range(g, tx0, tx1, ty0, ty1, tiles, n, err);
}

td_status td_grid_edit_file(const td_grid *g, const td_grid_region *r, const char *path,
                            td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    FILE *f = NULL;
    unsigned char *body = NULL;
    size_t want = (size_t)r->w * (size_t)r->h * 4, got = 0; /* r passed td_grid_edit_parse */
    float *z = NULL;

    *out = NULL;
    f = fopen(path, "rb");
    body = malloc(want + 1);
    if (!f || !body) {
        rc = td_err_set(err, f ? TD_ENOMEM : TD_EIO, "%s: %s", path, f ? "out of memory" : strerror(errno));
        goto out;
    }
    got = fread(body, 1, want + 1, f);
    if (ferror(f)) {
        rc = td_err_set(err, TD_EIO, "%s: read error", path);
        goto out;
    }
    rc = td_grid_edit_decode(r, body, got, &z, err);
    if (rc) {
        td_err why = {"bad heights", ""};
        if (err)
            why = *err;
        td_err_set(err, rc, "%s: %s", path, why.msg);
        if (err)
            memcpy(err->field, why.field, sizeof err->field);
        goto out;
    }
    rc = td_grid_edit_apply(g, r, z, out, err);
out:
    if (f)
        fclose(f);
    free(body);
    free(z);
    return rc;
}
