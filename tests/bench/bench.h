/* bench.h: the accuracy-vs-time benchmark behind `terrad bench`: measures every
 * tracer and surface against Embree on the same rays (one thread each), the error of
 * every surface and rendering option against one reference, Paglieroni's and Qu's
 * tables redone, the cost of each effect, camera and shadow rays of camera views against
 * Embree (bench_camera.c), and writes the report (markdown + SVG). */
#ifndef TD_BENCH_H
#define TD_BENCH_H

#include <stdio.h>

#include "status.h"
#include "scene.h"

/* The report's sections, one bit each (--sections). */
#define TD_BENCH_SECTION_LIST(X)                                               \
    X(TD_BENCH_SPEED, "speed")       /* 1: methods x surfaces vs Embree */     \
    X(TD_BENCH_ERROR, "error")       /* 2: error per surface, lod, samples, K */ \
    X(TD_BENCH_PAGLIERONI, "paglieroni") /* 3: Paglieroni's Table 1 */         \
    X(TD_BENCH_QU, "qu")             /* 4: Qu's Table 1 */                     \
    X(TD_BENCH_EFFECTS, "effects")   /* 5: cost of each effect */             \
    X(TD_BENCH_CAMERA, "camera")     /* 7: camera views vs Embree (issue 12) */

typedef enum td_bench_section {
#define TD_X_ENUM(e, name) e,
    TD_BENCH_SECTION_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_BENCH_SECTION_COUNT
} td_bench_section;

const char *td_bench_section_name(td_bench_section s);
td_status td_bench_section_parse(const char *name, td_bench_section *out);

typedef struct td_bench_opts {
    const char *out_dir;   /* report: OUT/accuracy-vs-time.md, OUT/bench-summary.md,
                              OUT/bench/ *.svg */
    char trinidad[TD_SCENE_PATH_MAX], picos[TD_SCENE_PATH_MAX], levi[TD_SCENE_PATH_MAX];
    char scene_dem[TD_SCENE_PATH_MAX]; /* the standard scene's DEM (Blanca Peak crop) */
    int procedural;        /* side of the procedural DEM in samples; 0 = leave it out */
    int runs;              /* timed repetitions per figure (median reported) */
    int quick;             /* tiny images and ray sets: a smoke test, not a measurement */
    unsigned sections;     /* bit (1 << td_bench_section) per section to run */
    const char *write_rays; /* write the speed rays of `rays_dataset` here and stop */
    const char *rays_dataset;
    int verbose;           /* progress on stderr */
} td_bench_opts;

/* Defaults: data paths of the source tree (the full Trinidad DEM of ../shared/data when
 * it exists), procedural 4096, 5 runs, every section, out_dir "docs". */
void td_bench_opts_default(td_bench_opts *o);

/* Runs the benchmark and writes the report (or only the ray file). */
td_status td_bench_run(const td_bench_opts *o, td_err *err);

#endif
