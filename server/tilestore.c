/* tilestore.c: datasets, per-tile reference-counted acceleration, LRU under a memory
 * budget, preload, the disk cache, the datasets' decoded drapes and heights edits (see
 * tilestore.h for the model). Called by the daemon's routes and admin jobs, and by `terrad serve` at
 * start; tests/server/test_tilestore.c drives it alone (also under ThreadSanitizer).
 *
 * Layout:
 *   td_store { mu, edit, clock, resident_bytes, ds[] }
 *     td_ds { id, shape, cur, slots[ntiles], counters, drapes }
 *       td_hver { atomic refs, version, chain, grid, lod }   the heights now (cur); a
 *                 snapshot holds one; an edit swaps in a new one (copy-on-write)
 *       td_slot { part[TD_PART_COUNT], stamp (LRU clock), pinned, job (in a running preload),
 *                 hver (the version that last changed the tile's heights) }
 *         td_part { atomic refs, kind, object, bytes }   immutable once built
 *       td_drape { atomic refs, path, RGB image, bytes } immutable, kept for the store's life
 *       td_sunkeep { atomic refs, version, sun, bound, bytes } immutable, the last few suns'
 *                 bounds of the current heights (td_snapshot_sunlit), least recently used last
 * Slots and counters are read and written under `mu` only; a part's refcount is atomic
 * so that snapshots release without the lock. A dataset's counters (tiles per kind,
 * resident and pinned tiles, bytes) change with its slots in slot_put_locked and
 * slot_pin_locked, so reading them walks nothing. LRU picks the smallest stamp by a
 * scan over all slots (a few thousand at most here); rejected: an intrusive list, which
 * needs the same lock and more code for no measurable gain at this size.
 *
 * Kinds: everything that differs between a max-mipmap and parameter planes is in
 * td_part_ops (build, free, byte bound, hand-over to a view, the cache payload's shape
 * and pieces), one row per TD_PART_LIST entry; the slot, snapshot, cache and preload
 * code loops over kinds. A third kind is a row of TD_PART_LIST (tilestore.h) and its
 * seven functions here, named after it (see TD_X_OPS).
 *
 * Measured (demo data, 64-cell tiles, 262 parts, one run each on a shared 2-core box):
 * building every part took 0.28 s, reading them back from the disk cache 0.011 s. */
#include "hash.h"
#include "tilestore.h"

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dem.h"
#include "gridedit.h"
#include "log.h"
#include "maxmip.h"
#include "planes.h"
#include "prepared.h"
#include "sunlit.h"

/* The most pixels of a drape: td_render's own limit when it loads one itself
 * (td_render_opts.drape_max_pixels 0). */
#define TD_STORE_DRAPE_MAX_PIXELS (64u << 20)

/* Sun bounds kept per dataset (td_snapshot_sunlit): a map's tiles and a page's renders
 * share one sun; a time slider moves through several. */
#define TD_STORE_SUNS 4

/* How often the background thread holds mapped heights to the budget (trim_mapped). */
#define TD_TRIM_MS 25

#define TD_X_CHECK(K, name, ext)                                                                \
    _Static_assert(offsetof(td_preload_spec, name) == offsetof(td_preload_spec, build[TD_PART_##K]), \
                   "td_preload_spec." #name " is build[TD_PART_" #K "]");                      \
    _Static_assert(offsetof(td_dataset_info, name##_tiles) ==                                   \
                       offsetof(td_dataset_info, part_tiles[TD_PART_##K]),                      \
                   "td_dataset_info." #name "_tiles is part_tiles[TD_PART_" #K "]");
TD_PART_LIST(TD_X_CHECK)
#undef TD_X_CHECK

typedef struct td_part {
    atomic_int refs;
    td_part_kind kind;
    void *ptr;
    size_t bytes;
} td_part;

typedef struct td_slot {
    td_part *part[TD_PART_COUNT];
    uint64_t stamp;
    int pinned; /* only while resident */
    int job;
    uint64_t hver; /* the dataset version that last changed this tile's heights (1: loaded) */
} td_slot;

/* One version of a dataset's heights (tilestore.h, "Edits"): immutable once published. */
typedef struct td_hver {
    atomic_int refs;
    uint64_t version; /* 1 as loaded, +1 an edit */
    uint64_t chain;   /* 0 as loaded; then a hash of every edit applied, in order */
    td_grid *grid;
    td_lod *lod;      /* coarse levels for quality.lod, built from this grid */
} td_hver;

typedef struct td_drape {
    atomic_int refs;
    struct td_drape *next; /* the dataset's kept drapes */
    td_image8 *img;
    uint64_t bytes;
    char path[];
} td_drape;

typedef struct td_sunkeep {
    atomic_int refs;
    struct td_sunkeep *next; /* the dataset's kept bounds, most recently used first */
    uint64_t version;        /* of the heights it was built from */
    double sun[3];
    td_sunlit *lit;          /* NULL: the sun gives none */
    atomic_int fine;         /* as fine as a kept bound (td_sunlit_build's kept): a sun used
                                before, or a grid whose kept bound is no finer; or set on a
                                coarse one that the budget has no room to replace */
    uint64_t bytes;
} td_sunkeep;

typedef struct td_ds {
    char id[TD_STORE_ID_MAX + 1];
    char file[256];
    char dir[PATH_MAX];
    const char *origin;
    td_hver *cur;         /* the heights now: swapped under `mu` by an edit (one at a time) */
    td_grid shape;        /* the grid's fixed fields (size, spacing, tiling, geo); no z, tiles */
    size_t ntiles;
    td_slot *slots;
    uint64_t grid_bytes;
    uint64_t fingerprint; /* of heights and tiling, for the disk cache */
    /* kept with the slots (store lock) */
    size_t resident_tiles, pinned_tiles, part_tiles[TD_PART_COUNT];
    uint64_t accel_bytes, drape_bytes, sun_bytes;
    uint64_t snapshots;   /* requests that traced it (td_store_acquire) */
    td_drape *drapes;
    td_sunkeep *suns;
    /* a prepared dataset (prepared.h): its index, and the background check of its chunks
       (state and progress under `mu`); NULL for a dataset whose heights were loaded */
    td_prepared *prep;
    int vstate;      /* TD_VERIFY_* */
    int32_t vdone;   /* chunks checked */
    char vwhy[512];  /* why it was refused */
} td_ds;

enum { TD_VERIFY_PENDING = 0, TD_VERIFY_OK, TD_VERIFY_REFUSED };

struct td_store {
    td_store_opts o;
    char *cache_dir;
    int param[TD_PART_COUNT]; /* each kind's build parameter (planes: K) */
    pthread_mutex_t mu;       /* slots, drapes, clock, resident_bytes, counters */
    pthread_mutex_t preload;  /* one preload at a time */
    pthread_mutex_t edit;     /* one edit at a time (the only writer of td_ds.cur) */
    uint64_t clock;
    uint64_t resident_bytes;  /* grids + parts in slots + kept drapes and sun bounds */
    uint64_t tiles_built, tiles_evicted, cache_hits, cache_misses;
    uint64_t sun_kept, sun_built; /* td_snapshot_sunlit's answers */
    td_ds *ds;
    size_t nds;
    int lod_iso; /* td_store_set_lod_iso */
    /* the background thread of prepared datasets (td_store_background_start) */
    pthread_t bg;
    int bg_on, bg_stop;     /* bg_stop under `mu` */
    pthread_cond_t bg_wake;
    uint64_t heights_trims;
    uint64_t trim_rss, trim_grow; /* trim_mapped's: the process at its last look, its growth */
};

struct td_snapshot {
    td_view view;
    td_store *store;
    size_t ds;
    td_hver *hv; /* the heights version this snapshot traces */
    td_tile_accel *accel;
    td_part **parts;
    size_t nparts;
    size_t count[TD_PART_COUNT];
    td_drape *drape;
    td_sunkeep *sun;
};

/* --- the kinds of part: per-kind operations --------------------------------------- */

#define TD_CACHE_MAGIC "TDACCEL"
#define TD_CACHE_VERSION 5u /* 2: planes stored as interleaved cones; 3: quantised cones;
                               4: the checksum covers the header too; 5: 16-bit maxima,
                               cones per 2 x 2 cells */

/* A cache file: this header, then the payload (the kind's pieces in order). The layout
 * is version 3's: `param` was named planes_k, and the shape fields (levels, dim, offset,
 * slope_scale; since 5 code_base, code_step) are each kind's to fill. */
typedef struct td_cache_hdr {
    char magic[8];
    uint32_t version, kind;
    uint64_t fingerprint;
    uint32_t tile_log2, param; /* the kind's build parameter (planes: K; maxmip: 0) */
    uint64_t tile;
    int32_t nx, ny;
    int32_t levels, pad;
    int32_t dim[17];
    int32_t pad2;
    uint64_t offset[17];
    double slope_scale; /* planes */
    double code_base, code_step; /* maxmip */
    uint64_t payload;   /* bytes after the header */
    uint64_t checksum;
} td_cache_hdr;

/* One contiguous piece of a part's payload. */
typedef struct td_piece {
    void *ptr;
    size_t len;
} td_piece;

#define TD_PIECES_MAX 4

typedef struct td_part_ops {
    const char *name, *ext;
    /* the kind's build parameter from the store's options */
    int (*param)(const td_store_opts *o);
    /* builds tile's structure: the object and its resident bytes */
    td_status (*build)(const td_grid *g, size_t tile, int param, void **obj, size_t *bytes,
                       td_err *err);
    void (*free)(void *obj);
    /* an upper bound of the part's bytes, for the preload's up-front budget check */
    uint64_t (*bound)(const td_tile *t, int tile_log2, int param);
    /* hands the object to a view's record of the tile */
    void (*attach)(td_tile_accel *a, const void *obj);
    /* cache write: fills h's shape fields, lists the payload's pieces; returns how many */
    int (*pieces)(void *obj, td_cache_hdr *h, td_piece *pc);
    /* cache read: checks h's shape fields (the common ones already match), makes an
     * object whose pieces the payload fills; returns NULL, or why not */
    const char *(*alloc)(const td_cache_hdr *h, void **obj, size_t *bytes, td_piece *pc,
                         int *npc);
    /* cache read: checks the filled object's values where a tracer indexes with them
     * (a file can pass its checksum and still be wrong); returns NULL, or why not */
    const char *(*check)(const void *obj);
} td_part_ops;

/* max-mipmaps (maxmip.h) */

static int maxmip_param(const td_store_opts *o)
{
    (void)o;
    return 0;
}

static td_status maxmip_build(const td_grid *g, size_t tile, int param, void **obj,
                              size_t *bytes, td_err *err)
{
    td_maxmip *m = NULL;
    td_status rc = td_maxmip_build(g, tile, &m, err);
    (void)param;
    *obj = m;
    *bytes = m ? m->bytes : 0;
    return rc;
}

static void maxmip_free(void *obj) { td_maxmip_free(obj); }

static uint64_t maxmip_bound(const td_tile *t, int tile_log2, int param)
{
    uint64_t tt = (uint64_t)1 << tile_log2;
    (void)t;
    (void)param;
    return sizeof(td_maxmip) + sizeof(uint16_t) * (tt * tt / 3 + 64) + sizeof(float) * (tt / 4 + 1) * (tt / 4 + 1);
}

static void maxmip_attach(td_tile_accel *a, const void *obj) { a->maxmip = obj; }

static int maxmip_pieces(void *obj, td_cache_hdr *h, td_piece *pc)
{
    td_maxmip *m = obj;
    h->levels = m->levels;
    for (int i = 0; i < 17; i++) {
        h->dim[i] = m->dim[i];
        h->offset[i] = m->offset[i];
    }
    h->code_base = m->base;
    h->code_step = m->step;
    pc[0].ptr = m->code;
    pc[0].len = (m->offset[m->levels] + (size_t)m->dim[m->levels] * (size_t)m->dim[m->levels]) * sizeof(uint16_t);
    pc[1].ptr = m->min4; /* the 4 x 4 blocks' minima (maxmip.h) */
    pc[1].len = (size_t)m->min4_w * (size_t)m->min4_h * sizeof(float);
    return 2;
}

static const char *maxmip_alloc(const td_cache_hdr *h, void **obj, size_t *bytes, td_piece *pc,
                                int *npc)
{
    const char *why = NULL;
    td_maxmip *m = calloc(1, sizeof *m);
    /* exactly the shape td_maxmip_build gives this tile (maxmip.c): levels 1 .. L of a
       2^L side covering its cells, each level right after the one before */
    const int32_t n = h->nx > h->ny ? h->nx : h->ny;
    int L = 1;
    uint64_t total = 0;
    while (L < (int)h->tile_log2 && L < 16 && ((int32_t)1 << L) < n)
        L++;
    *obj = m;
    if (!m || h->levels != L) {
        why = "bad shape";
        goto out;
    }
    for (int l = 1; l <= L && !why; l++) {
        if (h->dim[l] != ((int32_t)1 << L) >> l || h->offset[l] != total)
            why = "bad shape";
        total += (uint64_t)h->dim[l] * (uint64_t)h->dim[l];
    }
    const uint64_t n4 = (uint64_t)((h->nx + 3) / 4) * (uint64_t)((h->ny + 3) / 4) * sizeof(float);
    if (!why && h->payload != total * sizeof(uint16_t) + n4)
        why = "bad shape";
    if (why)
        goto out;
    m->levels = h->levels;
    for (int i = 0; i < 17; i++) {
        m->dim[i] = h->dim[i];
        m->offset[i] = (size_t)h->offset[i];
    }
    m->base = h->code_base;
    m->step = h->code_step;
    m->min4_w = (h->nx + 3) / 4;
    m->min4_h = (h->ny + 3) / 4;
    m->code = malloc(total ? total * sizeof(uint16_t) : 1);
    m->min4 = malloc(n4 ? n4 : 1);
    if (!m->code || !m->min4) {
        why = "out of memory";
        goto out;
    }
    m->bytes = sizeof *m + h->payload;
    *bytes = m->bytes;
    pc[0].ptr = m->code;
    pc[0].len = total * sizeof(uint16_t);
    pc[1].ptr = m->min4;
    pc[1].len = n4;
    *npc = 2;
out:
    return why;
}

static const char *maxmip_check(const void *obj)
{
    const td_maxmip *m = obj; /* any code is safe; a base of -inf or a step of 0 is not */
    return isfinite(m->base) && isfinite(m->step) && m->step > 0.0 ? NULL : "bad code scale";
}

/* parameter planes (planes.h) */

static int planes_param(const td_store_opts *o) { return o->planes_k; }

static td_status planes_build(const td_grid *g, size_t tile, int param, void **obj,
                              size_t *bytes, td_err *err)
{
    td_planes *p = NULL;
    td_status rc = td_planes_build(g, tile, param, &p, err);
    *obj = p;
    *bytes = p ? p->bytes : 0;
    return rc;
}

static void planes_free(void *obj) { td_planes_free(obj); }

static uint64_t planes_bound(const td_tile *t, int tile_log2, int param)
{
    (void)tile_log2;
    return sizeof(td_planes) +
           sizeof(td_cone) * (uint64_t)td_planes_blocks(t->nx) * (uint64_t)td_planes_blocks(t->ny) +
           sizeof(float) * ((uint64_t)param + 1);
}

static void planes_attach(td_tile_accel *a, const void *obj) { a->planes = obj; }

static int planes_pieces(void *obj, td_cache_hdr *h, td_piece *pc)
{
    td_planes *p = obj;
    h->levels = p->k;
    h->slope_scale = p->slope_scale;
    pc[0].ptr = p->cone;
    pc[0].len = (size_t)p->bnx * (size_t)p->bny * sizeof(td_cone);
    pc[1].ptr = p->apex;
    pc[1].len = ((size_t)p->k + 1) * sizeof(float);
    return 2;
}

static const char *planes_alloc(const td_cache_hdr *h, void **obj, size_t *bytes, td_piece *pc,
                                int *npc)
{
    const char *why = NULL;
    td_planes *p = calloc(1, sizeof *p);
    size_t n = (size_t)td_planes_blocks(h->nx) * (size_t)td_planes_blocks(h->ny) * sizeof(td_cone);
    size_t na = ((size_t)h->param + 1) * sizeof(float);
    *obj = p;
    if (!p || h->payload != n + na || h->levels != (int32_t)h->param || !(h->slope_scale > 0.0) ||
        !isfinite(h->slope_scale)) {
        why = "bad shape";
        goto out;
    }
    p->k = h->levels;
    p->nx = h->nx;
    p->ny = h->ny;
    p->bnx = td_planes_blocks(h->nx);
    p->bny = td_planes_blocks(h->ny);
    p->slope_scale = h->slope_scale;
    p->cone = malloc(n ? n : 1);
    p->apex = malloc(na);
    if (!p->cone || !p->apex) {
        why = "out of memory";
        goto out;
    }
    p->bytes = sizeof *p + n + na;
    *bytes = p->bytes;
    pc[0].ptr = p->cone;
    pc[0].len = n;
    pc[1].ptr = p->apex;
    pc[1].len = na;
    *npc = 2;
out:
    return why;
}

/* Every cone's apex indexes the k + 1 apex heights, which must be numbers. */
static const char *planes_check(const void *obj)
{
    const td_planes *p = obj;
    const char *why = NULL;
    for (int i = 0; i <= p->k && !why; i++)
        if (isnan(p->apex[i]))
            why = "bad apex heights";
    for (size_t c = 0; c < (size_t)p->bnx * (size_t)p->bny && !why; c++)
        if (p->cone[c].apex > p->k)
            why = "cone apex out of range";
    return why;
}

static const td_part_ops td_part_ops_of[TD_PART_COUNT] = {
#define TD_X_OPS(K, name, ext)                                                                  \
    [TD_PART_##K] = {#name, ext, name##_param, name##_build, name##_free, name##_bound,         \
                     name##_attach, name##_pieces, name##_alloc, name##_check},
    TD_PART_LIST(TD_X_OPS)
#undef TD_X_OPS
};

/* --- parts ------------------------------------------------------------------------ */

static td_part *part_new(td_part_kind kind, void *ptr, size_t bytes)
{
    td_part *p = calloc(1, sizeof *p);
    if (p) {
        atomic_init(&p->refs, 1);
        p->kind = kind;
        p->ptr = ptr;
        p->bytes = bytes;
    }
    return p;
}

static void part_unref(td_part *p)
{
    if (p && atomic_fetch_sub_explicit(&p->refs, 1, memory_order_acq_rel) == 1) {
        td_part_ops_of[p->kind].free(p->ptr);
        free(p);
    }
}

static void part_ref(td_part *p)
{
    atomic_fetch_add_explicit(&p->refs, 1, memory_order_relaxed);
}

static void hver_unref(td_hver *hv)
{
    if (hv && atomic_fetch_sub_explicit(&hv->refs, 1, memory_order_acq_rel) == 1) {
        td_lod_free(hv->lod);
        td_grid_free(hv->grid);
        free(hv);
    }
}

/* A version record for grid g and its levels (taken, also on failure). */
static td_status hver_new(td_grid *g, td_lod *lod, uint64_t version, uint64_t chain,
                          td_hver **out, td_err *err)
{
    td_status rc = TD_OK;
    td_hver *hv = calloc(1, sizeof *hv);
    *out = NULL;
    if (!hv) {
        td_lod_free(lod);
        td_grid_free(g);
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a heights version");
        goto out;
    }
    atomic_init(&hv->refs, 1);
    hv->version = version;
    hv->chain = chain;
    hv->grid = g;
    hv->lod = lod;
    *out = hv;
out:
    return rc;
}

static void drape_unref(td_drape *dr)
{
    if (dr && atomic_fetch_sub_explicit(&dr->refs, 1, memory_order_acq_rel) == 1) {
        td_image_free(dr->img);
        free(dr);
    }
}

static void sunkeep_unref(td_sunkeep *k)
{
    if (k && atomic_fetch_sub_explicit(&k->refs, 1, memory_order_acq_rel) == 1) {
        td_sunlit_free(k->lit);
        free(k);
    }
}

/* --- slots (store lock held) ------------------------------------------------------ */

static int slot_resident(const td_slot *sl)
{
    int any = 0;
    for (int k = 0; k < TD_PART_COUNT; k++)
        any |= sl->part[k] != NULL;
    return any;
}

/* Puts part p (NULL: none) in the slot as its kind-k part, dropping the store's
 * reference to the one it replaces; keeps the store's and the dataset's counters. A
 * slot left with no part is unpinned. */
static void slot_put_locked(td_store *s, td_ds *d, td_slot *sl, td_part_kind k, td_part *p)
{
    td_part *old = sl->part[k];
    int was = slot_resident(sl), now;
    if (old) {
        s->resident_bytes -= old->bytes;
        d->accel_bytes -= old->bytes;
        d->part_tiles[k]--;
        part_unref(old);
    }
    sl->part[k] = p;
    if (p) {
        s->resident_bytes += p->bytes;
        d->accel_bytes += p->bytes;
        d->part_tiles[k]++;
    }
    now = slot_resident(sl);
    d->resident_tiles = d->resident_tiles + (size_t)now - (size_t)was;
    if (!now && sl->pinned) {
        sl->pinned = 0;
        d->pinned_tiles--;
    }
}

/* Pins a resident slot. */
static void slot_pin_locked(td_ds *d, td_slot *sl)
{
    if (slot_resident(sl) && !sl->pinned) {
        sl->pinned = 1;
        d->pinned_tiles++;
    }
}

/* Drops a slot's parts. */
static void slot_clear_locked(td_store *s, td_ds *d, td_slot *sl)
{
    if (slot_resident(sl))
        s->tiles_evicted++;
    for (int k = 0; k < TD_PART_COUNT; k++)
        slot_put_locked(s, d, sl, (td_part_kind)k, NULL);
}

/* Evicts the least recently used unpinned tile outside the running preload; 0 if none. */
static int evict_lru_locked(td_store *s)
{
    td_slot *best = NULL;
    td_ds *bd = NULL;
    for (size_t d = 0; d < s->nds; d++)
        for (size_t t = 0; t < s->ds[d].ntiles; t++) {
            td_slot *sl = &s->ds[d].slots[t];
            if (slot_resident(sl) && !sl->pinned && !sl->job && (!best || sl->stamp < best->stamp)) {
                best = sl;
                bd = &s->ds[d];
            }
        }
    if (best)
        slot_clear_locked(s, bd, best);
    return best != NULL;
}

/* Bytes a preload must leave alone: heights, kept drapes, and the parts of pinned tiles
 * and of tiles in the running preload. */
static uint64_t kept_bytes_locked(const td_store *s)
{
    uint64_t kept = 0;
    for (size_t k = 0; k < s->nds; k++) {
        const td_ds *d = &s->ds[k];
        kept += d->grid_bytes + d->drape_bytes + d->sun_bytes;
        for (size_t t = 0; t < d->ntiles; t++) {
            const td_slot *sl = &d->slots[t];
            for (int j = 0; j < TD_PART_COUNT && (sl->pinned || sl->job); j++)
                kept += sl->part[j] ? sl->part[j]->bytes : 0;
        }
    }
    return kept;
}

/* --- store ------------------------------------------------------------------------ */

td_status td_store_create(const td_store_opts *o, td_store **out, td_err *err)
{
    td_status rc = TD_OK;
    td_store *s = calloc(1, sizeof *s);
    *out = NULL;
    if (!s) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the tile store");
        goto out;
    }
    s->o = *o;
    if (s->o.tile_log2 < 1 || s->o.tile_log2 > 16)
        s->o.tile_log2 = TD_TILE_LOG2_DEFAULT;
    if (s->o.planes_k < 1)
        s->o.planes_k = 16;
    if (o->cache_dir && *o->cache_dir) {
        if (mkdir(o->cache_dir, 0755) && errno != EEXIST) {
            rc = td_err_set(err, TD_EIO, "--cache %s: %s", o->cache_dir, strerror(errno));
            goto out;
        }
        s->cache_dir = strdup(o->cache_dir);
        if (!s->cache_dir) {
            rc = td_err_set(err, TD_ENOMEM, "out of memory");
            goto out;
        }
    }
    s->o.cache_dir = s->cache_dir;
    for (int k = 0; k < TD_PART_COUNT; k++)
        s->param[k] = td_part_ops_of[k].param(&s->o);
    pthread_mutex_init(&s->mu, NULL);
    pthread_mutex_init(&s->preload, NULL);
    pthread_mutex_init(&s->edit, NULL);
    pthread_cond_init(&s->bg_wake, NULL);
    *out = s;
    s = NULL;
out:
    if (s) {
        free(s->cache_dir);
        free(s);
    }
    return rc;
}

void td_store_set_lod_iso(td_store *s, int on) { s->lod_iso = on != 0; }

void td_store_free(td_store *s)
{
    if (!s)
        return;
    if (s->bg_on) {
        pthread_mutex_lock(&s->mu);
        s->bg_stop = 1;
        pthread_cond_signal(&s->bg_wake);
        pthread_mutex_unlock(&s->mu);
        pthread_join(s->bg, NULL);
    }
    for (size_t d = 0; d < s->nds; d++) {
        td_ds *ds = &s->ds[d];
        for (size_t t = 0; t < ds->ntiles; t++)
            for (int k = 0; k < TD_PART_COUNT; k++)
                part_unref(ds->slots[t].part[k]);
        while (ds->drapes) {
            td_drape *next = ds->drapes->next;
            drape_unref(ds->drapes);
            ds->drapes = next;
        }
        while (ds->suns) {
            td_sunkeep *next = ds->suns->next;
            sunkeep_unref(ds->suns);
            ds->suns = next;
        }
        free(ds->slots);
        hver_unref(ds->cur);
        td_prepared_free(ds->prep); /* after the levels, whose views point into it */
    }
    free(s->ds);
    free(s->cache_dir);
    pthread_mutex_destroy(&s->mu);
    pthread_mutex_destroy(&s->preload);
    pthread_mutex_destroy(&s->edit);
    pthread_cond_destroy(&s->bg_wake);
    free(s);
}

int td_store_id_valid(const char *id)
{
    size_t n = id ? strlen(id) : 0;
    int ok = n >= 1 && n <= TD_STORE_ID_MAX && id[0] != '.';
    for (size_t i = 0; i < n && ok; i++) {
        char c = id[i];
        ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
             c == '_' || c == '-' || c == '.';
    }
    return ok;
}

size_t td_store_count(const td_store *s) { return s->nds; }

long td_store_find(const td_store *s, const char *id)
{
    long idx = -1;
    for (size_t i = 0; i < s->nds && idx < 0 && id; i++)
        if (!strcmp(s->ds[i].id, id))
            idx = (long)i;
    return idx;
}


static uint64_t grid_fingerprint(const td_grid *g)
{
    uint64_t h = TD_FNV1A_INIT;
    h = td_fnv1a(h, &g->w, sizeof g->w);
    h = td_fnv1a(h, &g->h, sizeof g->h);
    h = td_fnv1a(h, &g->sx, sizeof g->sx);
    h = td_fnv1a(h, &g->sy, sizeof g->sy);
    h = td_fnv1a(h, &g->tile_log2, sizeof g->tile_log2);
    h = td_fnv1a(h, g->z, (size_t)g->w * (size_t)g->h * sizeof(float));
    return h;
}

/* Levels of detail of a heights version: filtered coarse grids with their max-mipmaps (a
 * third of the heights and little more), resident with the heights; and their isometric
 * twins where td_store_set_lod_iso asked for them. */
static td_status lod_build(const td_store *s, const td_grid *g, td_lod **lod, td_err *err)
{
    td_accel_opts ao;
    td_status rc;
    td_accel_opts_default(&ao);
    ao.planes = 0;
    ao.threads = 1;
    rc = td_lod_build(g, TD_LOD_MAX, &ao, lod, err);
    if (!rc && s->lod_iso)
        rc = td_lod_add_iso(*lod, g, err);
    return rc;
}

/* Appends dataset `id` with heights g and levels lod (both taken, also on failure),
 * counting `bytes` against the budget. */
static td_status ds_append(td_store *s, const char *id, const char *origin, td_grid *g,
                           td_lod *lod, uint64_t fingerprint, uint64_t bytes, td_err *err)
{
    td_status rc = TD_OK;
    td_ds *nds = NULL, *d;
    td_hver *hv = NULL;

    if (s->resident_bytes + bytes > s->o.budget_bytes) {
        rc = td_err_set(err, TD_ETOOBIG,
                        "dataset '%s' needs %llu bytes of heights, over what is left of the "
                        "memory budget (%llu of %llu bytes)", id, (unsigned long long)bytes,
                        (unsigned long long)(s->o.budget_bytes - s->resident_bytes),
                        (unsigned long long)s->o.budget_bytes);
        goto out;
    }
    nds = realloc(s->ds, (s->nds + 1) * sizeof *s->ds);
    if (!nds) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for dataset '%s'", id);
        goto out;
    }
    s->ds = nds;
    d = &s->ds[s->nds];
    memset(d, 0, sizeof *d);
    d->ntiles = (size_t)g->tiles_x * (size_t)g->tiles_y;
    d->slots = calloc(d->ntiles, sizeof *d->slots);
    if (!d->slots) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the tiles of '%s'", id);
        goto out;
    }
    for (size_t t = 0; t < d->ntiles; t++)
        d->slots[t].hver = 1;
    snprintf(d->id, sizeof d->id, "%s", id);
    d->origin = origin ? origin : "api";
    d->fingerprint = fingerprint;
    d->shape = *g;
    d->shape.z = NULL;
    d->shape.tiles = NULL;
    d->shape.map = NULL;
    d->shape.bmap = NULL;
    d->shape.cz.base = NULL;
    rc = hver_new(g, lod, 1, 0, &hv, err);
    g = NULL;
    lod = NULL;
    if (rc) {
        free(d->slots);
        goto out;
    }
    d->cur = hv;
    d->grid_bytes = bytes;
    s->resident_bytes += bytes;
    s->nds++;
out:
    td_lod_free(lod);
    td_grid_free(g);
    return rc;
}

static td_status id_check(const td_store *s, const char *id, td_err *err)
{
    td_status rc = TD_OK;
    if (!td_store_id_valid(id))
        rc = td_err_set(err, TD_EINVAL, "dataset id '%s' is not [A-Za-z0-9_.-]{1,64}", id);
    else if (td_store_find(s, id) >= 0)
        rc = td_err_set(err, TD_EINVAL, "dataset id '%s' is already taken", id);
    return rc;
}

td_status td_store_add_grid(td_store *s, const char *id, const char *origin, td_grid *g,
                            td_err *err)
{
    td_status rc;
    td_lod *lod = NULL;

    rc = id_check(s, id, err);
    if (!rc)
        rc = lod_build(s, g, &lod, err);
    if (!rc) {
        uint64_t bytes = td_grid_bytes(g->w, g->h, g->tile_log2) + lod->bytes;
        rc = ds_append(s, id, origin, g, lod, s->cache_dir ? grid_fingerprint(g) : 0, bytes, err);
        g = NULL;
        lod = NULL;
    }
    td_lod_free(lod);
    td_grid_free(g);
    return rc;
}

/* --- prepared datasets (prepared.h) ---------------------------------------------- */

td_status td_store_add_prepared(td_store *s, const char *id, const char *origin, const char *dir,
                                td_err *err)
{
    td_status rc;
    td_prepared *p = NULL;
    td_lod *lod = NULL;
    td_grid *g;

    rc = id_check(s, id, err);
    if (!rc)
        rc = td_prepared_open(dir, &p, err);
    if (rc)
        goto out;
    /* the coarse levels written by the prepare, mapped as the heights are (no
       acceleration: the tracers skip by their tile records) */
    lod = td_prepared_take_lod(p);
    if (!lod) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
        goto out;
    }
    g = td_prepared_take_grid(p);
    /* read-around (8 MiB a fault here) pays while the file fits the budget: 1 GiB under
       1 GiB, first render 1.6 s against 12.7 s one page a fault; beyond, it read 392 GB
       and mapped 9 GB for one view of a 16 GiB grid. Each level is judged alone; the full
       grid by heights.blk, what renders read (heights.f32 only viewsheds, peaks and map
       tiles' height sampling). */
    td_prepared_advise(g, (g->bmap ? g->bmap_bytes : g->map_bytes) > s->o.budget_bytes);
    for (int k = 1; k <= lod->levels; k++)
        td_prepared_advise(lod->grid[k], lod->grid[k]->map_bytes > s->o.budget_bytes);
    td_prepared_accel_advise(p, td_prepared_accel_mapped(p) > s->o.budget_bytes);
    rc = ds_append(s, id, origin, g, lod, td_prepared_fingerprint(p),
                   sizeof *g + (uint64_t)g->tiles_x * (uint64_t)g->tiles_y * sizeof(td_tile) + lod->bytes, err);
    lod = NULL;
    if (rc)
        goto out;
    {
        td_ds *d = &s->ds[s->nds - 1];
        d->prep = p;
        p = NULL;
        snprintf(d->dir, sizeof d->dir, "%s", dir);
        snprintf(d->file, sizeof d->file, "%s", TD_PREPARED_INDEX);
    }
out:
    td_lod_free(lod);
    td_prepared_free(p);
    return rc;
}

/* Coarse levels first: once a prepared dataset is checked (the check drops what it read
 * from the page cache), its coarsest levels that fit a quarter of the budget together, and
 * their tiles' structures, are asked back into the page cache (MADV_WILLNEED: read ahead by the kernel, not mapped into
 * the process), so a far ray's first touch of them is a minor fault, not a read. A prepared
 * dataset's heights are never edited, so d->cur stays. */
static void warm_levels(const td_store *s, const td_ds *d)
{
    const td_lod *l = d->cur->lod;
    uint64_t sum = 0;
    int from = 0;
    for (int k = l ? l->levels : 0; k >= 1; k--) {
        sum += l->grid[k]->map_bytes;
        if (sum > s->o.budget_bytes / 4)
            break;
        td_prepared_willneed(l->grid[k]);
        from = k;
    }
    if (from) /* and their tiles' structures (the coarsest last in accel.bin: one range) */
        td_prepared_accel_willneed(d->prep, from);
}

/* Checks the next pending chunk of one prepared dataset; 0 when none is left. */
static int verify_step(td_store *s)
{
    td_ds *d = NULL;
    int32_t c = 0;
    td_err e = {0};
    td_status rc;
    char q[600];

    pthread_mutex_lock(&s->mu);
    for (size_t k = 0; k < s->nds && !d; k++)
        if (s->ds[k].prep && s->ds[k].vstate == TD_VERIFY_PENDING) {
            d = &s->ds[k];
            c = d->vdone;
        }
    pthread_mutex_unlock(&s->mu);
    if (!d)
        return 0;
    rc = td_prepared_verify_chunk(d->prep, c, &e);
    pthread_mutex_lock(&s->mu);
    if (rc) {
        d->vstate = TD_VERIFY_REFUSED;
        snprintf(d->vwhy, sizeof d->vwhy, "%s", e.msg);
    } else if (++d->vdone == td_prepared_chunks(d->prep)) {
        d->vstate = TD_VERIFY_OK;
    }
    pthread_mutex_unlock(&s->mu);
    if (rc)
        td_log(TD_LOG_ERROR, "dataset_refused", "id=%s status=%s msg=%s", d->id, td_status_json(rc),
               td_log_quote(q, sizeof q, e.msg));
    else if (d->vstate == TD_VERIFY_OK) {
        warm_levels(s, d);
        td_log(TD_LOG_INFO, "dataset_verified", "id=%s chunks=%ld", d->id, (long)d->vdone);
    }
    return 1;
}

/* The mapped grids of a prepared dataset's heights: the full grid and its levels. */
static int mapped_grids(const td_hver *hv, const td_grid **out)
{
    int n = 0;
    out[n++] = hv->grid;
    for (int k = 1; hv->lod && k <= hv->lod->levels; k++)
        if (hv->lod->grid[k]->map)
            out[n++] = hv->lod->grid[k];
    return n;
}

/* Heights (and levels, and the tiles' structures) of prepared datasets resident in the
 * process, and their mapped size. */
static uint64_t mapped_resident(const td_store *s, uint64_t *mapped)
{
    uint64_t res = 0;
    const td_grid *gs[TD_LOD_MAX + 1];
    *mapped = 0;
    for (size_t k = 0; k < s->nds; k++)
        if (s->ds[k].prep) {
            for (int n = mapped_grids(s->ds[k].cur, gs), i = 0; i < n; i++) {
                res += td_prepared_resident(gs[i]);
                *mapped += gs[i]->map_bytes + gs[i]->bmap_bytes;
            }
            res += td_prepared_accel_resident(s->ds[k].prep);
            *mapped += td_prepared_accel_mapped(s->ds[k].prep);
        }
    return res;
}

/* The process's resident bytes, all and file-backed (/proc/self/statm: one line, cheap
 * enough to read 40 times a second, unlike smaps, which walks every mapping). */
static uint64_t process_rss(uint64_t *file)
{
    unsigned long long size = 0, res = 0, shared = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    long page = sysconf(_SC_PAGESIZE);
    if (!f || fscanf(f, "%llu %llu %llu", &size, &res, &shared) != 3)
        res = shared = 0;
    if (f)
        fclose(f);
    *file = (uint64_t)shared * (uint64_t)page;
    return (uint64_t)res * (uint64_t)page;
}

/* Near the budget: drop the process's pages of the mapped heights (the page cache keeps
 * them while memory allows). Near means the tile store's own bytes plus the resident
 * file pages (the mapped heights, and the binary's few MB), or the whole process, within
 * a margin of the budget: the most the process grew between two looks lately, twice (at
 * least an eighth of the budget, at most half). Asked every TD_TRIM_MS while there are
 * prepared datasets: renders map pages back from the page cache fast (hundreds of MB
 * between two looks when the looking thread waits for a core), so a 250 ms period against
 * the whole budget let the peak reach 2.2 GB under a 1 GiB budget, 25 ms against the
 * whole budget 1.27 GB, 25 ms against 7/8 of it 1.23 GB (bench-prepared, 4 GiB grid,
 * without quality.lod, shared 2-core machine). s->trim_* are this thread's alone. */
static void trim_mapped(td_store *s)
{
    uint64_t file, rss = process_rss(&file), other, margin, grow = rss > s->trim_rss ? rss - s->trim_rss : 0;
    const td_grid *gs[TD_LOD_MAX + 1];
    pthread_mutex_lock(&s->mu);
    other = s->resident_bytes;
    pthread_mutex_unlock(&s->mu);
    s->trim_grow = grow > s->trim_grow ? grow : s->trim_grow - s->trim_grow / 64; /* forgets in a few s */
    margin = 2 * s->trim_grow;
    margin = margin < s->o.budget_bytes / 8 ? s->o.budget_bytes / 8 : margin;
    margin = margin > s->o.budget_bytes / 2 ? s->o.budget_bytes / 2 : margin;
    s->trim_rss = rss;
    if (file && (other + file + margin > s->o.budget_bytes || rss + margin > s->o.budget_bytes)) {
        for (size_t k = 0; k < s->nds; k++)
            if (s->ds[k].prep) {
                for (int n = mapped_grids(s->ds[k].cur, gs), i = 0; i < n; i++)
                    td_prepared_trim(gs[i]);
                td_prepared_accel_trim(s->ds[k].prep);
            }
        s->trim_rss = process_rss(&file);
        pthread_mutex_lock(&s->mu);
        s->heights_trims++;
        pthread_mutex_unlock(&s->mu);
    }
}

/* The background thread: every pending chunk, and the budget of mapped heights every
 * TD_TRIM_MS (also between chunks: other datasets render meanwhile), until
 * td_store_free. */
static void *background(void *arg)
{
    td_store *s = arg;
    int stop = 0, mapped = 0;
    for (size_t k = 0; k < s->nds; k++)
        mapped |= s->ds[k].prep != NULL;
    while (!stop) {
        int busy = verify_step(s);
        if (mapped)
            trim_mapped(s);
        pthread_mutex_lock(&s->mu);
        if (!busy && !s->bg_stop) {
            struct timespec ts;
            clock_gettime(CLOCK_REALTIME, &ts);
            ts.tv_nsec += (mapped ? TD_TRIM_MS : 250) * 1000L * 1000L;
            ts.tv_sec += ts.tv_nsec / 1000000000L;
            ts.tv_nsec %= 1000000000L;
            pthread_cond_timedwait(&s->bg_wake, &s->mu, &ts);
        }
        stop = s->bg_stop;
        pthread_mutex_unlock(&s->mu);
    }
    return NULL;
}

td_status td_store_background_start(td_store *s, td_err *err)
{
    td_status rc = TD_OK;
    if (!s->bg_on) {
        if (pthread_create(&s->bg, NULL, background, s))
            rc = td_err_set(err, TD_ENOMEM, "cannot start the tile store's background thread");
        else
            s->bg_on = 1;
    }
    return rc;
}

static void set_file(td_store *s, const char *id, const char *path, const char *file)
{
    long i = td_store_find(s, id);
    if (i >= 0) {
        size_t n = strlen(path) - strlen(file);
        snprintf(s->ds[i].file, sizeof s->ds[i].file, "%s", file);
        snprintf(s->ds[i].dir, sizeof s->ds[i].dir, "%.*s", (int)(n ? n - 1 : 0), path);
    }
}

static void stem_of(const char *name, char *out, size_t n)
{
    const char *dot = strrchr(name, '.');
    size_t len = dot && dot != name ? (size_t)(dot - name) : strlen(name);
    if (len >= n)
        len = n - 1;
    memcpy(out, name, len);
    out[len] = '\0';
}

/* Loads one file as dataset `id`; failures are logged and skipped (not fatal). */
static int load_one(td_store *s, const char *path, const char *name, const char *id,
                    const char *origin)
{
    td_dem_opts o;
    td_grid *g = NULL;
    td_err e = {0};
    char qp[600], qm[600];
    td_status rc;
    int ok = 0;

    if (!td_store_id_valid(id) || td_store_find(s, id) >= 0) {
        td_log(TD_LOG_WARN, "dataset_skipped", "path=%s reason=\"id '%s' is %s\"",
               td_log_quote(qp, sizeof qp, path), id,
               td_store_id_valid(id) ? "already taken" : "not [A-Za-z0-9_.-]{1,64}");
        goto out;
    }
    td_dem_opts_default(&o);
    o.tile_log2 = s->o.tile_log2;
    o.limits.max_bytes = s->o.budget_bytes > s->resident_bytes ? s->o.budget_bytes - s->resident_bytes : 1;
    rc = td_dem_load(path, &o, &g, &e);
    if (rc == TD_OK)
        rc = td_store_add_grid(s, id, origin, g, &e);
    if (rc) {
        td_log(TD_LOG_WARN, "dataset_skipped", "id=%s path=%s status=%s msg=%s", id,
               td_log_quote(qp, sizeof qp, path), td_status_json(rc), td_log_quote(qm, sizeof qm, e.msg));
        goto out;
    }
    set_file(s, id, path, name);
    {
        const td_grid *gg = s->ds[s->nds - 1].cur->grid;
        td_log(TD_LOG_INFO, "dataset_loaded",
               "id=%s origin=%s path=%s width=%d height=%d spacing=%gx%g zmin=%g zmax=%g voids=%lld tiles=%dx%d",
               id, origin, td_log_quote(qp, sizeof qp, path), (int)gg->w, (int)gg->h, gg->sx, gg->sy,
               (double)gg->zmin, (double)gg->zmax, (long long)gg->voids, (int)gg->tiles_x,
               (int)gg->tiles_y);
    }
    ok = 1;
out:
    return ok;
}

/* A prepared dataset's folder as dataset `id`; failures are logged and skipped. */
static int load_prepared(td_store *s, const char *path, const char *id, const char *origin)
{
    td_err e = {0};
    td_status rc;
    char qp[600], qm[600];
    if (td_prepared_unfinished(path))
        rc = td_err_set(&e, TD_EFORMAT, "%s: an unfinished prepare (%s without %s): run terrad prepare again",
                        path, TD_PREPARED_STATE, TD_PREPARED_INDEX);
    else
        rc = td_store_add_prepared(s, id, origin, path, &e);
    if (rc) {
        td_log(TD_LOG_WARN, "dataset_skipped", "id=%s path=%s status=%s msg=%s", id,
               td_log_quote(qp, sizeof qp, path), td_status_json(rc), td_log_quote(qm, sizeof qm, e.msg));
    } else {
        const td_grid *g = s->ds[s->nds - 1].cur->grid;
        td_log(TD_LOG_INFO, "dataset_loaded",
               "id=%s origin=%s path=%s prepared=1 width=%d height=%d spacing=%gx%g zmin=%g zmax=%g tiles=%dx%d chunks=%ld",
               id, origin, td_log_quote(qp, sizeof qp, path), (int)g->w, (int)g->h, g->sx, g->sy,
               (double)g->zmin, (double)g->zmax, (int)g->tiles_x, (int)g->tiles_y,
               (long)td_prepared_chunks(s->ds[s->nds - 1].prep));
    }
    return rc == TD_OK;
}

/* Non-zero if `path` (after resolving links) lies inside the directory `root`. */
static int inside(const char *root, const char *path)
{
    char rp[PATH_MAX];
    size_t n = strlen(root);
    return realpath(path, rp) && !strncmp(rp, root, n) && rp[n] == '/';
}

static int skip_name(const struct dirent *e)
{
    return e->d_name[0] != '.';
}

td_status td_store_add_dir(td_store *s, const char *dir, const char *origin, int *loaded,
                           td_err *err)
{
    td_status rc = TD_OK;
    struct dirent **names = NULL;
    int n = 0;
    char root[PATH_MAX];

    *loaded = 0;
    if (!realpath(dir, root)) {
        rc = td_err_set(err, TD_ENOTFOUND, "%s: %s", dir, strerror(errno));
        goto out;
    }
    n = scandir(root, &names, skip_name, alphasort);
    if (n < 0) {
        rc = td_err_set(err, TD_EIO, "%s: %s", dir, strerror(errno));
        n = 0;
        goto out;
    }
    for (int i = 0; i < n; i++) {
        char path[PATH_MAX], id[512];
        struct stat st;
        if ((size_t)snprintf(path, sizeof path, "%s/%s", root, names[i]->d_name) >= sizeof path ||
            !inside(root, path) || stat(path, &st))
            continue;
        if (S_ISREG(st.st_mode) && td_dem_recognised(path)) {
            stem_of(names[i]->d_name, id, sizeof id);
            *loaded += load_one(s, path, names[i]->d_name, id, origin);
        } else if (S_ISDIR(st.st_mode) && (td_prepared_is(path) || td_prepared_unfinished(path))) {
            *loaded += load_prepared(s, path, names[i]->d_name, origin);
        } else if (S_ISDIR(st.st_mode)) {
            struct dirent **sub = NULL;
            int m = scandir(path, &sub, skip_name, alphasort), count = 0;
            char sp[PATH_MAX];
            for (int pass = 0; pass < 2; pass++) {
                for (int k = 0; k < m; k++) {
                    struct stat st2;
                    if ((size_t)snprintf(sp, sizeof sp, "%s/%s", path, sub[k]->d_name) >= sizeof sp ||
                        !inside(root, sp) || stat(sp, &st2) || !S_ISREG(st2.st_mode) ||
                        !td_dem_recognised(sp))
                        continue;
                    if (pass == 0) {
                        count++;
                    } else if (count == 1) {
                        snprintf(id, sizeof id, "%s", names[i]->d_name);
                        *loaded += load_one(s, sp, sub[k]->d_name, id, origin);
                    } else {
                        char st3[256];
                        stem_of(sub[k]->d_name, st3, sizeof st3);
                        snprintf(id, sizeof id, "%s-%s", names[i]->d_name, st3);
                        *loaded += load_one(s, sp, sub[k]->d_name, id, origin);
                    }
                }
            }
            for (int k = 0; k < m; k++)
                free(sub[k]);
            free(sub);
        }
    }
out:
    for (int i = 0; i < n; i++)
        free(names[i]);
    free(names);
    return rc;
}

void td_store_info(td_store *s, size_t idx, td_dataset_info *out)
{
    td_ds *d = &s->ds[idx];
    memset(out, 0, sizeof *out);
    out->id = d->id;
    out->file = d->file;
    out->dir = d->dir;
    out->origin = d->origin;
    out->ntiles = d->ntiles;
    pthread_mutex_lock(&s->mu);
    out->grid_bytes = d->grid_bytes;
    out->grid_hdr = *d->cur->grid;
    out->grid_hdr.z = NULL;
    out->grid_hdr.tiles = NULL;
    out->grid = &out->grid_hdr;
    out->version = d->cur->version;
    out->chain = d->cur->chain;
    out->resident_tiles = d->resident_tiles;
    for (int k = 0; k < TD_PART_COUNT; k++)
        out->part_tiles[k] = d->part_tiles[k];
    out->pinned_tiles = d->pinned_tiles;
    out->accel_bytes = d->accel_bytes;
    out->drape_bytes = d->drape_bytes;
    out->sun_bytes = d->sun_bytes;
    out->prepared = d->prep != NULL;
    out->chunks = d->prep ? td_prepared_chunks(d->prep) : 0;
    out->chunks_checked = d->vdone;
    out->refused = d->vstate == TD_VERIFY_REFUSED;
    out->snapshots = d->snapshots;
    pthread_mutex_unlock(&s->mu);
    out->levels = d->cur->lod ? d->cur->lod->levels : 0;
    if (d->prep) {
        const td_grid *gs[TD_LOD_MAX + 1];
        for (int n = mapped_grids(d->cur, gs), i = 0; i < n; i++)
            out->heights_resident += td_prepared_resident(gs[i]);
        out->heights_resident += td_prepared_accel_resident(d->prep);
    }
}

void td_store_stats_get(td_store *s, td_store_stats *st)
{
    memset(st, 0, sizeof *st);
    st->datasets = s->nds;
    st->budget_bytes = s->o.budget_bytes;
    pthread_mutex_lock(&s->mu);
    for (size_t d = 0; d < s->nds; d++) {
        st->total_tiles += s->ds[d].ntiles;
        st->resident_tiles += s->ds[d].resident_tiles;
    }
    st->resident_bytes = s->resident_bytes;
    st->tiles_built = s->tiles_built;
    st->tiles_evicted = s->tiles_evicted;
    st->cache_hits = s->cache_hits;
    st->cache_misses = s->cache_misses;
    st->sun_kept = s->sun_kept;
    st->sun_built = s->sun_built;
    for (size_t d = 0; d < s->nds; d++)
        st->sun_bytes += s->ds[d].sun_bytes;
    st->heights_trims = s->heights_trims;
    pthread_mutex_unlock(&s->mu);
    st->heights_mapped_resident = mapped_resident(s, &st->heights_mapped);
    st->resident_bytes += st->heights_mapped_resident;
}

/* --- snapshots -------------------------------------------------------------------- */

td_status td_store_acquire(td_store *s, const char *id, td_snapshot **out, td_err *err)
{
    td_status rc = TD_OK;
    long idx = td_store_find(s, id);
    td_snapshot *snap = NULL;
    td_ds *d;
    uint64_t stamp;

    *out = NULL;
    if (idx < 0) {
        rc = td_err_set(err, TD_ENOTFOUND, "unknown dataset '%s'", id ? id : "");
        goto out;
    }
    d = &s->ds[idx];
    snap = calloc(1, sizeof *snap);
    if (snap) {
        snap->accel = calloc(d->ntiles, sizeof *snap->accel);
        snap->parts = calloc(d->ntiles, TD_PART_COUNT * sizeof *snap->parts);
    }
    if (!snap || !snap->accel || !snap->parts) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a snapshot of '%s'", d->id);
        goto out;
    }
    snap->store = s;
    snap->ds = (size_t)idx;
    snap->view.accel = snap->accel;
    pthread_mutex_lock(&s->mu);
    if (d->prep && d->vstate != TD_VERIFY_OK) {
        rc = d->vstate == TD_VERIFY_PENDING
                 ? td_err_set(err, TD_EAGAIN, "dataset '%s' is being checked (%ld of %ld chunks of its heights)",
                              d->id, (long)d->vdone, (long)td_prepared_chunks(d->prep))
                 : td_err_set(err, TD_ENOTFOUND, "dataset '%s' was refused: %s", d->id, d->vwhy);
        pthread_mutex_unlock(&s->mu);
        goto out;
    }
    /* the heights and the parts in one critical section: an edit swaps both in one */
    snap->hv = d->cur;
    atomic_fetch_add_explicit(&snap->hv->refs, 1, memory_order_relaxed);
    snap->view.grid = snap->hv->grid;
    stamp = ++s->clock;
    d->snapshots++;
    if (d->prep) /* the prepare's structures, mapped; a preload's parts replace them below */
        memcpy(snap->accel, td_prepared_accel(d->prep), d->ntiles * sizeof *snap->accel);
    for (size_t t = 0; t < d->ntiles; t++) {
        td_slot *sl = &d->slots[t];
        for (int k = 0; k < TD_PART_COUNT; k++) {
            td_part *p = sl->part[k];
            if (p) {
                part_ref(p);
                snap->parts[snap->nparts++] = p;
                td_part_ops_of[k].attach(&snap->accel[t], p->ptr);
                snap->count[k]++;
                sl->stamp = stamp;
            }
        }
    }
    pthread_mutex_unlock(&s->mu);
    *out = snap;
    snap = NULL;
out:
    td_snapshot_release(snap);
    return rc;
}

const td_view *td_snapshot_view(const td_snapshot *snap) { return &snap->view; }

const td_lod *td_snapshot_lod(const td_snapshot *snap) { return snap->hv->lod; }

uint64_t td_snapshot_version(const td_snapshot *snap, uint64_t *chain)
{
    if (chain)
        *chain = snap->hv->chain;
    return snap->hv->version;
}

const char *td_snapshot_dir(const td_snapshot *snap) { return snap->store->ds[snap->ds].dir; }

size_t td_snapshot_count(const td_snapshot *snap, td_part_kind kind)
{
    return (unsigned)kind < TD_PART_COUNT ? snap->count[kind] : 0;
}

void td_snapshot_release(td_snapshot *snap)
{
    if (!snap)
        return;
    for (size_t i = 0; i < snap->nparts; i++)
        part_unref(snap->parts[i]);
    drape_unref(snap->drape);
    sunkeep_unref(snap->sun);
    hver_unref(snap->hv);
    free(snap->parts);
    free(snap->accel);
    free(snap);
}

/* --- drapes ----------------------------------------------------------------------- */

/* The dataset's kept drape decoded from `path`, with a reference for the caller; NULL if
 * none is kept. */
static td_drape *drape_find_locked(td_ds *d, const char *path)
{
    td_drape *dr = d->drapes;
    while (dr && strcmp(dr->path, path))
        dr = dr->next;
    if (dr)
        atomic_fetch_add_explicit(&dr->refs, 1, memory_order_relaxed);
    return dr;
}

static td_status drape_decode(const char *path, td_drape **out, td_err *err)
{
    td_status rc;
    td_image8 *img = NULL;
    size_t len = strlen(path) + 1;

    *out = NULL;
    rc = td_image_load(path, 3, TD_STORE_DRAPE_MAX_PIXELS, &img, err);
    if (rc)
        goto out;
    *out = malloc(sizeof **out + len);
    if (!*out) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the drape %s", path);
        goto out;
    }
    atomic_init(&(*out)->refs, 1);
    (*out)->next = NULL;
    (*out)->img = img;
    (*out)->bytes = sizeof **out + len + sizeof *img +
                    (uint64_t)img->width * (uint64_t)img->height * (uint64_t)img->channels;
    memcpy((*out)->path, path, len);
    img = NULL;
out:
    td_image_free(img);
    return rc;
}

/* Keeps a new drape with its dataset (a reference of its own) if the budget has room
 * for it after evicting acceleration least recently used first; 0 if it has not. */
static int drape_keep_locked(td_store *s, td_ds *d, td_drape *dr)
{
    int kept;
    while (s->resident_bytes + dr->bytes > s->o.budget_bytes && evict_lru_locked(s))
        ;
    kept = s->resident_bytes + dr->bytes <= s->o.budget_bytes;
    if (kept) {
        atomic_fetch_add_explicit(&dr->refs, 1, memory_order_relaxed);
        dr->next = d->drapes;
        d->drapes = dr;
        d->drape_bytes += dr->bytes;
        s->resident_bytes += dr->bytes;
    }
    return kept;
}

td_status td_snapshot_drape(td_snapshot *snap, const char *path, const td_image8 **out,
                            td_err *err)
{
    td_status rc = TD_OK;
    td_store *s = snap->store;
    td_ds *d = &s->ds[snap->ds];
    td_drape *dr, *mine = NULL;
    int kept = 1;

    *out = NULL;
    pthread_mutex_lock(&s->mu);
    dr = drape_find_locked(d, path);
    pthread_mutex_unlock(&s->mu);
    if (!dr) {
        /* decoded without the lock; a render that decoded it meanwhile wins */
        rc = drape_decode(path, &mine, err);
        if (rc)
            goto out;
        pthread_mutex_lock(&s->mu);
        dr = drape_find_locked(d, path);
        if (!dr) {
            dr = mine;
            mine = NULL;
            kept = drape_keep_locked(s, d, dr);
        }
        pthread_mutex_unlock(&s->mu);
    }
    if (!kept) {
        char q[600];
        td_log(TD_LOG_WARN, "drape_not_kept", "dataset=%s path=%s bytes=%llu reason=\"over the memory budget\"",
               d->id, td_log_quote(q, sizeof q, path), (unsigned long long)dr->bytes);
    }
    drape_unref(snap->drape);
    snap->drape = dr;
    *out = dr->img;
out:
    drape_unref(mine);
    return rc;
}

/* --- sun bounds ------------------------------------------------------------------- */

/* The dataset's kept bound for these heights and this sun (the same bits), moved to the
 * front, with a reference for the caller; NULL if none is kept. */
static td_sunkeep *sun_find_locked(td_ds *d, uint64_t version, const double sun[3])
{
    td_sunkeep **pp = &d->suns, *k;
    while ((k = *pp) && !(k->version == version && memcmp(k->sun, sun, sizeof k->sun) == 0))
        pp = &k->next;
    if (k) {
        *pp = k->next;
        k->next = d->suns;
        d->suns = k;
        atomic_fetch_add_explicit(&k->refs, 1, memory_order_relaxed);
    }
    return k;
}

/* Drops the dataset's reference to *pp (unlinked; freed with the last snapshot's). */
static void sun_drop_locked(td_store *s, td_ds *d, td_sunkeep **pp)
{
    td_sunkeep *k = *pp;
    *pp = k->next;
    d->sun_bytes -= k->bytes;
    s->resident_bytes -= k->bytes;
    sunkeep_unref(k);
}

/* Keeps a new bound at the front (a reference of its own): bounds of other heights are
 * dropped, and the least recently used beyond TD_STORE_SUNS; then it is kept if the
 * budget has room for it as it is (no acceleration is evicted for a bound: a tile's
 * max-mipmap saves more than a sun bound's build). 0 if not. */
static int sun_keep_locked(td_store *s, td_ds *d, td_sunkeep *k)
{
    td_sunkeep **pp = &d->suns;
    int n = 1, kept;
    while (*pp)
        if ((*pp)->version != k->version || n >= TD_STORE_SUNS)
            sun_drop_locked(s, d, pp);
        else {
            pp = &(*pp)->next;
            n++;
        }
    kept = s->resident_bytes + k->bytes <= s->o.budget_bytes;
    if (kept) {
        atomic_fetch_add_explicit(&k->refs, 1, memory_order_relaxed);
        k->next = d->suns;
        d->suns = k;
        d->sun_bytes += k->bytes;
        s->resident_bytes += k->bytes;
    }
    return kept;
}

td_status td_snapshot_sunlit(td_snapshot *snap, const double sun[3], const td_sunlit **out, int *kept,
                             td_err *err)
{
    td_status rc = TD_OK;
    td_store *s = snap->store;
    td_ds *d = &s->ds[snap->ds];
    td_sunkeep *k, *had, *mine = NULL;

    *out = NULL;
    *kept = 0;
    pthread_mutex_lock(&s->mu);
    k = sun_find_locked(d, snap->hv->version, sun);
    /* a render's bound kept from the sun's first use */
    had = k && !atomic_load_explicit(&k->fine, memory_order_relaxed) ? k : NULL;
    s->sun_kept += k && !had; /* (the counters as the answers' X-Terrad-Sun-Bound) */
    pthread_mutex_unlock(&s->mu);
    if (k && !had) {
        *kept = 1;
    } else {
        /* built without the lock on this snapshot's view: a sun's first use takes a
           render's own bound (cheap), its second the finer one kept bounds may take
           (sunlit.c), which replaces it; a render that built as fine a one meanwhile wins */
        mine = calloc(1, sizeof *mine);
        if (!mine) {
            rc = td_err_set(err, TD_ENOMEM, "out of memory for a sun bound");
            goto out;
        }
        const int fine = had != NULL || !td_sunlit_kept_finer(snap->view.grid);
        atomic_init(&mine->refs, 1);
        atomic_init(&mine->fine, fine);
        mine->version = snap->hv->version;
        memcpy(mine->sun, sun, sizeof mine->sun);
        rc = td_sunlit_build(&snap->view, sun, fine, &mine->lit, err);
        if (rc)
            goto out;
        mine->bytes = sizeof *mine + (mine->lit ? mine->lit->bytes : 0);
        pthread_mutex_lock(&s->mu);
        s->sun_built++;
        k = sun_find_locked(d, snap->hv->version, sun); /* at the front when found */
        int keep = 1;
        if (k && fine && !atomic_load_explicit(&k->fine, memory_order_relaxed)) {
            /* the coarse one goes where the budget has room for the finer (which
               sun_keep_locked keeps); else it stays, this snapshot alone has the finer,
               and no later use builds again */
            keep = s->resident_bytes - k->bytes + mine->bytes <= s->o.budget_bytes;
            if (keep)
                sun_drop_locked(s, d, &d->suns);
            else
                atomic_store_explicit(&k->fine, 1, memory_order_relaxed);
            sunkeep_unref(k);
            k = NULL;
        }
        if (!k) {
            k = mine;
            mine = NULL;
            if (keep && k->lit && d->cur->version == k->version) /* a bound, of the heights now */
                sun_keep_locked(s, d, k);
        } else {
            *kept = 1;
            s->sun_kept++;
        }
        pthread_mutex_unlock(&s->mu);
    }
    sunkeep_unref(snap->sun);
    snap->sun = k;
    *out = k->lit;
out:
    sunkeep_unref(had);
    sunkeep_unref(mine);
    return rc;
}

/* --- eviction --------------------------------------------------------------------- */

void td_store_evict_dataset(td_store *s, size_t idx, size_t *evicted)
{
    td_ds *d = &s->ds[idx];
    size_t n = 0;
    pthread_mutex_lock(&s->mu);
    for (size_t t = 0; t < d->ntiles; t++) {
        n += (size_t)slot_resident(&d->slots[t]);
        slot_clear_locked(s, d, &d->slots[t]);
    }
    pthread_mutex_unlock(&s->mu);
    *evicted = n;
}

/* --- disk cache ------------------------------------------------------------------- */

/* What a part is built from: the heights and the fingerprint that keys its cache file. */
typedef struct td_src {
    const td_grid *grid;
    uint64_t fp;
} td_src;

/* A tile's cache fingerprint: the dataset's as loaded while the tile is unedited (hver
 * 1), else the hash of the tile's own samples chained to it, so a structure cached
 * from other heights never matches, whatever the version numbers (they restart at 1). */
static uint64_t tile_fingerprint(const td_store *s, const td_ds *d, const td_grid *g,
                                 size_t tile, uint64_t hver)
{
    uint64_t h = d->fingerprint;
    const td_tile *t = &g->tiles[tile];
    for (int32_t j = t->j0; s->cache_dir && hver != 1 && j <= t->j0 + t->ny; j++)
        h = td_fnv1a(h, g->z + (size_t)j * (size_t)g->w + (size_t)t->i0,
                     ((size_t)t->nx + 1) * sizeof(float));
    return h;
}

static int cache_path(const td_store *s, const td_ds *d, const td_src *src, size_t tile,
                      td_part_kind kind, char *out, size_t n)
{
    int w = snprintf(out, n, "%s/%s-%016llx-t%d-%zu.%s", s->cache_dir, d->id,
                     (unsigned long long)src->fp, s->o.tile_log2, tile,
                     td_part_ops_of[kind].ext);
    return w > 0 && (size_t)w < n;
}

/* The header's fields common to every kind, as a file for this part must have them. */
static void cache_hdr_init(const td_store *s, const td_src *src, size_t tile, td_part_kind kind,
                           td_cache_hdr *h)
{
    const td_tile *t = &src->grid->tiles[tile];
    memset(h, 0, sizeof *h);
    memcpy(h->magic, TD_CACHE_MAGIC, sizeof TD_CACHE_MAGIC);
    h->version = TD_CACHE_VERSION;
    h->kind = kind;
    h->fingerprint = src->fp;
    h->tile_log2 = (uint32_t)s->o.tile_log2;
    h->param = (uint32_t)s->param[kind];
    h->tile = tile;
    h->nx = t->nx;
    h->ny = t->ny;
}

/* FNV-1a of the header (its checksum field taken as 0) and then the payload's pieces: a
 * flipped bit anywhere in the file, shape fields included, fails it. */
static uint64_t cache_checksum(const td_cache_hdr *hdr, const td_piece *pc, int npc)
{
    td_cache_hdr h0 = *hdr;
    uint64_t h;
    h0.checksum = 0;
    h = td_fnv1a(TD_FNV1A_INIT, &h0, sizeof h0);
    for (int i = 0; i < npc; i++)
        h = td_fnv1a(h, pc[i].ptr, pc[i].len);
    return h;
}

/* Writes a part to the cache through a temporary file, fsync and rename: a crash or kill
 * mid-write leaves at most a *.tmp file, which is never read, and never a torn file under
 * the real name. A failed write (disk full) is logged and dropped: the part is served
 * anyway, only not cached. */
static void cache_write(const td_store *s, const td_ds *d, const td_src *src, size_t tile,
                        const td_part *p)
{
    char path[PATH_MAX], tmp[PATH_MAX + 16];
    td_cache_hdr h;
    td_piece pc[TD_PIECES_MAX];
    FILE *f = NULL;
    int ok, npc;

    if (!s->cache_dir || !cache_path(s, d, src, tile, p->kind, path, sizeof path))
        return;
    snprintf(tmp, sizeof tmp, "%s.%ld.tmp", path, (long)getpid());
    cache_hdr_init(s, src, tile, p->kind, &h);
    npc = td_part_ops_of[p->kind].pieces(p->ptr, &h, pc);
    for (int i = 0; i < npc; i++)
        h.payload += pc[i].len;
    h.checksum = cache_checksum(&h, pc, npc);
    f = fopen(tmp, "wb");
    ok = f && fwrite(&h, sizeof h, 1, f) == 1;
    for (int i = 0; i < npc && ok; i++)
        ok = fwrite(pc[i].ptr, 1, pc[i].len, f) == pc[i].len;
    if (ok && (fflush(f) || fsync(fileno(f))))
        ok = 0;
    if (f && fclose(f))
        ok = 0;
    if (!ok || rename(tmp, path)) {
        char q[600];
        td_log(TD_LOG_WARN, "cache_write_failed", "path=%s", td_log_quote(q, sizeof q, path));
        unlink(tmp);
    }
}

/* Reads a part from the cache if present and valid in every field; NULL otherwise. */
static td_part *cache_read(td_store *s, const td_ds *d, const td_src *src, size_t tile,
                           td_part_kind kind)
{
    char path[PATH_MAX], q[600];
    td_cache_hdr h, want;
    td_piece pc[TD_PIECES_MAX];
    FILE *f = NULL;
    struct stat st;
    td_part *part = NULL;
    void *obj = NULL;
    size_t bytes = 0;
    const char *why = NULL;
    int npc = 0;

    if (!s->cache_dir || !cache_path(s, d, src, tile, kind, path, sizeof path) || stat(path, &st))
        goto out;
    cache_hdr_init(s, src, tile, kind, &want);
    f = fopen(path, "rb");
    if (!f || fread(&h, sizeof h, 1, f) != 1) {
        why = "short header";
        goto out;
    }
    if (memcmp(h.magic, want.magic, sizeof h.magic) || h.version != want.version ||
        h.kind != want.kind || h.fingerprint != want.fingerprint ||
        h.tile_log2 != want.tile_log2 || h.param != want.param || h.tile != want.tile ||
        h.nx != want.nx || h.ny != want.ny) {
        why = "header does not match (version, dataset or tiling changed)";
        goto out;
    }
    if ((uint64_t)st.st_size != sizeof h + h.payload) {
        why = "size does not match the header";
        goto out;
    }
    why = td_part_ops_of[kind].alloc(&h, &obj, &bytes, pc, &npc);
    if (why)
        goto out;
    for (int i = 0; i < npc && !why; i++)
        if (fread(pc[i].ptr, 1, pc[i].len, f) != pc[i].len)
            why = "checksum mismatch or short payload";
    if (!why && cache_checksum(&h, pc, npc) != h.checksum)
        why = "checksum mismatch or short payload";
    if (!why)
        why = td_part_ops_of[kind].check(obj);
    if (why)
        goto out;
    part = part_new(kind, obj, bytes);
    if (part)
        obj = NULL;
out:
    if (f)
        fclose(f);
    if (obj)
        td_part_ops_of[kind].free(obj);
    if (why)
        td_log(TD_LOG_WARN, "cache_rejected", "path=%s reason=\"%s\"", td_log_quote(q, sizeof q, path), why);
    pthread_mutex_lock(&s->mu);
    if (part)
        s->cache_hits++;
    else if (s->cache_dir)
        s->cache_misses++;
    pthread_mutex_unlock(&s->mu);
    return part;
}

/* --- preload ---------------------------------------------------------------------- */

typedef struct td_stage_tile {
    size_t tile;
    uint64_t hver;                /* the tile's heights version when marked */
    int want[TD_PART_COUNT];      /* what to build for this tile */
    td_part *part[TD_PART_COUNT]; /* built, not yet published */
} td_stage_tile;

/* The i-th tile a preload names. */
static size_t spec_tile(const td_preload_spec *p, size_t i) { return p->tiles ? p->tiles[i] : i; }

/* Builds one part, or reads it from the cache (and writes what it built there). */
static td_status build_part(td_store *s, td_ds *d, const td_src *src, size_t tile,
                            td_part_kind kind, td_part **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_part_ops *ops = &td_part_ops_of[kind];
    void *obj = NULL;
    size_t bytes = 0;

    *out = cache_read(s, d, src, tile, kind);
    if (*out)
        goto out;
    rc = ops->build(src->grid, tile, s->param[kind], &obj, &bytes, err);
    if (rc)
        goto out;
    *out = part_new(kind, obj, bytes);
    if (!*out) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a tile record");
        goto out;
    }
    obj = NULL;
    pthread_mutex_lock(&s->mu);
    s->tiles_built++;
    pthread_mutex_unlock(&s->mu);
    cache_write(s, d, src, tile, *out);
out:
    if (obj)
        ops->free(obj);
    return rc;
}

/* The request itself: a dataset, something to build, tiles that exist. */
static td_status preload_check(const td_store *s, const td_preload_spec *p, td_err *err)
{
    td_status rc = TD_OK;
    const td_ds *d;
    int any = 0;

    for (int k = 0; k < TD_PART_COUNT; k++)
        any |= p->build[k];
    if (p->dataset >= s->nds) {
        rc = td_err_set(err, TD_ENOTFOUND, "unknown dataset");
        goto out;
    }
    if (!any) {
        rc = td_err_set(err, TD_EINVAL, "build: nothing to build (maxmip and planes both off)");
        goto out;
    }
    d = &s->ds[p->dataset];
    for (size_t i = 0; p->tiles && i < p->ntiles; i++)
        if (p->tiles[i] >= d->ntiles) {
            rc = td_err_set(err, TD_EINVAL, "tiles[%zu]: tile %zu does not exist (dataset '%s' has %zu)",
                            i, p->tiles[i], d->id, d->ntiles);
            goto out;
        }
out:
    return rc;
}

/* Marks the n requested tiles as in this preload (so LRU leaves them), stages what to
 * build, and checks the budget up front: heights + drapes + pinned tiles + requested
 * tiles we keep + the bound of what we build. The tiles stay marked on failure too. */
static td_status preload_mark(td_store *s, const td_preload_spec *p, size_t n,
                              td_stage_tile *stage, size_t *nstage, td_hver **hv, td_err *err)
{
    td_status rc = TD_OK;
    td_ds *d = &s->ds[p->dataset];
    uint64_t need = 0, kept;

    *nstage = 0;
    pthread_mutex_lock(&s->mu);
    *hv = d->cur; /* built from these heights; published only where they still hold */
    atomic_fetch_add_explicit(&(*hv)->refs, 1, memory_order_relaxed);
    for (size_t i = 0; i < n; i++) {
        size_t t = spec_tile(p, i);
        td_slot *sl = &d->slots[t];
        td_stage_tile *st = &stage[*nstage];
        int any = 0;
        if (sl->job)
            continue; /* listed twice */
        sl->job = 1;
        for (int k = 0; k < TD_PART_COUNT; k++) {
            st->want[k] = p->build[k] && (!sl->part[k] || p->rebuild);
            if (st->want[k])
                need += td_part_ops_of[k].bound(&(*hv)->grid->tiles[t], s->o.tile_log2, s->param[k]);
            any |= st->want[k];
        }
        if (any) {
            st->tile = t;
            st->hver = sl->hver;
            (*nstage)++;
        }
    }
    kept = kept_bytes_locked(s);
    pthread_mutex_unlock(&s->mu);
    if (kept + need > s->o.budget_bytes)
        rc = td_err_set(err, TD_ETOOBIG,
                        "memory budget exceeded: %zu tiles of '%s' need up to %llu bytes, and "
                        "heights + pinned + kept tiles already take %llu of %llu bytes "
                        "(raise --memory-mb, or preload fewer tiles)",
                        *nstage, d->id, (unsigned long long)need, (unsigned long long)kept,
                        (unsigned long long)s->o.budget_bytes);
    return rc;
}

/* Builds the staged parts, kind by kind, each after evicting what it needs to fit
 * (resident + staged + this part within the budget). */
static td_status preload_build(td_store *s, td_ds *d, const td_hver *hv, td_stage_tile *stage,
                               size_t nstage, td_preload_progress cb, void *cls, td_err *err)
{
    td_status rc = TD_OK;
    uint64_t staged = 0;
    td_src src;

    for (int k = 0; k < TD_PART_COUNT; k++) {
        const td_part_ops *ops = &td_part_ops_of[k];
        for (size_t i = 0; i < nstage; i++) {
            uint64_t bound;
            if (!stage[i].want[k])
                continue;
            if (cb && cb(cls, ops->name, i, nstage)) {
                rc = td_err_set(err, TD_ECANCELED, "preload cancelled (server stopping)");
                goto out;
            }
            bound = ops->bound(&hv->grid->tiles[stage[i].tile], s->o.tile_log2, s->param[k]);
            pthread_mutex_lock(&s->mu);
            while (s->resident_bytes + staged + bound > s->o.budget_bytes && evict_lru_locked(s))
                ;
            pthread_mutex_unlock(&s->mu);
            src.grid = hv->grid;
            src.fp = tile_fingerprint(s, d, hv->grid, stage[i].tile, stage[i].hver);
            rc = build_part(s, d, &src, stage[i].tile, (td_part_kind)k, &stage[i].part[k], err);
            if (rc)
                goto out;
            staged += stage[i].part[k]->bytes;
        }
    }
out:
    return rc;
}

/* Puts every staged part in its slot at once, then pins the requested tiles if asked.
 * A tile whose heights an edit changed since it was marked keeps its parts out (they
 * are left in the stage, dropped by the caller): the edit's own job rebuilds it.
 * Returns the tiles published. */
static size_t preload_publish(td_store *s, const td_preload_spec *p, size_t n,
                              td_stage_tile *stage, size_t nstage)
{
    td_ds *d = &s->ds[p->dataset];
    size_t published = 0;
    pthread_mutex_lock(&s->mu);
    for (size_t i = 0; i < nstage; i++) {
        td_slot *sl = &d->slots[stage[i].tile];
        if (sl->hver != stage[i].hver)
            continue;
        published++;
        for (int k = 0; k < TD_PART_COUNT; k++)
            if (stage[i].part[k]) {
                slot_put_locked(s, d, sl, (td_part_kind)k, stage[i].part[k]);
                stage[i].part[k] = NULL;
            }
        sl->stamp = ++s->clock;
    }
    for (size_t i = 0; i < n && p->pin; i++)
        slot_pin_locked(d, &d->slots[spec_tile(p, i)]);
    pthread_mutex_unlock(&s->mu);
    return published;
}

/* Unmarks the requested tiles and evicts down to the budget. */
static void preload_unmark(td_store *s, const td_preload_spec *p, size_t n)
{
    td_ds *d = &s->ds[p->dataset];
    pthread_mutex_lock(&s->mu);
    for (size_t i = 0; i < n; i++)
        d->slots[spec_tile(p, i)].job = 0;
    while (s->resident_bytes > s->o.budget_bytes && evict_lru_locked(s))
        ;
    pthread_mutex_unlock(&s->mu);
}

td_status td_store_preload(td_store *s, const td_preload_spec *p, td_preload_progress cb,
                           void *cls, size_t *built, td_err *err)
{
    td_status rc;
    size_t n = 0, nstage = 0;
    td_stage_tile *stage = NULL;
    td_hver *hv = NULL;
    int marked = 0;

    *built = 0;
    pthread_mutex_lock(&s->preload);
    rc = preload_check(s, p, err);
    if (rc)
        goto out;
    n = p->tiles ? p->ntiles : s->ds[p->dataset].ntiles;
    if (cb)
        cb(cls, "checking", 0, n);
    stage = calloc(n ? n : 1, sizeof *stage);
    if (!stage) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %zu tiles", n);
        goto out;
    }
    marked = 1;
    rc = preload_mark(s, p, n, stage, &nstage, &hv, err);
    if (rc)
        goto out;
    rc = preload_build(s, &s->ds[p->dataset], hv, stage, nstage, cb, cls, err);
    if (rc)
        goto out;
    if (cb)
        cb(cls, "publishing", nstage, nstage);
    *built = preload_publish(s, p, n, stage, nstage);
out:
    if (marked)
        preload_unmark(s, p, n);
    for (size_t i = 0; stage && i < nstage; i++)
        for (int k = 0; k < TD_PART_COUNT; k++)
            part_unref(stage[i].part[k]); /* left over when the preload failed or an edit won */
    free(stage);
    hver_unref(hv);
    pthread_mutex_unlock(&s->preload);
    return rc;
}

td_status td_store_tiles_in_box(td_store *s, size_t idx, const double box[4], size_t **tiles,
                                size_t *n, td_err *err)
{
    td_status rc = TD_OK;
    const td_grid *g = &s->ds[idx].shape;
    double cx0, cx1, cy0, cy1;
    int32_t tx0, tx1, ty0, ty1, T = td_grid_tile_size(g);

    *tiles = NULL;
    *n = 0;
    for (int i = 0; i < 4; i++)
        if (!isfinite(box[i])) {
            rc = td_err_set(err, TD_EINVAL, "bbox[%d]: not a finite number", i);
            goto out;
        }
    if (box[0] > box[2] || box[1] > box[3]) {
        rc = td_err_set(err, TD_EINVAL, "bbox: min is above max");
        goto out;
    }
    cx0 = fmax(0.0, floor(box[0] / g->sx));
    cx1 = fmin((double)(g->w - 2), floor(box[2] / g->sx));
    cy0 = fmax(0.0, floor(box[1] / g->sy));
    cy1 = fmin((double)(g->h - 2), floor(box[3] / g->sy));
    if (cx0 > cx1 || cy0 > cy1)
        goto out;
    tx0 = (int32_t)cx0 / T;
    tx1 = (int32_t)cx1 / T;
    ty0 = (int32_t)cy0 / T;
    ty1 = (int32_t)cy1 / T;
    rc = td_grid_tile_range(g, tx0, tx1, ty0, ty1, tiles, n, err);
out:
    return rc;
}

/* --- edits ------------------------------------------------------------------------ */

/* The touched slots' parts out, their heights version moved on, and the new heights in,
 * all under the store lock: a snapshot sees all of the old or all of the new. Fills res
 * (rebuild: the touched tiles that held a part, and the kinds they held). */
static void edit_publish_locked(td_store *s, td_ds *d, td_hver *hv, const size_t *tiles,
                                size_t n, td_edit_result *res)
{
    for (size_t i = 0; i < n; i++) {
        td_slot *sl = &d->slots[tiles[i]];
        if (slot_resident(sl)) {
            res->rebuild.pin |= sl->pinned;
            for (int k = 0; k < TD_PART_COUNT; k++)
                res->rebuild.build[k] |= sl->part[k] != NULL;
            ((size_t *)res->rebuild.tiles)[res->rebuild.ntiles++] = tiles[i];
        }
        for (int k = 0; k < TD_PART_COUNT; k++)
            slot_put_locked(s, d, sl, (td_part_kind)k, NULL);
        sl->hver = hv->version;
    }
    while (d->suns) /* bounds of the heights replaced (snapshots holding one keep it) */
        sun_drop_locked(s, d, &d->suns);
    d->cur = hv;
}

td_status td_store_edit(td_store *s, size_t idx, const td_grid_region *r, const float *z,
                        td_edit_result *res, td_err *err)
{
    td_status rc = TD_OK;
    td_ds *d = &s->ds[idx];
    td_grid *g = NULL;
    td_lod *lod = NULL;
    td_hver *hv = NULL, *old = NULL;
    size_t *tiles = NULL, n = 0;
    uint64_t chain, bytes;

    memset(res, 0, sizeof *res);
    res->rebuild.dataset = idx;
    pthread_mutex_lock(&s->edit); /* d->cur changes only under this lock: read it freely */
    old = d->cur;
    if (d->prep)
        rc = td_err_field(err, TD_EUNSUPPORTED, "dataset", "'%s' is prepared (read-only, memory-mapped): "
                        "edit its source and prepare it again", d->id);
    else
        rc = td_grid_edit_apply(old->grid, r, z, &g, err);
    if (!rc)
        rc = td_grid_edit_tiles(g, r, &tiles, &n, err);
    if (rc)
        goto out;
    rc = lod_build(s, g, &lod, err);
    if (rc)
        goto out;
    bytes = td_grid_bytes(g->w, g->h, g->tile_log2) + lod->bytes;
    chain = td_fnv1a(old->chain ? old->chain : TD_FNV1A_INIT, r, sizeof *r);
    chain = td_fnv1a(chain, z, (size_t)r->w * (size_t)r->h * sizeof *z);
    rc = hver_new(g, lod, old->version + 1, chain, &hv, err);
    g = NULL;
    lod = NULL;
    if (rc)
        goto out;
    res->rebuild.tiles = malloc(n * sizeof *tiles);
    if (!res->rebuild.tiles) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory");
        goto out;
    }
    pthread_mutex_lock(&s->mu);
    edit_publish_locked(s, d, hv, tiles, n, res);
    s->resident_bytes = s->resident_bytes - d->grid_bytes + bytes;
    d->grid_bytes = bytes;
    pthread_mutex_unlock(&s->mu);
    res->version = hv->version;
    res->chain = hv->chain;
    res->touched = n;
    hv = NULL;
    hver_unref(old); /* the store's reference: freed when the last snapshot ends */
out:
    pthread_mutex_unlock(&s->edit);
    if (rc) {
        free((void *)res->rebuild.tiles);
        res->rebuild.tiles = NULL;
        res->rebuild.ntiles = 0;
    }
    hver_unref(hv);
    td_lod_free(lod);
    td_grid_free(g);
    free(tiles);
    return rc;
}
