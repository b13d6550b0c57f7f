/* cli_render.c: `terrad render SCENE.json -o OUT [--stats FILE] [--threads N] [--rays FILE]
 * [--shadow-rays FILE] [--edit X,Y,W,H,FILE ...]`: the
 * render path of the server without HTTP. The scene is parsed by the same pure function
 * as POST /v1/render (server/request.c), with file paths allowed.
 *
 * `dataset` (and `effects.drape`) are looked up as given, then beside the scene file,
 * then under the source tree's data/ folder, where a demo id names a folder (the first
 * file in it that the DEM loaders recognise, by name order) or a file. The acceleration
 * the method needs is built for the whole grid (hierarchical: max-mipmaps; parametric:
 * parameter planes; auto: both) and timed as `accel_ms`.
 *
 * Output: the image in the scene's format (png, depth16, depth32f), or for format pick
 * the JSON answer of POST /v1/pick (answer.c: the dataset as the scene names it, and the
 * terrain point of each pixel). --stats writes JSON: rays {primary, shadow, reflection,
 * ao}, steps {total, primary, shadow, reflection, ao}, coherent_rays, horizon_bins,
 * silhouette_rays, silhouette_entries, column_rays, hits, curved_rays, curved_secondary,
 * curve_segments, height_error_m {mean, max, hits}, sun_bound (none, built),
 * stages_ms (one entry per stage that ran), load_ms, accel_ms, render_ms, total_ms,
 * threads, bytes. --rays and --shadow-rays write the render's rays for another tracer
 * (the benchmark traces them with Embree). --edit applies a heights edit to the loaded
 * DEM before anything is built, by the same functions as PUT .../heights (gridedit.h:
 * X, Y the region's north-west sample, row 0 north; FILE W*H little-endian float32, row
 * 0 north, NaN void); repeated, the edits apply in order, so a render of the edited
 * file can be compared with the service's after the same edits.
 * Exit status: 0 ok, 1 runtime failure, 2 usage or scene error. */
#include "cli.h"
#include "answer.h"
#include "clock.h"

#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <jansson.h>

#include "accel.h"
#include "dem.h"
#include "gridedit.h"
#include "limit.h"
#include "mercator.h"
#include "render.h"
#include "request.h"
#include "solar.h"

#ifndef TERRAD_SOURCE_DIR
#define TERRAD_SOURCE_DIR "."
#endif

#define TD_SCENE_FILE_MAX (4u << 20)

static void render_usage(FILE *f)
{
    fprintf(f, "usage: terrad render SCENE.json -o OUT [--stats FILE] [--threads N] [--rays FILE]\n"
               "                    [--shadow-rays FILE]\n"
               "\n"
               "Renders a scene (the JSON body of POST /v1/render) to OUT in the scene's\n"
               "image.format: png, depth16 (16-bit PNG), depth32f (raw float32) or pick (JSON).\n"
               "`dataset` may be a DEM file path or a demo id (a folder under %s/data).\n"
               "  -o OUT          output file ('-' for stdout)\n"
               "  --stats FILE    write rays by kind and per-stage timings as JSON\n"
               "  --threads N     render threads (default: one per core)\n"
               "  --rays FILE     write the camera ray of every pixel centre (the render's\n"
               "                  primary rays when samples is 1), row-major from the top-left\n"
               "                  pixel, as `terrad trace` input (float64 ox oy oz dx dy dz)\n"
               "  --shadow-rays FILE  write the shadow rays the render traced, in image order,\n"
               "                  in the same format\n"
               "  --edit X,Y,W,H,FILE  apply a heights edit first, as PUT /v1/admin/datasets/\n"
               "                  {id}/heights?x=X&y=Y&w=W&h=H with FILE as the body (W*H\n"
               "                  little-endian float32, row 0 north, NaN void); repeatable\n",
               TERRAD_SOURCE_DIR);
}

static int is_file(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

static int is_dir(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISDIR(st.st_mode);
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(const char *const *)a, *(const char *const *)b);
}

/* First file of dir (by name) the DEM loaders recognise, into out. */
static int first_dem_in(const char *dir, char *out, size_t cap)
{
    int found = 0;
    DIR *d = opendir(dir);
    char *names[256];
    size_t n = 0;
    struct dirent *e;
    if (!d)
        return 0;
    while ((e = readdir(d)) && n < 256) {
        if (e->d_name[0] != '.')
            names[n++] = strdup(e->d_name);
    }
    closedir(d);
    qsort(names, n, sizeof names[0], cmp_str);
    for (size_t i = 0; i < n; i++) {
        char p[4096];
        if (!found && names[i] && snprintf(p, sizeof p, "%s/%s", dir, names[i]) < (int)sizeof p &&
            is_file(p) && td_dem_recognised(p)) {
            snprintf(out, cap, "%s", p);
            found = 1;
        }
        free(names[i]);
    }
    return found;
}

/* Resolves a dataset or drape name (see the top of the file). */
static int resolve(const char *name, const char *scene_dir, int dem, char *out, size_t cap)
{
    char p[4096];
    int ok = 0;
    const char *bases[3] = {NULL, scene_dir, TERRAD_SOURCE_DIR "/data"};
    for (int b = 0; b < 3 && !ok; b++) {
        if (b == 0)
            snprintf(p, sizeof p, "%s", name);
        else if (name[0] == '/' || !bases[b])
            continue;
        else
            snprintf(p, sizeof p, "%s/%s", bases[b], name);
        if (is_file(p)) {
            snprintf(out, cap, "%s", p);
            ok = 1;
        } else if (dem && is_dir(p)) {
            ok = first_dem_in(p, out, cap);
        }
    }
    return ok;
}

static char *read_file(const char *path, size_t *len)
{
    char *buf = NULL;
    FILE *f = fopen(path, "rb");
    if (f) {
        buf = malloc(TD_SCENE_FILE_MAX + 1);
        if (buf) {
            *len = fread(buf, 1, TD_SCENE_FILE_MAX + 1, f);
            if (ferror(f) || *len > TD_SCENE_FILE_MAX) {
                free(buf);
                buf = NULL;
            }
        }
        fclose(f);
    }
    return buf;
}

static json_t *stats_json(const td_render_stats *st)
{
    json_t *o = json_object(), *rays = json_object(), *stages = json_object();
    for (int k = 0; k < TD_RAY_KIND_COUNT; k++)
        json_object_set_new(rays, td_ray_kind_name((td_ray_kind)k), json_integer((json_int_t)st->rays[k]));
    for (int k = 0; k < TD_STAGE_COUNT; k++)
        if (st->stage_ran[k])
            json_object_set_new(stages, td_stage_name((td_stage)k), json_real(st->stage_ms[k]));
    json_t *methods = json_object();
    for (int k = 0; k < TD_METHOD_COUNT; k++)
        if (st->method_rays[k])
            json_object_set_new(methods, td_method_name((td_method)k), json_integer((json_int_t)st->method_rays[k]));
    json_object_set_new(o, "methods", methods);
    json_t *lod = json_array();
    int top = 0;
    for (int k = 0; k <= TD_LOD_MAX; k++)
        if (st->lod_rays[k])
            top = k;
    for (int k = 0; k <= top; k++)
        json_array_append_new(lod, json_integer((json_int_t)st->lod_rays[k]));
    json_object_set_new(o, "lod_rays", lod);
    json_object_set_new(o, "rays", rays);
    json_object_set_new(o, "stages_ms", stages);
    json_t *steps = json_object();
    json_object_set_new(steps, "total", json_integer((json_int_t)st->steps));
    for (int k = 0; k < TD_RAY_KIND_COUNT; k++)
        json_object_set_new(steps, td_ray_kind_name((td_ray_kind)k), json_integer((json_int_t)st->kind_steps[k]));
    json_object_set_new(o, "steps", steps);
    json_object_set_new(o, "coherent_rays", json_integer((json_int_t)st->coherent_rays));
    json_object_set_new(o, "horizon_bins", json_integer((json_int_t)st->horizon_bins));
    json_object_set_new(o, "silhouette_rays", json_integer((json_int_t)st->silhouette_rays));
    json_object_set_new(o, "silhouette_entries", json_integer((json_int_t)st->silhouette_entries));
    json_object_set_new(o, "column_rays", json_integer((json_int_t)st->column_rays));
    json_object_set_new(o, "hits", json_integer((json_int_t)st->hits));
    json_object_set_new(o, "curved_rays", json_integer((json_int_t)st->curved_rays));
    json_object_set_new(o, "curved_secondary", json_integer((json_int_t)st->curved_secondary));
    json_object_set_new(o, "curve_segments", json_integer((json_int_t)st->curve_segments));
    json_object_set_new(o, "sun_bound", json_string(td_sun_bound_name(st->sun_bound)));
    json_object_set_new(o, "height_error_m",
                        json_pack("{s:f, s:f, s:I}", "mean", st->height_err_mean_m, "max", st->height_err_max_m,
                                  "hits", (json_int_t)st->height_err_hits));
    json_object_set_new(o, "threads", json_integer(st->threads));
    json_object_set_new(o, "render_ms", json_real(st->total_ms));
    return o;
}

#define TD_CLI_EDITS_MAX 64

/* What one `terrad render` run reads, builds and writes. */
typedef struct render_run {
    const char *scene_path, *out_path, *stats_path, *rays_path, *shadow_path;
    int threads;
    const char *edits[TD_CLI_EDITS_MAX]; /* --edit arguments, in order */
    int nedits;
    td_scene *scene; /* large (the pick list): heap */
    char scene_dir[4096], dem_path[4096];
    td_grid *g;
    td_accel *acc;
    td_lod *lod;
    double load_ms, accel_ms;
} render_run;

/* The command line into run; -1 to go on, else the exit status (help: 0, misuse: 2). */
static int parse_args(int argc, char **argv, render_run *run)
{
    int rc = -1;
    for (int i = 1; i < argc && rc < 0; i++) {
        if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
            render_usage(stdout);
            rc = 0;
        } else if (!strcmp(argv[i], "-o") && i + 1 < argc) {
            run->out_path = argv[++i];
        } else if (!strcmp(argv[i], "--stats") && i + 1 < argc) {
            run->stats_path = argv[++i];
        } else if (!strcmp(argv[i], "--rays") && i + 1 < argc) {
            run->rays_path = argv[++i];
        } else if (!strcmp(argv[i], "--shadow-rays") && i + 1 < argc) {
            run->shadow_path = argv[++i];
        } else if (!strcmp(argv[i], "--edit") && i + 1 < argc) {
            if (run->nedits == TD_CLI_EDITS_MAX) {
                fprintf(stderr, "terrad render: at most %d --edit options\n", TD_CLI_EDITS_MAX);
                rc = 2;
            } else {
                run->edits[run->nedits++] = argv[++i];
            }
        } else if (!strcmp(argv[i], "--threads") && i + 1 < argc) {
            char *end = NULL;
            long v = strtol(argv[++i], &end, 10);
            if (*end || v < 1 || v > 1024) {
                fprintf(stderr, "terrad render: --threads wants 1 .. 1024\n");
                rc = 2;
            }
            run->threads = (int)v;
        } else if (argv[i][0] == '-' && argv[i][1]) {
            fprintf(stderr, "terrad render: unknown option '%s'\n", argv[i]);
            render_usage(stderr);
            rc = 2;
        } else if (!run->scene_path) {
            run->scene_path = argv[i];
        } else {
            fprintf(stderr, "terrad render: one scene file only\n");
            rc = 2;
        }
    }
    if (rc < 0 && (!run->scene_path || !run->out_path)) {
        render_usage(stderr);
        rc = 2;
    }
    return rc;
}

/* The limits of a render from the command line: larger than the service's, and paths. */
static void cli_limits(td_request_limits *lim)
{
    td_request_limits_default(lim);
    lim->max_width = lim->max_height = 16384;
    lim->max_pixels = (uint64_t)16384 * 16384;
    lim->max_samples = (int)td_limit_get(TD_LIMIT_SAMPLES)->max; /* what core accepts */
    lim->max_samples_total = (uint64_t)1 << 32;
    lim->max_ao_rays = (int)td_limit_get(TD_LIMIT_AO_RAYS)->max;
    lim->max_pick = (int)td_limit_get(TD_LIMIT_PICK)->max;
    lim->allow_paths = 1;
}

/* Reads and parses the scene file, then finds its dataset and drape (see the top of the
 * file). 0, or the exit status: 1 unreadable or not found, 2 a bad scene. */
static int load_scene(render_run *run)
{
    int rc = 1;
    size_t len = 0;
    char *body = read_file(run->scene_path, &len), *slash;
    char drape_path[4096];
    td_request_limits lim;
    td_request_error rerr;
    td_scene *scene = run->scene = malloc(sizeof *run->scene);

    if (!body) {
        fprintf(stderr, "terrad render: %s: cannot read (or larger than %u bytes): %s\n", run->scene_path,
                TD_SCENE_FILE_MAX, strerror(errno));
        goto out;
    }
    cli_limits(&lim);
    if (!scene)
        goto out;
    if (td_request_parse_scene(body, len, &lim, scene, &rerr)) {
        fprintf(stderr, "terrad render: %s: %s%s%s\n", run->scene_path, rerr.field,
                rerr.field[0] ? ": " : "", rerr.message);
        rc = 2;
        goto out;
    }
    snprintf(run->scene_dir, sizeof run->scene_dir, "%s", run->scene_path);
    slash = strrchr(run->scene_dir, '/');
    if (slash)
        *slash = 0;
    else
        snprintf(run->scene_dir, sizeof run->scene_dir, ".");
    if (!resolve(scene->dataset, run->scene_dir, 1, run->dem_path, sizeof run->dem_path)) {
        fprintf(stderr, "terrad render: dataset: '%s' is neither a DEM file nor a demo id under %s/data\n",
                scene->dataset, TERRAD_SOURCE_DIR);
        goto out;
    }
    if (scene->effects.drape[0]) {
        if (!resolve(scene->effects.drape, run->scene_dir, 0, drape_path, sizeof drape_path)) {
            fprintf(stderr, "terrad render: effects.drape: '%s' not found\n", scene->effects.drape);
            goto out;
        }
        if (strlen(drape_path) >= sizeof scene->effects.drape) {
            fprintf(stderr, "terrad render: effects.drape: path '%s' is too long\n", drape_path);
            goto out;
        }
        memcpy(scene->effects.drape, drape_path, strlen(drape_path) + 1);
    }
    rc = 0;
out:
    free(body);
    return rc;
}

/* --edit X,Y,W,H,FILE: the four numbers checked as the API checks its query (the same
 * messages), FILE read as its body; run->g replaced by the edited copy. */
static td_status apply_edit(render_run *run, const char *arg, td_err *err)
{
    td_status rc;
    char num[4][24];
    const char *p = arg;
    static const char *const names[4] = {"x", "y", "w", "h"};
    td_grid_region r;
    td_grid *g = NULL;

    for (int k = 0; k < 4; k++) {
        size_t l = strcspn(p, ",");
        if (!p[l] || l >= sizeof num[k]) {
            rc = td_err_set(err, TD_EINVAL, "--edit %s: want X,Y,W,H,FILE (%s missing or too long)", arg, names[k]);
            goto out;
        }
        memcpy(num[k], p, l);
        num[k][l] = '\0';
        p += l + 1;
    }
    rc = td_grid_edit_parse(run->g, num[0], num[1], num[2], num[3], INT64_MAX, &r, err);
    if (!rc)
        rc = td_grid_edit_file(run->g, &r, p, &g, err);
    if (rc)
        goto out;
    td_grid_free(run->g);
    run->g = g;
out:
    return rc;
}

/* Loads the DEM and builds what the method needs for the whole grid (and the levels of
 * detail when asked), timed as load_ms and accel_ms. 0, or 1 with the error printed. */
/* effects.sun.time: the sun at that instant over the grid's centre (solar.h), in the grid's
 * frame, as the server computes it (routes.c). */
static td_status sun_at_time(render_run *run, td_err *err)
{
    td_merc_proj *proj = NULL;
    double ll[4], merc[4], centre[2];
    td_scene_effects *fx = &run->scene->effects;
    td_status rc = td_merc_proj_create(run->dem_path, run->g, &proj, err);
    if (!rc) {
        td_merc_proj_bounds(proj, ll, merc, centre);
        rc = td_solar_in_grid(centre[0], centre[1], td_merc_proj_grid_north(proj), fx->sun_time_s,
                              &fx->sun_azimuth, &fx->sun_elevation, err);
    }
    td_merc_proj_free(proj);
    return rc;
}

static int load_dataset(render_run *run)
{
    int rc = 1;
    td_err err = {0};
    td_dem_opts dopts;
    td_accel_opts aopts;
    td_accel_stats ast;
    td_method m = run->scene->quality.method;
    double t = 1e3 * td_clock_s();

    td_dem_opts_default(&dopts);
    if (td_dem_load(run->dem_path, &dopts, &run->g, &err))
        goto out;
    for (int i = 0; i < run->nedits; i++)
        if (apply_edit(run, run->edits[i], &err))
            goto out;
    if (run->scene->effects.sun_time && sun_at_time(run, &err))
        goto out;
    run->load_ms = 1e3 * td_clock_s() - t;
    td_accel_opts_for(m, &aopts);
    aopts.threads = run->threads;
    if (aopts.maxmip || aopts.planes) {
        t = 1e3 * td_clock_s();
        if (td_accel_build(run->g, &aopts, &run->acc, &ast, &err))
            goto out;
        run->accel_ms = 1e3 * td_clock_s() - t;
    }
    if (run->scene->quality.lod) {
        t = 1e3 * td_clock_s();
        if (td_lod_build(run->g, TD_LOD_MAX, &aopts, &run->lod, &err))
            goto out;
        if (run->scene->quality.lod_grid == TD_LOD_GRID_ISOMETRIC &&
            td_lod_add_iso(run->lod, run->g, &err))
            goto out;
        run->accel_ms += 1e3 * td_clock_s() - t;
    }
    rc = 0;
out:
    if (rc)
        fprintf(stderr, "terrad render: %s\n", err.msg);
    return rc;
}

/* Format pick: the answer of /v1/pick into the output file; *stats gets the stats. */
static int write_picks(const render_run *run, const td_view *view, json_t **stats)
{
    int rc = 1;
    td_err err = {0};
    td_render_stats pst;
    td_pick *picks = calloc((size_t)run->scene->npick, sizeof *picks);
    json_t *pjson = NULL;
    char *text = NULL;

    if (!picks || td_render_pick(view, run->scene, picks, &pst, &err)) {
        fprintf(stderr, "terrad render: %s\n", picks ? err.msg : "no memory");
        goto out;
    }
    pjson = td_answer_picks(run->scene->dataset, run->g, picks, run->scene->npick); /* as /v1/pick */
    text = json_dumps(pjson, JSON_INDENT(2) | JSON_REAL_PRECISION(12));
    if (!text || !td_cli_write_file(run->out_path, text, strlen(text))) {
        fprintf(stderr, "terrad render: %s: cannot write\n", run->out_path);
        goto out;
    }
    *stats = stats_json(&pst);
    rc = 0;
out:
    json_decref(pjson);
    free(text);
    free(picks);
    return rc;
}

/* An image format: render, encode, write; *stats gets the stats, the size, the scale. */
/* Appends a ray to f in the ray format of `terrad trace` (little-endian float64). */
static int put_ray(FILE *f, const td_ray *r)
{
    unsigned char b[48];
    for (int k = 0; k < 6; k++) {
        double v = k < 3 ? r->o[k] : r->d[k - 3];
        uint64_t u;
        memcpy(&u, &v, sizeof u);
        for (int j = 0; j < 8; j++)
            b[8 * k + j] = (unsigned char)(u >> (8 * j));
    }
    return fwrite(b, sizeof b, 1, f) == 1;
}

/* --rays: the camera ray of every pixel centre, row-major from the top-left pixel (the
 * rays td_render traces for samples 1: the same td_camera_ray at the same coordinates). */
static int write_camera_rays(const render_run *run, const td_grid *g)
{
    int rc = 1;
    td_camera cam;
    td_err err = {0};
    FILE *f = NULL;
    if (td_camera_setup(&run->scene->camera, run->scene->image.width, run->scene->image.height, g, &cam,
                        &err)) {
        fprintf(stderr, "terrad render: %s\n", err.msg);
        goto out;
    }
    f = fopen(run->rays_path, "wb");
    for (int32_t y = 0; f && y < cam.height; y++) {
        for (int32_t x = 0; x < cam.width; x++) {
            td_ray r;
            td_camera_ray(&cam, x, y, &r);
            if (!put_ray(f, &r))
                goto out;
        }
    }
    rc = f && fclose(f) == 0 ? 0 : 1;
    f = NULL;
out:
    if (f)
        fclose(f);
    if (rc)
        fprintf(stderr, "terrad render: %s: cannot write the rays: %s\n", run->rays_path, strerror(errno));
    return rc;
}

/* --shadow-rays: the render's shadow rays (slots with a ray), in image order. */
static int write_shadow_rays(const render_run *run, const td_ray *rays, size_t n)
{
    int ok = 1;
    FILE *f = fopen(run->shadow_path, "wb");
    for (size_t k = 0; f && ok && k < n; k++)
        if (rays[k].tmax >= 0.0)
            ok = put_ray(f, &rays[k]);
    ok = f && ok;
    if (f && fclose(f) != 0)
        ok = 0;
    if (!ok)
        fprintf(stderr, "terrad render: %s: cannot write the shadow rays: %s\n", run->shadow_path, strerror(errno));
    return ok ? 0 : 1;
}

static int write_image(const render_run *run, const td_view *view, json_t **stats)
{
    int rc = 1;
    td_err err = {0};
    td_render_opts ropts;
    td_render_result res;
    td_buf buf = {0};
    double scale = 0.0;
    size_t nslots = 0;

    memset(&res, 0, sizeof res);
    td_render_opts_default(&ropts);
    ropts.threads = run->threads;
    ropts.lod = run->lod;
    if (run->shadow_path) {
        int n = run->scene->quality.samples;
        nslots = (size_t)run->scene->image.width * (size_t)run->scene->image.height * (size_t)(n * n);
        ropts.shadow_rays = calloc(nslots, sizeof *ropts.shadow_rays);
        if (!ropts.shadow_rays) {
            fprintf(stderr, "terrad render: no memory for %zu shadow rays\n", nslots);
            goto out;
        }
    }
    if (td_render(view, run->scene, &ropts, &res, &err) || td_render_encode(&res, run->scene, &buf, &scale, &err)) {
        fprintf(stderr, "terrad render: %s\n", err.msg);
        goto out;
    }
    if ((run->rays_path && write_camera_rays(run, view->grid)) ||
        (run->shadow_path && write_shadow_rays(run, ropts.shadow_rays, nslots)))
        goto out;
    if (!td_cli_write_file(run->out_path, buf.data, buf.len)) {
        fprintf(stderr, "terrad render: %s: cannot write: %s\n", run->out_path, strerror(errno));
        goto out;
    }
    *stats = stats_json(&res.stats);
    json_object_set_new(*stats, "bytes", json_integer((json_int_t)buf.len));
    if (scale > 0.0)
        json_object_set_new(*stats, "depth_scale_m", json_real(scale));
    rc = 0;
out:
    free(ropts.shadow_rays);
    td_buf_free(&buf);
    td_render_result_free(&res);
    return rc;
}

/* --stats: the render's stats and what the run was. 0, or 1 when it cannot be written. */
static int write_stats(const render_run *run, json_t *stats, double t0)
{
    const td_scene *scene = run->scene;
    json_object_set_new(stats, "dataset", json_string(run->dem_path));
    json_object_set_new(stats, "width", json_integer(scene->image.width));
    json_object_set_new(stats, "height", json_integer(scene->image.height));
    json_object_set_new(stats, "method", json_string(td_method_name(scene->quality.method)));
    json_object_set_new(stats, "surface", json_string(td_surface_name(scene->quality.surface)));
    json_object_set_new(stats, "samples", json_integer(scene->quality.samples));
    /* the sun the picture was shaded with (from effects.sun.time, or as given) */
    json_object_set_new(stats, "sun", json_pack("{s:f,s:f}", "azimuth", scene->effects.sun_azimuth, "elevation",
                                                 scene->effects.sun_elevation));
    json_object_set_new(stats, "load_ms", json_real(run->load_ms));
    json_object_set_new(stats, "accel_ms", json_real(run->accel_ms));
    json_object_set_new(stats, "total_ms", json_real((1e3 * td_clock_s()) - t0));
    if (json_dump_file(stats, run->stats_path, JSON_INDENT(2) | JSON_REAL_PRECISION(6))) {
        fprintf(stderr, "terrad render: %s: cannot write the stats\n", run->stats_path);
        return 1;
    }
    return 0;
}

int td_cli_render(int argc, char **argv)
{
    int rc;
    render_run run;
    json_t *stats = NULL;
    double t0 = 1e3 * td_clock_s();

    memset(&run, 0, sizeof run);
    rc = parse_args(argc, argv, &run);
    if (rc >= 0)
        goto out;
    rc = load_scene(&run);
    if (!rc)
        rc = load_dataset(&run);
    if (!rc) {
        td_view view = {run.g, run.acc ? run.acc->tiles : NULL};
        rc = run.scene->image.format == TD_FORMAT_PICK ? write_picks(&run, &view, &stats)
                                                       : write_image(&run, &view, &stats);
    }
    if (!rc && run.stats_path)
        rc = write_stats(&run, stats, t0);
out:
    json_decref(stats);
    td_lod_free(run.lod);
    td_accel_free(run.acc);
    td_grid_free(run.g);
    free(run.scene);
    return rc;
}
