/* prepared.c: writing, opening and checking terrad's prepared form of a dataset (see
 * prepared.h for the layout and why it is one mapped array). `terrad prepare`
 * (server/cli_prepare.c) calls td_prepare; the tile store (server/tilestore.c) calls
 * td_prepared_open for a --data folder holding an index, verifies its chunks in a
 * background thread and measures and trims the mapping's residency.
 *
 * Writing streams: a chunk of R file rows is read from the source (.f32: fread at its
 * offset; GDAL: RasterIO of the band, through its block cache; other formats from their
 * loader's whole grid), checked (NaN / infinities as the loaders do), reversed into
 * south-based order, checksummed and written with one pwrite at its place; the per-tile
 * min/max (td_tile, as td_grid_finish computes them: edge samples count in both tiles)
 * are accumulated row by row. After each chunk the heights are synced and the state file
 * (chunks done, their checksums, the running statistics) is replaced by rename, so a
 * killed prepare continues from its last chunk, and never from a chunk whose heights
 * were not on disk. The index is written last, by rename.
 *
 * Reading: td_prepared_open reads only the index (a few hundred bytes a chunk) and
 * tiles.bin (24 bytes a tile), stats heights.f32 and maps it: 16 GiB of heights open in
 * the time of 1 GiB's. Chunks are checked on demand (td_prepared_verify_chunk): the
 * server checks every chunk once, in the background, before it serves the dataset
 * (the tracers read the mapping directly, so "on first touch" has no hook short of
 * trapping page faults). */
#define _GNU_SOURCE
#include "prepared.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "demgdal.h"
#include "demraw.h"
#include "demutil.h"
#include "hash.h"

#define TD_PREPARED_FORMAT "terrad-prepared"
#define TD_STATE_MAGIC "TDPREP1"
#define TD_INDEX_MAX (16u << 20) /* 16 MiB of JSON: 65536 chunks of checksums */

_Static_assert(sizeof(td_tile) == 24, "tiles.bin holds td_tile records of 24 bytes");

struct td_prepared {
    char dir[PATH_MAX];
    td_grid *grid;
    int32_t w, h; /* kept when the grid is taken */
    int32_t chunk_rows, nchunks;
    uint64_t *sums;
    uint64_t fingerprint;
};

/* --- the source: a chunk of file rows at a time ------------------------------------ */

typedef struct td_src_rows {
    const char *path;
    td_grid shape;             /* w, h, sx, sy, geo, tile_log2 */
    FILE *f32;                 /* .f32: read in place */
    td_demutil_f32 p;
    td_demgdal_stream *gdal;   /* GDAL rasters */
    td_grid *whole;            /* other formats: their loader's grid */
    uint64_t size;             /* of the source file */
    int64_t mtime;
} td_src_rows;

static td_status src_open_f32(td_src_rows *s, const td_dem_opts *o, td_err *err)
{
    td_status rc;
    td_demside sc;

    rc = td_demraw_open(s->path, o, &sc, &s->f32, err);
    if (rc == TD_OK)
        rc = td_demutil_side_georef(s->path, o, &sc, sc.width, sc.height, &s->shape.sx, &s->shape.sy, err);
    if (rc == TD_OK) {
        s->shape.w = sc.width;
        s->shape.h = sc.height;
        s->shape.geo = sc.geo;
        td_demraw_rules(&sc, &s->p);
    }
    return rc;
}

/* The source's shape; its rows are then read by src_rows. */
static td_status src_open(td_src_rows *s, const char *path, const td_dem_opts *o, td_err *err)
{
    td_status rc = TD_OK;
    td_dem_opts lo = *o;
    char ext[16];
    struct stat st;

    memset(s, 0, sizeof *s);
    s->path = path;
    if (stat(path, &st)) {
        rc = td_err_set(err, TD_ENOTFOUND, "%s: %s", path, strerror(errno));
        goto out;
    }
    s->size = (uint64_t)st.st_size;
    s->mtime = (int64_t)st.st_mtime;
    td_demutil_ext(path, ext, sizeof ext);
    lo.limits.max_bytes = 0; /* streamed: nothing of the grid's size is allocated */
    if (!strcmp(ext, "f32"))
        rc = src_open_f32(s, &lo, err);
    else if (!strcmp(ext, "asc") || !strcmp(ext, "hgt") || !strcmp(ext, "png") || !td_dem_have_gdal())
        rc = td_dem_load(path, o, &s->whole, err); /* within the caller's memory limits */
    else
        rc = td_demgdal_stream_open(path, &lo, &s->gdal, &s->shape, err);
    if (rc == TD_OK && s->whole) {
        s->shape = *s->whole;
        s->shape.z = NULL;
        s->shape.tiles = NULL;
        s->shape.map = NULL;
    }
    s->shape.tile_log2 = o->tile_log2 ? o->tile_log2 : TD_TILE_LOG2_DEFAULT;
out:
    return rc;
}

/* File rows r0 .. r0+n-1 into dst, north row first. */
static td_status src_rows(td_src_rows *s, int32_t r0, int32_t n, float *dst, td_err *err)
{
    td_status rc = TD_OK;
    const size_t w = (size_t)s->shape.w;
    if (s->whole) {
        for (int32_t k = 0; k < n; k++)
            memcpy(dst + (size_t)k * w, td_demutil_file_row(s->whole, r0 + k), w * sizeof(float));
    } else if (s->gdal) {
        rc = td_demgdal_stream_rows(s->gdal, r0, n, dst, err);
    } else {
        if (fseeko(s->f32, (off_t)r0 * (off_t)w * 4, SEEK_SET))
            rc = td_err_set(err, TD_EIO, "%s: seek to row %ld failed (%s)", s->path, (long)r0, strerror(errno));
        for (int32_t k = 0; k < n && rc == TD_OK; k++)
            rc = td_demraw_row(s->path, &s->p, s->f32, dst + (size_t)k * w, s->shape.w, r0 + k, err);
    }
    return rc;
}

static void src_close(td_src_rows *s)
{
    if (s->f32)
        fclose(s->f32);
    td_demgdal_stream_close(s->gdal);
    td_grid_free(s->whole);
}

/* --- the prepare's state: chunks done and running statistics ----------------------- */

typedef struct td_state_hdr {
    char magic[8];
    uint32_t version;
    int32_t w, h, tile_log2, chunk_rows, nchunks, done, tiles_x, tiles_y;
    uint64_t src_size;
    int64_t src_mtime;
    int64_t voids;
    float zmin, zmax;
} td_state_hdr;

typedef struct td_prep_run {
    const char *dir;
    td_state_hdr st;
    uint64_t *sums;   /* nchunks */
    float *lo, *hi;   /* per tile */
    float *buf;       /* chunk_rows * w */
    int fd;           /* heights.f32 */
} td_prep_run;

/* dir/name into out (n bytes); 0 if it does not fit. */
static int path_in(char *out, size_t n, const char *dir, const char *name)
{
    size_t a = strlen(dir), b = strlen(name);
    int ok = a + b + 2 <= n;
    if (ok) {
        memcpy(out, dir, a);
        out[a] = '/';
        memcpy(out + a + 1, name, b + 1);
    }
    return ok;
}

static td_status write_file(const char *dir, const char *name, const void *const *parts,
                            const size_t *lens, int nparts, td_err *err)
{
    td_status rc = TD_OK;
    char path[PATH_MAX], tmp[PATH_MAX + 8];
    FILE *f = NULL;
    if (!path_in(path, sizeof path, dir, name) || (size_t)snprintf(tmp, sizeof tmp, "%s.tmp", path) >= sizeof tmp) {
        rc = td_err_set(err, TD_EINVAL, "%s: path too long", dir);
        goto out;
    }
    f = fopen(tmp, "wb");
    for (int k = 0; f && k < nparts; k++)
        if (lens[k] && fwrite(parts[k], 1, lens[k], f) != lens[k])
            break;
    if (!f || ferror(f) || fflush(f) || fsync(fileno(f)) || fclose(f)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot write (%s)", tmp, strerror(errno));
        if (f)
            fclose(f);
    } else if (rename(tmp, path)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot rename to %s (%s)", tmp, path, strerror(errno));
    }
    f = NULL;
out:
    return rc;
}

static td_status state_save(td_prep_run *r, td_err *err)
{
    size_t nt = (size_t)r->st.tiles_x * (size_t)r->st.tiles_y;
    const void *parts[4] = {&r->st, r->sums, r->lo, r->hi};
    size_t lens[4] = {sizeof r->st, (size_t)r->st.nchunks * 8, nt * 4, nt * 4};
    return write_file(r->dir, TD_PREPARED_STATE, parts, lens, 4, err);
}

/* A state file that matches `want` (same source, shape and chunking): its chunks done and
 * statistics into r. Anything else (absent, short, foreign): start again. */
static int state_load(td_prep_run *r, const td_state_hdr *want)
{
    char path[PATH_MAX];
    td_state_hdr h;
    size_t nt = (size_t)want->tiles_x * (size_t)want->tiles_y;
    FILE *f = path_in(path, sizeof path, r->dir, TD_PREPARED_STATE) ? fopen(path, "rb") : NULL;
    int ok = f && fread(&h, sizeof h, 1, f) == 1 && !memcmp(h.magic, want->magic, 8) &&
             h.version == want->version && h.w == want->w && h.h == want->h &&
             h.tile_log2 == want->tile_log2 && h.chunk_rows == want->chunk_rows &&
             h.nchunks == want->nchunks && h.src_size == want->src_size &&
             h.src_mtime == want->src_mtime && h.done >= 0 && h.done <= h.nchunks &&
             fread(r->sums, 8, (size_t)h.nchunks, f) == (size_t)h.nchunks &&
             fread(r->lo, 4, nt, f) == nt && fread(r->hi, 4, nt, f) == nt;
    if (ok)
        r->st = h;
    if (f)
        fclose(f);
    return ok;
}

/* Folds south row j (w samples) into the tiles' and the grid's statistics. */
static void stats_row(td_prep_run *r, int32_t j, const float *row)
{
    const int L = r->st.tile_log2;
    const int32_t T = (int32_t)1 << L, w = r->st.w;
    int32_t tys[2], nty = 0;
    if ((j >> L) < r->st.tiles_y)
        tys[nty++] = j >> L;
    if (j > 0 && (j & (T - 1)) == 0)
        tys[nty++] = (j >> L) - 1; /* the top edge of the tile row below */
    for (int32_t i = 0; i < w; i++) {
        float v = row[i];
        if (isnan(v)) {
            r->st.voids++;
        } else {
            r->st.zmin = v < r->st.zmin ? v : r->st.zmin;
            r->st.zmax = v > r->st.zmax ? v : r->st.zmax;
        }
    }
    for (int32_t tx = 0; tx < r->st.tiles_x; tx++) {
        int32_t i0 = tx * T, i1 = i0 + T < w - 1 ? i0 + T : w - 1;
        float lo = INFINITY, hi = -INFINITY;
        for (int32_t i = i0; i <= i1; i++) {
            lo = row[i] < lo ? row[i] : lo; /* false for NaN */
            hi = row[i] > hi ? row[i] : hi;
        }
        for (int k = 0; k < nty; k++) {
            size_t t = (size_t)tys[k] * (size_t)r->st.tiles_x + (size_t)tx;
            r->lo[t] = lo < r->lo[t] ? lo : r->lo[t];
            r->hi[t] = hi > r->hi[t] ? hi : r->hi[t];
        }
    }
}

/* Chunk c: read, reverse into south order, statistics, checksum, one pwrite. */
static td_status chunk_write(td_prep_run *r, td_src_rows *src, int32_t c, td_err *err)
{
    td_status rc;
    const size_t w = (size_t)r->st.w;
    int32_t r0 = c * r->st.chunk_rows;
    int32_t n = r->st.h - r0 < r->st.chunk_rows ? r->st.h - r0 : r->st.chunk_rows;
    float *tmp = r->buf + (size_t)r->st.chunk_rows * w; /* the second half: file order */
    size_t bytes = (size_t)n * w * 4;
    off_t at = (off_t)(r->st.h - r0 - n) * (off_t)w * 4;

    rc = src_rows(src, r0, n, tmp, err);
    for (int32_t k = 0; k < n && rc == TD_OK; k++) {
        float *dst = r->buf + (size_t)(n - 1 - k) * w;
        memcpy(dst, tmp + (size_t)k * w, w * 4);
        stats_row(r, r->st.h - 1 - (r0 + k), dst);
    }
    if (rc == TD_OK) {
        r->sums[c] = td_fnv1a(TD_FNV1A_INIT, r->buf, bytes);
        if (pwrite(r->fd, r->buf, bytes, at) != (ssize_t)bytes || fdatasync(r->fd))
            rc = td_err_set(err, TD_EIO, "%s/%s: cannot write chunk %ld (%s)", r->dir,
                            TD_PREPARED_HEIGHTS, (long)c, strerror(errno));
    }
    return rc;
}

static void hex64(char out[17], uint64_t v) { snprintf(out, 17, "%016llx", (unsigned long long)v); }

static json_t *geo_json(const td_georef *g)
{
    static const char *const kinds[] = {"none", "lonlat", "projected"};
    return json_pack("{s:s, s:f, s:f, s:f, s:f, s:s}", "kind", kinds[g->kind], "x0", g->x0, "y0",
                     g->y0, "dx", g->dx, "dy", g->dy, "crs", g->crs);
}

/* tiles.bin and the index, from the finished run. */
static td_status finish(td_prep_run *r, const td_src_rows *src, td_err *err)
{
    td_status rc;
    td_grid tg;
    size_t nt = (size_t)r->st.tiles_x * (size_t)r->st.tiles_y;
    td_tile *tiles = calloc(nt, sizeof *tiles);
    json_t *root = NULL, *sums = json_array();
    char *text = NULL, hx[17];
    const int32_t T = (int32_t)1 << r->st.tile_log2;
    uint64_t tsum;

    if (!tiles || !sums) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %zu tile records", nt);
        goto out;
    }
    memset(&tg, 0, sizeof tg);
    tg.w = r->st.w;
    tg.h = r->st.h;
    for (size_t t = 0; t < nt; t++) {
        td_tile *x = &tiles[t];
        x->i0 = (int32_t)(t % (size_t)r->st.tiles_x) * T;
        x->j0 = (int32_t)(t / (size_t)r->st.tiles_x) * T;
        x->nx = r->st.w - 1 - x->i0 < T ? r->st.w - 1 - x->i0 : T;
        x->ny = r->st.h - 1 - x->j0 < T ? r->st.h - 1 - x->j0 : T;
        x->zmin = r->lo[t];
        x->zmax = r->hi[t];
    }
    tsum = td_fnv1a(TD_FNV1A_INIT, tiles, nt * sizeof *tiles);
    {
        const void *parts[1] = {tiles};
        size_t lens[1] = {nt * sizeof *tiles};
        rc = write_file(r->dir, TD_PREPARED_TILES, parts, lens, 1, err);
    }
    if (rc)
        goto out;
    for (int32_t c = 0; c < r->st.nchunks; c++) {
        hex64(hx, r->sums[c]);
        json_array_append_new(sums, json_string(hx));
    }
    hex64(hx, tsum);
    {
        int allvoid = r->st.voids == (int64_t)r->st.w * r->st.h;
        root = json_pack("{s:s, s:i, s:I, s:I, s:[f,f], s:i, s:o, s:o, s:I, s:o, s:i, s:O, s:s, s:{s:s, s:I, s:I}}",
                         "format", TD_PREPARED_FORMAT, "version", TD_PREPARED_VERSION,
                         "width", (json_int_t)r->st.w, "height", (json_int_t)r->st.h,
                         "spacing", src->shape.sx, src->shape.sy, "tile_log2", r->st.tile_log2,
                         "zmin", allvoid ? json_null() : json_real((double)r->st.zmin),
                         "zmax", allvoid ? json_null() : json_real((double)r->st.zmax),
                         "voids", (json_int_t)r->st.voids, "georef", geo_json(&src->shape.geo),
                         "chunk_rows", r->st.chunk_rows, "chunks", sums, "tiles_fnv", hx,
                         "source", "name", td_demutil_basename(src->path),
                         "bytes", (json_int_t)src->size, "mtime", (json_int_t)src->mtime);
    }
    text = root ? json_dumps(root, JSON_INDENT(1) | JSON_COMPACT) : NULL;
    if (!text) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the index");
        goto out;
    }
    {
        const void *parts[1] = {text};
        size_t lens[1] = {strlen(text)};
        rc = write_file(r->dir, TD_PREPARED_INDEX, parts, lens, 1, err);
    }
out:
    free(text);
    json_decref(root);
    json_decref(sums);
    free(tiles);
    return rc;
}

/* The run's buffers and its state: fresh, or continued from a matching state file. */
static td_status run_init(td_prep_run *r, const td_src_rows *src, const td_prepare_opts *o,
                          td_err *err)
{
    td_status rc = TD_OK;
    td_state_hdr want;
    const int32_t T = (int32_t)1 << src->shape.tile_log2;
    size_t nt;

    memset(&want, 0, sizeof want);
    memcpy(want.magic, TD_STATE_MAGIC, 8);
    want.version = TD_PREPARED_VERSION;
    want.w = src->shape.w;
    want.h = src->shape.h;
    want.tile_log2 = src->shape.tile_log2;
    want.chunk_rows = o->chunk_rows > 0 ? o->chunk_rows : T;
    want.chunk_rows = want.chunk_rows < want.h ? want.chunk_rows : want.h;
    want.nchunks = (want.h + want.chunk_rows - 1) / want.chunk_rows;
    want.tiles_x = (want.w - 1 + T - 1) / T;
    want.tiles_y = (want.h - 1 + T - 1) / T;
    want.src_size = src->size;
    want.src_mtime = src->mtime;
    want.zmin = INFINITY;
    want.zmax = -INFINITY;
    nt = (size_t)want.tiles_x * (size_t)want.tiles_y;
    r->sums = calloc((size_t)want.nchunks, 8);
    r->lo = malloc(nt * 4);
    r->hi = malloc(nt * 4);
    r->buf = malloc((size_t)want.chunk_rows * (size_t)want.w * 8); /* south + file order */
    if (!r->sums || !r->lo || !r->hi || !r->buf) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for chunks of %ld rows of %ld samples",
                        (long)want.chunk_rows, (long)want.w);
        goto out;
    }
    if (!state_load(r, &want)) {
        r->st = want;
        for (size_t t = 0; t < nt; t++) {
            r->lo[t] = INFINITY;
            r->hi[t] = -INFINITY;
        }
    }
out:
    return rc;
}

/* An index already there for this very source and chunking: nothing to do. */
static int already_done(const char *dir, const td_src_rows *src)
{
    td_prepared *p = NULL;
    char path[PATH_MAX];
    json_t *root = NULL;
    int same = 0;
    if (td_prepared_open(dir, &p, NULL) == TD_OK && path_in(path, sizeof path, dir, TD_PREPARED_INDEX) &&
        (root = json_load_file(path, 0, NULL)) != NULL) {
        json_t *s = json_object_get(root, "source");
        same = p->grid->w == src->shape.w && p->grid->h == src->shape.h &&
               p->grid->tile_log2 == src->shape.tile_log2 &&
               json_integer_value(json_object_get(s, "bytes")) == (json_int_t)src->size &&
               json_integer_value(json_object_get(s, "mtime")) == (json_int_t)src->mtime;
    }
    json_decref(root);
    td_prepared_free(p);
    return same;
}

td_status td_prepare(const char *src_path, const char *dir, const td_prepare_opts *o,
                     td_prepare_result *res, td_err *err)
{
    td_status rc;
    td_src_rows src;
    td_prep_run r;
    char path[PATH_MAX];
    off_t total;
    int lock = -1;

    memset(res, 0, sizeof *res);
    memset(&r, 0, sizeof r);
    r.dir = dir;
    r.fd = -1;
    rc = src_open(&src, src_path, &o->dem, err);
    if (rc)
        goto out;
    res->w = src.shape.w;
    res->h = src.shape.h;
    res->streamed = src.whole == NULL;
    total = (off_t)src.shape.w * (off_t)src.shape.h * 4;
    res->bytes = (uint64_t)total;
    if (mkdir(dir, 0755) && errno != EEXIST) {
        rc = td_err_set(err, TD_EIO, "%s: cannot create (%s)", dir, strerror(errno));
        goto out;
    }
    /* one prepare at a time into a folder (the lock goes with the process, killed or not) */
    if (!path_in(path, sizeof path, dir, "prepare.lock") ||
        (lock = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644)) < 0 || flock(lock, LOCK_EX | LOCK_NB)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot lock (%s)", path,
                        errno == EWOULDBLOCK ? "another terrad prepare is writing this folder" : strerror(errno));
        goto out;
    }
    if (already_done(dir, &src)) {
        res->already = 1;
        goto out;
    }
    rc = run_init(&r, &src, o, err);
    if (rc)
        goto out;
    res->resumed_rows = (int64_t)r.st.done * r.st.chunk_rows;
    if (path_in(path, sizeof path, dir, TD_PREPARED_INDEX))
        unlink(path); /* a stale index must not describe half-rewritten heights */
    if (!path_in(path, sizeof path, dir, TD_PREPARED_HEIGHTS) ||
        (r.fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644)) < 0 || ftruncate(r.fd, total)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot create (%s)", path, strerror(errno));
        goto out;
    }
    while (r.st.done < r.st.nchunks && rc == TD_OK) {
        rc = chunk_write(&r, &src, r.st.done, err);
        if (rc == TD_OK) {
            r.st.done++;
            rc = state_save(&r, err);
        }
        if (rc == TD_OK && o->progress &&
            o->progress(o->cls, r.st.done == r.st.nchunks ? r.st.h : (int64_t)r.st.done * r.st.chunk_rows, r.st.h,
                        r.st.w))
            rc = td_err_set(err, TD_ECANCELED, "%s: prepare stopped after %ld of %ld chunks (run it again to continue)",
                            dir, (long)r.st.done, (long)r.st.nchunks);
    }
    if (rc == TD_OK)
        rc = finish(&r, &src, err);
    if (rc == TD_OK && path_in(path, sizeof path, dir, TD_PREPARED_STATE))
        unlink(path);
out:
    if (r.fd >= 0)
        close(r.fd);
    if (lock >= 0)
        close(lock);
    free(r.sums);
    free(r.lo);
    free(r.hi);
    free(r.buf);
    src_close(&src);
    return rc;
}

/* --- opening ---------------------------------------------------------------------- */

int td_prepared_is(const char *dir)
{
    char path[PATH_MAX];
    return path_in(path, sizeof path, dir, TD_PREPARED_INDEX) && access(path, R_OK) == 0;
}

int td_prepared_unfinished(const char *dir)
{
    char path[PATH_MAX];
    return !td_prepared_is(dir) && path_in(path, sizeof path, dir, TD_PREPARED_STATE) &&
           access(path, F_OK) == 0;
}

static int hex_parse(const char *s, uint64_t *out)
{
    char *end = NULL;
    if (!s || strlen(s) != 16)
        return 0;
    errno = 0;
    *out = strtoull(s, &end, 16);
    return errno == 0 && end && *end == '\0';
}

static td_status geo_parse(const char *path, json_t *g, td_georef *geo, td_err *err)
{
    td_status rc = TD_OK;
    const char *kind = json_string_value(json_object_get(g, "kind"));
    const char *crs = json_string_value(json_object_get(g, "crs"));
    memset(geo, 0, sizeof *geo);
    if (!kind || (strcmp(kind, "none") && strcmp(kind, "lonlat") && strcmp(kind, "projected"))) {
        rc = td_err_set(err, TD_EFORMAT, "%s: georef.kind is missing or unknown", path);
        goto out;
    }
    geo->kind = !strcmp(kind, "lonlat") ? TD_GEO_LONLAT : !strcmp(kind, "projected") ? TD_GEO_PROJECTED : TD_GEO_NONE;
    geo->x0 = json_number_value(json_object_get(g, "x0"));
    geo->y0 = json_number_value(json_object_get(g, "y0"));
    geo->dx = json_number_value(json_object_get(g, "dx"));
    geo->dy = json_number_value(json_object_get(g, "dy"));
    snprintf(geo->crs, sizeof geo->crs, "%s", crs ? crs : "");
out:
    return rc;
}

/* The index's fields into p and a grid record (no heights, no tiles yet). */
static td_status index_read(td_prepared *p, const char *path, td_grid *g, uint64_t *tiles_fnv,
                            td_err *err)
{
    td_status rc = TD_OK;
    json_error_t je;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je), *chunks, *sp;
    const char *fmt;
    json_int_t ver, w, h, tl, cr;
    size_t nc;

    if (!root) {
        rc = td_err_set(err, access(path, F_OK) ? TD_ENOTFOUND : TD_EFORMAT, "%s: %s", path, je.text);
        goto out;
    }
    fmt = json_string_value(json_object_get(root, "format"));
    ver = json_integer_value(json_object_get(root, "version"));
    if (!fmt || strcmp(fmt, TD_PREPARED_FORMAT) || ver != TD_PREPARED_VERSION) {
        rc = td_err_set(err, TD_EUNSUPPORTED, "%s: format %s version %lld, this terrad reads %s version %d "
                        "(prepare it again)", path, fmt ? fmt : "(none)", (long long)ver,
                        TD_PREPARED_FORMAT, TD_PREPARED_VERSION);
        goto out;
    }
    w = json_integer_value(json_object_get(root, "width"));
    h = json_integer_value(json_object_get(root, "height"));
    tl = json_integer_value(json_object_get(root, "tile_log2"));
    cr = json_integer_value(json_object_get(root, "chunk_rows"));
    sp = json_object_get(root, "spacing");
    chunks = json_object_get(root, "chunks");
    nc = json_array_size(chunks);
    if (w < 2 || h < 2 || w > INT32_MAX || h > INT32_MAX || tl < 1 || tl > 16 || cr < 1 || cr > h ||
        json_array_size(sp) != 2 || nc != (size_t)((h + cr - 1) / cr) ||
        !hex_parse(json_string_value(json_object_get(root, "tiles_fnv")), tiles_fnv)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: width, height, tile_log2, chunk_rows, spacing, chunks or "
                        "tiles_fnv missing or inconsistent", path);
        goto out;
    }
    g->w = (int32_t)w;
    g->h = (int32_t)h;
    g->tile_log2 = (int)tl;
    g->sx = json_number_value(json_array_get(sp, 0));
    g->sy = json_number_value(json_array_get(sp, 1));
    g->zmin = json_is_number(json_object_get(root, "zmin")) ? (float)json_number_value(json_object_get(root, "zmin")) : NAN;
    g->zmax = json_is_number(json_object_get(root, "zmax")) ? (float)json_number_value(json_object_get(root, "zmax")) : NAN;
    g->voids = json_integer_value(json_object_get(root, "voids"));
    if (!(g->sx > 0) || !(g->sy > 0) || !isfinite(g->sx) || !isfinite(g->sy)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: spacing is not positive and finite", path);
        goto out;
    }
    rc = geo_parse(path, json_object_get(root, "georef"), &g->geo, err);
    p->chunk_rows = (int32_t)cr;
    p->nchunks = (int32_t)nc;
    p->sums = rc ? NULL : calloc(nc, 8);
    if (!rc && !p->sums)
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
    for (size_t c = 0; c < nc && rc == TD_OK; c++)
        if (!hex_parse(json_string_value(json_array_get(chunks, c)), &p->sums[c]))
            rc = td_err_set(err, TD_EFORMAT, "%s: chunks[%zu] is not a 16-digit hex checksum", path, c);
out:
    json_decref(root);
    return rc;
}

/* tiles.bin: size, checksum, and records that fit the grid (a tracer indexes with them). */
static td_status tiles_read(const char *path, td_grid *g, uint64_t want, td_err *err)
{
    td_status rc = TD_OK;
    const int32_t T = (int32_t)1 << g->tile_log2;
    size_t nt = (size_t)g->tiles_x * (size_t)g->tiles_y;
    FILE *f = fopen(path, "rb");
    struct stat st;

    g->tiles = calloc(nt, sizeof *g->tiles);
    if (!f || fstat(fileno(f), &st)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
    } else if (!g->tiles) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory for %zu tiles", path, nt);
    } else if ((uint64_t)st.st_size != (uint64_t)nt * sizeof(td_tile)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: %lld bytes, expected %zu tiles of %zu bytes (%s)", path,
                        (long long)st.st_size, nt, sizeof(td_tile),
                        (uint64_t)st.st_size < (uint64_t)nt * sizeof(td_tile) ? "truncated" : "too long");
    } else if (fread(g->tiles, sizeof(td_tile), nt, f) != nt) {
        rc = td_err_set(err, TD_EIO, "%s: read failed", path);
    } else if (td_fnv1a(TD_FNV1A_INIT, g->tiles, nt * sizeof(td_tile)) != want) {
        rc = td_err_set(err, TD_EFORMAT, "%s: checksum differs from the index's tiles_fnv (corrupted)", path);
    }
    for (size_t t = 0; t < nt && rc == TD_OK; t++) {
        const td_tile *x = &g->tiles[t];
        int32_t i0 = (int32_t)(t % (size_t)g->tiles_x) * T, j0 = (int32_t)(t / (size_t)g->tiles_x) * T;
        if (x->i0 != i0 || x->j0 != j0 || x->nx != (g->w - 1 - i0 < T ? g->w - 1 - i0 : T) ||
            x->ny != (g->h - 1 - j0 < T ? g->h - 1 - j0 : T) || isnan(x->zmin) || isnan(x->zmax))
            rc = td_err_set(err, TD_EFORMAT, "%s: tile %zu's record does not fit the grid", path, t);
    }
    if (f)
        fclose(f);
    return rc;
}

/* heights.f32: exactly w*h*4 bytes, mapped read-only into g. */
static td_status heights_map(const char *path, td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    uint64_t want = (uint64_t)g->w * (uint64_t)g->h * 4u;
    struct stat st;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    void *m = MAP_FAILED;
    if (fd < 0 || fstat(fd, &st)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
    } else if ((uint64_t)st.st_size != want) {
        rc = td_err_set(err, TD_EFORMAT, "%s: %lld bytes, the index says %ld x %ld float32 = %llu bytes (%s)",
                        path, (long long)st.st_size, (long)g->w, (long)g->h, (unsigned long long)want,
                        (uint64_t)st.st_size < want ? "truncated" : "too long");
    } else if (want > SIZE_MAX || (m = mmap(NULL, (size_t)want, PROT_READ, MAP_SHARED, fd, 0)) == MAP_FAILED) {
        rc = td_err_set(err, TD_EIO, "%s: cannot map %llu bytes (%s)", path, (unsigned long long)want,
                        strerror(errno));
    } else {
        g->map = m;
        g->map_bytes = (size_t)want;
        g->z = m;
    }
    if (fd >= 0)
        close(fd);
    return rc;
}

td_status td_prepared_open(const char *dir, td_prepared **out, td_err *err)
{
    td_status rc = TD_OK;
    td_prepared *p = calloc(1, sizeof *p);
    char path[PATH_MAX];
    uint64_t tiles_fnv = 0;
    td_grid *g = calloc(1, sizeof *g);

    *out = NULL;
    if (!p || !g) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", dir);
        goto out;
    }
    p->grid = g;
    snprintf(p->dir, sizeof p->dir, "%s", dir);
    if (!path_in(path, sizeof path, dir, TD_PREPARED_INDEX)) {
        rc = td_err_set(err, TD_EINVAL, "%s: path too long", dir);
        goto out;
    }
    rc = index_read(p, path, g, &tiles_fnv, err);
    if (rc)
        goto out;
    g->tiles_x = (g->w - 1 + (1 << g->tile_log2) - 1) >> g->tile_log2;
    g->tiles_y = (g->h - 1 + (1 << g->tile_log2) - 1) >> g->tile_log2;
    path_in(path, sizeof path, dir, TD_PREPARED_TILES);
    rc = tiles_read(path, g, tiles_fnv, err);
    if (rc)
        goto out;
    path_in(path, sizeof path, dir, TD_PREPARED_HEIGHTS);
    rc = heights_map(path, g, err);
    if (rc)
        goto out;
    p->w = g->w;
    p->h = g->h;
    p->fingerprint = td_fnv1a(TD_FNV1A_INIT, p->sums, (size_t)p->nchunks * 8);
    p->fingerprint = td_fnv1a(p->fingerprint, &tiles_fnv, sizeof tiles_fnv);
    *out = p;
    p = NULL;
out:
    td_prepared_free(p);
    return rc;
}

td_grid *td_prepared_take_grid(td_prepared *p)
{
    td_grid *g = p->grid;
    p->grid = NULL;
    return g;
}

uint64_t td_prepared_fingerprint(const td_prepared *p) { return p->fingerprint; }

int32_t td_prepared_chunks(const td_prepared *p) { return p->nchunks; }

td_status td_prepared_verify_chunk(const td_prepared *p, int32_t c, td_err *err)
{
    td_status rc = TD_OK;
    char path[PATH_MAX];
    const int32_t w = p->w, h = p->h;
    int32_t r0 = c * p->chunk_rows, n;
    int fd = -1;
    unsigned char *buf = NULL;
    size_t bytes;
    off_t at;
    uint64_t sum;

    path_in(path, sizeof path, p->dir, TD_PREPARED_HEIGHTS);
    if (c < 0 || c >= p->nchunks) {
        rc = td_err_set(err, TD_EINVAL, "%s: no chunk %ld", path, (long)c);
        goto out;
    }
    n = h - r0 < p->chunk_rows ? h - r0 : p->chunk_rows;
    bytes = (size_t)n * (size_t)w * 4;
    at = (off_t)(h - r0 - n) * (off_t)w * 4;
    buf = malloc(bytes);
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (!buf || fd < 0 || pread(fd, buf, bytes, at) != (ssize_t)bytes) {
        rc = td_err_set(err, TD_EIO, "%s: cannot read chunk %ld (%s)", path, (long)c,
                        buf ? strerror(errno) : "out of memory");
        goto out;
    }
    sum = td_fnv1a(TD_FNV1A_INIT, buf, bytes);
    if (sum != p->sums[c])
        rc = td_err_set(err, TD_EFORMAT, "%s: chunk %ld (file rows %ld..%ld) has checksum %016llx, the index "
                        "says %016llx (corrupted)", path, (long)c, (long)r0, (long)(r0 + n - 1),
                        (unsigned long long)sum, (unsigned long long)p->sums[c]);
    posix_fadvise(fd, at, (off_t)bytes, POSIX_FADV_DONTNEED);
out:
    if (fd >= 0)
        close(fd);
    free(buf);
    return rc;
}

void td_prepared_free(td_prepared *p)
{
    if (p) {
        td_grid_free(p->grid);
        free(p->sums);
        free(p);
    }
}

uint64_t td_prepared_resident(const td_grid *g)
{
    uint64_t kb = 0;
    char line[256];
    unsigned long lo, hi;
    int in = 0;
    FILE *f = g->map ? fopen("/proc/self/smaps", "r") : NULL;
    while (f && fgets(line, sizeof line, f)) {
        unsigned long long v;
        if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2) /* a mapping's first line */
            in = (uintptr_t)lo >= (uintptr_t)g->map && (uintptr_t)hi <= (uintptr_t)g->map + g->map_bytes + 4096;
        else if (in && sscanf(line, "Rss: %llu kB", &v) == 1)
            kb += v;
    }
    if (f)
        fclose(f);
    return kb << 10;
}

uint64_t td_prepared_cached(const td_grid *g)
{
    uint64_t bytes = 0;
    long page = sysconf(_SC_PAGESIZE);
    size_t npages = g->map ? (g->map_bytes + (size_t)page - 1) / (size_t)page : 0;
    unsigned char *vec = npages ? malloc(npages) : NULL;
    if (vec && mincore(g->map, g->map_bytes, vec) == 0)
        for (size_t k = 0; k < npages; k++)
            bytes += (vec[k] & 1u) ? (uint64_t)page : 0;
    free(vec);
    return bytes;
}

void td_prepared_advise(const td_grid *g, int random)
{
    if (g->map)
        madvise(g->map, g->map_bytes, random ? MADV_RANDOM : MADV_NORMAL);
}

void td_prepared_trim(const td_grid *g)
{
    /* Not MADV_PAGEOUT (out of the page cache too): measured on the 16 GiB grid with a
       1 GiB budget, one view's pages (row strips across its whole wedge) outgrew the
       budget, every trim threw away what the view was reading, and 392 GB were read in
       8 minutes without finishing the first view. The page cache's clean pages are the
       kernel's to reclaim. */
    if (g->map)
        madvise(g->map, g->map_bytes, MADV_DONTNEED);
}
