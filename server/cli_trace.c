/* cli_trace.c: `terrad trace`: binary rays in, hit distances out, for tests, benchmarks
 * and anyone who wants terrad's tracer without the renderer.
 *
 *   terrad trace --dem FILE [--method M] [--surface S] [--threads N] [--k K]
 *                [--stats FILE] [--encoding E] < rays > hits
 *
 * stdin:  little-endian float64 records `ox oy oz dx dy dz` (48 bytes) in the dataset
 *         frame (x east, y north, metres from the south-west sample); the direction need
 *         not be unit length. A truncated final record is an error.
 * stdout: one little-endian float64 t per ray, hit point = o + t*d, +inf for a miss.
 * Each ray is checked with td_ray_validate before anything is traced; the first bad one
 * is refused with its index and the reason, and nothing is written.
 * --stats FILE writes JSON: rays, hits, steps (total), mean_steps, seconds (tracing
 * only), rays_per_second, threads, method, surface, dem, load_seconds, build_seconds,
 * build_bytes (the acceleration the method needs, built with td_accel_build).
 * Threads split the ray array into contiguous chunks; each writes its own slice of the
 * output and its own counters, so there are no locks.
 * Exit status: 0 ok, 1 runtime failure (load, build, bad input), 2 usage error. */
#include "cli.h"
#include "clock.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

#include "accel.h"
#include "dem.h"
#include "planes.h"
#include "trace.h"

#define TRACE_RECORD 48 /* six float64 */

typedef struct trace_job {
    const td_view *view;
    td_method method;
    td_surface surface;
    const td_ray *rays;
    double *t;
    size_t n0, n1;
    uint64_t steps, hits;
} trace_job;

static void trace_usage(FILE *f)
{
    fprintf(f,
            "usage: terrad trace --dem FILE [--method M] [--surface S] [--threads N] [--k K]\n"
            "                    [--stats FILE] [--encoding E] < rays > hits\n"
            "\n"
            "Reads little-endian float64 rays `ox oy oz dx dy dz` (dataset frame, metres) from\n"
            "stdin and writes one little-endian float64 t per ray (+inf for a miss).\n"
            "  --method M    incremental, hierarchical, parametric, silhouette (here the\n"
            "                incremental walk: its partition is for camera rays), auto\n"
            "                (default auto)\n"
            "  --surface S   plane, linear, triangle, bilinear (default bilinear)\n"
            "  --threads N   tracing and build threads (default: one per core)\n"
            "  --k K         slices of the parameter planes (default %d)\n"
            "  --stats FILE  write JSON statistics (rays, hits, steps, seconds, ...)\n"
            "  --encoding E  PNG height encoding: gray16, terrain-rgb, terrarium, rgb-div\n",
            TD_PLANES_K_DEFAULT);
}

static double le_double(const unsigned char *p)
{
    uint64_t u = 0;
    double d;
    for (int k = 7; k >= 0; k--)
        u = (u << 8) | p[k];
    memcpy(&d, &u, sizeof d);
    return d;
}

static void put_le_double(unsigned char *p, double d)
{
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    for (int k = 0; k < 8; k++, u >>= 8)
        p[k] = (unsigned char)(u & 0xff);
}

/* Reads all of f into a growing buffer. */
static int read_all(FILE *f, unsigned char **out, size_t *len)
{
    int rc = 0;
    size_t cap = 1 << 16, n = 0;
    unsigned char *buf = malloc(cap);
    while (buf && !rc) {
        size_t got;
        if (n == cap) {
            unsigned char *nb;
            if (!td_add_size(cap, cap, &cap)) {
                rc = ENOMEM;
                break;
            }
            nb = realloc(buf, cap);
            if (!nb) {
                rc = ENOMEM;
                break;
            }
            buf = nb;
        }
        got = fread(buf + n, 1, cap - n, f);
        n += got;
        if (got == 0) {
            if (ferror(f))
                rc = EIO;
            break;
        }
    }
    if (!buf)
        rc = ENOMEM;
    if (rc) {
        free(buf);
        buf = NULL;
        n = 0;
    }
    *out = buf;
    *len = n;
    return rc;
}

static void *trace_worker(void *arg)
{
    trace_job *j = arg;
    uint64_t steps = 0, hits = 0;
    for (size_t k = j->n0; k < j->n1; k++) {
        td_hit h;
        td_trace(j->view, j->method, j->surface, &j->rays[k], &h);
        j->t[k] = h.t;
        steps += h.steps;
        hits += h.t < INFINITY;
    }
    j->steps = steps;
    j->hits = hits;
    return NULL;
}

static int write_stats(const char *path, const char *dem, td_method m, td_surface s, size_t n,
                       uint64_t hits, uint64_t steps, double secs, int threads, double load_s,
                       const td_accel_stats *as)
{
    int rc = 1;
    json_t *o = json_pack("{s:s, s:s, s:s, s:I, s:I, s:I, s:f, s:f, s:f, s:i, s:f, s:f, s:I, s:I, s:I}",
                          "dem", dem, "method", td_method_name(m), "surface", td_surface_name(s),
                          "rays", (json_int_t)n, "hits", (json_int_t)hits, "steps",
                          (json_int_t)steps, "mean_steps", n ? (double)steps / (double)n : 0.0,
                          "seconds", secs, "rays_per_second", secs > 0.0 ? (double)n / secs : 0.0,
                          "threads", threads, "load_seconds", load_s, "build_seconds",
                          as->maxmip_seconds + as->planes_seconds, "build_bytes",
                          (json_int_t)(as->maxmip_bytes + as->planes_bytes), "maxmip_bytes",
                          (json_int_t)as->maxmip_bytes, "planes_bytes", (json_int_t)as->planes_bytes);
    if (o && json_dump_file(o, path, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) == 0)
        rc = 0;
    else
        fprintf(stderr, "terrad trace: cannot write statistics to %s\n", path);
    json_decref(o);
    return rc;
}

/* What one `terrad trace` run is asked for, loads and measures. */
typedef struct trace_run {
    const char *dem, *stats;
    td_method method;
    td_surface surface;
    int threads, k;
    td_dem_opts dopts;
    td_grid *g;
    td_accel *acc;
    td_accel_stats astats;
    double load_s;
} trace_run;

/* The command line into run; -1 to go on, else the exit status (help: 0, misuse: 2). */
static int parse_args(int argc, char **argv, trace_run *run)
{
    int rc = -1;
    for (int a = 1; a < argc && rc < 0; a++) {
        const char *opt = argv[a], *val = a + 1 < argc ? argv[a + 1] : NULL;
        int ok = 1;
        if (!strcmp(opt, "-h") || !strcmp(opt, "--help")) {
            trace_usage(stdout);
            rc = 0;
            break;
        } else if (!val) {
            ok = 0;
        } else if (!strcmp(opt, "--dem")) {
            run->dem = val;
        } else if (!strcmp(opt, "--method")) {
            ok = td_method_parse(val, &run->method) == TD_OK;
        } else if (!strcmp(opt, "--surface")) {
            ok = td_surface_parse(val, &run->surface) == TD_OK;
        } else if (!strcmp(opt, "--threads")) {
            ok = td_cli_parse_int(val, 1, 1024, &run->threads);
        } else if (!strcmp(opt, "--k")) {
            ok = td_cli_parse_int(val, 1, TD_PLANES_K_MAX, &run->k);
        } else if (!strcmp(opt, "--stats")) {
            run->stats = val;
        } else if (!strcmp(opt, "--encoding")) {
            ok = td_dem_encoding_parse(val, &run->dopts.encoding) == TD_OK;
        } else {
            ok = 0;
        }
        if (!ok) {
            fprintf(stderr, "terrad trace: bad or incomplete option %s%s%s\n", opt, val ? " " : "",
                    val ? val : "");
            trace_usage(stderr);
            rc = 2;
        }
        a++;
    }
    if (rc < 0 && !run->dem) {
        fprintf(stderr, "terrad trace: --dem FILE is required\n");
        trace_usage(stderr);
        rc = 2;
    }
    return rc;
}

/* Loads the DEM and builds what the method needs (neither is timed as tracing). */
static int load_dem(trace_run *run)
{
    int rc = 1;
    td_err err = {0};
    td_accel_opts aopts;
    double t0 = td_clock_s();
    if (td_dem_load(run->dem, &run->dopts, &run->g, &err) != TD_OK) {
        fprintf(stderr, "terrad trace: %s\n", err.msg);
        goto out;
    }
    run->load_s = td_clock_s() - t0;
    td_accel_opts_for(run->method, &aopts);
    aopts.planes_k = run->k;
    aopts.minima = 0; /* no sun bound to read them */
    aopts.threads = run->threads;
    if ((aopts.maxmip || aopts.planes) && td_accel_build(run->g, &aopts, &run->acc, &run->astats, &err) != TD_OK) {
        fprintf(stderr, "terrad trace: %s: %s\n", run->dem, err.msg);
        goto out;
    }
    rc = 0;
out:
    return rc;
}

/* The rays of stdin, each validated (the first bad one is refused with its index). */
static int read_rays(td_ray **rays_out, size_t *n_out)
{
    int rc = 1;
    td_err err = {0};
    unsigned char *in = NULL;
    size_t len = 0, n = 0, bytes = 0;
    td_ray *rays = NULL;

    if (read_all(stdin, &in, &len) != 0) {
        fprintf(stderr, "terrad trace: cannot read rays from stdin: %s\n", strerror(errno ? errno : EIO));
        goto out;
    }
    n = len / TRACE_RECORD;
    if (len % TRACE_RECORD) {
        fprintf(stderr,
                "terrad trace: truncated input: %zu bytes after ray %zu, a ray is %d bytes "
                "(six little-endian float64: ox oy oz dx dy dz)\n",
                len % TRACE_RECORD, n, TRACE_RECORD);
        goto out;
    }
    if (!td_mul_size(n, sizeof *rays, &bytes) || !(rays = malloc(bytes ? bytes : 1))) {
        fprintf(stderr, "terrad trace: out of memory for %zu rays\n", n);
        goto out;
    }
    for (size_t r = 0; r < n; r++) {
        const unsigned char *p = in + r * TRACE_RECORD;
        for (int c = 0; c < 3; c++) {
            rays[r].o[c] = le_double(p + 8 * c);
            rays[r].d[c] = le_double(p + 24 + 8 * c);
        }
        rays[r].tmin = 0.0;
        rays[r].tmax = INFINITY;
        if (td_ray_validate(&rays[r], &err) != TD_OK) {
            fprintf(stderr, "terrad trace: ray %zu: %s\n", r, err.msg);
            goto out;
        }
    }
    rc = 0;
out:
    free(in);
    if (rc) {
        free(rays);
        rays = NULL;
    }
    *rays_out = rays;
    *n_out = n;
    return rc;
}

/* Traces rays[0 .. n) into t on run->threads threads (contiguous chunks; this thread
 * takes the first); the totals and the seconds around the loops only. */
static int trace_all(trace_run *run, const td_view *view, const td_ray *rays, size_t n, double *t,
                     uint64_t *steps, uint64_t *hits, double *secs)
{
    int rc = 1, started = 0, threads = run->threads;
    trace_job *jobs = calloc((size_t)threads, sizeof *jobs);
    pthread_t *th = calloc((size_t)threads, sizeof *th);
    double t0;

    if (!jobs || !th) {
        fprintf(stderr, "terrad trace: out of memory\n");
        goto out;
    }
    t0 = td_clock_s();
    for (int j = 0; j < threads; j++) {
        jobs[j].view = view;
        jobs[j].method = run->method;
        jobs[j].surface = run->surface;
        jobs[j].rays = rays;
        jobs[j].t = t;
        jobs[j].n0 = n * (size_t)j / (size_t)threads;
        jobs[j].n1 = n * (size_t)(j + 1) / (size_t)threads;
        if (j > 0 && pthread_create(&th[j], NULL, trace_worker, &jobs[j]) != 0) {
            fprintf(stderr, "terrad trace: cannot start thread %d\n", j);
            goto out;
        }
        started = j + 1;
    }
    trace_worker(&jobs[0]);
    for (int j = 1; j < started; j++)
        pthread_join(th[j], NULL);
    started = 0;
    *secs = td_clock_s() - t0;
    for (int j = 0; j < threads; j++) {
        *steps += jobs[j].steps;
        *hits += jobs[j].hits;
    }
    rc = 0;
out:
    for (int j = 1; j < started; j++)
        pthread_join(th[j], NULL);
    free(th);
    free(jobs);
    return rc;
}

/* One little-endian float64 t per ray on stdout. */
static int write_hits(const double *t, size_t n)
{
    int rc = 1;
    unsigned char *outb = malloc(n ? n * 8 : 1);
    if (!outb) {
        fprintf(stderr, "terrad trace: out of memory for %zu rays\n", n);
        goto out;
    }
    for (size_t r = 0; r < n; r++)
        put_le_double(outb + 8 * r, t[r]);
    if ((n && fwrite(outb, 8, n, stdout) != n) || fflush(stdout) != 0) {
        fprintf(stderr, "terrad trace: cannot write hits to stdout\n");
        goto out;
    }
    rc = 0;
out:
    free(outb);
    return rc;
}

int td_cli_trace(int argc, char **argv)
{
    int rc;
    trace_run run;
    size_t n = 0;
    td_ray *rays = NULL;
    double *t = NULL, secs = 0;
    uint64_t steps = 0, hits = 0;
    td_view view;

    memset(&run, 0, sizeof run);
    run.method = TD_METHOD_AUTO;
    run.surface = TD_SURFACE_BILINEAR;
    run.k = TD_PLANES_K_DEFAULT;
    td_dem_opts_default(&run.dopts);
    rc = parse_args(argc, argv, &run);
    if (rc >= 0)
        goto out;
    if (run.threads <= 0)
        run.threads = td_cpu_count();
    rc = load_dem(&run);
    if (!rc)
        rc = read_rays(&rays, &n);
    if (!rc && !(t = malloc(n ? n * sizeof *t : 1))) {
        fprintf(stderr, "terrad trace: out of memory for %zu rays\n", n);
        rc = 1;
    }
    if (rc)
        goto out;
    if ((size_t)run.threads > n)
        run.threads = n ? (int)n : 1;
    view.grid = run.g;
    view.accel = run.acc ? run.acc->tiles : NULL;
    rc = trace_all(&run, &view, rays, n, t, &steps, &hits, &secs);
    if (!rc)
        rc = write_hits(t, n);
    if (!rc && run.stats)
        rc = write_stats(run.stats, run.dem, run.method, run.surface, n, hits, steps, secs, run.threads,
                         run.load_s, &run.astats);
out:
    free(t);
    free(rays);
    td_accel_free(run.acc);
    td_grid_free(run.g);
    return rc;
}
