/* demraw.c: the raw float32 loader (`<name>.f32` + `<name>.json`).
 *
 * File: width*height little-endian float32, row-major, row 0 = north edge, nothing else;
 * its size must be exactly width*height*4 (a shorter file is truncated, a longer one
 * does not match its sidecar: both refused before any allocation). Rows are read one at
 * a time straight into their south-based place in the grid (grid.h), so no second copy
 * of the heights is made.
 *
 * Voids: samples equal to the sidecar's numeric nodata become NaN. NaN samples in the
 * file are voids only when the sidecar says "nodata": "nan"; otherwise they are refused
 * (a NaN nobody declared is more likely a broken export than a hole). Infinities are
 * always refused. */
#include "demraw.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

#include "demutil.h"

static int host_is_little(void)
{
    const uint16_t one = 1;
    unsigned char b;
    memcpy(&b, &one, 1);
    return b == 1;
}

static void swap32(float *v, size_t n)
{
    for (size_t k = 0; k < n; k++) {
        uint32_t u;
        memcpy(&u, &v[k], 4);
        u = (u >> 24) | ((u >> 8) & 0xff00u) | ((u << 8) & 0xff0000u) | (u << 24);
        memcpy(&v[k], &u, 4);
    }
}

td_status td_demraw_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    td_demside sc;
    td_grid *g = NULL;
    FILE *f = NULL;
    struct stat st;
    size_t n = 0, want = 0;
    double sx = 0, sy = 0;
    const int little = host_is_little();

    *out = NULL;
    rc = td_demutil_sidecar_read(path, 1, 1, &sc, err);
    if (rc != TD_OK)
        goto out;
    rc = td_demutil_check_limits(path, o, sc.width, sc.height, err);
    if (rc != TD_OK)
        goto out;
    f = fopen(path, "rb");
    if (!f || fstat(fileno(f), &st) != 0) {
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
        goto out;
    }
    if (!td_mul_size((size_t)sc.width, (size_t)sc.height, &n) || !td_mul_size(n, 4, &want)) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: %ld x %ld samples overflow", path, (long)sc.width,
                        (long)sc.height);
        goto out;
    }
    if (!S_ISREG(st.st_mode) || (uint64_t)st.st_size != (uint64_t)want) {
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: %lld bytes, but its sidecar %s says %ld x %ld float32 = %llu bytes (%s)",
                        path, (long long)st.st_size, sc.path, (long)sc.width, (long)sc.height,
                        (unsigned long long)want,
                        (uint64_t)st.st_size < (uint64_t)want ? "truncated" : "too long");
        goto out;
    }
    if (sc.geo.kind == TD_GEO_LONLAT)
        td_demutil_georef_from_north(&sc.geo, sc.height);
    rc = td_demutil_spacing(path, o, &sc, &sc.geo, sc.width, sc.height, &sx, &sy, err);
    if (rc != TD_OK)
        goto out;
    if (sc.geo.kind == TD_GEO_PROJECTED) {
        sc.geo.dx = sx;
        sc.geo.dy = sy;
        td_demutil_georef_from_north(&sc.geo, sc.height);
    }
    rc = td_demutil_create(path, o, sc.width, sc.height, sx, sy, &g, err);
    if (rc != TD_OK)
        goto out;
    g->geo = sc.geo;
    for (int32_t r = 0; r < g->h && rc == TD_OK; r++) {
        float *row = g->z + (size_t)(g->h - 1 - r) * (size_t)g->w;
        if (fread(row, 4, (size_t)g->w, f) != (size_t)g->w) {
            rc = td_err_set(err, TD_EIO, "%s: read failed at row %ld (%s)", path, (long)r,
                            ferror(f) ? strerror(errno) : "file shrank while reading");
            break;
        }
        if (!little)
            swap32(row, (size_t)g->w);
        for (int32_t i = 0; i < g->w; i++) {
            float v = row[i];
            if (isnan(v)) {
                if (sc.nodata_kind != TD_NODATA_NAN) {
                    rc = td_err_set(err, TD_EFORMAT,
                                    "%s: NaN sample at column %ld, row %ld (if NaN marks voids, say "
                                    "\"nodata\": \"nan\" in %s)",
                                    path, (long)i, (long)r, sc.path);
                    break;
                }
            } else if (isinf(v)) {
                rc = td_err_set(err, TD_ERANGE, "%s: infinite sample at column %ld, row %ld", path,
                                (long)i, (long)r);
                break;
            } else if (sc.nodata_kind == TD_NODATA_VALUE && v == (float)sc.nodata) {
                row[i] = NAN;
            }
        }
    }
    if (rc != TD_OK)
        goto out;
    rc = td_demutil_finish(path, g, err);
out:
    if (f)
        fclose(f);
    if (rc != TD_OK) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}
