/* render.c: orchestration of a render: camera rays -> tracer -> the effects the scene
 * asks for -> pixels (see render.h for the stages and the contract).
 *
 * Parallelism: the image is cut into blocks 16 pixels wide and 16 tall (64 or 32 for an
 * upright camera: block_height); every thread (the caller
 * plus threads-1 pthreads) claims the next block with one atomic increment and runs the
 * whole pipeline on it in its own scratch, then writes the block's pixels, which no
 * other thread touches. No lock anywhere; counters (a td_render_stats) and stage times
 * live in the worker's own struct (padded to a cache line) and are added up after the
 * join by td_render_stats_add. Blocks rather than rows: a block's samples share tiles
 * and cache lines for every pass, and blocks balance the load between sky (cheap) and
 * terrain (dear) well.
 *
 * The pipeline is a table (after libuv's uv_run): one row a stage, built from
 * TD_BLOCK_STAGE_LIST, each with its function stage_<name>(worker, block) and its
 * predicate on_<name>(ctx). The predicates are asked once per render (ctx.on); a block
 * runs the enabled stages in order, each timed on its own, so an absent effect's loop is
 * never entered and its scratch never allocated.
 *
 * Per-thread scratch, allocated once per render (n = samples per axis):
 *   smp[16*16*n*n]              ray, hit, colour of each sample      always
 *   scratch[stage][16*16*n*n*k] k floats a sample, from the stage's row in the list:
 *                               shadows: direct sunlight 0/1; ao: unoccluded fraction;
 *                               water: reflected colour + Fresnel weight
 *
 * Earth curvature and refraction: a point at horizontal distance h from the camera
 * appears lower by a*h^2 with a = (1 - k) / 2R. Lowering the terrain by a*h^2 is the
 * same as bending the camera ray up by a*h^2, so the ray becomes the parabola
 * p(t) = o + t*d + (0, 0, a*(t*|d_xy|)^2), which the tracer (straight rays only) sees
 * as a chain of chords. A chord over a horizontal run D departs from the parabola by at
 * most a*D^2/4; the run is chosen so that this stays under a quarter of the pixel's
 * footprint at that distance (and at least 0.5 m), so the chain is never off by more
 * than a quarter pixel, and there are only a few chords per ray (about 2 per 50 km for
 * a 640-pixel 60-degree view). The chords lie above the parabola, so a grazing hit can
 * only be missed by that bound. Rays whose run over the grid is shorter than
 * s = 2*pixel_angle/a, where the drop reaches one pixel's footprint, are traced
 * straight; if no ray of the view can reach s, the curvature stage does not run at
 * all. An orthographic top-down view never bends: lowering the terrain under vertical
 * rays moves no pixel. The chords also lie above the straight ray with the same origin
 * and direction, so a bent ray meets nothing before that ray does: its chords start where
 * the straight ray's hit is (a panorama's or level camera's columns walk it with the
 * others) or where the block wedge's horizon clears it, and a straight miss is a miss.
 *
 * Shadow and reflection rays bend the same way about their own origin W: the terrain at
 * horizontal distance h' from W lies a*h'^2 below W's horizon, so the ray toward the sun
 * (the scene's sun is given in the local frame everywhere) is the parabola from W. A
 * reflected ray leaves the water with the bent camera ray's slope there, mirrored, and
 * bends about the water point. They are bent when their run over the grid is long
 * enough for the drop to reach TD_CURVE_EPS2 (0.5 m, about 2.7 km at k = 0.13), with
 * chords of the same 0.5 m tolerance; shorter ones are straight. This holds for every
 * projection: the sun's rays over an orthographic view bend too. AO rays stay straight
 * (their radius is local).
 *
 * Level of detail (quality.lod, Cohen-Or et al.; Qu et al.): the caller passes the
 * coarse levels of lod.h. A perspective camera ray is traced on level 0 up to the
 * distance d_1 where one pixel's footprint covers lod_pixels^-1 * 2 base cells, then on
 * level 1 up to d_2 (4 cells), and so on: d_l = 2^l * cell / (lod_pixels * pixel_angle),
 * cell = min(sx, sy). An orthographic view traces every ray on the one level whose cells
 * fit its pixel footprint. Shadow, AO and reflection rays of a sample use the level its
 * camera ray hit, so they start on the surface they were shaded with. The stats count
 * camera rays by the level they ended on; the error against lod off is measured by the
 * benchmark (PSNR, hit distance) and bounded in test_render. Curved rays and picks use
 * the full grid.
 *
 * Render and pick trace a camera ray with the same function (trace_camera: bent or
 * straight, over the levels of detail where the render has them, its hit and height
 * error counted in the stats), so a pick answers what the render drew (a level camera's
 * render, by image columns, to the rounding of the hits' parameter: colwalk.h).
 *
 * Coherence devices (issue 12; each can be turned off by td_render_opts.off, and none
 * changes a pixel: the tests compare on and off bit for bit; the column walk's hits are
 * the plain walk's to the rounding of their parameter, and test_colwalk judges every pixel
 * where a depth differs):
 *   horizon    straight camera rays of a perspective view on the full grid start where the
 *              conservative horizon of their wedge says nothing precedes their hit
 *              (horizon.h). A block's samples are cut into TD_SLICES column (or row)
 *              slices across the image direction of the verticals, each a wedge of
 *              azimuths bounded from its corners (td_camera_azimuths), its rays taken in
 *              rising elevation so each reuses the bins below it; where the verticals
 *              lean in the image (a rolled camera), into TD_BANDS bands along them
 *              (trace_band: picos's rolled bench view 362.6 -> 312.1 M instructions,
 *              10.7 -> 8.5 steps a camera ray); after a block whose rays walked far,
 *              into TD_BANDS_FAR bands or TD_SLICES_FAR slices; td_trace_from starts
 *              the ray at the boundary of the cell its bound falls in, so its hit is
 *              td_trace's. Rays above every bin are misses without a walk.
 *   beam       the slices the horizon cannot bound (their azimuths span a quarter turn or
 *              more: near the vanishing point of the verticals, looking down) whose rays
 *              all descend start where the beam of the slice's corner rays can first
 *              reach the terrain (beam.h: a few max-mipmap boxes a slice); so do the
 *              slices the horizon bounds whose rays are all steeper than 45 degrees,
 *              from the later of the two starts. Measured (bench camera views, steps per
 *              camera ray on the plane surface): straight down 4.63 -> 2.57 on trinidad,
 *              3.25 -> 1.70 on levi, 2.77 unchanged on picos; instructions of the primary
 *              stage (callgrind, trinidad views, triangle): straight down -4.8%, level,
 *              grazing and rolled +0.7-0.8% (the corner rays of every slice).
 *   columns    an upright, level camera (pitch 0, roll 0: each image column one vertical
 *              plane through the eye) with the method auto traces a block's sample columns
 *              one walk each (colwalk.h: the column's rays from the bottom up, each from the
 *              cell where the ray below hit; the column's lowest ray from its block's
 *              horizon), where the eye is above the surface around it. The same depths and
 *              pictures as the fans on trinidad's level view, every surface; primary stage
 *              (callgrind, triangle) 120.0 -> 91.2 M instructions, 23.5 -> 15.6 ms (medians
 *              of 11 interleaved runs). A panorama's columns too (each one azimuth at any
 *              pitch; the rays that bend under curvature left to the curvature stage),
 *              its rays made a sample row at a time (td_camera_cyl_dirs: a sine and cosine
 *              a column, not a sample): the gallery panorama without curvature, primary
 *              stage 808 -> 112 ms (README, "Coherent camera and shadow rays"), the same
 *              picture.
 *   occlusion  shadow and AO rays are any-hit queries (td_occluded): no hit point or
 *              normal, the max-mipmap climbed from 2 x 2 blocks; a block's straight
 *              shadow rays in packets of four that walk their first cells together
 *              (td_occluded_par). A shadow ray that bends under curvature is asked
 *              straight in the same packets first: its chords lie above the straight
 *              ray, so a clear straight ray is a lit bent one; the others' chords are
 *              any-hit queries too, with the sun bound (occluded_curved). The gallery
 *              panorama (trinidad, 1800 x 300, 2 x 2 samples, one thread): the shadows
 *              stage 512 -> 71 ms, 1,069,327 bent rays traced -> 707, the same picture.
 *   sunlit     one sweep against the sun per render bounds, per 4 x 4 cells (coarser on
 *              grids of more than 2^24 cells), the height above which a point is surely
 *              lit (sunlit.h); a shadow ray ends there. The server keeps the bound with
 *              the dataset for the next renders of the same heights and sun
 *              (td_render_opts.sunlit, td_snapshot_sunlit): no sweep then (trinidad's
 *              bench views: 5.7 / 12.0 / 6.0 / 5.7 M instructions of shadows stages of
 *              51 / 100 / 63 / 147 M, callgrind).
 * Method silhouette (issue 13) replaces the horizon and the beam for the camera rays: one
 * partition of the view per render from the heights alone (silhouette.h, built with the
 * render's threads before the blocks, timed in the primary stage), each ray started where
 * its wedge's running silhouette allows, again through td_trace_from; `auto` does the same
 * where most tiles lack a max-mipmap (a cold dataset), since the horizon's bins there fall
 * back to tiles' zmax (auto_silhouette). Its secondary rays are the plain walk's.
 * Measured (docs/accuracy-vs-time.md, camera views): steps per camera ray fall from 9-25
 * to 1.1-8 and camera rays get up to 2x and shadow rays up to 1.6x faster (with the
 * batches below: 0.32-0.56x and 0.28-1.00x Embree's packets of 16 on the same rays). A
 * camera ray that hits still costs about 1,550 instructions, a known miss about 380: per-ray
 * cost, not steps (see the batches). Tried and dropped:
 * slices cut by each sample's azimuth with an exact sort by elevation (fewer steps on
 * rolled views, 2-7% slower overall); 8 or 16 slices (narrower wedges, more bins: 10-35%
 * more instructions). Once the batches below had cut the rays' own cost, the bins' share
 * grew and 2 slices a block beat 4 (primary-stage instructions on the bench views of
 * trinidad -3 to -7%, picos -2 to -3% and +1.8% rolled; time -2 to -6% on trinidad's); 1
 * slice is no better than 2.
 *
 * Batches (issue 12): what rays share is set up once. A block's camera rays come a sample
 * row at a time (td_camera_dirs, vectorised), the straight ones on the full grid are
 * traced as fans from the camera (td_trace_fan: grid and origin set up once, the rays
 * and their hits as arrays that the packets load and store a vector at a time: primary
 * stage 144.3 -> 127.0 M instructions, 14.20 -> 12.69 ms on trinidad's level view, 22.91
 * -> 21.01 rolled, 27.40 -> 24.39 straight down, median of 9), and its straight shadow
 * rays on the full grid as parallel rays along the sun (td_occluded_par: grid and
 * direction set up once). Each
 * gives the bits the ray-by-ray calls give (same pictures and stats). Measured with
 * callgrind on trinidad's level bench view (triangle), the batches alone: primary stage
 * 325.7 -> 292.1 M instructions, shadows 164.4 -> 139.5 M; with 2 slices, known misses kept
 * at once and shadow rays from 2 x 2 blocks (trace.c): 264.8 M and 131.0 M. The cycles fell
 * further than the instructions (perf: two stalls gone, a store-forwarding one in the walk's
 * setup and the square root and divisions of each hit's normal): `make bench`, camera rays
 * 1.23-1.37x and shadow rays 1.15-1.35x the rates before. Tried and dropped: a fan in three
 * passes (starts, walks, normals) to overlap the divisions (no faster). */
#include "render.h"
#include "clock.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bigalloc.h"
#include "effects.h"
#include "beam.h"
#include "colwalk.h"
#include "horizon.h"
#include "silhouette.h"
#include "sunlit.h"
#include "limit.h"
#include "lod.h"
#include "shade.h"
#include "simd.h"

#define TD_BLOCK 16
/* Blocks are TD_BLOCK wide and bh tall: TD_BLOCK_TALL where the camera stands upright
 * enough that a slice that tall stays nearly one vertical plane (block_height). */
#define TD_BLOCK_TALL 64
#define TD_SLICE_CORNERS 6 /* a slice's polygon: a rectangle, or one cut by two lines */
/* Blocks whose verticals lean more than TD_BAND_LEAN (its sine) off the image's axes, and
 * whose middle ray is not steep, are cut into TD_BANDS bands along the verticals
 * (trace_band). Measured (callgrind, primary stage, triangle, M instructions; roll 35 is
 * the bench's rolled view): trinidad roll 10 / 20 / 35: 160.2 / 168.2 / 186.1 ->
 * 161.7 / 166.7 / 173.6; picos 288.0 / 322.9 / 362.6 -> 284.0 / 300.2 / 312.1; levi
 * roll 35 203.8 -> 175.5. A lean of 0.1 or 0.3 was worse on one DEM or the other; 3 or
 * 4 bands a block helped picos's rolled view (289, 279) and cost trinidad's and levi's
 * (190, 184; 200, 194); slices that the beam bounds (steep rays, looking down) gain
 * nothing from narrower wedges and cost their polygons' corner rays (+4% on the
 * straight-down views), so steep blocks keep their columns. */
#define TD_BAND_LEAN 0.2
#define TD_BANDS 2
/* TD_BANDS_FAR bands (5.5 pixels at roll 35) after a block whose camera rays took
 * more than TD_BAND_FAR steps each (a worker's last: rough terrain where rays that graze
 * ridges walk far): picos's rolled view 312.4 -> 276.0 M instructions, 31.4 -> 28.2 ms;
 * trinidad's 173.9 -> 175.0 M, 17.5 -> 17.8 ms, levi's 175.5 -> 175.0 M. Thresholds of 3,
 * 5 and 8 steps cost trinidad and levi 1-3%, 20 gained picos less (283.8 M). */
#define TD_BANDS_FAR 4
#define TD_BAND_FAR 12.0
#define TD_BAND_STEP (2.0 * TD_DEG) /* the bands follow the verticals to this angle */
#define TD_BAND_SAMPLES (TD_BLOCK * TD_BLOCK * TD_SAMPLES_MAX * TD_SAMPLES_MAX) /* a block's, at most */
#define TD_BAND_BUCKETS (2 * TD_BLOCK * TD_SAMPLES_MAX) /* buckets along the verticals, at most */
/* Upright blocks (their columns as slices) take TD_SLICES_FAR after a block whose rays
 * took more than TD_BAND_FAR steps each, as leaning ones take TD_BANDS_FAR bands; steep
 * blocks (their slices the beam's) keep TD_SLICES. Primary stage (callgrind, triangle):
 * picos level 128.0 -> 125.5 M instructions, grazing 184.8 -> 183.6; trinidad's and the
 * straight-down views within 0.05%; 8 slices: picos level 126.7, grazing 185.7. */
#define TD_SLICES_FAR 4
#define TD_SLICES 2 /* wedges a block's camera rays are cut into for the horizon device */
#define TD_SAMPLES_MAX 8 /* quality.samples at most (limit.h's core column, check_scene) */
#define TD_DEG (M_PI / 180.0)

static const char *const td_ray_kind_names[] = {
#define TD_X_NAME(e, name) name,
    TD_RAY_KIND_LIST(TD_X_NAME)
#undef TD_X_NAME
};

static const char *const td_stage_names[] = {
#define TD_X_NAME(e, name, scratch) #name,
    TD_STAGE_LIST(TD_X_NAME)
#undef TD_X_NAME
};

static const char *const td_sun_bound_names[] = {
#define TD_X_NAME(e, name) name,
    TD_SUN_BOUND_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_sun_bound_name(td_sun_bound b)
{
    return (unsigned)b < TD_SUN_BOUND_COUNT ? td_sun_bound_names[b] : "unknown";
}

const char *td_ray_kind_name(td_ray_kind k)
{
    return (unsigned)k < TD_RAY_KIND_COUNT ? td_ray_kind_names[k] : "unknown";
}

const char *td_stage_name(td_stage s)
{
    return (unsigned)s < TD_STAGE_COUNT ? td_stage_names[s] : "unknown";
}

void td_render_opts_default(td_render_opts *o)
{
    memset(o, 0, sizeof *o);
}

void td_render_stats_add(td_render_stats *sum, const td_render_stats *part)
{
    for (int k = 0; k < TD_RAY_KIND_COUNT; k++)
        sum->rays[k] += part->rays[k];
    sum->steps += part->steps;
    for (int k = 0; k < TD_RAY_KIND_COUNT; k++)
        sum->kind_steps[k] += part->kind_steps[k];
    sum->coherent_rays += part->coherent_rays;
    sum->horizon_bins += part->horizon_bins;
    sum->silhouette_rays += part->silhouette_rays;
    sum->column_rays += part->column_rays;
    sum->silhouette_entries += part->silhouette_entries;
    sum->hits += part->hits;
    sum->curved_rays += part->curved_rays;
    sum->curved_secondary += part->curved_secondary;
    sum->curve_segments += part->curve_segments;
    for (int k = 0; k < TD_METHOD_COUNT; k++)
        sum->method_rays[k] += part->method_rays[k];
    for (int k = 0; k <= TD_LOD_MAX; k++)
        sum->lod_rays[k] += part->lod_rays[k];
    sum->height_err_sum_m += part->height_err_sum_m;
    sum->height_err_max_m = part->height_err_max_m > sum->height_err_max_m ? part->height_err_max_m
                                                                           : sum->height_err_max_m;
    sum->height_err_hits += part->height_err_hits;
    sum->height_err_mean_m =
        sum->height_err_hits ? sum->height_err_sum_m / (double)sum->height_err_hits : 0.0;
    for (int k = 0; k < TD_STAGE_COUNT; k++) {
        sum->stage_ms[k] += part->stage_ms[k];
        sum->stage_ran[k] |= part->stage_ran[k];
    }
}

/* F_CLEAR: a bent ray (F_CURVE) whose t holds, until the curvature stage reads it, the
   ray parameter before which it surely meets nothing (its straight ray's hit, trace_columns) */
enum { F_HIT = 1, F_WATER = 2, F_CURVE = 4, F_CLEAR = 8 };

typedef struct smp {
    double o[3], d[3]; /* camera ray, unit direction */
    double t;          /* distance to the terrain, +inf */
    double tw;         /* distance to the water surface, +inf */
    double p[3];       /* terrain hit */
    float n[3];        /* surface normal at the hit */
    float rgb[3], alpha;
    int32_t ci, cj;
    uint32_t flags;
    int level; /* level of detail its camera ray ended on */
} smp;

typedef struct ctx ctx;

/* A leaning block's samples in trace_band's order, for the lean (in steps of
 * TD_BAND_STEP), block size and samples per axis it was sorted for: the next block of the
 * same shape and lean takes it as it is. */
typedef struct band_sort {
    int32_t lean, bw, bh, n;          /* n 0: nothing sorted yet */
    int32_t nbands;
    double sext;                      /* half the block's width across the verticals */
    int end[TD_BANDS_FAR];            /* where each band's samples end in order */
    int16_t *order;                   /* the block's sample indices, band by band */
} band_sort;

typedef struct worker {
    ctx *c;
    pthread_t th;
    smp *s;
    td_horizon hz;                  /* the primary stage's wedge (horizon device) */
    band_sort bs;                   /* the last leaning block's order (trace_band) */
    int band_far;                   /* the last block's camera rays took more than TD_BAND_FAR steps */
    float *scratch[TD_STAGE_COUNT]; /* per sample, for the stages whose row asks for it */
    td_render_stats st;             /* this thread's counts (stage_ms left 0: stage_s) */
    double stage_s[TD_STAGE_COUNT];
    int cancelled;
    char pad[64];
} worker;

struct ctx {
    const td_view *v;
    const td_view *views[TD_LOD_MAX + 1]; /* [0] = v, then the coarse levels */
    int nlod;                            /* coarse levels in use */
    double lod_dist[TD_LOD_MAX + 2];     /* level l is traced from lod_dist[l] on */
    int ortho_level;                     /* orthographic view: the one level used */
    const td_lod *lod_iso;               /* quality.lod_grid isometric: levels 1.. traced on its twins */
    const td_scene *s;
    td_camera cam;
    int n;           /* samples per axis */
    int32_t bx, by;  /* blocks across and down */
    int32_t bh;      /* a block's height in pixels (block_height) */
    int nblocks;
    atomic_int next;
    const atomic_int *cancel;
    int depth_only;
    int horizon;     /* camera rays start from their wedge's horizon (see horizon.h) */
    int beam;        /* or, where it gives none, from their slice's beam (see beam.h) */
    int columns;     /* an upright, level camera or a panorama: its sample columns walked as
                        one (colwalk.h) */
    int col_horizon; /* their lowest rays started from the block wedge's horizon */
    td_colwalk cw;   /* their eye's set-up */
    int plain_secondary; /* shadow and AO rays traced for their nearest hit (OFF_OCCLUSION) */
    td_ray *shadow_rays; /* the caller's copy of the shadow rays, or NULL */
    const td_sunlit *sunlit; /* heights surely in the sun (shadow rays end there), or NULL */
    td_sunlit *sunlit_own;   /* that bound when this render built it (freed with the render) */
    td_sun_bound sun_bound;  /* where c->sunlit came from */
    td_silhouette *silh; /* the camera rays' silhouette partition (method silhouette), or NULL */
    double silh_ms;      /* its build */
    double sunlit_ms;    /* its build */
    int on[TD_STAGE_COUNT]; /* the stages this render runs (their on_<name>) */
    double sun[3];
    td_sky sky; /* the sky's terms of the sun alone (td_sky_shade) */
    double eps;      /* origin offset along the normal for secondary rays */
    double zlo, zspan;
    const td_image8 *drape;
    double beta0, zref; /* haze */
    int curv;        /* camera rays may need bending */
    int curv2;       /* shadow and reflection rays may need bending */
    double curv_a, curv_smin, curv_smin2;
    double gx1, gy1; /* grid extent */
    double zmax;
    double ao_radius;
    uint8_t *rgba;
    float *depth;
};

/* The block a stage works on: pixels [x0, x1) x [y0, y1), bw wide, ns samples. */
typedef struct blk {
    int32_t x0, y0, x1, y1, bw;
    int ns;
} blk;

static inline double dmin_(double a, double b) { return a < b ? a : b; }
static inline double dmax_(double a, double b) { return a > b ? a : b; }

/* Enter/exit of the ray's xy line over the grid rectangle; 0 if it never crosses it. */
static int clip_xy(const ctx *c, const double o[3], const double d[3], double *t0, double *t1)
{
    double lo = 0.0, hi = INFINITY;
    double ext[2] = {c->gx1, c->gy1};
    int ok = 1;
    for (int k = 0; k < 2 && ok; k++) {
        if (fabs(d[k]) < 1e-300) {
            if (o[k] < 0.0 || o[k] > ext[k])
                ok = 0;
        } else {
            double ta = (0.0 - o[k]) / d[k], tb = (ext[k] - o[k]) / d[k];
            if (ta > tb) {
                double tmp = ta;
                ta = tb;
                tb = tmp;
            }
            lo = dmax_(lo, ta); /* lo and hi are never NaN: fmax's and fmin's answers */
            hi = dmin_(hi, tb);
        }
    }
    if (ok && !(lo <= hi))
        ok = 0;
    *t0 = lo;
    *t1 = hi;
    return ok;
}

/* Does this ray need bending: is its horizontal run from o to where it leaves the grid
 * at least smin (see the top of the file)? */
static int needs_curve(const ctx *c, const double o[3], const double d[3], double smin)
{
    int need = 0;
    double t0, t1;
    if (clip_xy(c, o, d, &t0, &t1)) {
        /* the squares decide unless the run is within 1e-9 of smin: hypot's answer, without
           its call (a panorama asks for every sample) */
        const double q = d[0] * d[0] + d[1] * d[1], r2 = t1 * t1 * q, s2 = smin * smin;
        const int sure = t1 < 1e150 && q > 1e-200 && s2 < 1e300 && fabs(r2 - s2) > 1e-9 * s2;
        if (sure) {
            need = r2 > s2;
        } else {
            double dxy = hypot(d[0], d[1]);
            need = dxy > 0.0 && t1 * dxy >= smin;
        }
    }
    return need;
}

/* The drop a secondary ray must reach to be bent, and its chords' tolerance (metres). */
#define TD_CURVE_EPS2 0.5

/* The method a camera ray known to miss (or, bent, known clear up to each chord) is
 * counted under without a walk: the one asked for, `auto` as its walk (incremental). */
static td_method untraced_method(const ctx *c)
{
    return c->s->quality.method == TD_METHOD_AUTO ? TD_METHOD_INCREMENTAL : c->s->quality.method;
}

/* The chords of a ray bent about its origin, p(t) = o + t*d + (0, 0, a*(t*|d_xy|)^2), over
 * its run across the grid (see the top of the file), each within max(0.5 m, eps_per_t * t)
 * of the parabola: chords_begin, then chords_next for each in turn. The chain ends at the
 * run's end, or once a chord ends above every height with the parabola climbing (it only
 * climbs faster). The chords lie above the parabola, which lies above the straight ray:
 * each has the straight ray's horizontal direction and at least its slope. */
typedef struct chords {
    double a, dxy, eps_per_t;
    double tc, t1, pc[3]; /* the next chord's start: its ray parameter and point */
    int more, started;
} chords;

/* The parabola's point at ray parameter t. */
static void chord_point(const chords *ch, const td_ray *r, double t, double p[3])
{
    for (int k = 0; k < 3; k++)
        p[k] = r->o[k] + t * r->d[k];
    p[2] += ch->a * (t * ch->dxy) * (t * ch->dxy);
}

static void chords_begin(const ctx *c, const td_ray *r, double eps_per_t, chords *ch)
{
    double t0 = 0.0, t1 = 0.0;
    ch->a = c->curv_a;
    ch->dxy = hypot(r->d[0], r->d[1]);
    ch->eps_per_t = eps_per_t;
    ch->more = clip_xy(c, r->o, r->d, &t0, &t1) && ch->dxy > 0.0;
    ch->started = 0;
    ch->tc = t0;
    ch->t1 = t1;
    if (ch->more)
        chord_point(ch, r, t0, ch->pc);
}

/* The next chord as a segment (seg: from its start to its end for t in [0, 1]) and the
 * bent ray's parameters at its ends, *ta and *tb; 0 when the chain has ended. */
static int chords_next(const ctx *c, chords *ch, const td_ray *r, td_ray *seg, double *ta, double *tb)
{
    /* above every height and climbing after the chord before: the parabola only climbs faster */
    if (ch->started && ch->pc[2] > c->zmax && r->d[2] + 2.0 * ch->a * ch->dxy * ch->dxy * ch->tc > 0.0)
        ch->more = 0;
    ch->more = ch->more && ch->tc < ch->t1;
    if (ch->more) {
        double eps = fmax(TD_CURVE_EPS2, ch->eps_per_t * ch->tc);
        double run = sqrt(4.0 * eps / ch->a); /* horizontal */
        double tn = fmin(ch->t1, ch->tc + run / ch->dxy);
        double pn[3];
        chord_point(ch, r, tn, pn);
        for (int k = 0; k < 3; k++) {
            seg->o[k] = ch->pc[k];
            seg->d[k] = pn[k] - ch->pc[k];
        }
        seg->tmin = 0.0;
        seg->tmax = 1.0;
        *ta = ch->tc;
        *tb = tn;
        ch->tc = tn;
        memcpy(ch->pc, pn, sizeof pn);
        ch->started = 1;
    }
    return ch->more;
}

/* A bent ray's nearest hit on view v, its chords traced in turn, from the ray parameter
 * t_clear on (0, or where the straight ray with its origin and direction meets nothing
 * before, horizon.h: the chords lie above that ray, so they meet nothing before either;
 * +inf: a miss): the chords that end before it are not traced, the one it falls in from
 * there. On a hit, hit->t is the distance along the unbent ray's parameter, hit->p the
 * terrain point. */
static void trace_curved(const ctx *c, const td_view *v, const td_ray *r, double eps_per_t, double t_clear,
                         td_hit *hit, uint64_t *steps, uint64_t *segs)
{
    const td_scene *s = c->s;
    chords ch;
    td_ray seg;
    double ta, tb;
    hit->t = INFINITY;
    hit->steps = 0;
    hit->method = untraced_method(c); /* a traced chord's walk says which */
    chords_begin(c, r, eps_per_t, &ch);
    while (hit->t == INFINITY && chords_next(c, &ch, r, &seg, &ta, &tb)) {
        if (tb <= t_clear)
            continue;
        seg.tmin = t_clear > ta ? (t_clear - ta) / (tb - ta) : 0.0; /* the chord is linear in t */
        td_trace(v, s->quality.method, s->quality.surface, &seg, hit);
        *steps += hit->steps;
        *segs += 1;
        hit->t = hit->t <= 1.0 ? ta + hit->t * (tb - ta) : INFINITY;
    }
}

/* Whether a bent shadow ray meets the terrain: its chords as any-hit queries
 * (td_occluded), each with the sun bound, which holds for them as for the straight ray.
 * A chord from a point P has the sun's horizontal direction and at least its slope, so
 * at horizontal distance d from P it is at least P_z + d tan (the sun's slope) high, and
 * so are the chords after it (the chain is convex); above the bound of P's block (sunlit.h)
 * that clears the terrain: a chord's query ends there (lit_end), and a chord starting
 * there ends the chain (td_sunlit_clear). Any crossing ends it too: the nearest is not
 * needed.
 * The answer is trace_curved's (fuzz_render holds the render's pixels to it). */
static int occluded_curved(const ctx *c, const td_view *v, const td_ray *r, const td_sunlit *lit,
                           uint64_t *steps, uint64_t *segs)
{
    chords ch;
    td_ray seg;
    double ta, tb;
    int hit = 0, clear = 0;
    chords_begin(c, r, 0.0, &ch);
    while (!hit && !clear && chords_next(c, &ch, r, &seg, &ta, &tb)) {
        uint32_t st = 0;
        clear = td_sunlit_clear(v->grid, lit, seg.o); /* the chain lit from the chord's start on */
        hit = !clear && td_occluded(v, c->s->quality.method, c->s->quality.surface, &seg, lit, &st);
        *steps += st;
        *segs += 1;
    }
    return hit;
}

/* Distance to the water plane along the (possibly bent) camera ray, inside the grid;
 * +inf if none. */
static double water_distance(const ctx *c, const smp *sm)
{
    double L = c->s->effects.water_level, tw = INFINITY;
    double oz = sm->o[2] - L, dz = sm->d[2];
    if (oz > 0.0) {
        if (sm->flags & F_CURVE) {
            /* a*dxy^2 t^2 + dz t + oz = 0, smallest positive root */
            double A = c->curv_a * (sm->d[0] * sm->d[0] + sm->d[1] * sm->d[1]);
            double disc = dz * dz - 4.0 * A * oz;
            if (dz < 0.0 && disc >= 0.0)
                tw = (2.0 * oz) / (-dz + sqrt(disc));
        } else if (dz < 0.0) {
            tw = oz / -dz;
        }
        if (isfinite(tw)) {
            double x = sm->o[0] + tw * sm->d[0], y = sm->o[1] + tw * sm->d[1];
            if (x < 0.0 || y < 0.0 || x > c->gx1 || y > c->gy1)
                tw = INFINITY;
        }
    }
    return tw;
}

static void albedo_of(const ctx *c, const double p[3], float rgb[3])
{
    if (c->drape)
        td_shade_drape(c->drape, c->v->grid, p[0], p[1], rgb);
    else
        td_shade_hypsometric((p[2] - c->zlo) / c->zspan, rgb);
}

/* The shading normal of a hit at p in cell (ci, cj) of level `level` whose surface
 * normal is hn: hn, or the smoothed normal there. */
static void normal_of(const ctx *c, const double p[3], const float hn[3], int32_t ci, int32_t cj, int level,
                      float n[3])
{
    if (c->s->quality.smooth_normals)
        td_shade_smooth_normal(c->views[level]->grid, ci, cj, p[0], p[1], n);
    else
        memcpy(n, hn, 3 * sizeof *n);
}

static void shade_plain(const ctx *c, const td_hit *h, int level, float rgb[3])
{
    float alb[3], n[3];
    albedo_of(c, h->p, alb);
    normal_of(c, h->p, h->n, h->ci, h->cj, level, n);
    td_shade_light(alb, n, c->sun, c->s->effects.ambient, 1.0, 1.0, rgb);
}

static void offset_origin(const ctx *c, const double p[3], const float n[3], double o[3])
{
    /* each coordinate computed before any is stored: o may alias nothing it reads, but the
       compiler cannot know (a loop reloaded eps and p after every store) */
    const double e = c->eps, x = p[0] + e * (double)n[0], y = p[1] + e * (double)n[1];
    const double z = p[2] + e * (double)n[2];
    o[0] = x;
    o[1] = y;
    o[2] = z;
}

/* A camera ray over the levels of detail (see the top of the file); *level is the level
 * it ended on. Without levels this is one td_trace on the full grid. */
static void trace_lod(const ctx *c, const td_ray *r, double t_clear, td_hit *hit, int *level,
                      uint64_t *steps)
{
    const td_scene *s = c->s;
    int l = c->ortho_level;
    uint64_t n = 0;
    if (c->nlod == 0 || c->cam.projection == TD_PROJ_ORTHOGRAPHIC) {
        if (l > 0 && c->lod_iso)
            td_lod_iso_trace(c->lod_iso, l, r, hit);
        else
            td_trace_from(c->views[l], s->quality.method, s->quality.surface, r, t_clear, hit);
        n = hit->steps;
    } else {
        td_ray seg = *r;
        for (l = 0; l <= c->nlod; l++) {
            seg.tmin = l == 0 ? r->tmin : dmax_(r->tmin, c->lod_dist[l]);
            seg.tmax = l == c->nlod ? r->tmax : dmin_(r->tmax, c->lod_dist[l + 1]);
            if (seg.tmin > seg.tmax)
                continue;
            if (l > 0 && c->lod_iso)
                td_lod_iso_trace(c->lod_iso, l, &seg, hit);
            else
                td_trace(c->views[l], s->quality.method, s->quality.surface, &seg, hit);
            n += hit->steps;
            if (hit->t < INFINITY)
                break;
        }
        if (l > c->nlod)
            l = c->nlod;
    }
    hit->steps = (uint32_t)(n > UINT32_MAX ? UINT32_MAX : n);
    *steps += n;
    *level = l;
}

/* The height errors' sum (in the order the hits come), maximum and count: taken from the
 * stats and put back by the loops that store samples between hits (the compiler cannot
 * keep the stats' fields in registers across those stores: trinidad's level view spent a
 * fifth of its column loop reloading and storing the maximum). */
typedef struct err_acc {
    double sum, max;
    uint64_t hits;
} err_acc;

static inline err_acc err_take(const td_render_stats *st)
{
    return (err_acc){st->height_err_sum_m, st->height_err_max_m, st->height_err_hits};
}

static inline void err_put(td_render_stats *st, const err_acc *a)
{
    st->height_err_sum_m = a->sum;
    st->height_err_max_m = a->max;
    st->height_err_hits = a->hits;
}

static inline void err_add(err_acc *a, double e)
{
    a->sum += e;
    a->max = e > a->max ? e : a->max;
    a->hits++;
}

/* A hit's height error into the stats. */
static inline void count_error(td_render_stats *st, double e)
{
    err_acc a = err_take(st);
    err_add(&a, e);
    err_put(st, &a);
}

/* How far a camera ray's hit lies above or below the exact surface (bilinear, full grid)
 * at its x, y: what the scene's surface and level of detail cost in accuracy, reported
 * with every render and pick. One interpolation per hit. NaN (and nothing counted) over
 * a void. */
static double note_error(const ctx *c, const td_hit *h, int level, td_render_stats *st)
{
    const double *p = h->p;
    double z = NAN, e = NAN;
    /* on the full grid the hit's cell holds the point (no search for it; a fan's hits come
       with that height from td_trace_fan, counted by fan_flush); a coarse level's hit on a
       mapped (prepared, larger than memory) grid is not measured: it would read a
       full-resolution page per far pixel (9.2 k of a cold 4 GiB view's 10.5 k faults) */
    if (level == 0 ? td_grid_bilinear_cell(c->v->grid, h->ci, h->cj, p[0], p[1], &z, NULL)
                   : !c->v->grid->map && td_grid_bilinear(c->v->grid, p[0], p[1], &z, NULL)) {
        e = fabs(p[2] - z);
        count_error(st, e);
    }
    return e;
}

/* Whether the camera ray r is traced bent (see the top of the file). */
static int camera_bends(const ctx *c, const double o[3], const double d[3])
{
    return c->curv && needs_curve(c, o, d, c->curv_smin);
}

/* A camera ray's counts: the ray, its steps, a hit and its height error. Returns the
 * error (NaN for a miss or over a void). */
static double count_camera(const ctx *c, const td_hit *hit, int level, uint64_t steps,
                           td_render_stats *st)
{
    double e = NAN;
    st->steps += steps;
    st->kind_steps[TD_RAY_PRIMARY] += steps;
    st->rays[TD_RAY_PRIMARY]++;
    if (hit->t < INFINITY) {
        st->hits++;
        e = note_error(c, hit, level, st);
    }
    return e;
}

/* One camera ray, as render and pick trace it: bent on the full grid (bent, from
 * camera_bends), else straight over the levels of detail the ctx has (none for a pick).
 * Counts the ray, its steps, a bent ray and its chords, a hit and its height error in
 * st; *level is the level it ended on (0 when bent). Returns the hit's height error
 * (NaN for a miss or over a void). */
static double trace_camera(const ctx *c, const td_ray *r, int bent, double t_clear, td_hit *hit,
                           int *level, td_render_stats *st)
{
    uint64_t steps = 0;
    *level = 0;
    if (bent) {
        trace_curved(c, c->v, r, 0.25 * c->cam.pixel_angle, t_clear, hit, &steps, &st->curve_segments);
        st->curved_rays++;
    } else {
        trace_lod(c, r, t_clear, hit, level, &steps);
    }
    return count_camera(c, hit, *level, steps, st);
}

/* A hit's point, normal and cell into its sample. */
static inline void sample_hit(smp *sm, const td_hit *hit)
{
    sm->flags |= F_HIT;
    sm->t = hit->t;
    memcpy(sm->p, hit->p, sizeof sm->p);
    memcpy(sm->n, hit->n, sizeof sm->n);
    sm->ci = hit->ci;
    sm->cj = hit->cj;
}

/* A camera ray's result into its sample: the method it ended with, and on a hit the
 * point, normal and cell. */
static void keep_camera_hit(td_render_stats *st, const td_hit *hit, smp *sm)
{
    if ((unsigned)hit->method < TD_METHOD_COUNT)
        st->method_rays[hit->method]++;
    if (hit->t < INFINITY)
        sample_hit(sm, hit);
}

/* A shadow or reflection ray on view v: bent about its origin when curvature is on and
 * its run is long enough (see the top of the file), else straight. */
static void trace_secondary(const ctx *c, worker *w, td_ray_kind kind, const td_view *v,
                            const td_ray *r, td_hit *hit)
{
    uint64_t steps = 0;
    if (c->curv2 && needs_curve(c, r->o, r->d, c->curv_smin2)) {
        trace_curved(c, v, r, 0.0, 0.0, hit, &steps, &w->st.curve_segments);
        w->st.curved_secondary++;
    } else {
        td_trace(v, c->s->quality.method, c->s->quality.surface, r, hit);
        steps = hit->steps;
    }
    w->st.steps += steps;
    w->st.kind_steps[kind] += steps;
}

/* The caller's copy of a sample's secondary ray (td_render_opts.shadow_rays): in image
 * order, a marker (tmax -1) where the sample has none. */
static void keep_ray(const ctx *c, td_ray *out, const blk *b, int i, const td_ray *r)
{
    if (out) {
        const int nn = c->n * c->n;
        int pix = i / nn;
        size_t x = (size_t)(b->x0 + pix % b->bw), y = (size_t)(b->y0 + pix / b->bw);
        td_ray *slot = &out[(y * (size_t)c->cam.width + x) * (size_t)nn + (size_t)(i % nn)];
        if (r) {
            *slot = *r;
        } else {
            memset(slot, 0, sizeof *slot);
            slot->tmax = -1.0;
        }
    }
}

/* Whether a shadow or AO ray meets the terrain: an any-hit query from the surface
 * (td_occluded), or for a long shadow ray under curvature its bent chords, as any-hit
 * queries (occluded_curved; their nearest hits, trace_secondary, with the device off). */
static int occluded(const ctx *c, worker *w, td_ray_kind kind, const td_view *v, const td_ray *r)
{
    int hit;
    uint32_t steps = 0;
    if (kind == TD_RAY_SHADOW && c->curv2 && needs_curve(c, r->o, r->d, c->curv_smin2)) {
        if (c->plain_secondary) { /* OFF_OCCLUSION: the nearest hit, as before the device */
            td_hit h;
            trace_secondary(c, w, kind, v, r, &h);
            hit = h.t < INFINITY;
        } else {
            uint64_t st = 0;
            hit = occluded_curved(c, v, r, v == c->v ? c->sunlit : NULL, &st, &w->st.curve_segments);
            w->st.curved_secondary++;
            w->st.steps += st;
            w->st.kind_steps[kind] += st;
        }
    } else {
        if (c->plain_secondary) { /* OFF_OCCLUSION: the nearest hit, as before the device */
            td_hit h;
            td_trace(v, c->s->quality.method, c->s->quality.surface, r, &h);
            steps = h.steps;
            hit = h.t < INFINITY;
        } else {
            /* the sun bound is the full grid's: not for rays on coarse levels */
            const td_sunlit *lit = kind == TD_RAY_SHADOW && v == c->v ? c->sunlit : NULL;
            hit = td_occluded(v, c->s->quality.method, c->s->quality.surface, r, lit, &steps);
        }
        w->st.steps += steps;
        w->st.kind_steps[kind] += steps;
    }
    return hit;
}

/* ---- The stages: stage_<name> runs on one block, on_<name> says whether the render
 * needs it (asked once per render). Their order is TD_BLOCK_STAGE_LIST's. ---- */

/* A sample record for the camera ray from o along d (not traced yet). */
static inline void sample_init(const ctx *c, const double o[3], double dx, double dy, double dz, smp *sm)
{
    sm->o[0] = o[0], sm->o[1] = o[1], sm->o[2] = o[2];
    sm->d[0] = dx, sm->d[1] = dy, sm->d[2] = dz;
    sm->flags = camera_bends(c, sm->o, sm->d) ? F_CURVE : 0; /* bent rays: the curvature stage */
    sm->level = 0;
    sm->t = INFINITY;
    sm->tw = INFINITY;
    sm->alpha = 0.0f;
    sm->rgb[0] = sm->rgb[1] = sm->rgb[2] = 0.0f; /* a miss without sky stays transparent black */
}

/* The block's camera rays into its sample records, in sample order (pixels, then
 * sub-samples). A perspective camera's come a sample row at a time (td_camera_dirs, the
 * same rays as td_camera_ray's: measured about 190 -> 70 instructions a sample with its
 * record's initialisation), and so do a panorama's (td_camera_cyl_dirs: one sine and
 * cosine a sample column). */
static void camera_samples(const ctx *c, worker *w, const blk *b)
{
    const int n = c->n, nn = n * n;
    const int32_t ns_row = b->bw * n; /* samples on a sample row of the block */
    double px[TD_BLOCK * TD_SAMPLES_MAX], ax[TD_BLOCK * TD_SAMPLES_MAX], d[3][TD_BLOCK * TD_SAMPLES_MAX];
    double sa[TD_BLOCK * TD_SAMPLES_MAX], ca[TD_BLOCK * TD_SAMPLES_MAX]; /* a panorama's columns */
    const int persp = c->cam.projection == TD_PROJ_PERSPECTIVE, cyl = c->cam.projection == TD_PROJ_CYLINDRICAL;
    const int eye = persp || cyl; /* rays from the eye, a sample row at a time */
    td_ray r = {.tmin = 0.0, .tmax = INFINITY};
    double sub[TD_SAMPLES_MAX]; /* (s + 0.5) / n: x + sub[s] - 0.5 is the sample's x, the
                                   same bits as computing it whole, without a division */
    for (int s = 0; s < n; s++)
        sub[s] = (s + 0.5) / n;
    for (int32_t x = b->x0, k = 0; x < b->x1; x++) /* the sample columns, the same each row */
        for (int sc = 0; sc < n; sc++)
            px[k++] = x + sub[sc] - 0.5;
    if (persp)
        td_camera_abscissas(&c->cam, px, ns_row, ax);
    else if (cyl)
        td_camera_cyl_columns(&c->cam, px, ns_row, sa, ca);
    for (int32_t y = b->y0; y < b->y1; y++) {
        for (int sr = 0; sr < n; sr++) {
            double py = y + sub[sr] - 0.5;
            smp *row = &w->s[(y - b->y0) * b->bw * nn + sr * n];
            if (persp)
                td_camera_dirs(&c->cam, py, ax, ns_row, d[0], d[1], d[2]);
            else if (cyl)
                td_camera_cyl_dirs(&c->cam, py, sa, ca, ns_row, d[0], d[1], d[2]);
            if (eye && n == 1) { /* a sample row is a pixel row of w->s: one loop (about
                                      35 instructions a sample less than the general one) */
                for (int32_t k = 0; k < ns_row; k++)
                    sample_init(c, c->cam.o, d[0][k], d[1][k], d[2][k], &row[k]);
                continue;
            }
            for (int32_t k = 0, pix = 0; pix < b->bw; pix++) {
                smp *sm = &row[pix * nn];
                for (int sc = 0; sc < n; sc++, k++) {
                    if (eye) {
                        sample_init(c, c->cam.o, d[0][k], d[1][k], d[2][k], &sm[sc]);
                    } else { /* an orthographic camera's rays start apart */
                        td_camera_ray(&c->cam, px[k], py, &r);
                        sample_init(c, r.o, r.d[0], r.d[1], r.d[2], &sm[sc]);
                    }
                }
            }
        }
    }
}

/* A straight camera ray's hit into its sample and the counts of the level it ended on
 * and its method. */
static void camera_keep(worker *w, smp *sm, td_hit *hit)
{
    if (w->c->silh && hit->method == TD_METHOD_INCREMENTAL)
        hit->method = TD_METHOD_SILHOUETTE; /* started by the partition, then the walk */
    w->st.lod_rays[sm->level]++;
    keep_camera_hit(&w->st, hit, sm);
}

/* A camera ray known to miss without tracing (t_clear +inf, horizon.h): its counts, as
 * camera_keep would count the miss's hit record (about 50 instructions less a ray; half
 * the rays of a level view are sky). */
static void camera_miss(worker *w, smp *sm)
{
    const ctx *c = w->c;
    td_method m = untraced_method(c);
    if (c->silh && m == TD_METHOD_INCREMENTAL)
        m = TD_METHOD_SILHOUETTE;
    sm->level = 0;
    w->st.rays[TD_RAY_PRIMARY]++;
    w->st.lod_rays[0]++;
    w->st.method_rays[m]++;
}

/* Traces the straight camera ray of a sample, from t_clear on (+inf: a miss known
 * without tracing, see horizon.h). */
static void camera_trace(worker *w, smp *sm, double t_clear)
{
    if (t_clear == INFINITY) {
        camera_miss(w, sm);
    } else {
        td_hit hit;
        td_ray r = {.tmin = 0.0, .tmax = INFINITY};
        memcpy(r.o, sm->o, sizeof r.o);
        memcpy(r.d, sm->d, sizeof r.d);
        trace_camera(w->c, &r, 0, t_clear, &hit, &sm->level, &w->st);
        camera_keep(w, sm, &hit);
    }
}

/* Camera rays of a slice waiting to be traced together (td_trace_fan: straight rays on
 * the full grid share the walk's setup of the grid and the camera's position). */
typedef struct fan {
    smp *sm[TD_FAN_MAX];
    td_fan r;
    int n;
} fan;

static void fan_flush(worker *w, fan *f)
{
    const ctx *c = w->c;
    td_render_stats *st = &w->st;
    td_fan_hits h;
    uint64_t steps = 0, nhit = 0, methods[TD_METHOD_COUNT] = {0};
    td_trace_fan(c->v, c->s->quality.method, c->s->quality.surface, c->cam.o, f->n, &f->r, &h);
    /* count_camera and camera_keep for each ray (a fan: full grid, no silhouette
       partition), the integer counts added once; the height errors in ray order, as
       note_error adds them; sample_hit's fields from the fan's arrays */
    err_acc err = err_take(st);
    for (int k = 0; k < f->n; k++) {
        smp *sm = f->sm[k];
        steps += h.steps[k];
        if ((unsigned)h.method[k] < TD_METHOD_COUNT)
            methods[h.method[k]]++;
        sm->level = 0;
        if (h.t[k] < INFINITY) {
            nhit++;
            if (!isnan(h.zb[k]))
                err_add(&err, fabs(h.pz[k] - h.zb[k]));
            sm->flags |= F_HIT;
            sm->t = h.t[k];
            sm->p[0] = h.px[k], sm->p[1] = h.py[k], sm->p[2] = h.pz[k];
            sm->n[0] = h.nx[k], sm->n[1] = h.ny[k], sm->n[2] = h.nz[k];
            sm->ci = h.ci[k];
            sm->cj = h.cj[k];
        }
    }
    err_put(st, &err);
    st->steps += steps;
    st->kind_steps[TD_RAY_PRIMARY] += steps;
    st->rays[TD_RAY_PRIMARY] += (uint64_t)f->n;
    st->lod_rays[0] += (uint64_t)f->n;
    st->hits += nhit;
    for (int m = 0; m < TD_METHOD_COUNT; m++)
        st->method_rays[m] += methods[m];
    f->n = 0;
}

/* A sample's camera ray from t_clear on: into the fan when the render has one (the
 * full grid, no levels of detail), else traced now; a known miss (+inf) is kept at once. */
static void fan_add(worker *w, fan *f, smp *sm, double t_clear)
{
    if (!f || t_clear == INFINITY) { /* a miss known without tracing costs nothing more */
        camera_trace(w, sm, t_clear);
    } else {
        const int k = f->n;
        f->sm[k] = sm;
        f->r.dx[k] = sm->d[0], f->r.dy[k] = sm->d[1], f->r.dz[k] = sm->d[2];
        f->r.t_clear[k] = t_clear;
        if (++f->n == TD_FAN_MAX)
            fan_flush(w, f);
    }
}

/* The floor of the beam of a slice's camera rays (beam.h), from the rays through the
 * corners p[0 .. np) of its convex polygon of pixel coordinates: +inf (no bound) unless
 * all of them descend, and, where the horizon bounds the slice (hz_ok), steeper than 45
 * degrees: shallower rays start where the horizon puts them, and the beam's boxes would
 * cost more than they save (measured: 3% more instructions in the primary stage of level,
 * grazing and rolled views when every slice takes its beam). */
static double slice_floor(worker *w, const double (*p)[2], int np, int hz_ok, uint32_t *steps)
{
    const ctx *c = w->c;
    double d[TD_SLICE_CORNERS][3];
    int steep = 1;
    for (int k = 0; k < np && (steep || !hz_ok); k++) { /* the corners, while they may matter */
        td_ray r;
        td_camera_ray(&c->cam, p[k][0], p[k][1], &r);
        memcpy(d[k], r.d, sizeof d[k]);
        steep = steep && -r.d[2] > hypot(r.d[0], r.d[1]);
    }
    return hz_ok && !steep ? INFINITY : td_beam_floor(c->v, c->cam.o, (const double(*)[3])d, np, steps);
}

/* What a slice's rays start from: the horizon of its wedge (use_hz) and the floor of its
 * beam (and the boxes it took). */
typedef struct slice_start {
    int use_hz;
    double floor_z;
    uint32_t boxes;
} slice_start;

/* The wedge and the beam of the slice whose samples lie in the convex polygon p[0 .. np)
 * of pixel coordinates. */
static slice_start slice_begin(worker *w, const double (*p)[2], int np)
{
    const ctx *c = w->c;
    slice_start ss = {.floor_z = INFINITY};
    double az0, az1;
    int hz_ok = c->horizon && td_camera_azimuths_poly(&c->cam, p, np, &az0, &az1) &&
                td_horizon_begin(&w->hz, c->v, c->cam.o, az0, az1);
    if (c->beam)
        ss.floor_z = slice_floor(w, p, np, hz_ok, &ss.boxes);
    /* a slice the beam bounds (its rays all steep) starts from the floor alone: the
       horizon's bins cost more there than they save (trinidad straight down: 22.0 -> 19.5
       ms in the primary stage, 19,239 -> 1,873 bins; levi 15.3 -> 12.8 ms) */
    ss.use_hz = hz_ok && ss.floor_z == INFINITY;
    return ss;
}

/* One sample's camera ray of a slice, started where nothing can precede its hit. The
 * lowest elevation the horizon said was a miss is kept: td_horizon_clear is monotone in
 * the elevation (a miss stays a miss higher up, and asks nothing new of the bins), so a
 * ray at or above it is a miss without asking (the same answer: measured about 60
 * instructions a sky pixel). */
static inline __attribute__((always_inline)) void slice_ray(worker *w, fan *f, int use_hz, double floor_z,
                                                             double *e_miss, uint32_t *bins, smp *sm)
{
    const ctx *c = w->c;
    double hk = sqrt(sm->d[0] * sm->d[0] + sm->d[1] * sm->d[1]), t_clear = 0.0;
    if (!(sm->flags & F_CURVE)) {
        if (use_hz && hk > 1e-9) {
            double e = sm->d[2] / hk;
            double dc = e >= *e_miss ? INFINITY : td_horizon_clear(&w->hz, e, bins);
            *e_miss = dc == INFINITY && e < *e_miss ? e : *e_miss;
            t_clear = dc == INFINITY ? INFINITY : dc / hk * (1.0 - 1e-12);
            w->st.coherent_rays++;
        }
        if (floor_z < INFINITY && sm->d[2] < 0.0) {
            double t = (c->cam.o[2] - floor_z) / -sm->d[2] * (1.0 - 1e-12);
            t_clear = t > t_clear ? t : t_clear;
            w->st.coherent_rays++;
        }
        fan_add(w, f, sm, t_clear);
    }
}

/* A slice's bins and boxes into the stats. */
static void slice_end(worker *w, const slice_start *ss, uint32_t bins)
{
    w->st.horizon_bins += bins;
    w->st.steps += bins + ss->boxes;
    w->st.kind_steps[TD_RAY_PRIMARY] += bins + ss->boxes;
}

/* A band of a block leaning along its verticals (trace_band): the samples p with
 * lo <= a . (p - c) < hi, a across the verticals. */
typedef struct band {
    double a[2], c[2], lo, hi;
} band;

/* The convex polygon of the rectangle [x0, x1] x [y0, y1] where bd->lo - m <= a . (p - c)
 * <= bd->hi + m (m = 1e-9 pixel, for the rounding of the samples' keys): q[0 ..) its corners in
 * order (at most TD_SLICE_CORNERS); returns their count. */
static int band_polygon(double x0, double y0, double x1, double y1, const band *bd, double (*q)[2])
{
    double p[TD_SLICE_CORNERS][2] = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
    int np = 4;
    for (int side = 0; side < 2; side++) { /* Sutherland-Hodgman, one half-plane a side */
        const double sg = side ? -1.0 : 1.0, lim = side ? -bd->hi - 1e-9 : bd->lo - 1e-9;
        double r[TD_SLICE_CORNERS][2];
        int nr = 0;
        for (int k = 0; k < np && lim > -INFINITY; k++) {
            const double *u = p[k], *v = p[(k + 1) % np];
            double fu = sg * (bd->a[0] * (u[0] - bd->c[0]) + bd->a[1] * (u[1] - bd->c[1])) - lim;
            double fv = sg * (bd->a[0] * (v[0] - bd->c[0]) + bd->a[1] * (v[1] - bd->c[1])) - lim;
            if (fu >= 0.0 && nr < TD_SLICE_CORNERS)
                r[nr][0] = u[0], r[nr][1] = u[1], nr++;
            if ((fu >= 0.0) != (fv >= 0.0) && nr < TD_SLICE_CORNERS) {
                double t = fu / (fu - fv);
                r[nr][0] = u[0] + t * (v[0] - u[0]), r[nr][1] = u[1] + t * (v[1] - u[1]), nr++;
            }
        }
        if (lim > -INFINITY) {
            memcpy(p, r, sizeof r);
            np = nr;
        }
    }
    memcpy(q, p, sizeof p);
    return np;
}

/* One slice of a block, pixels [xa, xb) x [ya, yb), from the horizon of its wedge (see
 * horizon.h), or where the horizon gives no bound, from the floor of its beam (beam.h):
 * its samples in order of rising elevation (a row at a time when `rows`, the slice
 * standing upright in the image, else a column at a time; from the bottom (right) end
 * when `up`), each ray started where nothing can precede its hit. */
static void trace_slice(worker *w, fan *f, const blk *b, int32_t xa, int32_t xb, int32_t ya,
                        int32_t yb, int rows, int up)
{
    const int n = w->c->n;
    const double px0 = xa + 0.5 / n - 0.5, py0 = ya + 0.5 / n - 0.5, px1 = xb - 0.5 / n - 0.5,
                 py1 = yb - 0.5 / n - 0.5;
    const double corner[4][2] = {{px0, py0}, {px1, py0}, {px0, py1}, {px1, py1}};
    const slice_start ss = slice_begin(w, corner, 4);
    double e_miss = INFINITY;
    uint32_t bins = 0;
    int32_t nmaj = rows ? (yb - ya) * n : (xb - xa) * n, nmin = rows ? (xb - xa) * n : (yb - ya) * n;
    /* sample index = (pixel row * bw + pixel column) * n^2 + sub-row * n + sub-column:
       along a sample row (column) of the slice the index steps by n^2 a pixel and by 1
       (n) a sub-sample, so the loop adds instead of dividing */
    const int nn = n * n, pstep = rows ? nn : b->bw * nn, sstep = rows ? 1 : n;
    int minor[TD_BLOCK_TALL * TD_SAMPLES_MAX]; /* offset of the m-th sample along a line */
    for (int32_t pm = 0, m = 0; pm < nmin / n; pm++)
        for (int q = 0; q < n; q++)
            minor[m++] = pm * pstep + q * sstep;
    for (int32_t a = 0; a < nmaj; a++) {
        int32_t ma = up ? nmaj - 1 - a : a; /* sample row (or column) in the slice */
        int32_t pa = ma / n, sa = ma % n;  /* its pixel row (column) and sub-row (sub-column) */
        int base = rows ? ((ya - b->y0 + pa) * b->bw + (xa - b->x0)) * nn + sa * n
                        : ((ya - b->y0) * b->bw + (xa - b->x0 + pa)) * nn + sa;
        for (int32_t m = 0; m < nmin; m++)
            slice_ray(w, f, ss.use_hz, ss.floor_z, &e_miss, &bins, &w->s[base + minor[m]]);
    }
    slice_end(w, &ss, bins);
}

/* The order of trace_band for a block of bw x bh pixels, n x n samples each, whose
 * verticals run along vert: bs->order and bs->end. A sample's band and its bucket along
 * the verticals (1 / n pixel a bucket) from its position; a counting sort, band by band,
 * bucket by bucket, each bucket in index order. The block has more than one sample
 * (stage_primary sends a one-sample block to the column slices): its width across the
 * verticals, sext, is the divisor of the band index. */
static void band_order(band_sort *bs, int32_t bw, int32_t bh, int n, const double vert[2], int nbands)
{
    const int nn = n * n, nx = bw * n, ny = bh * n;
    const double a[2] = {-vert[1], vert[0]}, hw = 0.5 * (bw - 1.0 / n), hh = 0.5 * (bh - 1.0 / n);
    const double sext = fabs(a[0]) * hw + fabs(a[1]) * hh, rext = fabs(vert[0]) * hw + fabs(vert[1]) * hh;
    const int nb = (int)fmin(2.0 * rext * n + 1.0, TD_BAND_BUCKETS); /* buckets along the verticals */
    int count[TD_BANDS_FAR * TD_BAND_BUCKETS + 1];
    int16_t key[TD_BAND_SAMPLES];
    /* a sample's band, (a . p + sext) * qs, and bucket, (vert . p + rext) * n (p from the
       block's centre), each the sum of a column's part and a row's */
    const double qs = nbands / (2.0 * sext);
    double qx[TD_BLOCK * TD_SAMPLES_MAX], rx[TD_BLOCK * TD_SAMPLES_MAX];
    int xoff[TD_BLOCK * TD_SAMPLES_MAX]; /* sample index of (k, 0) */
    for (int k = 0; k < nx; k++) {
        const double x = (double)k / n - hw;
        qx[k] = (a[0] * x + sext) * qs, rx[k] = (vert[0] * x + rext) * n;
        xoff[k] = k / n * nn + k % n;
    }
    memset(count, 0, sizeof count[0] * (size_t)(nbands * nb + 1));
    for (int ys = 0; ys < ny; ys++) {
        const double y = (double)ys / n - hh, qy = a[1] * y * qs, ry = vert[1] * y * n;
        const int row = ys / n * bw * nn + ys % n * n; /* sample index of (0, ys) */
        for (int xs = 0; xs < nx; xs++) {
            /* (int) truncates: a rounding below 0 is 0; past the last, clamped */
            int q = (int)(qx[xs] + qy), r = (int)(rx[xs] + ry);
            q = q < nbands ? q : nbands - 1;
            r = r < nb ? r : nb - 1;
            key[row + xoff[xs]] = (int16_t)(q * nb + r);
            count[q * nb + r + 1]++;
        }
    }
    for (int k = 1; k <= nbands * nb; k++)
        count[k] += count[k - 1];
    for (int i = 0; i < nx * ny; i++)
        bs->order[count[key[i]]++] = (int16_t)i; /* count[k] now ends bucket k */
    for (int q = 0; q < nbands; q++)
        bs->end[q] = count[(q + 1) * nb - 1];
    bs->sext = sext;
}

/* A block whose verticals lean in the image (a rolled camera): its samples cut into
 * TD_BANDS bands along the image direction of the verticals rather than into columns or
 * rows, each band's wedge bounded from its polygon (the band cut from the block;
 * td_camera_azimuths_poly). A band is as wide as the block is across the verticals over
 * TD_BANDS (roll 35: 11 pixels), where a column slice spans its width plus the verticals'
 * drift over its height (19 pixels): narrower wedges, tighter bins, rays started nearer
 * their hits. A band's samples are taken in rising elevation (band_order): rays asked in
 * rising elevation get the fine bins (horizon.h builds a coarse bin under a ray far above
 * every bin), and a fan's neighbours in that order hit near each other; the bands' samples
 * a line at a time instead took 5-9% more instructions than the sort on the rolled views.
 * The order is the same for blocks of one shape whose verticals lean alike, so the bands
 * follow the verticals to TD_BAND_STEP and a worker keeps its last order (sorting every
 * block cost 5 M of trinidad's rolled view's 178). */
static void trace_band(worker *w, fan *f, const blk *b, const double vert[2], int nbands)
{
    const int n = w->c->n;
    const int32_t bh = b->y1 - b->y0, lean = (int32_t)lround(atan2(vert[1], vert[0]) / TD_BAND_STEP);
    const double vq[2] = {cos(lean * TD_BAND_STEP), sin(lean * TD_BAND_STEP)}; /* the verticals, to the step */
    band_sort *bs = &w->bs;
    if (bs->lean != lean || bs->bw != b->bw || bs->bh != bh || bs->n != n || bs->nbands != nbands) {
        band_order(bs, b->bw, bh, n, vq, nbands);
        bs->lean = lean, bs->bw = b->bw, bs->bh = bh, bs->n = n, bs->nbands = nbands;
    }
    const double X0 = b->x0 + 0.5 / n - 0.5, Y0 = b->y0 + 0.5 / n - 0.5, X1 = b->x1 - 0.5 / n - 0.5,
                 Y1 = b->y1 - 0.5 / n - 0.5;
    band bd = {.a = {-vq[1], vq[0]}, .c = {0.5 * (X0 + X1), 0.5 * (Y0 + Y1)}};
    const double sext = bs->sext; /* the bands' bounds are the sort's */
    for (int q = 0, at = 0; q < nbands; q++) {
        double poly[TD_SLICE_CORNERS][2];
        /* the first and last bands open-ended, as the keys' clamps make them */
        bd.lo = q == 0 ? -INFINITY : -sext + 2.0 * sext * q / nbands;
        bd.hi = q == nbands - 1 ? INFINITY : -sext + 2.0 * sext * (q + 1) / nbands;
        if (at < bs->end[q]) {
            const int np = band_polygon(X0, Y0, X1, Y1, &bd, poly);
            const slice_start ss = slice_begin(w, (const double(*)[2])poly, np);
            double e_miss = INFINITY;
            uint32_t bins = 0;
            for (; at < bs->end[q]; at++)
                slice_ray(w, f, ss.use_hz, ss.floor_z, &e_miss, &bins, &w->s[bs->order[at]]);
            slice_end(w, &ss, bins);
        }
    }
}

/* Camera rays from the silhouette partition (silhouette.h): each starts where its wedge's
 * running silhouette says nothing precedes its hit (0: from its start, when the partition
 * says nothing for it; +inf: a miss without a walk). A probe of the binary search is a
 * step of the ray. */
static void trace_silhouette(worker *w, const blk *b)
{
    uint32_t probes = 0;
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        if (sm->flags & F_CURVE)
            continue;
        camera_trace(w, sm, td_silhouette_clear(w->c->silh, sm->d, &probes));
        w->st.silhouette_rays++;
    }
    w->st.steps += probes;
    w->st.kind_steps[TD_RAY_PRIMARY] += probes;
}

/* Sets up w->hz for the wedge of the block's samples (the azimuths of its corner samples'
 * rays: td_camera_azimuths_poly, perspective or cylindrical); 0 when it gives no bound. */
static int block_wedge(worker *w, const blk *b)
{
    const ctx *c = w->c;
    const int n = c->n;
    const double X0 = b->x0 + 0.5 / n - 0.5, Y0 = b->y0 + 0.5 / n - 0.5, X1 = b->x1 - 0.5 / n - 0.5,
                 Y1 = b->y1 - 0.5 / n - 0.5;
    const double corner[4][2] = {{X0, Y0}, {X1, Y0}, {X1, Y1}, {X0, Y1}};
    double az0, az1;
    return td_camera_azimuths_poly(&c->cam, corner, 4, &az0, &az1) &&
           td_horizon_begin(&w->hz, c->v, c->cam.o, az0, az1);
}

/* Vectors of four for the per-sample loops that GCC does not vectorise on its own (the
 * samples' fields strided in their structs): trace_columns' slopes, the resolve stage. */
typedef double rd4 __attribute__((vector_size(32)));
typedef int64_t rm4 __attribute__((vector_size(32)));
typedef int32_t ri4 __attribute__((vector_size(16)));
typedef float rf4 __attribute__((vector_size(16)));

/* lane by lane m ? a : b (a macro: no vector crosses a call) */
#define RSEL(m, a, b) ((rd4)(((rm4)(a) & (m)) | ((rm4)(b) & ~(m))))

/* trace_columns' slopes of a sample column, four samples at a time: the k-th up it,
 * col[row[k]], has the horizontal length hk[k] of its direction and rise e[k] per unit of
 * it (each lane the scalar expressions, the same bits; a column's last lanes repeat its
 * last sample and are not stored). Returns whether e rises up the column. */
TD_ROW_CLONES static int column_slopes(const smp *col, const int *row, int32_t nrow, double *hk, double *e)
{
    int rising = 1;
    for (int32_t k = 0; k < nrow; k += 4) {
        rd4 d0, d1, d2;
        for (int l = 0; l < 4; l++) {
            const smp *sm = &col[row[k + l < nrow ? k + l : nrow - 1]];
            d0[l] = sm->d[0], d1[l] = sm->d[1], d2[l] = sm->d[2];
        }
        rd4 h = d0 * d0 + d1 * d1;
        for (int l = 0; l < 4; l++)
            h[l] = sqrt(h[l]);
        const rd4 ek = d2 / h;
        for (int l = 0; l < 4 && k + l < nrow; l++)
            hk[k + l] = h[l], e[k + l] = ek[l];
    }
    for (int32_t k = 1; k < nrow; k++)
        rising &= e[k] >= e[k - 1];
    return rising;
}

/* Camera rays of an upright, level camera or a panorama, a sample column at a time
 * (colwalk.h): the column's rays share their horizontal direction (td_camera_dirs: the up
 * vector's x and y are 0, so x and y do not depend on the row; a panorama's column is one
 * azimuth), taken from the bottom up in rising slope. Each hit is finished as a fan's: t
 * along the ray's own unit direction, the point, the surface's normal there, the height
 * error against the bilinear surface. A ray that bends (F_CURVE) is the curvature stage's,
 * but walked with the others as the straight ray it bends up from: a bent ray lies above
 * that one, so it meets nothing before the straight ray's hit (a miss: nothing at all),
 * and the curvature stage starts its chords there (F_CLEAR; a 1e-9 short of it, far more
 * than the walk's rounding). */
static void trace_columns(worker *w, const blk *b)
{
    const ctx *c = w->c;
    const int n = c->n, nn = n * n;
    const int32_t ncol = b->bw * n, nrow = (b->y1 - b->y0) * n;
    td_render_stats *st = &w->st;
    double e[TD_BLOCK_TALL * TD_SAMPLES_MAX], hk[TD_BLOCK_TALL * TD_SAMPLES_MAX];
    int row[TD_BLOCK_TALL * TD_SAMPLES_MAX]; /* the k-th sample up a column: its offset */
    td_colhit h[TD_BLOCK_TALL * TD_SAMPLES_MAX];
    uint64_t steps = 0, nhit = 0, untraced = 0, bent = 0;
    uint32_t bins = 0;
    /* where each column's lowest ray may first meet the terrain */
    const int hz = c->col_horizon && block_wedge(w, b), curv = c->curv;
    for (int32_t k = 0; k < nrow; k++) { /* from the bottom sample row up */
        const int32_t r = nrow - 1 - k;
        row[k] = r / n * b->bw * nn + r % n * n;
    }
    for (int32_t xs = 0; xs < ncol; xs++) {
        smp *const col = &w->s[xs / n * nn + xs % n];
        if (!column_slopes(col, row, nrow, hk, e)) { /* not expected (the rows' slopes rise by a pixel's angle): the plain walk */
            for (int32_t k = 0; k < nrow; k++)
                if (col[row[k]].flags & F_CURVE) {
                    bent++;
                } else {
                    camera_trace(w, &col[row[k]], 0.0);
                    untraced++;
                }
            continue;
        }
        const double s0 = hz ? td_horizon_clear(&w->hz, e[0], &bins) * (1.0 - 1e-12) : 0.0;
        steps += td_colwalk_trace(&c->cw, col[row[0]].d[0] / hk[0], col[row[0]].d[1] / hk[0], s0, nrow, e, h);
        for (int32_t k = 0; k < nrow && curv; k++) {
            smp *sm = &col[row[k]];
            if (sm->flags & F_CURVE) { /* where its chords start (not known: from the eye) */
                bent++;
                if (h[k].s == h[k].s) {
                    sm->t = h[k].s == INFINITY ? INFINITY : h[k].s / hk[k] * (1.0 - 1e-9);
                    sm->flags |= F_CLEAR;
                }
                h[k].s = INFINITY; /* the curvature stage's: nothing to finish below */
            }
        }
        err_acc err = err_take(st);
        for (int32_t k = 0; k < nrow; k++) {
            smp *sm = &col[row[k]];
            if (h[k].s == INFINITY)
                continue;
            if (h[k].s != h[k].s) { /* not known (colwalk.h): the plain walk (its error in order) */
                err_put(st, &err);
                camera_trace(w, sm, 0.0);
                err = err_take(st);
                untraced++;
                continue;
            }
            const double t = h[k].s / hk[k];
            nhit++;
            sm->level = 0;
            sm->flags |= F_HIT;
            sm->t = t;
            sm->p[0] = sm->o[0] + t * sm->d[0];
            sm->p[1] = sm->o[1] + t * sm->d[1];
            sm->p[2] = sm->o[2] + t * sm->d[2];
            memcpy(sm->n, h[k].n, sizeof sm->n);
            sm->ci = h[k].ci;
            sm->cj = h[k].cj;
            if (!isnan(h[k].zb))
                err_add(&err, fabs(sm->p[2] - h[k].zb));
        }
        err_put(st, &err);
    }
    st->horizon_bins += bins;
    st->steps += steps + bins;
    st->kind_steps[TD_RAY_PRIMARY] += steps + bins;
    /* camera_trace counted the ones it traced, the curvature stage counts the bent */
    const uint64_t mine = (uint64_t)(ncol * nrow) - untraced - bent;
    st->rays[TD_RAY_PRIMARY] += mine;
    st->lod_rays[0] += mine;
    st->method_rays[TD_METHOD_HIERARCHICAL] += mine;
    st->column_rays += mine;
    st->coherent_rays += mine; /* started from the horizon or the ray below */
    st->hits += nhit;
}

/* Camera rays. With the silhouette partition, each ray starts from it. An upright, level
 * camera's or a panorama's go a sample column at a time (trace_columns). Else, with the
 * horizon or beam device on (perspective, full grid), the block is cut into TD_SLICES
 * slices across the image direction of the verticals, each traced from its wedge's
 * horizon and beam; else every ray is traced from its start. Rays that must bend are
 * flagged for the curvature stage. */
static void stage_primary(worker *w, const blk *b)
{
    const ctx *c = w->c;
    camera_samples(c, w, b);
    if (c->silh) {
        trace_silhouette(w, b);
    } else if (c->columns) {
        trace_columns(w, b);
    } else if (c->horizon || c->beam) {
        double vert[2];
        td_camera_rising(&c->cam, 0.5 * (b->x0 + b->x1 - 1), 0.5 * (b->y0 + b->y1 - 1), vert);
        int rows = fabs(vert[1]) >= fabs(vert[0]); /* verticals run up the image: slices are columns */
        /* rising elevation: samples taken from the end the verticals rise away from */
        int up = rows ? vert[1] < 0.0 : vert[0] < 0.0;
        int32_t len = rows ? b->bw : b->y1 - b->y0;
        fan f = {.n = 0};
        fan *fp = c->nlod == 0 && c->ortho_level == 0 ? &f : NULL;
        const double lean = fmin(fabs(vert[0]), fabs(vert[1])); /* sine of the verticals' lean off the nearer axis */
        td_ray mid;
        td_camera_ray(&c->cam, 0.5 * (b->x0 + b->x1 - 1), 0.5 * (b->y0 + b->y1 - 1), &mid);
        const uint64_t steps0 = w->st.kind_steps[TD_RAY_PRIMARY], rays0 = w->st.rays[TD_RAY_PRIMARY];
        const int steep = -mid.d[2] >= hypot(mid.d[0], mid.d[1]);
        /* bands need a block of more than one sample: one sample (a 1 x 1 pixel block at
         * the image's corner, one ray a pixel) spans no width across the verticals, which
         * band_order divides by (the rolled 65 x 17 image wrote out of its counts) */
        if (lean > TD_BAND_LEAN && b->ns > 1 && b->ns <= TD_BAND_SAMPLES && !steep) {
            trace_band(w, fp, b, vert, w->band_far ? TD_BANDS_FAR : TD_BANDS);
        } else {
            const int ns = w->band_far && !steep ? TD_SLICES_FAR : TD_SLICES;
            for (int q = 0; q < ns; q++) {
                int32_t s0 = len * q / ns, s1 = len * (q + 1) / ns;
                if (s1 <= s0)
                    continue;
                if (rows)
                    trace_slice(w, fp, b, b->x0 + s0, b->x0 + s1, b->y0, b->y1, 1, up);
                else
                    trace_slice(w, fp, b, b->x0, b->x1, b->y0 + s0, b->y0 + s1, 0, up);
            }
        }
        if (fp && fp->n > 0)
            fan_flush(w, fp);
        const uint64_t ds = w->st.kind_steps[TD_RAY_PRIMARY] - steps0, dr = w->st.rays[TD_RAY_PRIMARY] - rays0;
        w->band_far = (double)ds > TD_BAND_FAR * (double)dr;
    } else {
        for (int i = 0; i < b->ns; i++)
            if (!(w->s[i].flags & F_CURVE))
                camera_trace(w, &w->s[i], 0.0);
    }
}

static int on_primary(const ctx *c)
{
    (void)c;
    return 1;
}

/* The camera rays the primary stage flagged, traced bent. */
static void stage_curvature(worker *w, const blk *b)
{
    const ctx *c = w->c;
    td_hit hit;
    td_ray r;
    uint32_t bins = 0;
    int hz = -1; /* the block's wedge (block_wedge), set up at its first bent ray */
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        double t_clear = 0.0;
        if (!(sm->flags & F_CURVE))
            continue;
        memcpy(r.o, sm->o, sizeof r.o);
        memcpy(r.d, sm->d, sizeof r.d);
        r.tmin = 0.0;
        r.tmax = INFINITY;
        const double hk = sqrt(r.d[0] * r.d[0] + r.d[1] * r.d[1]);
        if (sm->flags & F_CLEAR) { /* its straight ray's hit, from the columns */
            t_clear = sm->t;
            sm->t = INFINITY;
            sm->flags &= ~(uint32_t)F_CLEAR;
            w->st.coherent_rays++;
        } else {
            hz = hz < 0 ? (c->horizon || c->col_horizon) && block_wedge(w, b) : hz;
            if (hz && hk > 1e-9) { /* where the straight ray meets nothing before: the bent one neither */
                const double dc = td_horizon_clear(&w->hz, r.d[2] / hk, &bins);
                t_clear = dc == INFINITY ? INFINITY : dc / hk * (1.0 - 1e-12);
                w->st.coherent_rays++;
            }
        }
        trace_camera(c, &r, 1, t_clear, &hit, &sm->level, &w->st);
        keep_camera_hit(&w->st, &hit, sm);
    }
    w->st.horizon_bins += bins;
    w->st.steps += bins;
    w->st.kind_steps[TD_RAY_PRIMARY] += bins;
}

static int on_curvature(const ctx *c)
{
    return c->curv;
}

/* Samples whose ray meets the water before the terrain: the reflection ray, its colour
 * and Fresnel weight into the stage's scratch. */
static void stage_water(worker *w, const blk *b)
{
    const ctx *c = w->c;
    const td_scene *s = c->s;
    float *refl = w->scratch[TD_STAGE_WATER];
    td_hit hit;
    td_ray r;
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        double tw = water_distance(c, sm);
        if (!(tw < sm->t))
            continue;
        sm->flags |= F_WATER;
        sm->tw = tw;
        /* reflection: from the water point, the ray mirrored in the plane */
        double wp[3];
        for (int k = 0; k < 3; k++)
            wp[k] = sm->o[k] + tw * sm->d[k];
        wp[2] = s->effects.water_level + 0.01;
        memcpy(r.o, wp, sizeof r.o);
        r.d[0] = sm->d[0];
        r.d[1] = sm->d[1];
        /* a bent camera ray meets the water with the parabola's slope there */
        r.d[2] = fabs((sm->flags & F_CURVE) ? sm->d[2] + 2.0 * c->curv_a * (sm->d[0] * sm->d[0] + sm->d[1] * sm->d[1]) * tw
                                            : sm->d[2]);
        r.tmin = 0.0;
        r.tmax = INFINITY;
        trace_secondary(c, w, TD_RAY_REFLECTION, c->views[sm->level], &r, &hit);
        w->st.rays[TD_RAY_REFLECTION]++;
        float *rf = &refl[4 * i];
        if (hit.t < INFINITY)
            shade_plain(c, &hit, sm->level, rf);
        else
            td_sky_shade(&c->sky, r.d, 1, rf);
        rf[3] = (float)td_water_fresnel(fabs(sm->d[2]));
    }
}

/* The shadow ray from o toward the sun */
static td_ray sun_ray(const ctx *c, const double o[3])
{
    td_ray r = {{o[0], o[1], o[2]}, {c->sun[0], c->sun[1], c->sun[2]}, 0.0, INFINITY};
    return r;
}

static int on_water(const ctx *c)
{
    return !c->depth_only && c->s->effects.water;
}

/* One ray toward the sun per dry hit facing it: 1 lit, 0 shadowed, into the scratch. */
#define TD_SHADOW_BATCH 64 /* shadow rays a td_occluded_par call takes */

/* The batched shadow rays of a block (np of them, from o[k], sample at[k], bent[k] when
 * the ray bends): one td_occluded_par along the sun with the sun bound, as occluded() asks
 * each straight one. A bent ray's chords lie above its straight ray (chords_next), so a
 * bent ray whose straight ray is clear is lit; the others are asked again bent
 * (occluded_curved). */
static void shadows_flush(worker *w, const double (*o)[3], const int *at, const uint8_t *bent, int np,
                          float *lit)
{
    const ctx *c = w->c;
    uint8_t hit[TD_SHADOW_BATCH];
    uint32_t steps = 0;
    uint64_t more = 0;
    td_occluded_par(c->v, c->s->quality.method, c->s->quality.surface, c->sun, np, o, c->sunlit,
                    hit, &steps);
    for (int k = 0; k < np && c->curv2; k++)
        if (hit[k] && bent[k]) {
            td_ray r = sun_ray(c, o[k]);
            hit[k] = (uint8_t)occluded_curved(c, c->v, &r, c->sunlit, &more, &w->st.curve_segments);
            w->st.curved_secondary++;
        }
    for (int k = 0; k < np; k++)
        lit[at[k]] = hit[k] ? 0.0f : 1.0f;
    w->st.steps += steps + more;
    w->st.kind_steps[TD_RAY_SHADOW] += steps + more;
}

static void stage_shadows(worker *w, const blk *b)
{
    const ctx *c = w->c;
    float *lit = w->scratch[TD_STAGE_SHADOWS];
    double o[TD_SHADOW_BATCH][3];
    int at[TD_SHADOW_BATCH], np = 0;
    uint8_t bent[TD_SHADOW_BATCH];
    /* rays from the full grid are batched (td_occluded_par; a bent one's straight ray
       first, shadows_flush); a sample on a coarse level is traced alone (occluded) */
    const int batch = !c->plain_secondary, up = c->sun[2] > 0.0, bends = batch && c->curv2;
    /* locals: the loop's stores (the batch's origins are doubles) would reload them */
    const double sun[3] = {c->sun[0], c->sun[1], c->sun[2]};
    const smp *const s = w->s;
    uint64_t rays = 0;
    for (int i = 0; i < b->ns; i++) {
        const smp *sm = &s[i];
        lit[i] = 0.0f;
        /* none for a miss, under water, with the sun down, or on a face turned away from
           the sun (dark whatever lies between) */
        if ((sm->flags & (F_HIT | F_WATER)) != F_HIT || !up ||
            sm->n[0] * sun[0] + sm->n[1] * sun[1] + sm->n[2] * sun[2] <= 0.0) {
            keep_ray(c, c->shadow_rays, b, i, NULL);
            continue;
        }
        /* the origin straight into the batch's slot; the ray itself only where it is kept
           or traced alone (trinidad level view: 56.3 -> 54.5 M instructions in the stage) */
        double *q = o[np];
        offset_origin(c, sm->p, sm->n, q);
        rays++;
        if (c->shadow_rays) {
            td_ray r = sun_ray(c, q);
            keep_ray(c, c->shadow_rays, b, i, &r);
        }
        if (batch && sm->level == 0) {
            bent[np] = (uint8_t)(bends && needs_curve(c, q, c->sun, c->curv_smin2));
            at[np++] = i;
            if (np == TD_SHADOW_BATCH) {
                shadows_flush(w, o, at, bent, np, lit);
                np = 0;
            }
        } else {
            td_ray r = sun_ray(c, q);
            lit[i] = occluded(c, w, TD_RAY_SHADOW, c->views[sm->level], &r) ? 0.0f : 1.0f;
        }
    }
    if (np > 0)
        shadows_flush(w, o, at, bent, np, lit);
    w->st.rays[TD_RAY_SHADOW] += rays;
}

static int on_shadows(const ctx *c)
{
    return !c->depth_only && c->s->effects.shadows;
}

/* N hemisphere rays per dry hit: the unoccluded fraction into the scratch. */
static void stage_ao(worker *w, const blk *b)
{
    const ctx *c = w->c;
    const td_scene *s = c->s;
    const int n = c->n, na = s->effects.ambient_occlusion;
    float *occl = w->scratch[TD_STAGE_AO];
    td_ray r;
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        occl[i] = 1.0f;
        if ((sm->flags & (F_HIT | F_WATER)) != F_HIT)
            continue;
        int pix = i / (n * n), sub = i % (n * n);
        uint32_t gx = (uint32_t)(b->x0 + pix % b->bw), gy = (uint32_t)(b->y0 + pix / b->bw);
        uint32_t seed = td_hash32(gx * 73856093u ^ gy * 19349663u ^ (uint32_t)sub * 83492791u);
        int open = 0;
        offset_origin(c, sm->p, sm->n, r.o);
        for (int k = 0; k < na; k++) {
            td_ao_direction(sm->n, k, na, seed, r.d);
            r.tmin = 0.0;
            r.tmax = c->ao_radius;
            open += !occluded(c, w, TD_RAY_AO, c->views[sm->level], &r);
        }
        w->st.rays[TD_RAY_AO] += (uint64_t)na;
        occl[i] = (float)open / (float)na;
    }
}

static int on_ao(const ctx *c)
{
    return !c->depth_only && c->s->effects.ambient_occlusion > 0;
}

/* Colour of every sample that hit something: albedo, normal, sun and ambient, with the
 * shadow, AO and water stages' results where they ran. */
static void stage_shade(worker *w, const blk *b)
{
    const ctx *c = w->c;
    const float *lits = w->scratch[TD_STAGE_SHADOWS], *occls = w->scratch[TD_STAGE_AO];
    const float *refl = w->scratch[TD_STAGE_WATER];
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        if (!(sm->flags & (F_HIT | F_WATER)))
            continue;
        float col[3] = {0.0f, 0.0f, 0.0f};
        if (sm->flags & F_HIT) {
            float alb[3], nn[3];
            albedo_of(c, sm->p, alb);
            normal_of(c, sm->p, sm->n, sm->ci, sm->cj, sm->level, nn);
            /* the floor under water is not shadowed or occluded (no rays for it) */
            int dry = !(sm->flags & F_WATER);
            double lit = lits && dry ? lits[i] : 1.0;
            double occ = occls && dry ? occls[i] : 1.0;
            td_shade_light(alb, nn, c->sun, c->s->effects.ambient, occ, lit, col);
        }
        if (sm->flags & F_WATER) {
            float under[3];
            double path = (sm->flags & F_HIT) ? sm->t - sm->tw : 1e4;
            td_water_tint(col, path, under);
            const float *rf = &refl[4 * i];
            for (int k = 0; k < 3; k++)
                col[k] = rf[3] * rf[k] + (1.0f - rf[3]) * under[k];
        }
        memcpy(sm->rgb, col, sizeof col);
        sm->alpha = 1.0f;
    }
}

static int on_shade(const ctx *c)
{
    return !c->depth_only;
}

/* Aerial perspective over the distance to the terrain or the water. */
static void stage_haze(worker *w, const blk *b)
{
    const ctx *c = w->c;
    const td_scene *s = c->s;
    double z0 = NAN, e0 = NAN; /* the last start's height and its exp (a camera's: one) */
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        if (!(sm->flags & (F_HIT | F_WATER)))
            continue;
        double dist = (sm->flags & F_WATER) ? sm->tw : sm->t;
        double zend = (sm->flags & F_WATER) ? s->effects.water_level : sm->p[2];
        if (!(sm->o[2] - c->zref == z0)) {
            z0 = sm->o[2] - c->zref;
            e0 = exp(-z0 / TD_HAZE_SCALE_HEIGHT_M);
        }
        double tr = td_haze_transmittance(c->beta0, z0, e0, zend - c->zref, dist);
        double hd[3] = {sm->d[0], sm->d[1], 0.0};
        float hc[3];
        td_sky_shade(&c->sky, hd, 0, hc);
        for (int k = 0; k < 3; k++)
            sm->rgb[k] = (float)(sm->rgb[k] * tr + hc[k] * (1.0 - tr));
    }
}

static int on_haze(const ctx *c)
{
    return !c->depth_only && c->s->effects.haze;
}

/* The background of the samples that hit nothing. */
static void stage_sky(worker *w, const blk *b)
{
    const ctx *c = w->c;
    for (int i = 0; i < b->ns; i++) {
        smp *sm = &w->s[i];
        if (sm->flags & (F_HIT | F_WATER))
            continue;
        td_sky_shade(&c->sky, sm->d, 1, sm->rgb);
        sm->alpha = 1.0f;
    }
}

static int on_sky(const ctx *c)
{
    return !c->depth_only && c->s->effects.sky;
}

/* n x n samples -> one pixel: the nearest distance (depth formats) or the alpha-weighted
 * mean colour, gamma 2 and 8 bits. */
/* A block's pixels from its samples (n x n a pixel): depth, or the alpha-weighted mean
 * colour, square-rooted (the samples are in a linear space) to 8 bits. Inlined twice by
 * stage_resolve, once with n = 1 (the common case: the loops over samples and channels
 * unrolled, the division by the count gone; the same bits). */
static inline __attribute__((always_inline)) void resolve_block(const ctx *c, const smp *s, const blk *b,
                                                               const int n)
{
    for (int32_t y = b->y0; y < b->y1; y++) {
        for (int32_t x = b->x0; x < b->x1; x++) {
            int pix = (int)((y - b->y0) * b->bw + (x - b->x0));
            const smp *sm = &s[pix * n * n];
            size_t o = (size_t)y * (size_t)c->cam.width + (size_t)x;
            if (c->depth_only) {
                /* the nearest visible surface: with water, its surface where it is nearer */
                double best = INFINITY;
                for (int k = 0; k < n * n; k++) {
                    if ((sm[k].flags & F_HIT) && sm[k].t < best)
                        best = sm[k].t;
                    if (c->s->effects.water)
                        best = dmin_(best, water_distance(c, &sm[k]));
                }
                c->depth[o] = (float)best;
            } else {
                double acc[3] = {0.0, 0.0, 0.0}, a = 0.0;
                for (int k = 0; k < n * n; k++) {
                    a += sm[k].alpha;
#pragma GCC unroll 3
                    for (int ch = 0; ch < 3; ch++)
                        acc[ch] += sm[k].alpha * sm[k].rgb[ch];
                }
                uint8_t *dst = c->rgba + 4 * o;
#pragma GCC unroll 3
                for (int ch = 0; ch < 3; ch++) { /* compares, not libm's fmax/fmin calls */
                    double q = a == 1.0 ? acc[ch] : (a > 0.0 ? acc[ch] / a : 0.0); /* x/1 is x */
                    double v = sqrt(q > 0.0 ? q : 0.0);
                    dst[ch] = (uint8_t)((v < 1.0 ? v : 1.0) * 255.0 + 0.5);
                }
                dst[3] = (uint8_t)(a / (n * n) * 255.0 + 0.5);
            }
        }
    }
}

/* Four pixels' RGBA (lane l: sample p[l]) as four little-endian words */
static inline __attribute__((always_inline)) ri4 resolve4(const smp *const p[4])
{
    rf4 af, cf[3];
    for (int l = 0; l < 4; l++) {
        af[l] = p[l]->alpha;
        cf[0][l] = p[l]->rgb[0], cf[1][l] = p[l]->rgb[1], cf[2][l] = p[l]->rgb[2];
    }
    const rd4 a = 0.0 + __builtin_convertvector(af, rd4), zero = {0}, one = zero + 1.0; /* a += alpha */
    const rm4 opaque = (rm4)(a == 1.0);
    const int all = (opaque[0] & opaque[1] & opaque[2] & opaque[3]) != 0; /* no division */
    ri4 px = (__builtin_convertvector(a * 255.0 + 0.5, ri4) & 0xff) << 24; /* a / (n n), n 1 */
    for (int ch = 0; ch < 3; ch++) {
        rd4 acc = 0.0 + __builtin_convertvector(af * cf[ch], rd4); /* alpha * rgb: a float product */
        rd4 q = all ? acc : RSEL(opaque, acc, RSEL((rm4)(a > 0.0), acc / a, zero));
        rd4 v = RSEL((rm4)(q > 0.0), q, zero);
        for (int l = 0; l < 4; l++)
            v[l] = sqrt(v[l]);
        v = RSEL((rm4)(v < 1.0), v, one);
        px |= (__builtin_convertvector(v * 255.0 + 0.5, ri4) & 0xff) << (8 * ch);
    }
    return px;
}

/* resolve_block's colour for one sample a pixel, cnt pixels of a row (sm[k] -> dst[4 k ..]),
 * four at a time: each lane resolve_block's expressions for its pixel in the same order (no
 * FMA: the same bytes), the square roots four to an instruction; a row's last pixels
 * repeat its last one in the lanes past it, and only theirs are stored. Trinidad's and
 * levi's views, one thread: the stage 2.7-3.6 -> 2.1-2.2 ms a 512 x 512 render. */
TD_ROW_CLONES static void resolve_row1(const smp *sm, int32_t cnt, uint8_t *dst)
{
    int32_t x = 0;
    for (; x + 4 <= cnt; x += 4) {
        const smp *const p[4] = {&sm[x], &sm[x + 1], &sm[x + 2], &sm[x + 3]};
        ri4 px = resolve4(p);
        memcpy(dst + 4 * x, &px, sizeof px);
    }
    if (x < cnt) { /* the row's last pixels, the last one repeated in the lanes past it */
        const smp *const p[4] = {&sm[x], &sm[x + 1 < cnt ? x + 1 : x], &sm[x + 2 < cnt ? x + 2 : x],
                                 &sm[x + 3 < cnt ? x + 3 : x]};
        ri4 px = resolve4(p);
        for (int l = 0; x + l < cnt; l++) {
            const int32_t word = px[l]; /* (no address of a vector's element: clang) */
            memcpy(dst + 4 * (x + l), &word, sizeof word);
        }
    }
}

static void stage_resolve(worker *w, const blk *b)
{
    const ctx *c = w->c;
    if (c->n == 1 && !c->depth_only) {
        for (int32_t y = b->y0; y < b->y1; y++)
            resolve_row1(&w->s[(y - b->y0) * b->bw], b->bw,
                         c->rgba + 4 * ((size_t)y * (size_t)c->cam.width + (size_t)b->x0));
    } else { /* several samples a pixel, or the depth alone */
        resolve_block(c, w->s, b, c->n);
    }
}

static int on_resolve(const ctx *c)
{
    (void)c;
    return 1;
}

typedef struct stage_op {
    td_stage id;
    void (*run)(worker *w, const blk *b);
    int (*enabled)(const ctx *c);
    int scratch; /* floats per sample it fills for later stages */
} stage_op;

static const stage_op stage_ops[] = {
#define TD_X_OP(e, name, scratch) {e, stage_##name, on_##name, scratch},
    TD_BLOCK_STAGE_LIST(TD_X_OP)
#undef TD_X_OP
};

#define TD_NSTAGE_OPS ((int)(sizeof stage_ops / sizeof stage_ops[0]))

/* One block through the stages this render runs, each timed on its own. */
static void run_block(worker *w, int bi)
{
    const ctx *c = w->c;
    blk b;
    b.x0 = (bi % c->bx) * TD_BLOCK;
    b.y0 = (bi / c->bx) * c->bh;
    b.x1 = b.x0 + TD_BLOCK < c->cam.width ? b.x0 + TD_BLOCK : c->cam.width;
    b.y1 = b.y0 + c->bh < c->cam.height ? b.y0 + c->bh : c->cam.height;
    b.bw = b.x1 - b.x0;
    b.ns = (int)(b.bw * (b.y1 - b.y0) * c->n * c->n);
    for (int k = 0; k < TD_NSTAGE_OPS; k++) {
        const stage_op *op = &stage_ops[k];
        if (!c->on[op->id])
            continue;
        double t = td_clock_s();
        op->run(w, &b);
        w->stage_s[op->id] += td_clock_s() - t;
        w->st.stage_ran[op->id] = 1;
    }
}

static void *work(void *arg)
{
    worker *w = arg;
    ctx *c = w->c;
    for (;;) {
        if (c->cancel && atomic_load_explicit(c->cancel, memory_order_relaxed)) {
            w->cancelled = 1;
            break;
        }
        int b = atomic_fetch_add_explicit(&c->next, 1, memory_order_relaxed);
        if (b >= c->nblocks)
            break;
        run_block(w, b);
    }
    return NULL;
}

static int cpu_count(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : (n > 256 ? 256 : (int)n);
}

/* Checks the fields core relies on, against the core column of limit.h (the request
 * parser checks the same rows with the service's column; this keeps td_render safe for
 * any caller). */
static td_status check_scene(const td_scene *s, td_err *err)
{
    const td_scene_effects *e = &s->effects;
    td_status rc = td_limit_check(TD_LIMIT_WIDTH, s->image.width, err);
    if (!rc)
        rc = td_limit_check(TD_LIMIT_HEIGHT, s->image.height, err);
    if (!rc)
        rc = td_limit_check(TD_LIMIT_SAMPLES, s->quality.samples, err);
    if (!rc && s->quality.lod)
        rc = td_limit_check(TD_LIMIT_LOD_PIXELS, s->quality.lod_pixels, err);
    if (!rc && (unsigned)s->quality.method >= TD_METHOD_COUNT)
        rc = td_err_field(err, TD_EINVAL, "quality.method", "unknown method %d", (int)s->quality.method);
    if (!rc && (unsigned)s->quality.surface >= TD_SURFACE_COUNT)
        rc = td_err_field(err, TD_EINVAL, "quality.surface", "unknown surface %d", (int)s->quality.surface);
    if (!rc && s->image.format == TD_FORMAT_PICK)
        rc = td_err_field(err, TD_EINVAL, "image.format", "pick is answered by td_render_pick");
    if (!rc)
        rc = td_limit_check(TD_LIMIT_AO_RAYS, e->ambient_occlusion, err);
    if (!rc && e->haze)
        rc = td_limit_check(TD_LIMIT_HAZE_KM, e->haze_visibility_km, err);
    if (!rc)
        rc = td_limit_check(TD_LIMIT_AMBIENT, e->ambient, err);
    if (!rc && !isfinite(e->sun_azimuth))
        rc = td_err_field(err, TD_ERANGE, "effects.sun.azimuth", "must be a finite number");
    if (!rc)
        rc = td_limit_check(TD_LIMIT_SUN_ELEVATION, e->sun_elevation, err);
    if (!rc && e->curvature)
        rc = td_limit_check(TD_LIMIT_CURVATURE_K, e->curvature_k, err);
    return rc;
}

/* Shared setup of render and pick: camera, sun, curvature. */
static td_status setup_ctx(ctx *c, const td_view *v, const td_scene *s, td_err *err)
{
    td_status rc;
    const td_grid *g = v->grid;
    memset(c, 0, sizeof *c);
    c->v = v;
    c->views[0] = v;
    c->s = s;
    c->n = s->quality.samples < 1 ? 1 : s->quality.samples;
    rc = td_camera_setup(&s->camera, s->image.width, s->image.height, g, &c->cam, err);
    if (rc)
        goto out;
    td_shade_sun_dir(s->effects.sun_azimuth, s->effects.sun_elevation, c->sun);
    td_sky_init(&c->sky, c->sun);
    c->gx1 = (g->w - 1) * g->sx;
    c->gy1 = (g->h - 1) * g->sy;
    c->zlo = isfinite(g->zmin) ? g->zmin : 0.0;
    c->zmax = isfinite(g->zmax) ? g->zmax : 0.0;
    c->zspan = c->zmax > c->zlo ? c->zmax - c->zlo : 1.0;
    c->eps = 0.02 * fmin(g->sx, g->sy);
    if (s->effects.water && c->cam.projection == TD_PROJ_ORTHOGRAPHIC &&
        s->effects.water_level + 100.0 > c->cam.ztop)
        c->cam.ztop = s->effects.water_level + 100.0;
    if (s->effects.curvature) {
        c->curv_a = (1.0 - s->effects.curvature_k) / (2.0 * TD_EARTH_RADIUS_M);
        c->curv_smin2 = sqrt(TD_CURVE_EPS2 / c->curv_a);
        c->curv2 = hypot(c->gx1, c->gy1) >= c->curv_smin2;
    }
    if (s->effects.curvature && c->cam.projection != TD_PROJ_ORTHOGRAPHIC) { /* pano: cylindrical too */
        c->curv_smin = 2.0 * c->cam.pixel_angle / c->curv_a;
        /* the farthest the view can reach over the grid: its farthest corner */
        double far = 0.0;
        for (int k = 0; k < 4; k++) {
            double cx = (k & 1) ? c->gx1 : 0.0, cy = (k & 2) ? c->gy1 : 0.0;
            far = fmax(far, hypot(cx - c->cam.o[0], cy - c->cam.o[1]));
        }
        c->curv = far >= c->curv_smin;
    }
out:
    return rc;
}

/* Levels of detail for this view (see the top of the file). */
static td_status setup_lod(ctx *c, const td_lod *lod, td_err *err)
{
    td_status rc = TD_OK;
    const td_grid *g = c->v->grid;
    double cell = g->sx < g->sy ? g->sx : g->sy;
    if (!lod) {
        rc = td_err_field(err, TD_EUNSUPPORTED, "quality.lod",
                          "no coarse levels are resident for this dataset");
    } else {
        c->nlod = lod->levels;
        for (int l = 1; l <= lod->levels; l++)
            c->views[l] = &lod->view[l];
        c->lod_iso = c->s->quality.lod_grid == TD_LOD_GRID_ISOMETRIC ? lod : NULL;
        if (c->lod_iso && lod->levels > 0 && !lod->iso[1])
            rc = td_err_field(err, TD_EUNSUPPORTED, "quality.lod_grid",
                              "no isometric levels are resident for this dataset");
        if (c->cam.projection == TD_PROJ_ORTHOGRAPHIC) {
            /* the coarsest level whose cells still fit lod_pixels pixels */
            double foot = (c->cam.dx < c->cam.dy ? c->cam.dx : c->cam.dy) * c->s->quality.lod_pixels;
            while (c->ortho_level < c->nlod && ldexp(cell, c->ortho_level + 1) <= foot)
                c->ortho_level++;
        } else {
            for (int l = 0; l <= c->nlod; l++)
                c->lod_dist[l] = ldexp(cell, l) / (c->s->quality.lod_pixels * c->cam.pixel_angle);
            c->lod_dist[0] = 0.0;
        }
    }
    return rc;
}


/* The rest of a render's ctx after setup_ctx: levels of detail, blocks, the stages it
 * runs (their predicates, asked once here), the drape (*drape when loaded here: the
 * caller frees it) and the effects' constants. */
/* A block's height: TD_BLOCK_TALL, or the largest power of two down to TD_BLOCK, such
 * that the image of the verticals drifts at most TD_BLOCK_DRIFT pixels sideways over it
 * anywhere in the image (the horizon device's slices are a block tall and TD_BLOCK /
 * TD_SLICES wide: a taller slice's wedge of azimuths is wider by what the verticals
 * drift over it). Upright cameras (level, grazing) then build their horizon bins once for
 * 64 rows instead of 16. Only speed depends on it (every slice's horizon is a bound).
 * Measured (callgrind, primary stage of trinidad's bench views, triangle, M
 * instructions): level 185.6 -> 177.0 (32 rows) / 172.7 (64) / 170.7 (128), grazing
 * 201.3 -> 193.9 / 190.7 / 190.8; 64 rows on the rolled view 265.2 -> 297.1 and the
 * straight-down one 334.3 -> 382.9, which this keeps at 16. */
#define TD_BLOCK_DRIFT 4.0
static int32_t block_height(const ctx *c)
{
    double tilt = 0.0; /* sideways drift of the verticals per pixel up the image */
    int32_t bh = TD_BLOCK;
    if (c->horizon) {
        for (int k = 0; k < 9; k++) { /* corners, edges' middles, centre */
            double vert[2];
            td_camera_rising(&c->cam, 0.5 * (k % 3) * (c->cam.width - 1), 0.5 * (k / 3) * (c->cam.height - 1),
                             vert);
            double t = fabs(vert[1]) > 0.0 ? fabs(vert[0]) / fabs(vert[1]) : INFINITY;
            tilt = t > tilt ? t : tilt;
        }
        /* and no more samples a block than 16 x 16 pixels at 4 x 4 samples (a worker's
           memory, as square blocks at 8 x 8 samples allowed 4 times as many) */
        const int most = TD_BLOCK * TD_BLOCK * 16;
        for (bh = TD_BLOCK_TALL; bh > TD_BLOCK && (bh * tilt > TD_BLOCK_DRIFT || bh * TD_BLOCK * c->n * c->n > most);
             bh /= 2)
            ;
    }
    return bh;
}

static td_status setup_render(ctx *c, const td_render_opts *o, td_image8 **drape, td_err *err)
{
    td_status rc = TD_OK;
    const td_scene *s = c->s;
    if (s->quality.lod) {
        rc = setup_lod(c, o->lod, err);
        if (rc)
            goto out;
    }
    c->cancel = o->cancel;
    /* the horizon bounds the full grid: not for coarse levels (their filtered heights may
       exceed a bin's cells), not for orthographic views (no eye) */
    c->horizon = !(o->off & TD_RENDER_OFF_HORIZON) && c->nlod == 0 &&
                 c->cam.projection == TD_PROJ_PERSPECTIVE;
    c->beam = !(o->off & TD_RENDER_OFF_BEAM) && c->nlod == 0 && c->cam.projection == TD_PROJ_PERSPECTIVE;
    c->plain_secondary = (o->off & TD_RENDER_OFF_OCCLUSION) != 0;
    c->shadow_rays = o->shadow_rays;
    c->depth_only = s->image.format == TD_FORMAT_DEPTH16 || s->image.format == TD_FORMAT_DEPTH32F;
    c->bh = block_height(c);
    c->bx = (s->image.width + TD_BLOCK - 1) / TD_BLOCK;
    c->by = (s->image.height + c->bh - 1) / c->bh;
    c->nblocks = (int)(c->bx * c->by);
    atomic_init(&c->next, 0);
    for (int k = 0; k < TD_NSTAGE_OPS; k++)
        c->on[stage_ops[k].id] = stage_ops[k].enabled(c);

    if (!c->depth_only && s->effects.drape[0]) {
        if (o->drape) {
            c->drape = o->drape;
        } else {
            td_err lerr = {0};
            rc = td_image_load(s->effects.drape, 3,
                               o->drape_max_pixels ? o->drape_max_pixels : 64u << 20, drape, &lerr);
            if (rc) {
                td_err_field(err, rc, "effects.drape", "%s", lerr.msg);
                goto out;
            }
            c->drape = *drape;
        }
    }
    if (c->on[TD_STAGE_HAZE]) {
        c->beta0 = td_haze_beta(s->effects.haze_visibility_km);
        c->zref = c->zlo;
    }
    if (s->effects.ambient_occlusion > 0)
        c->ao_radius = s->effects.ao_radius > 0.0 ? s->effects.ao_radius
                                                  : 16.0 * fmax(c->v->grid->sx, c->v->grid->sy);
out:
    return rc;
}

/* The output: an RGBA8 image, or a float depth image for the depth formats. */
static td_status alloc_image(ctx *c, td_render_result *res, td_err *err)
{
    td_status rc = TD_OK;
    const td_scene *s = c->s;
    size_t npix = (size_t)s->image.width * (size_t)s->image.height, bytes;
    if (c->depth_only) {
        if (!td_mul_size(npix, sizeof(float), &bytes) || !(res->depth = td_bigalloc(bytes)))
            rc = td_err_set(err, TD_ENOMEM, "render: no memory for a %d x %d depth image",
                            (int)s->image.width, (int)s->image.height);
    } else {
        if (!td_mul_size(npix, 4, &bytes) || !(res->rgba = td_bigalloc(bytes)))
            rc = td_err_set(err, TD_ENOMEM, "render: no memory for a %d x %d image",
                            (int)s->image.width, (int)s->image.height);
    }
    c->rgba = res->rgba;
    c->depth = res->depth;
    res->width = s->image.width;
    res->height = s->image.height;
    return rc;
}

static void free_workers(worker *ws, int nthreads)
{
    for (int i = 0; ws && i < nthreads; i++) {
        free(ws[i].s);
        free(ws[i].bs.order);
        for (int k = 0; k < TD_STAGE_COUNT; k++)
            free(ws[i].scratch[k]);
    }
    free(ws);
}

/* nthreads workers, each with its samples and the scratch of the stages that run (the
 * sizes from the stage table). *out is set even on failure, for free_workers. */
static td_status alloc_workers(ctx *c, int nthreads, worker **out, td_err *err)
{
    td_status rc = TD_OK;
    size_t nsmp = (size_t)TD_BLOCK * (size_t)c->bh * (size_t)(c->n * c->n);
    worker *ws = calloc((size_t)nthreads, sizeof *ws);
    if (!ws) {
        rc = td_err_set(err, TD_ENOMEM, "render: no memory for %d workers", nthreads);
        goto out;
    }
    for (int i = 0; i < nthreads && !rc; i++) {
        worker *w = &ws[i];
        w->c = c;
        w->s = malloc(nsmp * sizeof *w->s);
        w->bs.order = malloc(nsmp * sizeof *w->bs.order);
        int ok = w->s != NULL && w->bs.order != NULL;
        for (int k = 0; k < TD_NSTAGE_OPS && ok; k++) {
            const stage_op *op = &stage_ops[k];
            if (op->scratch > 0 && c->on[op->id])
                ok = (w->scratch[op->id] = malloc(nsmp * (size_t)op->scratch * sizeof(float))) != NULL;
        }
        if (!ok)
            rc = td_err_set(err, TD_ENOMEM, "render: no memory for per-thread scratch");
    }
out:
    *out = ws;
    return rc;
}

/* The sun bound of the shadow rays (sunlit.h): the caller's kept one (o->sunlit) when it
 * fits this render's sun and grid, else one built for this render; its time (a lookup, or
 * the build) is the shadows stage's. None with the occlusion device off, or for a sun it
 * cannot bound. */
static td_status setup_sunlit(ctx *c, const td_render_opts *o, td_err *err)
{
    td_status rc = TD_OK;
    if (c->on[TD_STAGE_SHADOWS] && !(o->off & TD_RENDER_OFF_SUNLIT) && !c->plain_secondary) {
        double t = td_clock_s();
        const td_sunlit *kept = NULL;
        int was_kept = 0;
        if (o->sunlit)
            rc = o->sunlit(o->sunlit_ctx, c->v, c->sun, &kept, &was_kept, err);
        if (rc == TD_OK && td_sunlit_fits(kept, c->v, c->sun)) {
            c->sunlit = kept;
            c->sun_bound = was_kept ? TD_SUN_BOUND_KEPT : TD_SUN_BOUND_BUILT;
        } else if (rc == TD_OK) {
            rc = td_sunlit_build(c->v, c->sun, 0, &c->sunlit_own, err);
            c->sunlit = c->sunlit_own;
            c->sun_bound = c->sunlit ? TD_SUN_BOUND_BUILT : TD_SUN_BOUND_NONE;
        }
        c->sunlit_ms = 1000.0 * (td_clock_s() - t);
    }
    return rc;
}

/* Whether `auto` starts its camera rays from the silhouette partition rather than the
 * horizon device: when fewer than TD_AUTO_SILH_MAXMIPS of the grid's tiles hold a
 * max-mipmap (a cold dataset, or one whose structures are being rebuilt). Measured on
 * views without any max-mipmap (README, Silhouette partitioning: primary stage medians
 * lower in 7 of 8 views, fewer instructions in all that callgrind counted). With every
 * max-mipmap built the horizon wins on 3 of 5 views (primary stage instructions, auto
 * with the horizon / with the partition: trinidad sunset 414 / 430 M, levi 427 / 438 M,
 * trinidad grazing 387 / 404 M, picos level 347 / 340 M, picos rolled 422 / 334 M), so
 * built datasets keep it. Between the two (some tiles built) nothing was measured: the
 * half is a guess. */
#define TD_AUTO_SILH_MAXMIPS 0.5

static int auto_silhouette(const td_view *v)
{
    const td_grid *g = v->grid;
    size_t nt = (size_t)g->tiles_x * (size_t)g->tiles_y, with = 0;
    for (size_t k = 0; v->accel && k < nt; k++)
        with += v->accel[k].maxmip != NULL;
    return (double)with < TD_AUTO_SILH_MAXMIPS * (double)nt;
}

/* The silhouette partition of the camera rays (silhouette.h), once per render, with the
 * render's threads; its time is the primary stage's, its entries steps of primary rays.
 * For method silhouette, and for `auto` on a view whose tiles mostly lack a max-mipmap
 * (auto_silhouette); it replaces the horizon and beam devices. Not for what it cannot bound:
 * orthographic views, levels of detail (coarse heights), or with the devices off
 * (TD_RENDER_OFF_HORIZON: camera rays from their start); those rays take the walk. */
static td_status setup_silhouette(ctx *c, const td_render_opts *o, int nthreads, td_err *err)
{
    td_status rc = TD_OK;
    td_method m = c->s->quality.method;
    if ((m == TD_METHOD_SILHOUETTE || (m == TD_METHOD_AUTO && auto_silhouette(c->v))) && c->nlod == 0 &&
        c->cam.projection == TD_PROJ_PERSPECTIVE && !(o->off & TD_RENDER_OFF_HORIZON)) {
        double t = td_clock_s();
        rc = td_silhouette_build(c->v->grid, &c->cam, nthreads, &c->silh, err);
        c->silh_ms = 1000.0 * (td_clock_s() - t);
        c->horizon = c->horizon && !c->silh;
        c->beam = c->beam && !c->silh;
    }
    return rc;
}

/* Runs the workers (the caller's thread is the first; a thread that cannot be started
 * leaves its share to the others) and adds their stats into st in thread order. */
/* The column walk (colwalk.h) for an upright, level perspective camera (its up vector
 * the world's z: td_camera_dirs' x and y the same on every row) or a panorama (every
 * column one azimuth, whatever the pitch) on the full grid, with the method `auto` (the
 * walk is its choice there, as the partition is a cold dataset's), and the eye above
 * every surface around it (td_colwalk_init). With curvature, the rays that bend are the
 * curvature stage's (trace_columns walks them as straight rays for where their chords
 * start). The block wedges' horizon
 * (horizon.h) starts each column's lowest ray, as the fans' for a perspective camera. */
static void setup_columns(ctx *c, const td_render_opts *o)
{
    const td_camera *cam = &c->cam;
    const int level = cam->projection == TD_PROJ_PERSPECTIVE && cam->up[0] == 0.0 && cam->up[1] == 0.0 &&
                      cam->up[2] > 0.0 && cam->fwd[2] == 0.0 && cam->right[2] == 0.0;
    c->columns = !(o->off & TD_RENDER_OFF_COLUMNS) && (level || cam->projection == TD_PROJ_CYLINDRICAL) &&
                 c->nlod == 0 && !c->silh && c->s->quality.method == TD_METHOD_AUTO &&
                 td_colwalk_init(&c->cw, c->v, c->s->quality.surface, cam->o);
    c->col_horizon = c->columns && !(o->off & TD_RENDER_OFF_HORIZON);
}

static td_status run_workers(worker *ws, int nthreads, td_render_stats *st, td_err *err)
{
    td_status rc = TD_OK;
    int started;
    for (started = 1; started < nthreads; started++) {
        if (pthread_create(&ws[started].th, NULL, work, &ws[started]) != 0)
            break; /* run with the threads we got */
    }
    work(&ws[0]);
    for (int i = 1; i < started; i++)
        pthread_join(ws[i].th, NULL);

    st->threads = started;
    for (int i = 0; i < started; i++) {
        worker *w = &ws[i];
        for (int k = 0; k < TD_STAGE_COUNT; k++)
            w->st.stage_ms[k] = 1000.0 * w->stage_s[k] / started;
        td_render_stats_add(st, &w->st);
        if (w->cancelled)
            rc = td_err_set(err, TD_ECANCELED, "render: cancelled");
    }
    return rc;
}

td_status td_render(const td_view *v, const td_scene *s, const td_render_opts *o,
                    td_render_result *res, td_err *err)
{
    td_status rc = TD_OK;
    td_render_opts dflt;
    ctx *c = NULL;
    worker *ws = NULL;
    td_image8 *drape = NULL;
    int nthreads = 0;
    double t_start = td_clock_s();

    memset(res, 0, sizeof *res);
    if (!o) {
        td_render_opts_default(&dflt);
        o = &dflt;
    }
    rc = check_scene(s, err);
    if (rc)
        goto out;
    c = calloc(1, sizeof *c);
    if (!c) {
        rc = td_err_set(err, TD_ENOMEM, "render: no memory");
        goto out;
    }
    rc = setup_ctx(c, v, s, err);
    if (!rc)
        rc = setup_render(c, o, &drape, err);
    if (!rc)
        rc = alloc_image(c, res, err);
    if (rc)
        goto out;
    nthreads = o->threads > 0 ? o->threads : cpu_count();
    if (nthreads > c->nblocks)
        nthreads = c->nblocks;
    rc = alloc_workers(c, nthreads, &ws, err);
    if (!rc)
        rc = setup_sunlit(c, o, err);
    if (!rc)
        rc = setup_silhouette(c, o, nthreads, err);
    if (rc)
        goto out;
    setup_columns(c, o);
    rc = run_workers(ws, nthreads, &res->stats, err);
    res->stats.stage_ms[TD_STAGE_SHADOWS] += c->sunlit_ms;
    res->stats.sun_bound = c->sun_bound;
    res->stats.stage_ms[TD_STAGE_PRIMARY] += c->silh_ms;
    if (c->silh) {
        res->stats.silhouette_entries = c->silh->entries;
        res->stats.steps += c->silh->entries;
        res->stats.kind_steps[TD_RAY_PRIMARY] += c->silh->entries;
    }
    res->stats.total_ms = 1000.0 * (td_clock_s() - t_start);
out:
    free_workers(ws, nthreads);
    td_sunlit_free(c ? c->sunlit_own : NULL);
    td_silhouette_free(c ? c->silh : NULL);
    td_image_free(drape);
    free(c);
    if (rc)
        td_render_result_free(res);
    return rc;
}

td_status td_render_encode(td_render_result *res, const td_scene *s, td_buf *out,
                           double *depth_scale_out, td_err *err)
{
    td_status rc = TD_OK;
    uint16_t *u16 = NULL;
    double t = td_clock_s();
    size_t npix = (size_t)res->width * (size_t)res->height;

    memset(out, 0, sizeof *out);
    if (s->image.format == TD_FORMAT_PNG) {
        if (!res->rgba) {
            rc = td_err_field(err, TD_EINVAL, "image.format", "the render holds no colour image");
            goto out;
        }
        rc = td_image_encode_rgba(res->rgba, res->width, res->height, out, err);
    } else if (s->image.format == TD_FORMAT_DEPTH32F || s->image.format == TD_FORMAT_DEPTH16) {
        if (!res->depth) {
            rc = td_err_field(err, TD_EINVAL, "image.format", "the render holds no depth image");
            goto out;
        }
        if (s->image.format == TD_FORMAT_DEPTH32F) {
            rc = td_image_encode_f32(res->depth, res->width, res->height, out, err);
            goto out;
        }
        double scale = s->image.depth_scale, far = 0.0;
        if (!(scale > 0.0)) {
            for (size_t i = 0; i < npix; i++)
                if (isfinite(res->depth[i]) && res->depth[i] > far)
                    far = res->depth[i];
            scale = far > 0.0 ? far / 65534.0 : 1.0;
        }
        u16 = malloc(npix * sizeof *u16);
        if (!u16) {
            rc = td_err_set(err, TD_ENOMEM, "render: no memory for the depth image");
            goto out;
        }
        for (size_t i = 0; i < npix; i++) {
            double units = res->depth[i] / scale;
            u16[i] = isfinite(res->depth[i]) ? (uint16_t)fmin(65534.0, floor(units + 0.5)) : 65535;
        }
        char val[64];
        snprintf(val, sizeof val, "%.17g", scale);
        if (depth_scale_out)
            *depth_scale_out = scale;
        rc = td_image_encode_gray16(u16, res->width, res->height, "depth_scale_m", val, out, err);
    } else {
        rc = td_err_field(err, TD_EINVAL, "image.format", "%s is not an image encoding",
                          td_format_name(s->image.format));
    }
out:
    free(u16);
    if (!rc) {
        res->stats.stage_ms[TD_STAGE_ENCODE] += 1000.0 * (td_clock_s() - t);
        res->stats.stage_ran[TD_STAGE_ENCODE] = 1;
    }
    return rc;
}

void td_render_result_free(td_render_result *res)
{
    if (res) {
        free(res->rgba);
        free(res->depth);
        res->rgba = NULL;
        res->depth = NULL;
    }
}


/* One picked pixel: its camera ray traced as the render traces it (no levels of
 * detail: a pick names the point of the full grid). */
static void pick_one(const ctx *c, const double px[2], td_pick *pk, td_render_stats *st)
{
    td_ray r;
    td_hit hit;
    int level;
    memset(pk, 0, sizeof *pk);
    pk->px = px[0];
    pk->py = px[1];
    td_camera_ray(&c->cam, pk->px, pk->py, &r);
    pk->height_error_m = trace_camera(c, &r, camera_bends(c, r.o, r.d), 0.0, &hit, &level, st);
    pk->distance = INFINITY;
    if (hit.t < INFINITY) {
        pk->hit = 1;
        memcpy(pk->p, hit.p, sizeof pk->p);
        pk->distance = hit.t;
        pk->ci = hit.ci;
        pk->cj = hit.cj;
    }
}

td_status td_render_pick(const td_view *v, const td_scene *s, td_pick *out,
                         td_render_stats *stats, td_err *err)
{
    td_status rc;
    td_render_stats acc;
    ctx c;
    double t = td_clock_s();

    memset(&acc, 0, sizeof acc);
    if (stats)
        memset(stats, 0, sizeof *stats);
    rc = td_limit_check(TD_LIMIT_PICK, s->npick, err);
    if (!rc)
        rc = setup_ctx(&c, v, s, err);
    if (rc)
        goto out;
    for (int i = 0; i < s->npick; i++)
        pick_one(&c, s->pick[i], &out[i], &acc);
    if (stats) {
        td_render_stats_add(stats, &acc);
        stats->threads = 1;
        stats->stage_ran[TD_STAGE_PRIMARY] = 1;
        stats->stage_ms[TD_STAGE_PRIMARY] = 1000.0 * (td_clock_s() - t);
        stats->total_ms = stats->stage_ms[TD_STAGE_PRIMARY];
    }
out:
    return rc;
}
