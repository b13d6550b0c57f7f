/* tilestore.h: the datasets terrad serves and the per-tile acceleration it keeps
 * resident (max-mipmaps, parameter planes), shared by concurrent renders.
 *
 * Datasets are loaded before the server starts (td_store_add_dir, td_store_add_grid);
 * their list can be read without a lock. What changes at run time is, per tile, which
 * acceleration is resident, and a dataset's heights (td_store_edit). Each built
 * structure is immutable and reference-counted (C11 atomics):
 *
 *   store --(1 ref)--> part {refs, kind, object, bytes} <--(1 ref each)-- snapshots
 *
 * A tile holds at most one part of each kind (TD_PART_LIST: max-mipmap, planes); a new
 * kind is one row there and one row of per-kind operations in tilestore.c.
 *
 * A render takes a snapshot (td_store_acquire): the td_view it traces plus one
 * reference to every part resident at that instant, and the dataset's fixed fields
 * (grid, levels of detail, directory). A preload that replaces a tile, or an eviction,
 * only swaps the store's pointer under the store lock and drops the store's reference;
 * the part is freed by whoever drops the last one, so a render never sees a structure
 * change or vanish under it. A render's drape (effects.drape) is decoded on first use
 * and kept with its dataset (td_snapshot_drape), immutable and shared the same way.
 *
 * Memory: heights count against the budget from load, a kept drape from its first use,
 * and neither is evicted; acceleration is evicted least recently used first (a snapshot
 * marks every tile of its dataset used), pinned tiles never. A preload builds one tile
 * at a time (one builder thread), evicting before it builds, so the budget is never
 * exceeded by more than the tile being built.
 * A preload is checked up front (tiles, budget against heights + drapes + pinned + kept
 * tiles), builds into a staging list, and publishes every tile at once under the lock;
 * if a build fails the staging list is dropped and the resident tiles stay as they were
 * (apart from LRU evictions made to fit the budget, which only lose cached work).
 *
 * Edits: a dataset's heights are a refcounted version (grid + levels of detail, number,
 * edit hash), copied on write (gridedit.h) and published with one pointer swap under
 * the store lock, in the same critical section that drops the touched tiles' parts and
 * moves their per-tile heights version on; a snapshot takes the version and the parts
 * in one critical section too, so it sees all old or all new heights and only parts
 * built from the heights it traces. Old versions are freed by the last snapshot that
 * holds one. A preload records each tile's heights version when it marks it and
 * publishes a part only where it still holds (an edit racing a preload wins; the
 * edit's own rebuild job, queued behind, builds the tile again). Cache files of an
 * edited tile are keyed by the hash of its samples. Edits live in memory only: a
 * restart loads the files again. During an edit, the old and new grids are both
 * resident (the new one is counted against the budget once published).
 *
 * With a cache directory, built parts are also written to disk (header with magic,
 * version, kind, dataset fingerprint, tile and shape, payload size and an FNV-1a
 * checksum) and read back instead of rebuilt when every field checks out. */
#ifndef TD_TILESTORE_H
#define TD_TILESTORE_H

#include <stddef.h>
#include <stdint.h>

#include "gridedit.h"
#include "image.h"
#include "lod.h"
#include "sunlit.h"
#include "trace.h"

#define TD_STORE_ID_MAX 64

/* X(KIND, name, ext): the structures a tile can hold. TD_PART_KIND indexes per-kind
 * arrays; `name` is the preload phase, the admin API's word and the field names below
 * (spec.maxmip, info.maxmip_tiles); `ext` ends the kind's cache files. */
#define TD_PART_LIST(X)     \
    X(MAXMIP, maxmip, "mm") \
    X(PLANES, planes, "pl")

typedef enum td_part_kind {
#define TD_X_ENUM(K, name, ext) TD_PART_##K,
    TD_PART_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_PART_COUNT
} td_part_kind;

typedef struct td_store td_store;
typedef struct td_snapshot td_snapshot;

typedef struct td_store_opts {
    uint64_t budget_bytes; /* heights + acceleration */
    int tile_log2;
    int planes_k;
    const char *cache_dir; /* NULL or "": no disk cache */
} td_store_opts;

typedef struct td_dataset_info {
    const char *id;
    const char *file;       /* file name of the source (no directory) */
    const char *dir;        /* its directory (server side only; never sent to clients) */
    const char *origin;     /* "demo", "data" or "api" */
    const td_grid *grid;    /* &grid_hdr below: the current heights' fields, no z or tiles */
    td_grid grid_hdr;
    uint64_t version;       /* of the heights: 1 as loaded, +1 an edit */
    uint64_t chain;         /* 0 as loaded, then a hash of the edits applied in order */
    size_t ntiles;
    size_t resident_tiles;  /* with any acceleration */
    union {                 /* tiles holding each kind, by name or by kind */
        struct {
#define TD_X_FIELD(K, name, ext) size_t name##_tiles;
            TD_PART_LIST(TD_X_FIELD)
#undef TD_X_FIELD
        };
        size_t part_tiles[TD_PART_COUNT];
    };
    size_t pinned_tiles;
    uint64_t grid_bytes, accel_bytes;
    uint64_t drape_bytes;   /* decoded drapes kept with the dataset */
    uint64_t sun_bytes;     /* sun bounds kept with it (td_snapshot_sunlit) */
    int prepared;           /* served from a prepared folder (td_store_add_prepared) */
    int32_t chunks, chunks_checked; /* its chunks (heights and levels), and how many the background check passed */
    int levels;             /* coarse levels (quality.lod) */
    int refused;            /* a chunk failed its check: never served */
    uint64_t heights_resident; /* bytes of its mapped heights resident in the process */
    uint64_t snapshots;     /* requests that traced it since start (renders, tiles, picks,
                               viewsheds: one td_store_acquire each) */
} td_dataset_info;

typedef struct td_store_stats {
    size_t datasets;
    uint64_t total_tiles, resident_tiles, resident_bytes, budget_bytes;
    uint64_t tiles_built, tiles_evicted, cache_hits, cache_misses;
    uint64_t sun_kept, sun_built; /* td_snapshot_sunlit: bounds found kept, and built */
    uint64_t sun_bytes;           /* the kept sun bounds' (in resident_bytes) */
    /* prepared datasets: bytes of heights mapped, resident in the process (counted in
       resident_bytes too), and how often they were trimmed back to the budget */
    uint64_t heights_mapped, heights_mapped_resident, heights_trims;
} td_store_stats;

td_status td_store_create(const td_store_opts *o, td_store **out, td_err *err);

/* Datasets added from now on also keep their levels of detail's isometric twins (lod.h:
 * quality.lod_grid isometric; two-byte vertices, about half the levels' float heights).
 * Off by default; call before adding datasets (terrad serve --isometric-lod 1). */
void td_store_set_lod_iso(td_store *s, int on);
/* Call only when no snapshot is held any more. */
void td_store_free(td_store *s);

/* Non-zero for an id made of [A-Za-z0-9_.-], 1..64 characters, not starting with '.'. */
int td_store_id_valid(const char *id);

/* Makes a dataset of every file td_dem_recognised accepts in `dir` (id: its name without
 * extension) and of every folder holding such files (id: the folder's name; with several
 * files, folder-file), and of every prepared folder (prepared.h, td_store_add_prepared;
 * id: the folder's name). Nothing outside `dir` can be named: symbolic links that resolve
 * outside it are skipped. A file that fails to load is logged and skipped. Not
 * thread-safe: call before serving. *loaded counts the datasets added. */
td_status td_store_add_dir(td_store *s, const char *dir, const char *origin, int *loaded,
                           td_err *err);
/* Adds a finished grid under `id` (the store takes it, also on failure). */
td_status td_store_add_grid(td_store *s, const char *id, const char *origin, td_grid *g,
                            td_err *err);

/* Adds the prepared dataset in folder `dir` (prepared.h) under `id`: its index is read and
 * its heights mapped, in time independent of their size. It is served once the background
 * thread (td_store_background_start) has checked every chunk of its heights; until then
 * td_store_acquire answers TD_EAGAIN, and for ever TD_ENOTFOUND (naming the file, chunk and
 * reason, also logged as dataset_refused) if a chunk of its heights, levels or tile
 * structures fails. Its coarse levels of detail are the prepare's, mapped
 * (td_prepared_take_lod), and so are every tile's max-mipmap and planes, of the full grid
 * and of the levels (prepaccel.h): every snapshot holds them where no preload has put a
 * part (which then replaces them); it refuses
 * edits. Its heights and levels count against the budget as far as they are resident in
 * the process: the background thread drops them (td_prepared_trim) when the process nears
 * the budget, and reads its coarsest levels ahead once checked. Not thread-safe: call
 * before serving. */
td_status td_store_add_prepared(td_store *s, const char *id, const char *origin, const char *dir,
                                td_err *err);
/* Starts the thread that checks prepared datasets and trims their mapped heights; call
 * once every dataset is added (td_store_free stops it). */
td_status td_store_background_start(td_store *s, td_err *err);

size_t td_store_count(const td_store *s);
/* Index of a dataset, or -1. */
long td_store_find(const td_store *s, const char *id);
/* A few stores under the store lock: the counters are kept as tiles change. */
void td_store_info(td_store *s, size_t idx, td_dataset_info *out);
void td_store_stats_get(td_store *s, td_store_stats *st);

/* The dataset's grid and every acceleration part resident now, held until release:
 * everything a render needs of its dataset, resolved once. TD_ENOTFOUND for an
 * unknown id. */
td_status td_store_acquire(td_store *s, const char *id, td_snapshot **out, td_err *err);
const td_view *td_snapshot_view(const td_snapshot *snap);
/* The dataset's levels of detail (td_render_opts.lod). */
const td_lod *td_snapshot_lod(const td_snapshot *snap);
/* The directory of the dataset's file ("" for a dataset added as a grid). */
const char *td_snapshot_dir(const td_snapshot *snap);
/* The version of the heights the snapshot holds (and, if chain is not NULL, their edit
 * hash: 0 as loaded), for ETags. */
uint64_t td_snapshot_version(const td_snapshot *snap, uint64_t *chain);
/* Tiles of the snapshot holding a part of this kind. */
size_t td_snapshot_count(const td_snapshot *snap, td_part_kind kind);
/* The drape PNG at `path` as RGB (td_render_opts.drape), held by the snapshot until its
 * release: decoded on the dataset's first use of it and kept with the dataset (counted
 * in the budget; when it cannot fit, this snapshot alone keeps it). td_image_load's
 * status and message when it cannot be read. One drape per snapshot: a second call
 * drops the first one's reference. */
td_status td_snapshot_drape(td_snapshot *snap, const char *path, const td_image8 **out,
                            td_err *err);
/* The sun bound (sunlit.h) of the snapshot's heights for the sun's unit direction, held
 * by the snapshot until its release (one per snapshot: a second call drops the first
 * one's reference): built on the first use of those heights with that sun (the same
 * bits) as a render builds its own, again at the second use as a kept bound, finer where
 * the grid allows (td_sunlit_kept_finer: dearer to build, cheaper rays; sunlit.c), and
 * kept with the dataset, the last TD_STORE_SUNS suns (tilestore.c), counted
 * in the budget (when it does not fit without evicting acceleration, this snapshot alone
 * keeps it); an edit's new heights
 * start afresh. *out NULL for a sun that gives none; *kept 1 when it was not built by this
 * call. A bound bounds the heights whatever structures the view that built it held, so
 * every snapshot of the same heights gives the same answers with it (td_sunlit_fits). */
td_status td_snapshot_sunlit(td_snapshot *snap, const double sun[3], const td_sunlit **out, int *kept,
                             td_err *err);
void td_snapshot_release(td_snapshot *snap);

typedef struct td_preload_spec {
    size_t dataset;       /* index */
    const size_t *tiles;  /* tile indices, or NULL for all */
    size_t ntiles;
    union {               /* what to build (at least one), by name or by kind */
        struct {
#define TD_X_FIELD(K, name, ext) int name;
            TD_PART_LIST(TD_X_FIELD)
#undef TD_X_FIELD
        };
        int build[TD_PART_COUNT];
    };
    int pin;              /* pinned tiles are never evicted by LRU */
    int rebuild;          /* replace resident parts instead of keeping them */
} td_preload_spec;

/* phase: "checking", a kind's name ("maxmip", "planes"), "publishing"; done of total. A non-zero
 * return cancels the preload (TD_ECANCELED) before its next tile. */
typedef int (*td_preload_progress)(void *cls, const char *phase, size_t done, size_t total);

/* Builds (or reads from the cache) what the spec asks for. Preloads run one at a time.
 * TD_EINVAL for a bad tile index, TD_ETOOBIG when the budget cannot hold it, the
 * builder's status otherwise; *built counts the tiles published. */
td_status td_store_preload(td_store *s, const td_preload_spec *p, td_preload_progress cb,
                           void *cls, size_t *built, td_err *err);

/* Drops all resident acceleration of a dataset, pinned or not; *evicted counts tiles. */
void td_store_evict_dataset(td_store *s, size_t idx, size_t *evicted);

/* Tiles of dataset idx whose cells meet the box [x0, x1] x [y0, y1] in the dataset
 * frame (metres). Returns a malloc'ed list (NULL with *n = 0 when none meet it). */
td_status td_store_tiles_in_box(td_store *s, size_t idx, const double box[4], size_t **tiles,
                                size_t *n, td_err *err);

typedef struct td_edit_result {
    uint64_t version, chain; /* the dataset's new heights version */
    size_t touched;          /* tiles whose heights changed */
    td_preload_spec rebuild; /* the touched tiles that held acceleration and the kinds they
                                held (tiles malloc'ed: free it; ntiles 0 when none) */
} td_edit_result;

/* Applies a checked region (td_grid_edit_parse) and its heights (td_grid_edit_decode:
 * w*h, row 0 north) to dataset idx as a new version, at once and atomically for
 * snapshots; the touched tiles lose their acceleration (res->rebuild says what to build
 * again: a preload). Edits run one at a time. On failure nothing changed. */
td_status td_store_edit(td_store *s, size_t idx, const td_grid_region *r, const float *z,
                        td_edit_result *res, td_err *err);

#endif
