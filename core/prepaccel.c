/* prepaccel.c: a prepared dataset's per-tile max-mipmaps and parameter planes on disk
 * (see prepaccel.h for the files and why). prepared.c calls td_pacc_build_row while it
 * writes a folder (a tile row at a time, on every core, after the heights) and
 * td_pacc_open / td_pacc_verify_row when it opens and checks one; the tile store hands
 * td_pacc_tiles to every render of the dataset.
 *
 * Opening allocates one td_maxmip and one td_planes a tile whose arrays point into the
 * read-only mapping of accel.bin (about 300 bytes a tile: 26 MB for the 87 k tiles of a
 * 16 GiB grid and its levels), so the tracers read the structures exactly as built, and
 * the kernel pages them in where rays go. */
#define _GNU_SOURCE
#include "prepaccel.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "hash.h"
#include "lod.h"
#include "maxmip.h"
#include "planes.h"

_Static_assert(sizeof(td_pacc_rec) == 48, "accel.tab holds records of 48 bytes");

#define TD_PACC_LAYERS (TD_LOD_MAX + 1)

struct td_pacc {
    char dir[PATH_MAX];
    int nlayers, k;
    void *map;
    size_t map_bytes;
    td_pacc_rec *recs;
    size_t nrec;
    size_t first[TD_PACC_LAYERS + 1]; /* layer l's records: first[l] .. first[l+1] */
    int32_t tiles_x[TD_PACC_LAYERS], row0[TD_PACC_LAYERS + 1]; /* row0: its first tile row */
    td_maxmip *mm;
    td_planes *pl;
    td_tile_accel *acc;
};

/* The shape td_maxmip_build gives tile t of a grid of 2^tile_log2 tiles (maxmip.c):
 * levels 1 .. L of a 2^L side covering its cells, each right after the one before.
 * Returns the codes of all levels. */
static size_t mm_shape(int tile_log2, const td_tile *t, td_maxmip *m)
{
    const int32_t n = t->nx > t->ny ? t->nx : t->ny;
    size_t total = 0;
    int L = 1;
    while (L < tile_log2 && L < 16 && ((int32_t)1 << L) < n)
        L++;
    m->levels = L;
    for (int l = 1; l <= L; l++) {
        m->dim[l] = ((int32_t)1 << L) >> l;
        m->offset[l] = total;
        total += (size_t)m->dim[l] * (size_t)m->dim[l];
    }
    return total;
}

static size_t cones_of(const td_tile *t)
{
    return (size_t)td_planes_blocks(t->nx) * (size_t)td_planes_blocks(t->ny);
}

/* A tile's payload: apex heights, codes, cones, padding to 8; *at_codes, *at_cones where
 * the second and third begin. K 0: no planes (codes only). */
static size_t payload_bytes(int tile_log2, const td_tile *t, int k, size_t *at_codes, size_t *at_cones)
{
    td_maxmip m;
    size_t codes = mm_shape(tile_log2, t, &m);
    *at_codes = k ? ((size_t)k + 1) * sizeof(float) : 0;
    *at_cones = *at_codes + codes * sizeof(uint16_t);
    return (*at_cones + (k ? cones_of(t) * sizeof(td_cone) : 0) + 7u) & ~(size_t)7u;
}

td_status td_pacc_build(const td_grid *g, size_t tile, int k, td_pacc_blob *b, td_err *err)
{
    td_status rc;
    td_maxmip *m = NULL;
    td_planes *p = NULL;
    const td_tile *t = &g->tiles[tile];
    size_t at_codes, at_cones, n;

    memset(b, 0, sizeof *b);
    rc = td_maxmip_build(g, tile, &m, err);
    if (rc == TD_OK && k)
        rc = td_planes_build(g, tile, k, &p, err);
    if (rc)
        goto out;
    n = payload_bytes(g->tile_log2, t, k, &at_codes, &at_cones);
    b->data = calloc(1, n);
    if (!b->data) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for tile %zu's structures", tile);
        goto out;
    }
    if (p) {
        memcpy(b->data, p->apex, at_codes);
        memcpy(b->data + at_cones, p->cone, cones_of(t) * sizeof(td_cone));
    }
    memcpy(b->data + at_codes, m->code, at_cones - at_codes);
    b->rec.mm_base = m->base;
    b->rec.mm_step = m->step;
    b->rec.slope_scale = p ? p->slope_scale : 0.0;
    b->rec.k = k;
    b->rec.bytes = (uint32_t)n;
    b->rec.sum = td_fnv1a(TD_FNV1A_INIT, b->data, n);
out:
    td_maxmip_free(m);
    td_planes_free(p);
    return rc;
}

typedef struct row_job {
    const td_grid *g;
    int32_t ty;
    int k, threads, id;
    td_pacc_blob *blobs;
    td_status rc;
    td_err err;
} row_job;

static void *row_worker(void *arg)
{
    row_job *j = arg;
    for (int32_t tx = j->id; tx < j->g->tiles_x && j->rc == TD_OK; tx += j->threads)
        j->rc = td_pacc_build(j->g, (size_t)j->ty * (size_t)j->g->tiles_x + (size_t)tx, j->k, &j->blobs[tx],
                              &j->err);
    return NULL;
}

td_status td_pacc_build_row(const td_grid *g, int32_t ty, int k, int threads, td_pacc_blob *blobs,
                            td_err *err)
{
    td_status rc = TD_OK;
    row_job jobs[64];
    pthread_t th[64];
    int started[64] = {0};
    threads = threads < 1 ? 1 : threads > 64 ? 64 : threads;
    threads = threads > g->tiles_x ? g->tiles_x : threads;
    for (int i = 0; i < threads; i++) {
        memset(&jobs[i], 0, sizeof jobs[i]);
        jobs[i].g = g;
        jobs[i].ty = ty;
        jobs[i].k = k;
        jobs[i].threads = threads;
        jobs[i].id = i;
        jobs[i].blobs = blobs;
        started[i] = i > 0 && pthread_create(&th[i], NULL, row_worker, &jobs[i]) == 0;
        if (i > 0 && !started[i])
            jobs[i].rc = td_err_set(&jobs[i].err, TD_ENOMEM, "cannot start a prepare thread");
    }
    row_worker(&jobs[0]);
    for (int i = 0; i < threads; i++) {
        if (started[i])
            pthread_join(th[i], NULL);
        if (jobs[i].rc && rc == TD_OK) {
            rc = jobs[i].rc;
            if (err)
                *err = jobs[i].err;
        }
    }
    return rc;
}

/* --- reading ------------------------------------------------------------------------ */

static int rec_fits(const td_pacc_rec *r, int tile_log2, const td_tile *t, int k, size_t file)
{
    size_t a, c, n = payload_bytes(tile_log2, t, k, &a, &c);
    return r->k == k && r->bytes == n && r->off % 8u == 0 && r->off <= file && file - r->off >= n &&
           isfinite(r->mm_base) && isfinite(r->mm_step) && r->mm_step > 0.0 &&
           (k ? isfinite(r->slope_scale) && r->slope_scale > 0.0 : r->slope_scale == 0.0);
}

/* Tile t of layer l (record i) pointed into the mapping. */
static void tile_attach(td_pacc *p, size_t i, int tile_log2, const td_tile *t)
{
    const td_pacc_rec *r = &p->recs[i];
    unsigned char *base = (unsigned char *)p->map + r->off;
    td_maxmip *m = &p->mm[i];
    td_planes *pl = &p->pl[i];
    size_t at_codes, at_cones, n = payload_bytes(tile_log2, t, p->k, &at_codes, &at_cones);
    size_t codes = mm_shape(tile_log2, t, m);
    m->base = r->mm_base;
    m->step = r->mm_step;
    m->code = (uint16_t *)(void *)(base + at_codes);
    m->bytes = sizeof *m + codes * sizeof(uint16_t);
    pl->k = p->k;
    pl->nx = t->nx;
    pl->ny = t->ny;
    pl->bnx = td_planes_blocks(t->nx);
    pl->bny = td_planes_blocks(t->ny);
    pl->slope_scale = r->slope_scale;
    pl->apex = (float *)(void *)base;
    pl->cone = (td_cone *)(void *)(base + at_cones);
    pl->bytes = sizeof *pl + at_codes + (n - at_cones);
    p->acc[i].maxmip = m;
    p->acc[i].planes = p->k ? pl : NULL;
}

static td_status tab_read(td_pacc *p, const char *path, uint64_t want, td_err *err)
{
    td_status rc = TD_OK;
    struct stat st;
    FILE *f = fopen(path, "rb");
    p->recs = calloc(p->nrec, sizeof *p->recs);
    if (!f || fstat(fileno(f), &st))
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
    else if (!p->recs)
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory for %zu records", path, p->nrec);
    else if ((uint64_t)st.st_size != (uint64_t)p->nrec * sizeof *p->recs)
        rc = td_err_set(err, TD_EFORMAT, "%s: %lld bytes, expected %zu records of %zu bytes (%s)", path,
                        (long long)st.st_size, p->nrec, sizeof *p->recs,
                        (uint64_t)st.st_size < (uint64_t)p->nrec * sizeof *p->recs ? "truncated" : "too long");
    else if (fread(p->recs, sizeof *p->recs, p->nrec, f) != p->nrec)
        rc = td_err_set(err, TD_EIO, "%s: read failed", path);
    else if (td_fnv1a(TD_FNV1A_INIT, p->recs, p->nrec * sizeof *p->recs) != want)
        rc = td_err_set(err, TD_EFORMAT, "%s: checksum differs from the index's accel.tab_fnv (corrupted)", path);
    if (f)
        fclose(f);
    return rc;
}

static td_status bin_map(td_pacc *p, const char *path, uint64_t bytes, td_err *err)
{
    td_status rc = TD_OK;
    struct stat st;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0 || fstat(fd, &st))
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
    else if ((uint64_t)st.st_size != bytes || bytes == 0 || bytes > SIZE_MAX)
        rc = td_err_set(err, TD_EFORMAT, "%s: %lld bytes, the index says %llu (%s)", path, (long long)st.st_size,
                        (unsigned long long)bytes, (uint64_t)st.st_size < bytes ? "truncated" : "too long");
    else if ((p->map = mmap(NULL, (size_t)bytes, PROT_READ, MAP_SHARED, fd, 0)) == MAP_FAILED) {
        p->map = NULL;
        rc = td_err_set(err, TD_EIO, "%s: cannot map %llu bytes (%s)", path, (unsigned long long)bytes,
                        strerror(errno));
    } else {
        p->map_bytes = (size_t)bytes;
    }
    if (fd >= 0)
        close(fd);
    return rc;
}

td_status td_pacc_open(const char *dir, const td_grid *const *grids, int nlayers, int k, uint64_t bytes,
                       uint64_t tab_fnv, td_pacc **out, td_err *err)
{
    td_status rc = TD_OK;
    td_pacc *p = calloc(1, sizeof *p);
    char path[PATH_MAX + 16];

    *out = NULL;
    if (!p || nlayers < 1 || nlayers > TD_PACC_LAYERS || k < 0 || k > TD_PLANES_K_MAX) {
        rc = p ? td_err_set(err, TD_EFORMAT, "%s: accel: %d layers, K %d", dir, nlayers, k)
               : td_err_set(err, TD_ENOMEM, "%s: out of memory", dir);
        goto out;
    }
    snprintf(p->dir, sizeof p->dir, "%s", dir);
    p->nlayers = nlayers;
    p->k = k;
    for (int l = 0; l < nlayers; l++) {
        p->first[l] = p->nrec;
        p->row0[l] = l ? p->row0[l - 1] + grids[l - 1]->tiles_y : 0;
        p->tiles_x[l] = grids[l]->tiles_x;
        p->nrec += (size_t)grids[l]->tiles_x * (size_t)grids[l]->tiles_y;
    }
    p->first[nlayers] = p->nrec;
    p->row0[nlayers] = p->row0[nlayers - 1] + grids[nlayers - 1]->tiles_y;
    snprintf(path, sizeof path, "%s/%s", dir, TD_PACC_TAB);
    rc = tab_read(p, path, tab_fnv, err);
    snprintf(path, sizeof path, "%s/%s", dir, TD_PACC_BIN);
    if (rc == TD_OK)
        rc = bin_map(p, path, bytes, err);
    if (rc)
        goto out;
    p->mm = calloc(p->nrec, sizeof *p->mm);
    p->pl = calloc(p->nrec, sizeof *p->pl);
    p->acc = calloc(p->nrec, sizeof *p->acc);
    if (!p->mm || !p->pl || !p->acc) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory for %zu tiles' structures", dir, p->nrec);
        goto out;
    }
    snprintf(path, sizeof path, "%s/%s", dir, TD_PACC_TAB);
    for (int l = 0; l < nlayers && rc == TD_OK; l++)
        for (size_t t = 0; t < p->first[l + 1] - p->first[l] && rc == TD_OK; t++) {
            size_t i = p->first[l] + t;
            if (!rec_fits(&p->recs[i], grids[l]->tile_log2, &grids[l]->tiles[t], k, p->map_bytes))
                rc = td_err_set(err, TD_EFORMAT, "%s: layer %d tile %zu's record does not fit its tile or %s", path,
                                l, t, TD_PACC_BIN);
            else
                tile_attach(p, i, grids[l]->tile_log2, &grids[l]->tiles[t]);
        }
    if (rc)
        goto out;
    *out = p;
    p = NULL;
out:
    td_pacc_free(p);
    return rc;
}

const td_tile_accel *td_pacc_tiles(const td_pacc *p, int layer)
{
    return p && layer >= 0 && layer < p->nlayers ? p->acc + p->first[layer] : NULL;
}

int32_t td_pacc_rows(const td_pacc *p) { return p ? p->row0[p->nlayers] : 0; }

/* Tile i's values where a tracer indexes with them: apex heights are numbers, every
 * cone's apex index is one of them (the code scales were checked at open); nothing to
 * check without planes (K 0). */
static const char *tile_check(const td_planes *pl, const unsigned char *data, size_t at_cones)
{
    const char *why = NULL;
    const size_t n = pl->k ? (size_t)pl->bnx * (size_t)pl->bny : 0;
    for (int s = 0; pl->k && s <= pl->k && !why; s++) {
        float a;
        memcpy(&a, data + (size_t)s * sizeof a, sizeof a);
        why = isnan(a) ? "an apex height is not a number" : NULL;
    }
    for (size_t c = 0; c < n && !why; c++)
        why = data[at_cones + c * sizeof(td_cone) + offsetof(td_cone, apex)] > pl->k ? "a cone's apex is out of range"
                                                                                   : NULL;
    return why;
}

td_status td_pacc_verify_row(const td_pacc *p, int32_t r, td_err *err)
{
    td_status rc = TD_OK;
    int l = 0, fd = -1;
    size_t i0, i1, span;
    uint64_t lo;
    unsigned char *buf = NULL;
    char path[PATH_MAX + 16];

    if (r < 0 || r >= td_pacc_rows(p)) {
        rc = td_err_set(err, TD_EINVAL, "%s: no tile row %ld of structures", p->dir, (long)r);
        goto out;
    }
    while (r >= p->row0[l + 1])
        l++;
    i0 = p->first[l] + (size_t)(r - p->row0[l]) * (size_t)p->tiles_x[l];
    i1 = i0 + (size_t)p->tiles_x[l];
    lo = p->recs[i0].off;
    span = 0;
    for (size_t i = i0; i < i1; i++) {
        lo = p->recs[i].off < lo ? p->recs[i].off : lo;
        span = p->recs[i].off + p->recs[i].bytes > lo + span ? (size_t)(p->recs[i].off + p->recs[i].bytes - lo) : span;
    }
    snprintf(path, sizeof path, "%s/%s", p->dir, TD_PACC_BIN);
    buf = malloc(span ? span : 1);
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (!buf || fd < 0 || pread(fd, buf, span, (off_t)lo) != (ssize_t)span) {
        rc = td_err_set(err, TD_EIO, "%s: cannot read tile row %ld of layer %d (%s)", path, (long)(r - p->row0[l]), l,
                        buf ? strerror(errno) : "out of memory");
        goto out;
    }
    for (size_t i = i0; i < i1 && rc == TD_OK; i++) {
        const unsigned char *d = buf + (p->recs[i].off - lo);
        size_t at_cones = (size_t)((const unsigned char *)p->pl[i].cone - ((const unsigned char *)p->map + p->recs[i].off));
        const char *why = td_fnv1a(TD_FNV1A_INIT, d, p->recs[i].bytes) != p->recs[i].sum
                              ? "its checksum differs from accel.tab's (corrupted)"
                              : tile_check(&p->pl[i], d, at_cones);
        if (why)
            rc = td_err_set(err, TD_EFORMAT, "%s: layer %d tile %zu (tile row %ld): %s", path, l, i - p->first[l],
                            (long)(r - p->row0[l]), why);
    }
    posix_fadvise(fd, (off_t)lo, (off_t)span, POSIX_FADV_DONTNEED);
out:
    if (fd >= 0)
        close(fd);
    free(buf);
    return rc;
}

uint64_t td_pacc_willneed(const td_pacc *p, int from)
{
    size_t page = (size_t)sysconf(_SC_PAGESIZE), at;
    if (!p || from < 0 || from >= p->nlayers || p->first[from] >= p->nrec)
        return 0;
    at = (size_t)p->recs[p->first[from]].off / page * page;
    madvise((char *)p->map + at, p->map_bytes - at, MADV_WILLNEED);
    return p->map_bytes - at;
}

void td_pacc_mapping(const td_pacc *p, void **base, size_t *len)
{
    *base = p ? p->map : NULL;
    *len = p ? p->map_bytes : 0;
}

void td_pacc_free(td_pacc *p)
{
    if (p) {
        if (p->map)
            munmap(p->map, p->map_bytes);
        free(p->recs);
        free(p->mm);
        free(p->pl);
        free(p->acc);
        free(p);
    }
}
