/* accel.h: building the per-tile acceleration structures (max-mipmaps, parameter
 * planes) for a whole grid, in parallel over tiles. Built structures are immutable and
 * shared by threads without locks. A server that keeps tiles individually (refcounted,
 * evictable) calls the per-tile builders of maxmip.h and planes.h directly. */
#ifndef TD_ACCEL_H
#define TD_ACCEL_H

#include "trace.h"

/* Slices of the parameter planes. Chosen by the benchmark's K sweep (trinidad, one
 * thread, docs/accuracy-vs-time.md): K = 8, 16, 32, 64 give 13.4, 10.8, 9.5, 8.7 steps
 * per ray for 0.16, 0.30, 0.58, 1.17 s of build; 16 is the knee, where doubling K
 * doubles the build for a tenth fewer steps. */
#define TD_PLANES_K_DEFAULT 16

typedef struct td_accel_opts {
    int maxmip;   /* build max-mipmaps */
    int planes;   /* build parameter planes */
    int planes_k; /* slices for the planes (>= 1) */
    int threads;  /* <= 0: one per core */
    int minima;   /* the max-mipmaps keep their 4 x 4 blocks' minima (maxmip.h; the sun
                     bound's shadow side reads them): 1 by default */
    int transient; /* the structures live for one command (`terrad viewshed`): their buffer
                      is scratch (td_bigalloc_scratch); 0 by default */
} td_accel_opts;

typedef struct td_accel_stats {
    double maxmip_seconds, planes_seconds; /* wall time of each build */
    uint64_t maxmip_bytes, planes_bytes;   /* resident bytes of each */
    int64_t tiles;
} td_accel_stats;

typedef struct td_accel {
    size_t ntiles;
    td_tile_accel *tiles; /* ntiles entries, owned */
    td_maxmip *mm;        /* the tiles' max-mipmaps when built, one record a tile, owned */
    void *store;          /* all their codes, then all their minima: one buffer (bigalloc.h),
                             where a buffer a tile was 2 MB of fresh pages in 50 pieces on
                             trinidad, 640 page faults and 6 of the build's 12 ms */
} td_accel;

void td_accel_opts_default(td_accel_opts *o);

/* The defaults, with only what method m reads: the max-mipmap for hierarchical and auto
 * (auto takes it wherever it is resident, so planes beside it would never be read; on
 * trinidad they were 0.3 s of a 0.7 s `terrad render`), the planes for parametric,
 * neither for incremental and silhouette. */
void td_accel_opts_for(td_method m, td_accel_opts *o);
td_status td_accel_build(const td_grid *g, const td_accel_opts *o, td_accel **out,
                         td_accel_stats *st, td_err *err);
void td_accel_free(td_accel *a);

/* Cores available to this process (at least 1). */
int td_cpu_count(void);

#endif
