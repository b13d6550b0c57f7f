/* hc.h: the harness of the hard-cases suite (tests/hardcases): degenerate terrains,
 * ray generators, and the judge that holds every method and surface of td_trace to the
 * double-precision references of tests/oracle/reference.h (and, for the triangle
 * surface, reports where Embree itself is wrong).
 *
 * A "scene" is one grid with its acceleration (max-mipmaps and parameter planes of K
 * slices) and, when built with Embree, its triangle scene. hc_run_ray traces one ray by
 * every method over every surface and checks the rules of issue 4:
 *   - no NaN or inf in any output except t = +inf for a miss;
 *   - t in [tmin, tmax]; the hit point o + t*d; a unit normal facing up;
 *   - the hit lies in the cell it names (footprint up to a tiny tolerance), and that
 *     cell exists and is not a hole;
 *   - the answer agrees with the reference: within tolerance of the exact hit, or a tie
 *     inside the exact band (1e-9 of the scene's size), or at worst inside the float32
 *     band of the oracle tests; anything else is a disagreement (a wrong hit, a missed
 *     hit or a hit behind the origin).
 * Every violation is printed with the scene, the surface, the method and the ray as hex
 * doubles, so it can be replayed. */
#ifndef HC_H
#define HC_H

#include <stdint.h>
#include <stdio.h>

#include "accel.h"
#include "reference.h"
#include "trace.h"

#include "embree_ref.h"

/* ---- random numbers (splitmix64: same sequence on every machine) ------------------ */
uint64_t hc_rng_next(uint64_t *s);
double hc_rng_u(uint64_t *s);                       /* [0, 1) */
double hc_rng_range(uint64_t *s, double a, double b);
int32_t hc_rng_int(uint64_t *s, int32_t n);         /* [0, n) */

/* ---- terrains ----------------------------------------------------------------------- */
#define HC_TERRAIN_LIST(X)                                                     \
    X(HC_T_FLAT, "flat")             /* zmin == zmax */                        \
    X(HC_T_PROCEDURAL, "procedural") /* td_terrain fBm with ridges */          \
    X(HC_T_RIDGE, "ridge")           /* sharp ridges on a grid line and a diagonal */ \
    X(HC_T_NEEDLE, "needle")         /* one sample far above flat ground */    \
    X(HC_T_WALL, "wall")             /* relief jump between neighbouring samples */ \
    X(HC_T_PLATEAU, "plateau")       /* flat tops at exactly `plateau` */      \
    X(HC_T_TERRACES, "terraces")     /* heights on the planes' slice heights */ \
    X(HC_T_SADDLES, "saddles")       /* twisted cells: bilinear patches with k != 0 */ \
    X(HC_T_STEPS, "steps")           /* random integer heights, many equal ones */

typedef enum hc_terrain {
#define HC_X_ENUM(e, name) e,
    HC_TERRAIN_LIST(HC_X_ENUM)
#undef HC_X_ENUM
    HC_T_COUNT
} hc_terrain;

#define HC_VOIDS_LIST(X)                                                       \
    X(HC_V_NONE, "none")                                                       \
    X(HC_V_SINGLE, "single")   /* isolated void samples */                     \
    X(HC_V_ROWS, "rows")       /* whole rows and columns of voids */           \
    X(HC_V_TILES, "tiles")     /* whole tiles (their edge samples too) */      \
    X(HC_V_SEAMS, "seams")     /* the samples on tile seams */                 \
    X(HC_V_ALL, "all")         /* every sample */

typedef enum hc_voids {
#define HC_X_ENUM(e, name) e,
    HC_VOIDS_LIST(HC_X_ENUM)
#undef HC_X_ENUM
    HC_V_COUNT
} hc_voids;

typedef struct hc_terrain_params {
    hc_terrain kind;
    int32_t w, h;     /* samples */
    double sx, sy;    /* spacing, metres */
    int tile_log2;
    double base;      /* lowest height */
    double relief;    /* height range (needle/wall: the jump) */
    double plateau;   /* plateau height (HC_T_PLATEAU) */
    int k;            /* slices whose heights HC_T_TERRACES uses */
    hc_voids voids;
    uint64_t seed;
} hc_terrain_params;

const char *hc_terrain_name(hc_terrain t);
const char *hc_voids_name(hc_voids v);
void hc_terrain_defaults(hc_terrain_params *p, hc_terrain kind);
/* Builds a finished grid; NULL (with a message on stderr) on failure. */
td_grid *hc_terrain_make(const hc_terrain_params *p);
/* A grid from explicit heights (south-based rows, NaN = void). */
td_grid *hc_grid_from(int32_t w, int32_t h, double sx, double sy, int tile_log2, const float *z);

/* ---- rays ----------------------------------------------------------------------------- */
#define HC_RAY_LIST(X)                                                         \
    X(HC_R_OBLIQUE, "oblique")         /* camera-like, from above */           \
    X(HC_R_GRAZING, "grazing")         /* 1e-3 .. 1e-9 rad, skimming a point of the surface */ \
    X(HC_R_GRIDLINE, "gridline")       /* x = i*sx or y = j*sy exactly */      \
    X(HC_R_DIAGONAL, "diagonal")       /* along either cell diagonal */        \
    X(HC_R_SAMPLE, "sample")           /* aimed at a sample point */           \
    X(HC_R_SEAM, "seam")               /* along tile seams, through tile corners */ \
    X(HC_R_VERTICAL, "vertical")       /* dx = dy = 0, down and up */          \
    X(HC_R_HORIZONTAL, "horizontal")   /* dz = 0 at a sample's height */       \
    X(HC_R_OUTSIDE, "outside")         /* from outside the box, on its faces, far away */ \
    X(HC_R_ONSURFACE, "on-surface")    /* origin exactly on a sample point */  \
    X(HC_R_BELOW, "below")             /* origin below the surface */          \
    X(HC_R_SCALED, "scaled")           /* unnormalised, huge or denormal components */

typedef enum hc_ray_kind {
#define HC_X_ENUM(e, name) e,
    HC_RAY_LIST(HC_X_ENUM)
#undef HC_X_ENUM
    HC_R_COUNT
} hc_ray_kind;

const char *hc_ray_kind_name(hc_ray_kind k);
void hc_ray_set(td_ray *r, double ox, double oy, double oz, double dx, double dy, double dz);
/* One ray of the given kind over g (valid samples preferred); never NaN. */
void hc_ray_make(const td_grid *g, hc_ray_kind kind, uint64_t *s, td_ray *r);
/* Bilinear height at (x, y) clamped into the grid, zmax over a void. */
double hc_ground(const td_grid *g, double x, double y);

/* ---- scenes and the judge -------------------------------------------------------------- */
typedef struct hc_scene {
    char label[160];
    td_grid *g;
    td_accel *acc;
    td_view view;
    double eps_x, eps_f; /* exact band and float32 band, metres (as in tests/oracle) */
    td_embree *emb;
} hc_scene;

/* Takes ownership of g; builds max-mipmaps and planes with k slices (k <= 0: neither,
 * nor the Embree scene: a judge only). 0 on success. */
int hc_scene_init(hc_scene *sc, const char *label, td_grid *g, int k);
void hc_scene_free(hc_scene *sc);

enum { HC_AGREE, HC_TIE, HC_FLOAT, HC_WRONG, HC_VERDICTS };

typedef struct hc_cell {
    uint64_t rays, hits, v[HC_VERDICTS], rule, vs_incremental, steps;
    double max_dt; /* metres, over agreeing hits */
} hc_cell;

typedef struct hc_stats {
    const char *name;
    hc_cell c[TD_SURFACE_COUNT][TD_METHOD_COUNT];
    uint64_t embree_rays, embree_agree, embree_tie, embree_wrong_miss, embree_wrong_hit;
    uint64_t checks, check_fail; /* the case's own assertions */
    uint64_t scenes, rays;
    unsigned printed;
    int quiet_embree;
} hc_stats;

void hc_stats_init(hc_stats *st, const char *name);

/* Traces r by every method over every surface of sc and judges each answer; the hits
 * are stored in out (may be NULL). Returns the number of failures for this ray. */
int hc_run_ray(hc_stats *st, const hc_scene *sc, const td_ray *r,
               td_hit out[TD_SURFACE_COUNT][TD_METHOD_COUNT]);

/* The verdict of answer t for ray r on surface s of sc (the reference runs on a copy of
 * r whose direction is scaled by a power of two to unit size, so huge and tiny
 * directions are judged exactly). ref_t receives the exact reference t. */
int hc_judge(const hc_scene *sc, td_surface s, const td_ray *r, double t, double *ref_t,
             double *near_t, double *strict_t);

/* The case's own assertion: counts it, prints the message when it fails. */
int hc_check(hc_stats *st, int ok, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* Prints a ray as hex doubles (for replay). */
void hc_print_ray(FILE *f, const td_ray *r);

/* Prints the per-surface, per-method table and the totals; returns the failures
 * (disagreements + rule violations + failed checks). */
uint64_t hc_report(const hc_stats *st);

#endif
