/* prepared.h: terrad's prepared on-disk form of a dataset, for grids larger than memory
 * (issue 16). `terrad prepare DEM OUT_DIR` writes it (td_prepare: streaming, resumable);
 * `terrad serve --data` opens it in constant time (td_prepared_open) and serves it from a
 * read-only memory mapping, checking its heights chunk by chunk in the background
 * (td_prepared_verify_chunk) before the first render.
 *
 * A prepared dataset is a directory:
 *
 *   terrad.json   the index (written last, by rename: a directory without it is an
 *                 unfinished prepare): format "terrad-prepared", version, width, height,
 *                 spacing, tile_log2, zmin/zmax/voids, georeference, the source's name,
 *                 size and mtime, chunk_rows and one FNV-1a checksum per chunk of
 *                 heights.f32, the checksum of tiles.bin, and "blocks": {log2, bands: one
 *                 checksum per band of heights.blk}
 *   heights.f32   w*h little-endian float32, SOUTH-based rows, row-major: exactly the
 *                 layout of td_grid.z (grid.h), for the readers of z (viewsheds, peaks,
 *                 map tiles' height sampling, levels of detail)
 *   heights.blk   the same samples in blocks of B x B cells (B = 2^blocks.log2, 32 by
 *                 default), (B+1) x (B+1) samples each, the edge samples duplicated so
 *                 that a cell's four corners are in one block: td_grid.cz (grid.h's
 *                 td_grid_corner) points into it, and the render path (tracers, hit
 *                 shading, the tiles' max-mipmaps and planes) reads only it. Blocks are
 *                 row-major, south first; a band (a row of blocks, blocks_x of them, one
 *                 contiguous range) per B sample rows, with one more band where the last
 *                 row starts one (and one more block a band where the last column does), so
 *                 every sample is addressable; samples past the grid are NaN. Made while
 *                 the heights stream (a band is written, with one pwrite, when its lowest
 *                 row arrives); its checksum unit is the band ("blocks" in the index)
 *   tiles.bin     the td_tile records (grid.h), tiles_x*tiles_y of them, as
 *                 td_grid_finish computes them (so opening never scans the heights)
 *   lodK.f32      coarse level K = 1 .. n (n as td_lod_build makes them: halved while both
 *   lodK.tiles    sides exceed 2 samples, at most TD_LOD_MAX): the heights and tile records
 *                 of td_lod_build's level K, bit for bit (lod.c's 1-2-1 filter, the same
 *                 sums in the same order), in the same layout; "levels" in the index has
 *                 each one's shape, statistics, chunk checksums and tile checksum. They are
 *                 made while the heights stream (each level keeps three rows of the finer
 *                 one), so a far ray of quality.lod reads a small file, not the heights
 *   accel.tab    every tile's max-mipmap and parameter planes, of the full grid and of
 *   accel.bin    every level (prepaccel.h): written after the heights, a tile row at a
 *                time on every core, from heights.blk and the levels' files; mapped by
 *                the server (td_prepared_accel, and each level's view in
 *                td_prepared_take_lod) so that a render on a mapped dataset steps as one
 *                in memory does, paging in the structures its rays reach; "accel" in the
 *                index has K, accel.bin's size and accel.tab's checksum
 *   prepare.state only while a prepare is unfinished: how many chunks are written, every
 *                 layer's rows written, checksums and running tile statistics (a re-run
 *                 continues there; the levels' three-row windows and the band of blocks in
 *                 progress are read back from the files)
 *   prepare.lock  held (flock) by the prepare writing the folder: a second one is refused
 *
 * Chunk c holds the file's rows [c*R, c*R + R) (row 0 north, R = chunk_rows), which are
 * one contiguous byte range of heights.f32 (south rows h-c*R-n .. h-1-c*R); a level's
 * chunks are R of its rows alike.
 *
 * Why blocks, and why the row-major copy too (version 3): a row-major page is a strip of
 * 1024 samples of one row, so a cold view's near rays (those the coarse levels do not
 * take, quality.lod) faulted some 35 times the pages a 2D layout needs, and 89% of a cold
 * view's faults were heights.f32's (README "Datasets larger than memory" has the
 * measurements before and after). The render path reads samples through one accessor
 * (td_grid_corner: the row-major address for an in-memory grid, one predicted branch)
 * so that only its few sites changed; the other readers of z (viewsheds, peaks, map
 * tiles, the levels, edits) keep indexing it row-major, from heights.f32, at the price
 * of the heights on disk twice (plus 3% for the blocks' shared edges). Resident heights
 * are what rays touched: measured from the mappings' Rss (td_prepared_resident) and
 * dropped from the process (madvise, td_prepared_trim) when over the budget; the page
 * cache keeps them for the next touch while memory allows. */
#ifndef TD_PREPARED_H
#define TD_PREPARED_H

#include <stdint.h>

#include "dem.h"
#include "lod.h"

/* 2: the coarse levels (lodK.f32, lodK.tiles, "levels" in the index);
 * 3: heights.blk, the heights in blocks (the render path's copy; "blocks" in the index);
 * 4: accel.tab and accel.bin, the tiles' structures ("accel" in the index) */
#define TD_PREPARED_VERSION 4
#define TD_PREPARED_INDEX "terrad.json"
#define TD_PREPARED_HEIGHTS "heights.f32"
#define TD_PREPARED_BLOCKS "heights.blk"
#define TD_PREPARED_BLOCK_LOG2 5 /* B = 32 cells a block side, a block about a 4 KiB page
                                    (README: 32 and 64 measured) */
#define TD_PREPARED_BLOCK_LOG2_MIN 2
#define TD_PREPARED_BLOCK_LOG2_MAX 8
#define TD_PREPARED_TILES "tiles.bin"
#define TD_PREPARED_STATE "prepare.state"
#define TD_PREPARED_LEVEL_FMT "lod%d.f32"
#define TD_PREPARED_LEVEL_TILES_FMT "lod%d.tiles"

/* Called after each chunk: rows of the file done of total, and the samples a row (then,
 * with 0 samples, after each tile row of structures: tile rows done of total); non-zero
 * cancels (the state written so far stays, so a later run continues). */
typedef int (*td_prepare_progress)(void *cls, int64_t rows_done, int64_t rows_total, int32_t w);

#define TD_PREPARE_NO_PLANES (-1)

typedef struct td_prepare_opts {
    td_dem_opts dem;     /* loader options (spacing, encoding...); tile_log2 from here */
    int32_t chunk_rows;  /* 0: the tile size */
    int block_log2;      /* heights.blk's blocks: 2^block_log2 cells a side; 0: TD_PREPARED_BLOCK_LOG2 */
    int planes_k;        /* slices of the tiles' parameter planes; 0: TD_PLANES_K_DEFAULT;
                            TD_PREPARE_NO_PLANES: none (max-mipmaps only) */
    int threads;         /* that build the tiles' structures; 0: one a core */
    /* called with the rows of the heights (width > 0), then with the tile rows of the
       structures done of all (width 0) */
    td_prepare_progress progress;
    void *cls;
} td_prepare_opts;

typedef struct td_prepare_result {
    int32_t w, h;
    int64_t resumed_rows; /* rows already written by an earlier run (0: from the start) */
    int already;          /* the index was there and matches the source: nothing done */
    int streamed;         /* 1: read row by row; 0: the format's loader read it whole */
    int levels;           /* coarse levels written */
    uint64_t bytes;       /* of heights.f32 */
} td_prepare_result;

/* Writes (or continues writing) the prepared form of DEM `src` into directory `dir`
 * (created if missing). .f32 and GDAL rasters (GeoTIFF...) are read a chunk of rows at a
 * time and never held whole; the other formats' loaders (.asc, .hgt, .png) read the whole
 * file, within opts->dem.limits. */
td_status td_prepare(const char *src, const char *dir, const td_prepare_opts *o,
                     td_prepare_result *res, td_err *err);

/* Non-zero when `dir` holds a prepared index; td_prepared_unfinished: a prepare state
 * without an index. */
int td_prepared_is(const char *dir);
int td_prepared_unfinished(const char *dir);

typedef struct td_prepared td_prepared;

/* Reads the index and tiles.bin, checks the heights file's size, maps it read-only. In
 * time and memory independent of the heights (their size is only stat'ed): a truncated
 * heights.f32, an index of another version or shape, a tiles.bin that fails its checksum
 * or whose records do not fit the grid are refused with the file and the reason. */
td_status td_prepared_open(const char *dir, td_prepared **out, td_err *err);
/* The mapped grid: the caller owns it from now on (td_grid_free unmaps it). Once. */
td_grid *td_prepared_take_grid(td_prepared *p);
/* The coarse levels, mapped (td_lod with no built acceleration: view[k].accel points to
 * the level's mapped structures, owned by p, so p must outlive the levels): the caller owns them from now on (td_lod_free
 * unmaps them). Once; NULL when out of memory. */
td_lod *td_prepared_take_lod(td_prepared *p);
int td_prepared_levels(const td_prepared *p);
/* The full grid's per-tile structures, mapped (prepaccel.h), owned by p: valid while p is
 * (the tile store keeps p as long as the dataset). */
const td_tile_accel *td_prepared_accel(const td_prepared *p);
/* The structures' mapping: bytes resident in this process, dropped from it (MADV_DONTNEED),
 * advised as td_prepared_advise does a grid. */
uint64_t td_prepared_accel_resident(const td_prepared *p);
void td_prepared_accel_trim(const td_prepared *p);
void td_prepared_accel_advise(const td_prepared *p, int random);
uint64_t td_prepared_accel_mapped(const td_prepared *p);
/* MADV_WILLNEED on the structures of levels `from` .. the coarsest (prepaccel.h). */
void td_prepared_accel_willneed(const td_prepared *p, int from);
/* A hash of the index's checksums, shape and version (the disk cache's fingerprint). */
uint64_t td_prepared_fingerprint(const td_prepared *p);
/* Chunks of every layer: the heights' first, then level 1's, ..., heights.blk's bands,
 * then the tile rows of the structures (every layer's). */
int32_t td_prepared_chunks(const td_prepared *p);
/* Reads chunk c (of td_prepared_chunks) from its file (not through the mapping, and dropping it from the page
 * cache after) and compares its checksum: TD_EFORMAT naming the file, the chunk, its rows
 * and both checksums when it differs; TD_EIO when it cannot be read. */
td_status td_prepared_verify_chunk(const td_prepared *p, int32_t c, td_err *err);
void td_prepared_free(td_prepared *p);

/* Bytes of a mapped grid's heights resident in this process now (its mapping's Rss in
 * /proc/self/smaps: what the tile store's budget counts); 0 for a grid that is not mapped.
 * td_prepared_cached: bytes of it in the page cache (mincore), whichever process (a
 * replica on the same machine) brought them in. */
uint64_t td_prepared_resident(const td_grid *g);
uint64_t td_prepared_cached(const td_grid *g);
/* How a fault on the mapping reads: random (one page a fault, MADV_RANDOM) or with the
 * kernel's read-around (MADV_NORMAL: read_ahead_kb around the fault, 8 MiB on the
 * development machine). The tile store picks random when the heights exceed its budget
 * (README "Datasets larger than memory" has the measurements). */
void td_prepared_advise(const td_grid *g, int random);
/* Asks the kernel to read a mapped grid into the page cache ahead of its first touch
 * (MADV_WILLNEED; nothing is mapped into the process). */
void td_prepared_willneed(const td_grid *g);
/* The same for the blocks of a prepared full grid's heights.blk within `cells` cells of
 * (x, y) in the dataset frame (the camera, when a render ran out of its page-in time: the
 * retry finds the near field read); nothing for a grid that is not blocked and mapped. */
void td_prepared_willneed_near(const td_grid *g, double x, double y, int32_t cells);
/* Drops this process's pages of a mapped grid (MADV_DONTNEED): the page cache keeps them
 * while memory allows (clean pages the kernel reclaims under pressure), so the next touch
 * is a minor fault, not a read. */
void td_prepared_trim(const td_grid *g);

#endif
