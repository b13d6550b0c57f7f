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
 * are accumulated row by row. Each row then feeds the coarse levels: level k keeps the
 * last three rows of level k-1 and makes each of its rows (lod.c's filter) as soon as the
 * rows around it have arrived, passing it on to level k+1 (rows arrive north first, so a
 * level's rows are made in the same order; the whole pyramid needs three rows a level).
 * Each row also goes into the band of blocks of heights.blk it belongs to (band_feed), and
 * a band is written whole when its lowest row has arrived (that row starts the band below:
 * the blocks share their edge samples).
 * Two threads (chunks_run): the caller reads, checks, checksums and writes chunk c+1
 * while a worker makes the levels of chunk c. After each chunk every file is synced and
 * the state file (chunks done, every layer's rows and checksums, the running statistics)
 * is replaced by rename, so a killed prepare continues from its last chunk, and never
 * from a chunk whose rows were not on disk. The index is written last, by rename.
 *
 * Reading: td_prepared_open reads only the index (a few hundred bytes a chunk) and the
 * tile records (24 bytes a tile), stats the heights and levels and maps them: 16 GiB of
 * heights open in the time of 1 GiB's. Chunks are checked on demand (td_prepared_verify_chunk): the
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
#include <pthread.h>
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
#include "planes.h"
#include "prepaccel.h"

#define TD_PREPARED_FORMAT "terrad-prepared"
#define TD_STATE_MAGIC "TDPREP4"
#define TD_INDEX_MAX (16u << 20) /* 16 MiB of JSON: 65536 chunks of checksums */

_Static_assert(sizeof(td_tile) == 24, "tiles.bin holds td_tile records of 24 bytes");

/* heights.blk (grid.h's td_corners, prepared.h): blocks of B x B cells, (B+1)^2 samples,
 * a row of them (a band: blocks_x blocks, one contiguous range) per B sample rows. */
typedef struct td_blocks {
    int log2;
    int32_t bx, by;          /* blocks a band, bands */
    size_t stride, floats;   /* B + 1, (B + 1)^2 */
    size_t band_bytes;
} td_blocks;

/* Layer k: 0 the heights (grid), 1 .. nlev the coarse levels (lev[k]); their shapes,
 * chunks and checksums are kept when the grids are taken. */
struct td_prepared {
    char dir[PATH_MAX];
    td_grid *grid;
    td_grid *lev[TD_LOD_MAX + 1];
    int nlev;
    int32_t lw[TD_LOD_MAX + 1], lh[TD_LOD_MAX + 1], lchunks[TD_LOD_MAX + 1];
    uint64_t *sums[TD_LOD_MAX + 1];
    uint64_t tiles_fnv[TD_LOD_MAX + 1];
    int32_t chunk_rows, nchunks; /* nchunks: of every layer, then heights.blk's bands */
    td_blocks k;                 /* heights.blk */
    uint64_t *bsums;             /* a checksum per band */
    uint64_t fingerprint;
    int planes_k;                /* the index's "accel" */
    uint64_t accel_bytes, accel_tab_fnv;
    td_pacc *pacc;               /* the tiles' structures, mapped (prepaccel.h) */
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

/* One grid of the form (0: heights.f32; k >= 1: coarse level k, lodk.f32) as the state
 * file keeps it: its shape, the rows written from the north, running statistics. */
typedef struct td_layer {
    int32_t w, h, tiles_x, tiles_y, nchunks, emitted;
    int64_t voids;
    float zmin, zmax;
} td_layer;

typedef struct td_state_hdr {
    char magic[8];
    uint32_t version;
    int32_t tile_log2, chunk_rows, done, nlayers; /* done: chunks of heights.f32 */
    int32_t block_log2, bands;                    /* heights.blk: B = 2^block_log2, band rows */
    int32_t planes_k, accel_rows;                 /* the structures: K, tile rows written */
    uint64_t accel_bytes;                         /* accel.bin's bytes written */
    uint64_t src_size;
    int64_t src_mtime;
    td_layer layer[TD_LOD_MAX + 1];
} td_state_hdr;

typedef struct td_layer_buf {
    uint64_t *sums; /* nchunks */
    float *lo, *hi; /* per tile */
    float *ring;    /* levels: the finer layer's last three rows, at (south row % 3) */
    float *row;     /* levels: the row being made */
    int fd;
} td_layer_buf;

typedef struct td_prep_run {
    const char *dir;
    td_state_hdr st;
    td_layer_buf b[TD_LOD_MAX + 1];
    td_blocks k;
    float *band;     /* the band being filled (the worker's) */
    uint64_t *bsums; /* a checksum per band */
    int bfd;
    int afd[2];      /* accel.tab, accel.bin */
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

/* The name of layer k's heights (tiles 0) or tile records (tiles 1). */
static const char *layer_name(int k, int tiles, char *out, size_t n)
{
    if (k == 0)
        snprintf(out, n, "%s", tiles ? TD_PREPARED_TILES : TD_PREPARED_HEIGHTS);
    else
        snprintf(out, n, tiles ? TD_PREPARED_LEVEL_TILES_FMT : TD_PREPARED_LEVEL_FMT, k);
    return out;
}

static const char *layer_file(int k, char *out, size_t n) { return layer_name(k, 0, out, n); }

/* The blocked layout of a w x h grid with blocks of 2^log2 cells (every sample addressable,
 * grid.h). */
static td_blocks blocks_plan(int32_t w, int32_t h, int log2)
{
    td_blocks k;
    k.log2 = log2;
    k.bx = ((w - 1) >> log2) + 1;
    k.by = ((h - 1) >> log2) + 1;
    k.stride = ((size_t)1 << log2) + 1;
    k.floats = k.stride * k.stride;
    k.band_bytes = (size_t)k.bx * k.floats * 4;
    return k;
}

/* g->cz for heights.blk mapped at m. */
static void blocks_corners(const td_blocks *k, const float *m, td_grid *g)
{
    td_corners c = {m, (size_t)k->bx, k->floats, k->stride, ((uint32_t)1 << k->log2) - 1u, k->log2};
    g->cz = c;
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

static size_t layer_tiles_n(const td_layer *m) { return (size_t)m->tiles_x * (size_t)m->tiles_y; }

static td_status state_save(td_prep_run *r, td_err *err)
{
    const void *parts[2 + 3 * (TD_LOD_MAX + 1)] = {&r->st};
    size_t lens[2 + 3 * (TD_LOD_MAX + 1)] = {sizeof r->st};
    int n = 1;
    for (int k = 0; k < r->st.nlayers; k++) {
        const td_layer *m = &r->st.layer[k];
        parts[n] = r->b[k].sums;
        lens[n++] = (size_t)m->nchunks * 8;
        parts[n] = r->b[k].lo;
        lens[n++] = layer_tiles_n(m) * 4;
        parts[n] = r->b[k].hi;
        lens[n++] = layer_tiles_n(m) * 4;
    }
    parts[n] = r->bsums;
    lens[n++] = (size_t)r->st.bands * 8;
    return write_file(r->dir, TD_PREPARED_STATE, parts, lens, n, err);
}

static int same_layer(const td_layer *a, const td_layer *b)
{
    return a->w == b->w && a->h == b->h && a->tiles_x == b->tiles_x && a->tiles_y == b->tiles_y &&
           a->nchunks == b->nchunks && a->emitted >= 0 && a->emitted <= a->h;
}

/* A state file that matches `want` (same source, shape, chunking and levels): its rows
 * done and statistics into r. Anything else (absent, short, foreign): start again. */
static int state_load(td_prep_run *r, const td_state_hdr *want)
{
    char path[PATH_MAX];
    td_state_hdr h;
    FILE *f = path_in(path, sizeof path, r->dir, TD_PREPARED_STATE) ? fopen(path, "rb") : NULL;
    int ok = f && fread(&h, sizeof h, 1, f) == 1 && !memcmp(h.magic, want->magic, 8) &&
             h.version == want->version && h.tile_log2 == want->tile_log2 &&
             h.chunk_rows == want->chunk_rows && h.nlayers == want->nlayers &&
             h.src_size == want->src_size && h.src_mtime == want->src_mtime && h.done >= 0 &&
             h.done <= want->layer[0].nchunks && h.block_log2 == want->block_log2 && h.bands == want->bands &&
             h.planes_k == want->planes_k && h.accel_rows >= 0;
    for (int k = 0; ok && k < want->nlayers; k++) {
        size_t nt = layer_tiles_n(&want->layer[k]);
        ok = same_layer(&h.layer[k], &want->layer[k]) &&
             fread(r->b[k].sums, 8, (size_t)want->layer[k].nchunks, f) == (size_t)want->layer[k].nchunks &&
             fread(r->b[k].lo, 4, nt, f) == nt && fread(r->b[k].hi, 4, nt, f) == nt;
    }
    ok = ok && fread(r->bsums, 8, (size_t)want->bands, f) == (size_t)want->bands;
    if (ok)
        r->st = h;
    if (f)
        fclose(f);
    return ok;
}

/* Folds south row j (m->w samples) of layer m into its tiles' and its statistics. */
static void stats_row(td_layer *m, td_layer_buf *b, int L, int32_t j, const float *row)
{
    const int32_t T = (int32_t)1 << L, w = m->w;
    int32_t tys[2], nty = 0;
    if ((j >> L) < m->tiles_y)
        tys[nty++] = j >> L;
    if (j > 0 && (j & (T - 1)) == 0)
        tys[nty++] = (j >> L) - 1; /* the top edge of the tile row below */
    for (int32_t i = 0; i < w; i++) {
        float v = row[i];
        if (isnan(v)) {
            m->voids++;
        } else {
            m->zmin = v < m->zmin ? v : m->zmin;
            m->zmax = v > m->zmax ? v : m->zmax;
        }
    }
    for (int32_t tx = 0; tx < m->tiles_x; tx++) {
        int32_t i0 = tx * T, i1 = i0 + T < w - 1 ? i0 + T : w - 1;
        float lo = INFINITY, hi = -INFINITY;
        for (int32_t i = i0; i <= i1; i++) {
            lo = row[i] < lo ? row[i] : lo; /* false for NaN */
            hi = row[i] > hi ? row[i] : hi;
        }
        for (int k = 0; k < nty; k++) {
            size_t t = (size_t)tys[k] * (size_t)m->tiles_x + (size_t)tx;
            b->lo[t] = lo < b->lo[t] ? lo : b->lo[t];
            b->hi[t] = hi > b->hi[t] ? hi : b->hi[t];
        }
    }
}

/* Chunk c of a layer: its rows (*n) and where they start in its file (rows from the
 * north c*R .. c*R+n-1 are the south rows h-c*R-n .. h-1-c*R, one contiguous range). */
static off_t chunk_span(int32_t w, int32_t h, int32_t R, int32_t c, int32_t *n)
{
    int32_t r0 = c * R;
    *n = h - r0 < R ? h - r0 : R;
    return (off_t)(h - r0 - *n) * (off_t)w * 4;
}

/* --- the coarse levels, made while the heights stream ------------------------------ */

/* The finer row whose arrival (rows come north first) completes coarse row J: the
 * lowest of the rows around its node, which lod.c's filter reads. */
static int32_t level_trigger(const td_layer *f, int32_t J)
{
    int32_t cj = 2 * J < f->h - 1 ? 2 * J : f->h - 1;
    return cj > 0 ? cj - 1 : 0;
}

/* Coarse row J from the finer layer f's last three rows: lod.c's filtered() at every node
 * (same weights, same sums in the same order, so the same floats as td_lod_build). */
static void level_row(const td_layer *f, const float *ring, int32_t J, int32_t wk, float *out)
{
    static const double wt[3] = {1.0, 2.0, 1.0};
    const int32_t cj = 2 * J < f->h - 1 ? 2 * J : f->h - 1;
    for (int32_t I = 0; I < wk; I++) {
        int32_t ci = 2 * I < f->w - 1 ? 2 * I : f->w - 1;
        double sum = 0.0, wsum = 0.0;
        float v = NAN;
        if (!isnan(ring[(size_t)(cj % 3) * (size_t)f->w + (size_t)ci])) {
            for (int dj = -1; dj <= 1; dj++) {
                int32_t j = cj + dj;
                if (j < 0 || j >= f->h)
                    continue;
                for (int di = -1; di <= 1; di++) {
                    int32_t i = ci + di;
                    if (i < 0 || i >= f->w)
                        continue;
                    float z = ring[(size_t)(j % 3) * (size_t)f->w + (size_t)i];
                    if (!isnan(z)) {
                        sum += wt[di + 1] * wt[dj + 1] * (double)z;
                        wsum += wt[di + 1] * wt[dj + 1];
                    }
                }
            }
            v = (float)(sum / wsum);
        }
        out[I] = v;
    }
}

/* Chunk c of layer k is written: read it back (from the page cache) for its checksum. */
static td_status layer_sum(td_prep_run *r, int k, int32_t c, unsigned char *scratch, td_err *err)
{
    td_status rc = TD_OK;
    const td_layer *m = &r->st.layer[k];
    int32_t n;
    off_t at = chunk_span(m->w, m->h, r->st.chunk_rows, c, &n);
    size_t bytes = (size_t)n * (size_t)m->w * 4;
    char name[32];
    if (pread(r->b[k].fd, scratch, bytes, at) != (ssize_t)bytes)
        rc = td_err_set(err, TD_EIO, "%s/%s: cannot read back chunk %ld (%s)", r->dir,
                        layer_file(k, name, sizeof name), (long)c, strerror(errno));
    else
        r->b[k].sums[c] = td_fnv1a(TD_FNV1A_INIT, scratch, bytes);
    return rc;
}

/* South row j of layer k-1 arrives (north first): every row of level k it completes is
 * made, written, counted and passed on to level k+1. `scratch` holds a chunk of k. */
static td_status level_feed(td_prep_run *r, int k, int32_t j, const float *row, unsigned char *scratch,
                            td_err *err)
{
    td_status rc = TD_OK;
    const td_layer *f = &r->st.layer[k - 1];
    td_layer *m = &r->st.layer[k];
    td_layer_buf *b = &r->b[k];
    const int32_t R = r->st.chunk_rows;
    char name[32];
    memcpy(b->ring + (size_t)(j % 3) * (size_t)f->w, row, (size_t)f->w * 4);
    while (rc == TD_OK && m->emitted < m->h && level_trigger(f, m->h - 1 - m->emitted) >= j) {
        int32_t J = m->h - 1 - m->emitted;
        size_t bytes = (size_t)m->w * 4;
        level_row(f, b->ring, J, m->w, b->row);
        stats_row(m, b, r->st.tile_log2, J, b->row);
        if (pwrite(b->fd, b->row, bytes, (off_t)J * (off_t)bytes) != (ssize_t)bytes) {
            rc = td_err_set(err, TD_EIO, "%s/%s: cannot write row %ld (%s)", r->dir,
                            layer_file(k, name, sizeof name), (long)J, strerror(errno));
            break;
        }
        m->emitted++;
        if (m->emitted % R == 0 || m->emitted == m->h)
            rc = layer_sum(r, k, (m->emitted - 1) / R, scratch, err);
        if (rc == TD_OK && k + 1 < r->st.nlayers)
            rc = level_feed(r, k + 1, J, b->row, scratch, err);
    }
    return rc;
}

/* After a resume: each level's ring again holds the last rows its finer layer wrote (from
 * that layer's file: what the state counts was synced before the state was saved). */
static td_status rings_load(td_prep_run *r, td_err *err)
{
    td_status rc = TD_OK;
    char name[32];
    for (int k = 1; k < r->st.nlayers && rc == TD_OK; k++) {
        const td_layer *f = &r->st.layer[k - 1];
        size_t bytes = (size_t)f->w * 4;
        for (int32_t j = f->h - f->emitted; j < f->h && j < f->h - f->emitted + 3 && rc == TD_OK; j++)
            if (pread(r->b[k - 1].fd, r->b[k].ring + (size_t)(j % 3) * (size_t)f->w, bytes,
                      (off_t)j * (off_t)bytes) != (ssize_t)bytes)
                rc = td_err_set(err, TD_EIO, "%s/%s: cannot read row %ld to continue (%s)", r->dir,
                                layer_file(k - 1, name, sizeof name), (long)j, strerror(errno));
    }
    return rc;
}

/* --- the blocked copy of the heights, made while they stream ------------------------ */

/* A band of voids: what a band's blocks hold past the grid's last samples. */
static void band_clear(td_prep_run *r)
{
    size_t n = r->k.band_bytes / 4;
    for (size_t i = 0; i < n; i++)
        r->band[i] = NAN;
}

/* South row `row` of the heights as local row lr of every block of the band. */
static void band_put(td_prep_run *r, const float *row, size_t lr)
{
    const int32_t w = r->st.layer[0].w;
    for (int32_t x = 0; x < r->k.bx; x++) {
        int32_t i0 = x << r->k.log2, n = w - i0 < (int32_t)r->k.stride ? w - i0 : (int32_t)r->k.stride;
        memcpy(r->band + (size_t)x * r->k.floats + lr * r->k.stride, row + i0, (size_t)n * 4);
    }
}

/* South row j of the heights arrives (north first): into the band it belongs to; its
 * lowest row completes the band (checksummed and written with one pwrite) and is also the
 * top row of the band below, which starts with it. */
static td_status band_feed(td_prep_run *r, int32_t j, const float *row, td_err *err)
{
    td_status rc = TD_OK;
    const uint32_t mask = ((uint32_t)1 << r->k.log2) - 1u;
    int32_t bj = j >> r->k.log2;
    band_put(r, row, (uint32_t)j & mask);
    if (((uint32_t)j & mask) == 0) {
        r->bsums[bj] = td_fnv1a(TD_FNV1A_INIT, r->band, r->k.band_bytes);
        if (pwrite(r->bfd, r->band, r->k.band_bytes, (off_t)bj * (off_t)r->k.band_bytes) !=
            (ssize_t)r->k.band_bytes)
            rc = td_err_set(err, TD_EIO, "%s/%s: cannot write band %ld (%s)", r->dir, TD_PREPARED_BLOCKS,
                            (long)bj, strerror(errno));
        band_clear(r);
        if (j > 0)
            band_put(r, row, mask + 1u);
    }
    return rc;
}

/* The band in progress when continuing: the rows of it already written, read back from
 * heights.f32 (synced before the state that counts them was saved). */
static td_status band_load(td_prep_run *r, td_err *err)
{
    td_status rc = TD_OK;
    const td_layer *m = &r->st.layer[0];
    const size_t bytes = (size_t)m->w * 4;
    int32_t next = m->h - 1 - m->emitted, top;
    float *row = NULL;
    band_clear(r);
    if (next < 0)
        goto out;
    top = ((next >> r->k.log2) << r->k.log2) + (1 << r->k.log2);
    top = top < m->h - 1 ? top : m->h - 1;
    row = malloc(bytes);
    if (!row && top > next) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a row of %ld samples", (long)m->w);
        goto out;
    }
    for (int32_t j = top; j > next && rc == TD_OK; j--) {
        if (pread(r->b[0].fd, row, bytes, (off_t)j * (off_t)bytes) != (ssize_t)bytes)
            rc = td_err_set(err, TD_EIO, "%s/%s: cannot read row %ld to continue (%s)", r->dir,
                            TD_PREPARED_HEIGHTS, (long)j, strerror(errno));
        else
            band_put(r, row, (size_t)(j - ((next >> r->k.log2) << r->k.log2)));
    }
out:
    free(row);
    return rc;
}

static void hex64(char out[17], uint64_t v) { snprintf(out, 17, "%016llx", (unsigned long long)v); }

static json_t *geo_json(const td_georef *g)
{
    static const char *const kinds[] = {"none", "lonlat", "projected"};
    return json_pack("{s:s, s:f, s:f, s:f, s:f, s:s}", "kind", kinds[g->kind], "x0", g->x0, "y0",
                     g->y0, "dx", g->dx, "dy", g->dy, "crs", g->crs);
}

/* Layer k's tile records, as td_grid_finish computes them (malloc'ed), or NULL. */
static td_tile *tiles_make(const td_prep_run *r, int k)
{
    const td_layer *m = &r->st.layer[k];
    const int32_t T = (int32_t)1 << r->st.tile_log2;
    size_t nt = layer_tiles_n(m);
    td_tile *tiles = calloc(nt, sizeof *tiles);
    for (size_t t = 0; tiles && t < nt; t++) {
        td_tile *x = &tiles[t];
        x->i0 = (int32_t)(t % (size_t)m->tiles_x) * T;
        x->j0 = (int32_t)(t / (size_t)m->tiles_x) * T;
        x->nx = m->w - 1 - x->i0 < T ? m->w - 1 - x->i0 : T;
        x->ny = m->h - 1 - x->j0 < T ? m->h - 1 - x->j0 : T;
        x->zmin = r->b[k].lo[t];
        x->zmax = r->b[k].hi[t];
    }
    return tiles;
}

/* Layer k's tile records written to its tiles file; their checksum into *sum. */
static td_status tiles_write(td_prep_run *r, int k, uint64_t *sum, td_err *err)
{
    td_status rc;
    size_t nt = layer_tiles_n(&r->st.layer[k]);
    td_tile *tiles = tiles_make(r, k);
    char name[32];
    if (!tiles) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %zu tile records", nt);
        goto out;
    }
    *sum = td_fnv1a(TD_FNV1A_INIT, tiles, nt * sizeof *tiles);
    {
        const void *parts[1] = {tiles};
        size_t lens[1] = {nt * sizeof *tiles};
        rc = write_file(r->dir, layer_name(k, 1, name, sizeof name), parts, lens, 1, err);
    }
out:
    free(tiles);
    return rc;
}

/* --- the tiles' structures, after the heights (prepaccel.h) ------------------------- */

/* Layer k as a grid over its written file, mapped read-only (heights.blk for the full
 * grid, as a server maps it; lodK.f32 for a level), with its tile records: what
 * td_prepared_open gives a server, so the structures are the ones a server would build. */
static td_status accel_grid(const td_prep_run *r, const td_src_rows *src, int k, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_layer *m = &r->st.layer[k];
    size_t bytes = k ? (size_t)m->w * (size_t)m->h * 4 : (size_t)r->k.by * r->k.band_bytes;
    td_grid *g = calloc(1, sizeof *g);
    void *map = MAP_FAILED;
    if (g) {
        g->w = m->w;
        g->h = m->h;
        g->sx = ldexp(src->shape.sx, k);
        g->sy = ldexp(src->shape.sy, k);
        g->tile_log2 = r->st.tile_log2;
        g->tiles_x = m->tiles_x;
        g->tiles_y = m->tiles_y;
        g->tiles = tiles_make(r, k);
        map = mmap(NULL, bytes, PROT_READ, MAP_SHARED, k ? r->b[k].fd : r->bfd, 0);
    }
    if (!g || !g->tiles || map == MAP_FAILED) {
        rc = td_err_set(err, g && g->tiles ? TD_EIO : TD_ENOMEM, "%s: cannot map layer %d to build its structures (%s)",
                        r->dir, k, g && g->tiles ? strerror(errno) : "out of memory");
        goto out;
    }
    madvise(map, bytes, MADV_SEQUENTIAL);
    if (k) {
        g->map = map;
        g->map_bytes = bytes;
        g->z = map;
        td_grid_corners_flat(g);
    } else {
        g->bmap = map;
        g->bmap_bytes = bytes;
        blocks_corners(&r->k, map, g);
    }
out:
    if (rc) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}

/* A tile row's payloads appended to accel.bin, their records written at `first` in
 * accel.tab, both synced (before the state that counts them is saved). */
static td_status accel_append(td_prep_run *r, size_t first, td_pacc_blob *b, int32_t n, td_err *err)
{
    td_status rc = TD_OK;
    td_pacc_rec *recs = calloc((size_t)n, sizeof *recs);
    if (!recs) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %ld records", (long)n);
        goto out;
    }
    for (int32_t i = 0; i < n && rc == TD_OK; i++) {
        recs[i] = b[i].rec;
        recs[i].off = r->st.accel_bytes;
        if (pwrite(r->afd[1], b[i].data, b[i].rec.bytes, (off_t)recs[i].off) != (ssize_t)b[i].rec.bytes)
            rc = td_err_set(err, TD_EIO, "%s/%s: cannot write (%s)", r->dir, TD_PACC_BIN, strerror(errno));
        r->st.accel_bytes += b[i].rec.bytes;
    }
    if (rc == TD_OK && pwrite(r->afd[0], recs, (size_t)n * sizeof *recs, (off_t)(first * sizeof *recs)) !=
                           (ssize_t)((size_t)n * sizeof *recs))
        rc = td_err_set(err, TD_EIO, "%s/%s: cannot write (%s)", r->dir, TD_PACC_TAB, strerror(errno));
    if (rc == TD_OK && (fdatasync(r->afd[0]) || fdatasync(r->afd[1])))
        rc = td_err_set(err, TD_EIO, "%s: cannot sync the structures (%s)", r->dir, strerror(errno));
out:
    free(recs);
    return rc;
}

/* Asks the kernel to read tile row ty of layer k's file (g's mapping) while the row before
 * is being built: the build's threads then fault on pages already on their way instead of
 * waiting for each read in turn (heights.blk is read back from disk at 16 GiB). */
static void accel_prefetch(const td_prep_run *r, int k, const td_grid *g, int32_t ty)
{
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    const int32_t T = (int32_t)1 << r->st.tile_log2;
    int32_t j0 = ty * T, j1 = j0 + T < g->h - 1 ? j0 + T : g->h - 1;
    size_t a = k ? (size_t)j0 * (size_t)g->w * 4 : (size_t)(j0 >> r->k.log2) * r->k.band_bytes;
    size_t b = k ? ((size_t)j1 + 1) * (size_t)g->w * 4 : ((size_t)(j1 >> r->k.log2) + 1) * r->k.band_bytes;
    if (ty < g->tiles_y)
        madvise((char *)(k ? g->map : g->bmap) + a / page * page, b - a / page * page, MADV_WILLNEED);
}

/* Every layer's tile rows from where the state says: each row's tiles built on every
 * core (the mapped layer read a tile row at a time, then dropped from the process),
 * appended, the state saved; progress in tile rows. */
static td_status accel_layer(td_prep_run *r, const td_src_rows *src, const td_prepare_opts *o, int k,
                             size_t first, int32_t row0, int32_t total, td_err *err)
{
    td_status rc;
    const td_layer *m = &r->st.layer[k];
    td_grid *g = NULL;
    td_pacc_blob *blobs = calloc((size_t)m->tiles_x, sizeof *blobs);
    rc = blobs ? accel_grid(r, src, k, &g, err) : td_err_set(err, TD_ENOMEM, "out of memory");
    for (int32_t ty = r->st.accel_rows - row0; ty < m->tiles_y && rc == TD_OK; ty++) {
        accel_prefetch(r, k, g, ty + 1);
        rc = td_pacc_build_row(g, ty, r->st.planes_k, o->threads > 0 ? o->threads : td_cpu_count(), blobs, err);
        if (rc == TD_OK)
            rc = accel_append(r, first + (size_t)ty * (size_t)m->tiles_x, blobs, m->tiles_x, err);
        for (int32_t i = 0; i < m->tiles_x; i++) {
            free(blobs[i].data);
            blobs[i].data = NULL;
        }
        madvise(k ? g->map : g->bmap, k ? g->map_bytes : g->bmap_bytes, MADV_DONTNEED);
        if (rc == TD_OK) {
            r->st.accel_rows++;
            rc = state_save(r, err);
        }
        if (rc == TD_OK && o->progress && o->progress(o->cls, r->st.accel_rows, total, 0))
            rc = td_err_set(err, TD_ECANCELED, "%s: prepare stopped after %ld of %ld tile rows of structures (run it "
                            "again to continue)", r->dir, (long)r->st.accel_rows, (long)total);
    }
    td_grid_free(g);
    free(blobs);
    return rc;
}

static td_status accel_run(td_prep_run *r, const td_src_rows *src, const td_prepare_opts *o, td_err *err)
{
    td_status rc = TD_OK;
    int32_t total = 0, row0 = 0;
    size_t first = 0;
    const char *names[2] = {TD_PACC_TAB, TD_PACC_BIN};
    char path[PATH_MAX];
    for (int k = 0; k < r->st.nlayers; k++)
        total += r->st.layer[k].tiles_y;
    for (int f = 0; f < 2 && rc == TD_OK; f++)
        if (!path_in(path, sizeof path, r->dir, names[f]) ||
            (r->afd[f] = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644)) < 0)
            rc = td_err_set(err, TD_EIO, "%s: cannot create (%s)", path, strerror(errno));
    for (int k = 0; k < r->st.nlayers && rc == TD_OK; k++) {
        const td_layer *m = &r->st.layer[k];
        if (r->st.accel_rows < row0 + m->tiles_y)
            rc = accel_layer(r, src, o, k, first, row0, total, err);
        first += layer_tiles_n(m);
        row0 += m->tiles_y;
    }
    /* what a killed run wrote past the last row the state counts */
    if (rc == TD_OK && (ftruncate(r->afd[0], (off_t)(first * sizeof(td_pacc_rec))) ||
                        ftruncate(r->afd[1], (off_t)r->st.accel_bytes) || fsync(r->afd[0]) || fsync(r->afd[1])))
        rc = td_err_set(err, TD_EIO, "%s: cannot finish the structures' files (%s)", r->dir, strerror(errno));
    return rc;
}

/* accel.tab's checksum (the index's accel.tab_fnv), read back whole (48 bytes a tile). */
static td_status accel_tab_sum(const td_prep_run *r, uint64_t *sum, td_err *err)
{
    td_status rc = TD_OK;
    struct stat st;
    unsigned char *buf = NULL;
    if (fstat(r->afd[0], &st) || !(buf = malloc((size_t)st.st_size + 1)) ||
        pread(r->afd[0], buf, (size_t)st.st_size, 0) != (ssize_t)st.st_size)
        rc = td_err_set(err, TD_EIO, "%s/%s: cannot read back (%s)", r->dir, TD_PACC_TAB,
                        buf ? strerror(errno) : "out of memory");
    else
        *sum = td_fnv1a(TD_FNV1A_INIT, buf, (size_t)st.st_size);
    free(buf);
    return rc;
}

/* A layer's index fields: chunks, height range, voids, the tile records' checksum. */
static json_t *layer_json(const td_prep_run *r, int k, uint64_t tsum)
{
    const td_layer *m = &r->st.layer[k];
    int allvoid = m->voids == (int64_t)m->w * m->h;
    json_t *sums = json_array();
    char hx[17];
    for (int32_t c = 0; sums && c < m->nchunks; c++) {
        hex64(hx, r->b[k].sums[c]);
        json_array_append_new(sums, json_string(hx));
    }
    hex64(hx, tsum);
    return json_pack("{s:I, s:I, s:o, s:o, s:I, s:o, s:s}", "width", (json_int_t)m->w, "height", (json_int_t)m->h,
                     "zmin", allvoid ? json_null() : json_real((double)m->zmin),
                     "zmax", allvoid ? json_null() : json_real((double)m->zmax), "voids", (json_int_t)m->voids,
                     "chunks", sums ? sums : json_null(), "tiles_fnv", hx);
}

/* The tile records of every layer and the index, from the finished run. */
static td_status finish(td_prep_run *r, const td_src_rows *src, td_err *err)
{
    td_status rc = TD_OK;
    json_t *root = NULL, *levels = json_array(), *base = NULL, *bands = json_array();
    char *text = NULL, hx[17], ahx[17];
    uint64_t tsum = 0, asum = 0;

    rc = accel_tab_sum(r, &asum, err);
    hex64(ahx, asum);
    for (int k = 0; k < r->st.nlayers && rc == TD_OK; k++) {
        rc = tiles_write(r, k, &tsum, err);
        if (rc == TD_OK && k == 0)
            base = layer_json(r, 0, tsum);
        else if (rc == TD_OK && levels)
            json_array_append_new(levels, layer_json(r, k, tsum));
    }
    for (int32_t b = 0; bands && b < r->st.bands; b++) {
        hex64(hx, r->bsums[b]);
        json_array_append_new(bands, json_string(hx));
    }
    if (rc)
        goto out;
    root = base && levels && bands ? json_pack("{s:s, s:i, s:[f,f], s:i, s:o, s:i, s:{s:s, s:I, s:I}, s:O, s:{s:i, s:O}, "
                                               "s:{s:i, s:I, s:s}}",
                                      "format", TD_PREPARED_FORMAT, "version", TD_PREPARED_VERSION,
                                      "spacing", src->shape.sx, src->shape.sy, "tile_log2", r->st.tile_log2,
                                      "georef", geo_json(&src->shape.geo), "chunk_rows", r->st.chunk_rows,
                                      "source", "name", td_demutil_basename(src->path),
                                      "bytes", (json_int_t)src->size, "mtime", (json_int_t)src->mtime,
                                      "levels", levels, "blocks", "log2", r->st.block_log2, "bands", bands,
                                      "accel", "planes_k", r->st.planes_k, "bytes", (json_int_t)r->st.accel_bytes,
                                      "tab_fnv", ahx)
                              : NULL;
    text = root && json_object_update(root, base) == 0 ? json_dumps(root, JSON_INDENT(1) | JSON_COMPACT) : NULL;
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
    json_decref(levels);
    json_decref(base);
    json_decref(bands);
    return rc;
}

/* The layers' shapes: the heights, then lod.c's levels (halved while both sides exceed 2
 * samples, at most TD_LOD_MAX). */
static void layers_plan(td_state_hdr *st, int32_t w, int32_t h)
{
    const int32_t T = (int32_t)1 << st->tile_log2;
    for (int k = 0; k <= TD_LOD_MAX; k++) {
        td_layer *m = &st->layer[k];
        if (k > 0 && (st->layer[k - 1].w <= 2 || st->layer[k - 1].h <= 2))
            break;
        m->w = k == 0 ? w : st->layer[k - 1].w / 2 + 1; /* lod.c: ceil((n-1)/2) + 1 */
        m->h = k == 0 ? h : st->layer[k - 1].h / 2 + 1;
        m->tiles_x = (m->w - 1 + T - 1) / T;
        m->tiles_y = (m->h - 1 + T - 1) / T;
        m->nchunks = (m->h + st->chunk_rows - 1) / st->chunk_rows;
        m->zmin = INFINITY;
        m->zmax = -INFINITY;
        st->nlayers = k + 1;
    }
}

/* The run's buffers and its state: fresh, or continued from a matching state file. */
static td_status run_init(td_prep_run *r, const td_src_rows *src, const td_prepare_opts *o,
                          td_err *err)
{
    td_status rc = TD_OK;
    td_state_hdr want;
    const int32_t T = (int32_t)1 << src->shape.tile_log2;
    int ok;

    memset(&want, 0, sizeof want);
    memcpy(want.magic, TD_STATE_MAGIC, 8);
    want.version = TD_PREPARED_VERSION;
    want.tile_log2 = src->shape.tile_log2;
    want.chunk_rows = o->chunk_rows > 0 ? o->chunk_rows : T;
    want.chunk_rows = want.chunk_rows < src->shape.h ? want.chunk_rows : src->shape.h;
    want.src_size = src->size;
    want.src_mtime = src->mtime;
    layers_plan(&want, src->shape.w, src->shape.h);
    want.block_log2 = o->block_log2 ? o->block_log2 : TD_PREPARED_BLOCK_LOG2;
    r->k = blocks_plan(src->shape.w, src->shape.h, want.block_log2);
    want.bands = r->k.by;
    want.planes_k = o->planes_k > 0 ? o->planes_k : o->planes_k == TD_PREPARE_NO_PLANES ? 0 : TD_PLANES_K_DEFAULT;
    r->band = malloc(r->k.band_bytes);
    r->bsums = calloc((size_t)r->k.by, 8);
    ok = r->band && r->bsums;
    for (int k = 0; k < want.nlayers && ok; k++) {
        const td_layer *m = &want.layer[k];
        td_layer_buf *b = &r->b[k];
        b->sums = calloc((size_t)m->nchunks, 8);
        b->lo = malloc(layer_tiles_n(m) * 4);
        b->hi = malloc(layer_tiles_n(m) * 4);
        b->ring = k ? malloc((size_t)want.layer[k - 1].w * 3 * 4) : NULL;
        b->row = k ? malloc((size_t)m->w * 4) : NULL;
        ok = b->sums && b->lo && b->hi && (!k || (b->ring && b->row));
    }
    if (!ok) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for chunks of %ld rows of %ld samples",
                        (long)want.chunk_rows, (long)src->shape.w);
        goto out;
    }
    if (!state_load(r, &want)) {
        r->st = want;
        for (int k = 0; k < want.nlayers; k++)
            for (size_t t = 0; t < layer_tiles_n(&want.layer[k]); t++) {
                r->b[k].lo[t] = INFINITY;
                r->b[k].hi[t] = -INFINITY;
            }
    }
out:
    return rc;
}

static void run_free(td_prep_run *r)
{
    if (r->bfd >= 0)
        close(r->bfd);
    for (int f = 0; f < 2; f++)
        if (r->afd[f] >= 0)
            close(r->afd[f]);
    free(r->band);
    free(r->bsums);
    for (int k = 0; k <= TD_LOD_MAX; k++) {
        if (r->b[k].fd >= 0)
            close(r->b[k].fd);
        free(r->b[k].sums);
        free(r->b[k].lo);
        free(r->b[k].hi);
        free(r->b[k].ring);
        free(r->b[k].row);
    }
}

/* Every layer's file, of its final size (kept as they are when continuing). */
static td_status files_open(td_prep_run *r, td_err *err)
{
    td_status rc = TD_OK;
    char path[PATH_MAX], name[32];
    for (int k = 0; k < r->st.nlayers && rc == TD_OK; k++) {
        const td_layer *m = &r->st.layer[k];
        if (!path_in(path, sizeof path, r->dir, layer_file(k, name, sizeof name)) ||
            (r->b[k].fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644)) < 0 ||
            ftruncate(r->b[k].fd, (off_t)m->w * (off_t)m->h * 4))
            rc = td_err_set(err, TD_EIO, "%s: cannot create (%s)", path, strerror(errno));
    }
    if (rc == TD_OK && (!path_in(path, sizeof path, r->dir, TD_PREPARED_BLOCKS) ||
                        (r->bfd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644)) < 0 ||
                        ftruncate(r->bfd, (off_t)r->k.by * (off_t)r->k.band_bytes)))
        rc = td_err_set(err, TD_EIO, "%s: cannot create (%s)", path, strerror(errno));
    return rc;
}

/* An index already there for this very source and chunking: nothing to do. */
static int already_done(const char *dir, const td_src_rows *src, int block_log2)
{
    td_prepared *p = NULL;
    char path[PATH_MAX];
    json_t *root = NULL;
    int same = 0;
    if (td_prepared_open(dir, &p, NULL) == TD_OK && path_in(path, sizeof path, dir, TD_PREPARED_INDEX) &&
        (root = json_load_file(path, 0, NULL)) != NULL) {
        json_t *s = json_object_get(root, "source");
        same = p->grid->w == src->shape.w && p->grid->h == src->shape.h && p->k.log2 == block_log2 &&
               p->grid->tile_log2 == src->shape.tile_log2 &&
               json_integer_value(json_object_get(s, "bytes")) == (json_int_t)src->size &&
               json_integer_value(json_object_get(s, "mtime")) == (json_int_t)src->mtime;
    }
    json_decref(root);
    td_prepared_free(p);
    return same;
}

/* --- the pipeline: the caller's thread reads, a worker makes the levels -------------- */

/* A chunk between the two threads: its rows in south order, its own statistics (merged
 * into the run's by the worker, in chunk order, so the state saved counts exactly the
 * chunks done) and checksum. */
typedef struct td_pchunk {
    int32_t c, n;
    int full;     /* read and written; the worker's until it empties it */
    float *rows;  /* chunk_rows * w */
    td_layer m;   /* zmin, zmax, voids of its rows */
    td_layer_buf b; /* lo, hi per tile of its rows (sums, ring, row unused) */
    uint64_t sum;
} td_pchunk;

typedef struct td_pipe {
    td_prep_run *r;
    const td_prepare_opts *o;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    td_pchunk ch[2];          /* chunk c in ch[c % 2] */
    unsigned char *scratch;   /* the worker's: a chunk of level 1, read back for its checksum */
    int stop, eof;            /* under mu: the worker failed or was stopped; nothing more to read */
    td_status wrc;            /* the worker's failure */
    td_err werr;
} td_pipe;

/* The caller's part of chunk c: read, reverse into south order (in place, a row swap at a
 * time), its statistics, checksum and one pwrite. */
static td_status chunk_read(td_prep_run *r, td_src_rows *src, td_pchunk *p, int32_t c, td_err *err)
{
    td_status rc;
    const td_layer *m = &r->st.layer[0];
    const size_t w = (size_t)m->w;
    off_t at = chunk_span(m->w, m->h, r->st.chunk_rows, c, &p->n);
    int32_t r0 = c * r->st.chunk_rows;
    size_t bytes = (size_t)p->n * w * 4;

    p->c = c;
    /* the shape only: the worker is updating the statistics of *m meanwhile */
    p->m.w = m->w;
    p->m.h = m->h;
    p->m.tiles_x = m->tiles_x;
    p->m.tiles_y = m->tiles_y;
    p->m.zmin = INFINITY;
    p->m.zmax = -INFINITY;
    p->m.voids = 0;
    for (size_t t = 0; t < layer_tiles_n(m); t++) {
        p->b.lo[t] = INFINITY;
        p->b.hi[t] = -INFINITY;
    }
    rc = src_rows(src, r0, p->n, p->rows, err);
    for (int32_t k = 0; k < p->n / 2 && rc == TD_OK; k++) {
        float *a = p->rows + (size_t)k * w, *b = p->rows + (size_t)(p->n - 1 - k) * w;
        for (size_t i = 0; i < w; i++) {
            float t = a[i];
            a[i] = b[i];
            b[i] = t;
        }
    }
    for (int32_t k = 0; k < p->n && rc == TD_OK; k++)
        stats_row(&p->m, &p->b, r->st.tile_log2, m->h - 1 - (r0 + k), p->rows + (size_t)(p->n - 1 - k) * w);
    if (rc == TD_OK) {
        p->sum = td_fnv1a(TD_FNV1A_INIT, p->rows, bytes);
        if (pwrite(r->b[0].fd, p->rows, bytes, at) != (ssize_t)bytes)
            rc = td_err_set(err, TD_EIO, "%s/%s: cannot write chunk %ld (%s)", r->dir,
                            TD_PREPARED_HEIGHTS, (long)c, strerror(errno));
    }
    return rc;
}

/* The worker's part of chunk p->c (the next in order): its statistics and checksum into
 * the run's, the levels its rows complete, every file synced, the state saved, progress. */
static td_status chunk_finish(td_pipe *pp, td_pchunk *p, td_err *err)
{
    td_status rc = TD_OK;
    td_prep_run *r = pp->r;
    td_layer *m = &r->st.layer[0];
    const size_t w = (size_t)m->w;
    int32_t r0 = p->c * r->st.chunk_rows;

    m->zmin = p->m.zmin < m->zmin ? p->m.zmin : m->zmin;
    m->zmax = p->m.zmax > m->zmax ? p->m.zmax : m->zmax;
    m->voids += p->m.voids;
    for (size_t t = 0; t < layer_tiles_n(m); t++) {
        r->b[0].lo[t] = p->b.lo[t] < r->b[0].lo[t] ? p->b.lo[t] : r->b[0].lo[t];
        r->b[0].hi[t] = p->b.hi[t] > r->b[0].hi[t] ? p->b.hi[t] : r->b[0].hi[t];
    }
    r->b[0].sums[p->c] = p->sum;
    for (int32_t k = 0; k < p->n && rc == TD_OK; k++)
        rc = band_feed(r, m->h - 1 - (r0 + k), p->rows + (size_t)(p->n - 1 - k) * w, err);
    for (int32_t k = 0; k < p->n && rc == TD_OK && r->st.nlayers > 1; k++)
        rc = level_feed(r, 1, m->h - 1 - (r0 + k), p->rows + (size_t)(p->n - 1 - k) * w, pp->scratch, err);
    for (int k = 0; k < r->st.nlayers && rc == TD_OK; k++)
        if (fdatasync(r->b[k].fd))
            rc = td_err_set(err, TD_EIO, "%s: cannot sync layer %d (%s)", r->dir, k, strerror(errno));
    if (rc == TD_OK && fdatasync(r->bfd))
        rc = td_err_set(err, TD_EIO, "%s/%s: cannot sync (%s)", r->dir, TD_PREPARED_BLOCKS, strerror(errno));
    if (rc == TD_OK) {
        m->emitted += p->n;
        r->st.done = p->c + 1;
        rc = state_save(r, err);
    }
    if (rc == TD_OK && pp->o->progress &&
        pp->o->progress(pp->o->cls, r->st.done == m->nchunks ? m->h : (int64_t)r->st.done * r->st.chunk_rows,
                        m->h, m->w))
        rc = td_err_set(err, TD_ECANCELED, "%s: prepare stopped after %ld of %ld chunks (run it again to continue)",
                        r->dir, (long)r->st.done, (long)m->nchunks);
    return rc;
}

static void *pipe_worker(void *arg)
{
    td_pipe *pp = arg;
    for (int32_t c = pp->r->st.done;; c++) {
        td_pchunk *p = &pp->ch[c % 2];
        td_status rc;
        td_err e = {0};
        int go;
        pthread_mutex_lock(&pp->mu);
        while (!p->full && !pp->stop && !pp->eof)
            pthread_cond_wait(&pp->cv, &pp->mu);
        go = p->full && !pp->stop;
        pthread_mutex_unlock(&pp->mu);
        if (!go)
            break;
        rc = chunk_finish(pp, p, &e);
        pthread_mutex_lock(&pp->mu);
        p->full = 0;
        if (rc) {
            pp->stop = 1;
            pp->wrc = rc;
            pp->werr = e;
        }
        pthread_cond_broadcast(&pp->cv);
        pthread_mutex_unlock(&pp->mu);
        if (rc)
            break;
    }
    return NULL;
}

static int pipe_alloc(td_pipe *pp, const td_prep_run *r)
{
    const td_layer *m = &r->st.layer[0];
    size_t rows = (size_t)r->st.chunk_rows * (size_t)m->w;
    int ok = (pp->scratch = malloc(r->st.nlayers > 1 ? (size_t)r->st.chunk_rows * (size_t)r->st.layer[1].w * 4 : 1)) != NULL;
    for (int k = 0; k < 2 && ok; k++) {
        pp->ch[k].rows = malloc(rows * 4);
        pp->ch[k].b.lo = malloc(layer_tiles_n(m) * 4);
        pp->ch[k].b.hi = malloc(layer_tiles_n(m) * 4);
        ok = pp->ch[k].rows && pp->ch[k].b.lo && pp->ch[k].b.hi;
    }
    return ok;
}

static void pipe_free(td_pipe *pp)
{
    for (int k = 0; k < 2; k++) {
        free(pp->ch[k].rows);
        free(pp->ch[k].b.lo);
        free(pp->ch[k].b.hi);
    }
    free(pp->scratch);
}

/* The chunks left: this thread reads, checks, checksums and writes chunk c + 1 while the
 * worker makes the levels of chunk c, syncs and saves the state that counts it (each
 * part about half the work: the two cores of this machine). Stopped by the progress
 * callback, the worker saves no chunk after the one it was told at. */
static td_status chunks_run(td_prep_run *r, td_src_rows *src, const td_prepare_opts *o, td_err *err)
{
    td_status rc = TD_OK;
    td_pipe pp;
    pthread_t th;
    int started = 0;

    memset(&pp, 0, sizeof pp);
    pp.r = r;
    pp.o = o;
    pthread_mutex_init(&pp.mu, NULL);
    pthread_cond_init(&pp.cv, NULL);
    if (!pipe_alloc(&pp, r)) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for chunks of %ld rows of %ld samples",
                        (long)r->st.chunk_rows, (long)r->st.layer[0].w);
        goto out;
    }
    if (pthread_create(&th, NULL, pipe_worker, &pp)) {
        rc = td_err_set(err, TD_ENOMEM, "cannot start the prepare's worker thread");
        goto out;
    }
    started = 1;
    for (int32_t c = r->st.done; c < r->st.layer[0].nchunks && rc == TD_OK; c++) {
        td_pchunk *p = &pp.ch[c % 2];
        int stop;
        pthread_mutex_lock(&pp.mu);
        while (p->full && !pp.stop)
            pthread_cond_wait(&pp.cv, &pp.mu);
        stop = pp.stop;
        pthread_mutex_unlock(&pp.mu);
        if (stop)
            break;
        rc = chunk_read(r, src, p, c, err);
        pthread_mutex_lock(&pp.mu);
        p->full = rc == TD_OK;
        pp.stop |= rc != TD_OK;
        pthread_cond_broadcast(&pp.cv);
        pthread_mutex_unlock(&pp.mu);
    }
out:
    if (started) {
        pthread_mutex_lock(&pp.mu);
        pp.eof = 1;
        pthread_cond_broadcast(&pp.cv);
        pthread_mutex_unlock(&pp.mu);
        pthread_join(th, NULL);
    }
    if (rc == TD_OK && pp.wrc) {
        rc = pp.wrc;
        if (err)
            *err = pp.werr;
    }
    pipe_free(&pp);
    pthread_mutex_destroy(&pp.mu);
    pthread_cond_destroy(&pp.cv);
    return rc;
}

td_status td_prepare(const char *src_path, const char *dir, const td_prepare_opts *o,
                     td_prepare_result *res, td_err *err)
{
    td_status rc;
    td_src_rows src;
    td_prep_run r;
    char path[PATH_MAX];
    int lock = -1;

    memset(res, 0, sizeof *res);
    memset(&r, 0, sizeof r);
    r.dir = dir;
    r.bfd = -1;
    r.afd[0] = r.afd[1] = -1;
    for (int k = 0; k <= TD_LOD_MAX; k++)
        r.b[k].fd = -1;
    if (o->planes_k < TD_PREPARE_NO_PLANES || o->planes_k > TD_PLANES_K_MAX) {
        memset(&src, 0, sizeof src);
        rc = td_err_field(err, TD_EINVAL, "planes_k", "%d slices: outside 1 .. %d", o->planes_k, TD_PLANES_K_MAX);
        goto out;
    }
    if (o->block_log2 && (o->block_log2 < TD_PREPARED_BLOCK_LOG2_MIN || o->block_log2 > TD_PREPARED_BLOCK_LOG2_MAX)) {
        memset(&src, 0, sizeof src);
        rc = td_err_field(err, TD_EINVAL, "block_log2", "blocks of 2^%d cells: outside 2^%d .. 2^%d", o->block_log2,
                          TD_PREPARED_BLOCK_LOG2_MIN, TD_PREPARED_BLOCK_LOG2_MAX);
        goto out;
    }
    rc = src_open(&src, src_path, &o->dem, err);
    if (rc)
        goto out;
    res->w = src.shape.w;
    res->h = src.shape.h;
    res->streamed = src.whole == NULL;
    res->bytes = (uint64_t)src.shape.w * (uint64_t)src.shape.h * 4u;
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
    if (already_done(dir, &src, o->block_log2 ? o->block_log2 : TD_PREPARED_BLOCK_LOG2)) {
        res->already = 1;
        goto out;
    }
    rc = run_init(&r, &src, o, err);
    if (rc)
        goto out;
    res->resumed_rows = (int64_t)r.st.done * r.st.chunk_rows;
    res->resumed_rows = res->resumed_rows < r.st.layer[0].h ? res->resumed_rows : r.st.layer[0].h;
    res->levels = r.st.nlayers - 1;
    if (path_in(path, sizeof path, dir, TD_PREPARED_INDEX))
        unlink(path); /* a stale index must not describe half-rewritten heights */
    rc = files_open(&r, err);
    if (rc == TD_OK)
        rc = rings_load(&r, err);
    if (rc == TD_OK)
        rc = band_load(&r, err);
    if (rc == TD_OK)
        rc = chunks_run(&r, &src, o, err);
    if (rc == TD_OK)
        rc = accel_run(&r, &src, o, err);
    if (rc == TD_OK)
        rc = finish(&r, &src, err);
    if (rc == TD_OK && path_in(path, sizeof path, dir, TD_PREPARED_STATE))
        unlink(path);
out:
    run_free(&r);
    if (lock >= 0)
        close(lock);
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

/* One layer's fields of the index (o: the root for the heights, an entry of "levels"):
 * its shape must be (w, h); height range, voids, chunk checksums and tile checksum into
 * g, p->sums[k] and p->tiles_fnv[k]. */
static td_status layer_read(td_prepared *p, const char *path, json_t *o, int k, int32_t w, int32_t h,
                            td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    json_t *chunks = json_object_get(o, "chunks");
    size_t nc = json_array_size(chunks);
    char name[32];
    layer_file(k, name, sizeof name);
    if (json_integer_value(json_object_get(o, "width")) != w || json_integer_value(json_object_get(o, "height")) != h ||
        nc != (size_t)((h + p->chunk_rows - 1) / p->chunk_rows) ||
        !hex_parse(json_string_value(json_object_get(o, "tiles_fnv")), &p->tiles_fnv[k])) {
        rc = td_err_set(err, TD_EFORMAT, "%s: %s's width, height, chunks or tiles_fnv missing or inconsistent",
                        path, name);
        goto out;
    }
    g->w = w;
    g->h = h;
    g->zmin = json_is_number(json_object_get(o, "zmin")) ? (float)json_number_value(json_object_get(o, "zmin")) : NAN;
    g->zmax = json_is_number(json_object_get(o, "zmax")) ? (float)json_number_value(json_object_get(o, "zmax")) : NAN;
    g->voids = json_integer_value(json_object_get(o, "voids"));
    p->lw[k] = w;
    p->lh[k] = h;
    p->lchunks[k] = (int32_t)nc;
    p->sums[k] = calloc(nc, 8);
    if (!p->sums[k]) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
        goto out;
    }
    for (size_t c = 0; c < nc && rc == TD_OK; c++)
        if (!hex_parse(json_string_value(json_array_get(chunks, c)), &p->sums[k][c]))
            rc = td_err_set(err, TD_EFORMAT, "%s: %s chunks[%zu] is not a 16-digit hex checksum", path, name, c);
out:
    return rc;
}

/* The coarse levels of the index: as many, and of the shapes, lod.c's rule gives for the
 * grid g; each gets g's tiling and georeference at its spacing. */
static td_status levels_read(td_prepared *p, const char *path, json_t *levels, const td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    int32_t w = g->w, h = g->h;
    int n = 0;
    while (n < TD_LOD_MAX && w > 2 && h > 2) {
        w = w / 2 + 1;
        h = h / 2 + 1;
        n++;
    }
    if (!json_is_array(levels) || json_array_size(levels) != (size_t)n) {
        rc = td_err_set(err, TD_EFORMAT, "%s: levels missing or not the %d coarse levels of a %ld x %ld grid",
                        path, n, (long)g->w, (long)g->h);
        goto out;
    }
    w = g->w;
    h = g->h;
    for (int k = 1; k <= n && rc == TD_OK; k++) {
        td_grid *l = calloc(1, sizeof *l);
        p->lev[k] = l;
        if (!l) {
            rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
            break;
        }
        w = w / 2 + 1;
        h = h / 2 + 1;
        rc = layer_read(p, path, json_array_get(levels, (size_t)k - 1), k, w, h, l, err);
        l->sx = ldexp(g->sx, k);
        l->sy = ldexp(g->sy, k);
        l->tile_log2 = g->tile_log2;
        l->geo = g->geo;
        l->geo.dx = ldexp(g->geo.dx, k);
        l->geo.dy = ldexp(g->geo.dy, k);
        p->nlev = k;
    }
out:
    return rc;
}

/* heights.blk's block size and band checksums (the index's "blocks"). */
static td_status blocks_read(td_prepared *p, const char *path, json_t *o, const td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    json_t *bands = json_object_get(o, "bands");
    json_int_t l2 = json_integer_value(json_object_get(o, "log2"));
    if (l2 < TD_PREPARED_BLOCK_LOG2_MIN || l2 > TD_PREPARED_BLOCK_LOG2_MAX) {
        rc = td_err_set(err, TD_EFORMAT, "%s: blocks.log2 missing or outside %d..%d", path,
                        TD_PREPARED_BLOCK_LOG2_MIN, TD_PREPARED_BLOCK_LOG2_MAX);
        goto out;
    }
    p->k = blocks_plan(g->w, g->h, (int)l2);
    if (json_array_size(bands) != (size_t)p->k.by) {
        rc = td_err_set(err, TD_EFORMAT, "%s: blocks.bands is not %ld checksums (bands of %d rows of a %ld-row grid)",
                        path, (long)p->k.by, 1 << (int)l2, (long)g->h);
        goto out;
    }
    p->bsums = calloc((size_t)p->k.by, 8);
    if (!p->bsums) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
        goto out;
    }
    for (int32_t b = 0; b < p->k.by && rc == TD_OK; b++)
        if (!hex_parse(json_string_value(json_array_get(bands, (size_t)b)), &p->bsums[b]))
            rc = td_err_set(err, TD_EFORMAT, "%s: blocks.bands[%ld] is not a 16-digit hex checksum", path, (long)b);
out:
    return rc;
}

/* The structures' K, accel.bin's size and accel.tab's checksum (the index's "accel"). */
static td_status accel_read(td_prepared *p, const char *path, json_t *o, td_err *err)
{
    td_status rc = TD_OK;
    json_int_t k = json_integer_value(json_object_get(o, "planes_k"));
    json_int_t bytes = json_integer_value(json_object_get(o, "bytes"));
    if (!json_is_integer(json_object_get(o, "planes_k")) || k < 0 || k > TD_PLANES_K_MAX || bytes < 8 ||
        !hex_parse(json_string_value(json_object_get(o, "tab_fnv")), &p->accel_tab_fnv))
        rc = td_err_set(err, TD_EFORMAT, "%s: accel.planes_k, accel.bytes or accel.tab_fnv missing or out of range",
                        path);
    p->planes_k = (int)k;
    p->accel_bytes = (uint64_t)bytes;
    return rc;
}

/* The index's fields into p and the grid records (no heights, no tiles yet). */
static td_status index_read(td_prepared *p, const char *path, td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    json_error_t je;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je), *sp;
    const char *fmt;
    json_int_t ver, w, h, tl, cr;

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
    if (w < 2 || h < 2 || w > INT32_MAX || h > INT32_MAX || tl < 1 || tl > 16 || cr < 1 || cr > h ||
        json_array_size(sp) != 2) {
        rc = td_err_set(err, TD_EFORMAT, "%s: width, height, tile_log2, chunk_rows or spacing missing or "
                        "inconsistent", path);
        goto out;
    }
    p->chunk_rows = (int32_t)cr;
    g->tile_log2 = (int)tl;
    g->sx = json_number_value(json_array_get(sp, 0));
    g->sy = json_number_value(json_array_get(sp, 1));
    if (!(g->sx > 0) || !(g->sy > 0) || !isfinite(g->sx) || !isfinite(g->sy)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: spacing is not positive and finite", path);
        goto out;
    }
    rc = layer_read(p, path, root, 0, (int32_t)w, (int32_t)h, g, err);
    if (rc == TD_OK)
        rc = geo_parse(path, json_object_get(root, "georef"), &g->geo, err);
    if (rc == TD_OK)
        rc = levels_read(p, path, json_object_get(root, "levels"), g, err);
    if (rc == TD_OK)
        rc = blocks_read(p, path, json_object_get(root, "blocks"), g, err);
    if (rc == TD_OK)
        rc = accel_read(p, path, json_object_get(root, "accel"), err);
out:
    json_decref(root);
    return rc;
}

/* A layer's tile records: size, checksum, and records that fit the grid (a tracer
 * indexes with them). */
static td_status tiles_read(const char *path, td_grid *g, uint64_t want, td_err *err)
{
    td_status rc = TD_OK;
    const int32_t T = (int32_t)1 << g->tile_log2;
    size_t nt;
    FILE *f = fopen(path, "rb");
    struct stat st;

    g->tiles_x = (g->w - 1 + T - 1) >> g->tile_log2;
    g->tiles_y = (g->h - 1 + T - 1) >> g->tile_log2;
    nt = (size_t)g->tiles_x * (size_t)g->tiles_y;
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

/* A file of exactly `want` bytes (`what`: how the index makes them so), mapped read-only. */
static td_status file_map(const char *path, uint64_t want, const char *what, void **out, td_err *err)
{
    td_status rc = TD_OK;
    struct stat st;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    void *m = MAP_FAILED;
    if (fd < 0 || fstat(fd, &st)) {
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
    } else if ((uint64_t)st.st_size != want) {
        rc = td_err_set(err, TD_EFORMAT, "%s: %lld bytes, the index says %s = %llu bytes (%s)", path,
                        (long long)st.st_size, what, (unsigned long long)want,
                        (uint64_t)st.st_size < want ? "truncated" : "too long");
    } else if (want > SIZE_MAX || (m = mmap(NULL, (size_t)want, PROT_READ, MAP_SHARED, fd, 0)) == MAP_FAILED) {
        rc = td_err_set(err, TD_EIO, "%s: cannot map %llu bytes (%s)", path, (unsigned long long)want,
                        strerror(errno));
    }
    *out = rc == TD_OK ? m : NULL;
    if (fd >= 0)
        close(fd);
    return rc;
}

/* A layer's heights: exactly w*h*4 bytes, mapped read-only into g (and g->cz row-major). */
static td_status heights_map(const char *path, td_grid *g, td_err *err)
{
    char what[96];
    void *m = NULL;
    td_status rc;
    snprintf(what, sizeof what, "%ld x %ld float32", (long)g->w, (long)g->h);
    rc = file_map(path, (uint64_t)g->w * (uint64_t)g->h * 4u, what, &m, err);
    if (rc == TD_OK) {
        g->map = m;
        g->map_bytes = (size_t)g->w * (size_t)g->h * 4;
        g->z = m;
        td_grid_corners_flat(g);
    }
    return rc;
}

/* heights.blk: p->k's bands, mapped read-only as g->cz (what the render path reads). */
static td_status blocks_map(const td_prepared *p, td_grid *g, td_err *err)
{
    char path[PATH_MAX], what[96];
    void *m = NULL;
    td_status rc = TD_OK;
    uint64_t want = (uint64_t)p->k.by * (uint64_t)p->k.band_bytes;
    snprintf(what, sizeof what, "%ld bands of %ld blocks of %zu float32", (long)p->k.by, (long)p->k.bx, p->k.floats);
    if (!path_in(path, sizeof path, p->dir, TD_PREPARED_BLOCKS))
        rc = td_err_set(err, TD_EINVAL, "%s: path too long", p->dir);
    if (rc == TD_OK)
        rc = file_map(path, want, what, &m, err);
    if (rc == TD_OK) {
        g->bmap = m;
        g->bmap_bytes = (size_t)want;
        blocks_corners(&p->k, m, g);
    }
    return rc;
}

/* Layer k (0: the heights) of p: its tile records read, its heights mapped. */
static td_status layer_open(td_prepared *p, int k, td_err *err)
{
    td_status rc;
    char path[PATH_MAX], name[32];
    td_grid *g = k ? p->lev[k] : p->grid;
    if (!path_in(path, sizeof path, p->dir, layer_name(k, 1, name, sizeof name)))
        return td_err_set(err, TD_EINVAL, "%s: path too long", p->dir);
    rc = tiles_read(path, g, p->tiles_fnv[k], err);
    if (rc == TD_OK && path_in(path, sizeof path, p->dir, layer_file(k, name, sizeof name)))
        rc = heights_map(path, g, err);
    if (rc == TD_OK && k == 0)
        rc = blocks_map(p, g, err);
    return rc;
}

td_status td_prepared_open(const char *dir, td_prepared **out, td_err *err)
{
    td_status rc = TD_OK;
    td_prepared *p = calloc(1, sizeof *p);
    char path[PATH_MAX];
    td_grid *g = calloc(1, sizeof *g);

    *out = NULL;
    if (!p || !g) {
        free(g);
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", dir);
        goto out;
    }
    p->grid = g;
    snprintf(p->dir, sizeof p->dir, "%s", dir);
    if (!path_in(path, sizeof path, dir, TD_PREPARED_INDEX)) {
        rc = td_err_set(err, TD_EINVAL, "%s: path too long", dir);
        goto out;
    }
    rc = index_read(p, path, g, err);
    for (int k = 0; k <= p->nlev && rc == TD_OK; k++)
        rc = layer_open(p, k, err);
    if (rc == TD_OK) {
        const td_grid *grids[TD_LOD_MAX + 1];
        for (int k = 0; k <= p->nlev; k++)
            grids[k] = k ? p->lev[k] : p->grid;
        rc = td_pacc_open(dir, grids, p->nlev + 1, p->planes_k, p->accel_bytes, p->accel_tab_fnv, &p->pacc, err);
    }
    if (rc)
        goto out;
    p->fingerprint = TD_FNV1A_INIT;
    for (int k = 0; k <= p->nlev; k++) {
        p->fingerprint = td_fnv1a(p->fingerprint, p->sums[k], (size_t)p->lchunks[k] * 8);
        p->fingerprint = td_fnv1a(p->fingerprint, &p->tiles_fnv[k], 8);
        p->nchunks += p->lchunks[k];
    }
    p->fingerprint = td_fnv1a(p->fingerprint, p->bsums, (size_t)p->k.by * 8);
    p->fingerprint = td_fnv1a(p->fingerprint, &p->k.log2, sizeof p->k.log2);
    p->fingerprint = td_fnv1a(p->fingerprint, &p->accel_tab_fnv, 8);
    p->nchunks += p->k.by + td_pacc_rows(p->pacc);
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

td_lod *td_prepared_take_lod(td_prepared *p)
{
    td_lod *l = calloc(1, sizeof *l);
    for (int k = 1; l && k <= p->nlev; k++) {
        l->grid[k] = p->lev[k];
        p->lev[k] = NULL;
        l->view[k].grid = l->grid[k];
        l->view[k].accel = td_pacc_tiles(p->pacc, k); /* mapped, p's */
        l->bytes += (uint64_t)l->grid[k]->tiles_x * (uint64_t)l->grid[k]->tiles_y * sizeof(td_tile);
        l->levels = k;
    }
    return l;
}

int td_prepared_levels(const td_prepared *p) { return p->nlev; }

const td_tile_accel *td_prepared_accel(const td_prepared *p) { return td_pacc_tiles(p->pacc, 0); }

uint64_t td_prepared_fingerprint(const td_prepared *p) { return p->fingerprint; }

int32_t td_prepared_chunks(const td_prepared *p) { return p->nchunks; }

/* Chunk c of td_prepared_chunks: its file, byte range, checksum and a name for messages. */
static int chunk_where(const td_prepared *p, int32_t c, char *path, size_t n, off_t *at, size_t *bytes,
                       uint64_t *sum, char *what, size_t wn)
{
    int32_t k = 0, cc = c, rows;
    char name[32];
    while (k <= p->nlev && cc >= p->lchunks[k])
        cc -= p->lchunks[k++];
    if (c < 0 || (k > p->nlev && cc >= p->k.by))
        return 0;
    if (k <= p->nlev) {
        path_in(path, n, p->dir, layer_file(k, name, sizeof name));
        *at = chunk_span(p->lw[k], p->lh[k], p->chunk_rows, cc, &rows);
        *bytes = (size_t)rows * (size_t)p->lw[k] * 4;
        *sum = p->sums[k][cc];
        snprintf(what, wn, "chunk %ld (file rows %ld..%ld)", (long)cc, (long)(cc * p->chunk_rows),
                 (long)(cc * p->chunk_rows + rows - 1));
    } else {
        int32_t j0 = cc << p->k.log2, j1 = j0 + (1 << p->k.log2) < p->lh[0] - 1 ? j0 + (1 << p->k.log2) : p->lh[0] - 1;
        path_in(path, n, p->dir, TD_PREPARED_BLOCKS);
        *at = (off_t)cc * (off_t)p->k.band_bytes;
        *bytes = p->k.band_bytes;
        *sum = p->bsums[cc];
        snprintf(what, wn, "band %ld (south rows %ld..%ld)", (long)cc, (long)j0, (long)j1);
    }
    return 1;
}

td_status td_prepared_verify_chunk(const td_prepared *p, int32_t c, td_err *err)
{
    td_status rc = TD_OK;
    char path[PATH_MAX], what[96];
    int fd = -1;
    unsigned char *buf = NULL;
    size_t bytes = 0;
    off_t at = 0;
    uint64_t sum, want = 0;

    if (c >= p->nchunks - td_pacc_rows(p->pacc) && c < p->nchunks) {
        rc = td_pacc_verify_row(p->pacc, c - (p->nchunks - td_pacc_rows(p->pacc)), err);
        goto out;
    }
    if (!chunk_where(p, c, path, sizeof path, &at, &bytes, &want, what, sizeof what)) {
        rc = td_err_set(err, TD_EINVAL, "%s: no chunk %ld", p->dir, (long)c);
        goto out;
    }
    buf = malloc(bytes);
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (!buf || fd < 0 || pread(fd, buf, bytes, at) != (ssize_t)bytes) {
        rc = td_err_set(err, TD_EIO, "%s: cannot read %s (%s)", path, what, buf ? strerror(errno) : "out of memory");
        goto out;
    }
    sum = td_fnv1a(TD_FNV1A_INIT, buf, bytes);
    if (sum != want)
        rc = td_err_set(err, TD_EFORMAT, "%s: %s has checksum %016llx, the index says %016llx (corrupted)", path,
                        what, (unsigned long long)sum, (unsigned long long)want);
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
        for (int k = 0; k <= TD_LOD_MAX; k++) {
            td_grid_free(k ? p->lev[k] : NULL);
            free(p->sums[k]);
        }
        free(p->bsums);
        td_pacc_free(p->pacc);
        free(p);
    }
}

/* The mappings of g: its row-major heights and, for a prepared full grid, heights.blk. */
static int grid_maps(const td_grid *g, void *base[2], size_t len[2])
{
    int n = 0;
    if (g->map) {
        base[n] = g->map;
        len[n++] = g->map_bytes;
    }
    if (g->bmap) {
        base[n] = g->bmap;
        len[n++] = g->bmap_bytes;
    }
    return n;
}

/* The Rss of the mappings base[0 .. n) in /proc/self/smaps. */
static uint64_t maps_resident(void *const *base, const size_t *len, int n)
{
    uint64_t kb = 0;
    char line[256];
    unsigned long lo, hi;
    int in = 0;
    FILE *f = n ? fopen("/proc/self/smaps", "r") : NULL;
    while (f && fgets(line, sizeof line, f)) {
        unsigned long long v;
        if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2) { /* a mapping's first line */
            in = 0;
            for (int k = 0; k < n; k++)
                in |= (uintptr_t)lo >= (uintptr_t)base[k] && (uintptr_t)hi <= (uintptr_t)base[k] + len[k] + 4096;
        } else if (in && sscanf(line, "Rss: %llu kB", &v) == 1) {
            kb += v;
        }
    }
    if (f)
        fclose(f);
    return kb << 10;
}

uint64_t td_prepared_resident(const td_grid *g)
{
    void *base[2];
    size_t len[2];
    int n = grid_maps(g, base, len);
    return maps_resident(base, len, n);
}

uint64_t td_prepared_accel_resident(const td_prepared *p)
{
    void *base;
    size_t len;
    td_pacc_mapping(p->pacc, &base, &len);
    return maps_resident(&base, &len, base != NULL);
}

uint64_t td_prepared_accel_mapped(const td_prepared *p)
{
    void *base;
    size_t len;
    td_pacc_mapping(p->pacc, &base, &len);
    return len;
}

static void accel_madvise(const td_prepared *p, int advice)
{
    void *base;
    size_t len;
    td_pacc_mapping(p->pacc, &base, &len);
    if (base)
        madvise(base, len, advice);
}

void td_prepared_accel_willneed(const td_prepared *p, int from) { td_pacc_willneed(p->pacc, from); }

void td_prepared_accel_trim(const td_prepared *p) { accel_madvise(p, MADV_DONTNEED); }

void td_prepared_accel_advise(const td_prepared *p, int random) { accel_madvise(p, random ? MADV_RANDOM : MADV_NORMAL); }

uint64_t td_prepared_cached(const td_grid *g)
{
    uint64_t bytes = 0;
    long page = sysconf(_SC_PAGESIZE);
    void *base[2];
    size_t len[2];
    int n = grid_maps(g, base, len);
    for (int k = 0; k < n; k++) {
        size_t npages = (len[k] + (size_t)page - 1) / (size_t)page;
        unsigned char *vec = malloc(npages);
        if (vec && mincore(base[k], len[k], vec) == 0)
            for (size_t i = 0; i < npages; i++)
                bytes += (vec[i] & 1u) ? (uint64_t)page : 0;
        free(vec);
    }
    return bytes;
}

static void grid_madvise(const td_grid *g, int advice)
{
    void *base[2];
    size_t len[2];
    int n = grid_maps(g, base, len);
    for (int k = 0; k < n; k++)
        madvise(base[k], len[k], advice);
}

void td_prepared_advise(const td_grid *g, int random) { grid_madvise(g, random ? MADV_RANDOM : MADV_NORMAL); }

void td_prepared_willneed(const td_grid *g) { grid_madvise(g, MADV_WILLNEED); }

void td_prepared_willneed_near(const td_grid *g, double x, double y, int32_t cells)
{
    const td_corners *c = &g->cz;
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    double fi = x / g->sx, fj = y / g->sy;
    int32_t i0, i1, j0, j1;
    if (!g->bmap || !isfinite(fi) || !isfinite(fj) || cells < 0)
        return;
    fi = fi < 0 ? 0 : fi > g->w - 1 ? g->w - 1 : fi;
    fj = fj < 0 ? 0 : fj > g->h - 1 ? g->h - 1 : fj;
    i0 = (int32_t)fi - cells < 0 ? 0 : (int32_t)fi - cells;
    i1 = (int32_t)fi > g->w - 1 - cells ? g->w - 1 : (int32_t)fi + cells;
    j0 = (int32_t)fj - cells < 0 ? 0 : (int32_t)fj - cells;
    j1 = (int32_t)fj > g->h - 1 - cells ? g->h - 1 : (int32_t)fj + cells;
    for (int32_t by = j0 >> c->log2; by <= j1 >> c->log2; by++) { /* a band's blocks bx0..bx1: one range */
        size_t a = (((size_t)by * c->blocks_x + (size_t)(i0 >> c->log2)) * c->block_floats * 4) / page * page;
        size_t b = ((size_t)by * c->blocks_x + (size_t)(i1 >> c->log2) + 1) * c->block_floats * 4;
        madvise((char *)g->bmap + a, (b < g->bmap_bytes ? b : g->bmap_bytes) - a, MADV_WILLNEED);
    }
}

void td_prepared_trim(const td_grid *g)
{
    /* Not MADV_PAGEOUT (out of the page cache too): measured on the 16 GiB grid with a
       1 GiB budget, one view's pages (row strips across its whole wedge) outgrew the
       budget, every trim threw away what the view was reading, and 392 GB were read in
       8 minutes without finishing the first view. The page cache's clean pages are the
       kernel's to reclaim. */
    grid_madvise(g, MADV_DONTNEED);
}
