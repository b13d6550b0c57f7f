/* prepaccel.h: the acceleration of a prepared dataset (prepared.h, version 4), written by
 * `terrad prepare` and mapped by `terrad serve --data`: every tile's max-mipmap (maxmip.h)
 * and parameter planes (planes.h) of the full grid and of every coarse level, so that a
 * render on a mapped dataset steps over empty space as an in-memory one does, and reads
 * (faults in) only the pieces of them its rays reach, under the tile store's budget like
 * the heights (issue 16, "loaded on demand").
 *
 * Two files in the prepared folder:
 *   accel.tab  one td_pacc_rec a tile, the layers' tiles one after the other (layer 0 the
 *              full grid, then level 1 .. n), each layer row-major, south first; its
 *              checksum is in the index ("accel": tab_fnv), read whole at open
 *   accel.bin  the tiles' payloads in the same order, each at an 8-byte boundary: the
 *              planes' K + 1 apex heights (float), the max-mipmap's codes (uint16, every
 *              level), the planes' cones (td_cone), zero padding to 8 bytes; each
 *              payload's FNV-1a is in its record, checked a tile row at a time in the
 *              background before the dataset is served (td_pacc_verify_row), with the
 *              values a tracer indexes with (cone apex indices, code scales)
 * The shapes (levels, dims, offsets; blocks of cones) follow from the tile record and the
 * tile size, as td_maxmip_build and td_planes_build make them, so a record holds only what
 * does not: the code scale, the slope scale, the payload's place and checksum.
 *
 * Why written by the prepare and mapped, not built by the server on first touch
 * (README, "Datasets larger than memory", measures both): a tile's structures are built
 * from all its heights, while a ray passing high over a tile touches none of them and
 * one reaching its ground touches a few pages; the tracers give no hook on "first
 * touch" short of a per-step check in the walk, so building on demand means building
 * every tile a view's frustum meets, before the render. Mapped, a cold view reads the
 * pages of codes and cones its rays descend into, at 1.2 bytes a cell beside the
 * heights' 4. */
#ifndef TD_PREPACCEL_H
#define TD_PREPACCEL_H

#include <stdint.h>

#include "trace.h"

#define TD_PACC_TAB "accel.tab"
#define TD_PACC_BIN "accel.bin"

typedef struct td_pacc_rec {
    uint64_t off;       /* of the payload in accel.bin (a multiple of 8) */
    double mm_base, mm_step; /* the max-mipmap's code scale */
    double slope_scale; /* the planes' */
    int32_t k;          /* the planes' slices (the prepare's K; 0: no planes) */
    uint32_t bytes;     /* of the payload, padding included */
    uint64_t sum;       /* FNV-1a of the payload */
} td_pacc_rec;

/* The payload of one tile as the prepare writes it: its record (off left 0) and bytes. */
typedef struct td_pacc_blob {
    td_pacc_rec rec;
    unsigned char *data;
} td_pacc_blob;

/* Builds tile `tile` of g's max-mipmap and K-slice planes (none for K 0: the payload is the
 * codes alone, and the tile's planes pointer NULL when read) into b (b->data malloc'ed). */
td_status td_pacc_build(const td_grid *g, size_t tile, int k, td_pacc_blob *b, td_err *err);

/* Builds the tiles of tile row ty of g on `threads` threads into blobs[0 .. tiles_x). */
td_status td_pacc_build_row(const td_grid *g, int32_t ty, int k, int threads, td_pacc_blob *blobs,
                            td_err *err);

typedef struct td_pacc td_pacc;

/* Maps dir's accel.bin (of `bytes` bytes) and reads accel.tab (checksum `tab_fnv`), whose
 * records must fit the tiles of grids[0 .. nlayers) (their tile records read already) with
 * K = k: TD_EFORMAT naming the file and the tile otherwise. Nothing of accel.bin is read. */
td_status td_pacc_open(const char *dir, const td_grid *const *grids, int nlayers, int k, uint64_t bytes,
                       uint64_t tab_fnv, td_pacc **out, td_err *err);
/* Layer l's per-tile acceleration (tiles_x * tiles_y entries, as its grid's tiles), owned
 * by p. */
const td_tile_accel *td_pacc_tiles(const td_pacc *p, int layer);
/* Tile rows of every layer (the background check's units). */
int32_t td_pacc_rows(const td_pacc *p);
/* Checks tile row r (of td_pacc_rows): reads its payloads from the file (dropping them from
 * the page cache after), compares each with its record's checksum and checks the values a
 * tracer indexes with; TD_EFORMAT naming the file, the layer, the tile and why. */
td_status td_pacc_verify_row(const td_pacc *p, int32_t r, td_err *err);
/* Asks the kernel to read the structures of layers `from` .. last (the coarsest levels are
 * last in accel.bin: one range) into the page cache ahead of their first touch
 * (MADV_WILLNEED); returns their bytes. */
uint64_t td_pacc_willneed(const td_pacc *p, int from);
/* accel.bin's mapping (for residency, trimming and advice alike to the heights'). */
void td_pacc_mapping(const td_pacc *p, void **base, size_t *len);
void td_pacc_free(td_pacc *p);

#endif
