/* demraw.c: the raw float32 loader (`<name>.f32` + `<name>.json`).
 *
 * File: width*height little-endian float32, row-major, row 0 = north edge, nothing else;
 * its size must be exactly width*height*4 (a shorter file is truncated, a longer one
 * does not match its sidecar: both refused before any allocation). Rows are read straight
 * into their south-based place in the grid (grid.h), a batch of them a call, so no second
 * copy of the heights is made.
 *
 * Voids: samples equal to the sidecar's numeric nodata become NaN. NaN samples in the
 * file are voids only when the sidecar says "nodata": "nan"; otherwise they are refused
 * (a NaN nobody declared is more likely a broken export than a hole). Infinities are
 * always refused. */
#include "demraw.h"

#include <float.h>
#include <stdio.h>
#include <string.h>
#include <errno.h>
#include <sys/uio.h>
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

td_status td_demraw_open(const char *path, const td_dem_opts *o, td_demside *sc, FILE **f,
                         td_err *err)
{
    td_status rc;
    struct stat st;
    size_t n = 0, want = 0;

    rc = td_demutil_sidecar_read(path, 1, 1, sc, err);
    if (rc == TD_OK)
        rc = td_demutil_check_limits(path, o, sc->width, sc->height, err);
    if (rc == TD_OK)
        rc = td_demutil_open(path, f, &st, err);
    if (rc != TD_OK)
        goto out;
    if (!td_mul_size((size_t)sc->width, (size_t)sc->height, &n) || !td_mul_size(n, 4, &want)) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: %ld x %ld samples overflow", path, (long)sc->width,
                        (long)sc->height);
    } else if (!S_ISREG(st.st_mode) || (uint64_t)st.st_size != (uint64_t)want) {
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: %lld bytes, but its sidecar %s says %ld x %ld float32 = %llu bytes (%s)",
                        path, (long long)st.st_size, sc->path, (long)sc->width, (long)sc->height,
                        (unsigned long long)want,
                        (uint64_t)st.st_size < (uint64_t)want ? "truncated" : "too long");
    }
out:
    return rc;
}

void td_demraw_rules(const td_demside *sc, td_demutil_f32 *p)
{
    *p = (td_demutil_f32){.nan_void = sc->nodata_kind == TD_NODATA_NAN,
                          .inf_refused = 1,
                          .has_nodata = sc->nodata_kind == TD_NODATA_VALUE,
                          .nodata = (float)sc->nodata,
                          .scale = 1.0,
                          .offset = -0.0, /* with scale 1: every sample as it is */
                          .max_abs = FLT_MAX};
    snprintf(p->nan_why, sizeof p->nan_why, " (if NaN marks voids, say \"nodata\": \"nan\" in %s)",
             sc->path);
}

/* A row of the file's bytes in place: to the host's order, then checked. */
static td_status raw_row_finish(const char *path, const td_demutil_f32 *p, float *row, int32_t w, int32_t r,
                                td_err *err)
{
    if (!host_is_little())
        swap32(row, (size_t)w);
    return td_demutil_f32_row(path, p, row, w, r, err);
}

td_status td_demraw_row(const char *path, const td_demutil_f32 *p, FILE *f, float *row, int32_t w,
                        int32_t r, td_err *err)
{
    td_status rc = td_demutil_read_row(path, f, row, 4, (size_t)w, r, err);
    if (rc == TD_OK)
        rc = raw_row_finish(path, p, row, w, r, err);
    return rc;
}

/* The samples, TD_RAW_BATCH rows a call: one preadv() whose vectors point at each row's
 * south-based place in the grid (the kernel copies from the page cache straight there),
 * then those rows are checked while they are still in the cache. trinidad's 11.5 MB on
 * the shared 2-core VM (2026-12-02, rd.c in the closing note, medians of 3): a private
 * populated mapping of the file copied row by row 8.4 ms, pread() a row at a time 5.1 ms,
 * preadv() of 1024 rows a call 2.4 ms: the copy from a user mapping of the page cache
 * paid a TLB miss every 4 kB page, where the kernel's copy reads its own linear map.
 * 0: not read this way (preadv refused at the first call: the caller reads; *rc as it
 * was). A short count later is a file that shrank under us: an error, as fread's. */
#define TD_RAW_BATCH 64
static int raw_readv(const char *path, const td_demutil_f32 *p, FILE *f, td_grid *g, td_status *rc,
                     td_err *err)
{
    const size_t row = (size_t)g->w * sizeof(float);
    struct iovec iov[TD_RAW_BATCH];
    int done = 1;
    for (int32_t r0 = 0; r0 < g->h && *rc == TD_OK && done; r0 += TD_RAW_BATCH) {
        const int n = g->h - r0 < TD_RAW_BATCH ? (int)(g->h - r0) : TD_RAW_BATCH;
        for (int k = 0; k < n; k++)
            iov[k] = (struct iovec){.iov_base = td_demutil_file_row(g, r0 + k), .iov_len = row};
        ssize_t got = preadv(fileno(f), iov, n, (off_t)((size_t)r0 * row));
        if (got < 0 && r0 == 0) {
            done = 0;
        } else if (got != (ssize_t)(row * (size_t)n)) {
            *rc = td_err_set(err, TD_EIO, "%s: read failed at row %ld (%s)", path, (long)r0,
                             got < 0 ? strerror(errno) : "file shrank while reading");
        }
        for (int k = 0; k < n && *rc == TD_OK && done; k++)
            *rc = raw_row_finish(path, p, iov[k].iov_base, g->w, r0 + k, err);
    }
    return done;
}

/* The samples, one row at a time straight into its south-based place (where preadv is
 * refused): rows of a page or more unbuffered, each one read() into the grid
 * (through stdio's 4 kB buffer, a second copy of most of the file and twice the calls:
 * trinidad's load about 11.5 -> 9.5 ms of CPU, medians of 11 and 15 on the shared
 * machine). */
static td_status raw_read(const char *path, const td_demside *sc, FILE *f, td_grid *g,
                          td_err *err)
{
    td_status rc = TD_OK;
    td_demutil_f32 p;
    td_demraw_rules(sc, &p);
    int done = raw_readv(path, &p, f, g, &rc, err);
    if (!done && (size_t)g->w * sizeof(float) >= 4096)
        setvbuf(f, NULL, _IONBF, 0); /* before any read of f */
    for (int32_t r = 0; !done && r < g->h && rc == TD_OK; r++)
        rc = td_demraw_row(path, &p, f, td_demutil_file_row(g, r), g->w, r, err);
    return rc;
}

td_status td_demraw_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc;
    td_demside sc;
    td_grid *g = NULL;
    FILE *f = NULL;
    double sx = 0, sy = 0;

    rc = td_demraw_open(path, o, &sc, &f, err);
    if (rc == TD_OK)
        rc = td_demutil_side_georef(path, o, &sc, sc.width, sc.height, &sx, &sy, err);
    if (rc == TD_OK)
        rc = td_demutil_create(path, o, sc.width, sc.height, sx, sy, &sc.geo, &g, err);
    if (rc == TD_OK)
        rc = raw_read(path, &sc, f, g, err);
    if (f)
        fclose(f);
    return td_demutil_deliver(path, rc, g, out, err);
}
