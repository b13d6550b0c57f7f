/* bench_main.c: terrad-bench, the accuracy-vs-time benchmark and its report (bench.c
 * measures, bench_report.c writes), also run as `terrad bench` (server/cli_bench.c execs
 * this program with the same arguments). Options only; see bench.h for what is measured.
 * A program of its own, beside terrad, because it links Embree and the daemon must not.
 * Exit status: 0 ok, 1 runtime failure, 2 usage error. */
#include "cli.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "bigalloc.h"

static void bench_usage(FILE *f, const td_bench_opts *d)
{
    fprintf(f,
            "usage: terrad-bench [--out DIR] [--runs N] [--quick] [--sections LIST]\n"
            "                    [--trinidad FILE] [--picos FILE] [--levi FILE] [--scene-dem FILE]\n"
            "                    [--procedural N] [--quiet]\n"
            "       terrad-bench --write-rays FILE [--rays-dataset NAME] [dataset options]\n"
            "       (`terrad bench ...` runs this program with the same arguments)\n"
            "\n"
            "Measures every tracer and surface against Embree on the same rays (one thread\n"
            "each), the error of every surface and option against the bilinear surface,\n"
            "Paglieroni's and Qu's tables, the cost of each effect and camera views' camera\n"
            "and shadow rays against Embree's rtcIntersect16 / rtcOccluded16, and writes\n"
            "DIR/accuracy-vs-time.md, DIR/bench-summary.md and DIR/bench/*.svg.\n"
            "  --out DIR          report directory (default %s)\n"
            "  --runs N           repetitions per figure, the median is reported (default %d)\n"
            "  --quick            tiny ray sets and images: checks the machinery, measures nothing\n"
            "  --sections LIST    comma-separated subset of speed,error,paglieroni,qu,effects,camera\n"
            "                     (default all; the report leaves out what did not run)\n"
            "  --trinidad FILE    Trinidad DEM (default %s)\n"
            "  --picos FILE       Picos de Europa DEM (default %s)\n"
            "  --levi FILE        Levi DEM (default %s)\n"
            "  --scene-dem FILE   DEM of the standard scene of the effects table (default %s)\n"
            "  --procedural N     side of the procedural DEM, 0 leaves it out (default %d)\n"
            "  --write-rays FILE  write the speed section's rays of one dataset as `terrad trace`\n"
            "                     input (float64 ox oy oz dx dy dz) and stop\n"
            "  --rays-dataset D   trinidad, picos, levi or procedural (default trinidad)\n"
            "  --quiet            no progress on stderr\n",
            d->out_dir, d->runs, d->trinidad, d->picos, d->levi, d->scene_dem, d->procedural);
}

static int copy_path(char *dst, size_t n, const char *src)
{
    int ok = strlen(src) < n;
    if (ok)
        memcpy(dst, src, strlen(src) + 1);
    return ok;
}

static int parse_sections(const char *list, unsigned *out)
{
    char buf[256];
    int ok = strlen(list) < sizeof buf;
    unsigned bits = 0;
    if (ok) {
        char *save = NULL;
        memcpy(buf, list, strlen(list) + 1);
        for (char *tok = strtok_r(buf, ",", &save); tok && ok; tok = strtok_r(NULL, ",", &save)) {
            td_bench_section s;
            ok = td_bench_section_parse(tok, &s) == TD_OK;
            if (ok)
                bits |= 1u << s;
        }
    }
    if (ok && bits)
        *out = bits;
    return ok && bits;
}

int main(int argc, char **argv)
{
    int rc = 2;
    td_bench_opts o, defaults;
    td_err err = {0};

    td_bigalloc_policy(); /* terrad's: the renders' buffers as the server allocates them */
    td_bench_opts_default(&o);
    defaults = o;
    o.verbose = 1;
    for (int a = 1; a < argc; a++) {
        const char *opt = argv[a], *val = a + 1 < argc ? argv[a + 1] : NULL;
        int ok = 1, flag = 0;
        if (!strcmp(opt, "-h") || !strcmp(opt, "--help")) {
            bench_usage(stdout, &defaults);
            rc = 0;
            goto out;
        } else if (!strcmp(opt, "--quick")) {
            o.quick = 1;
            flag = 1;
        } else if (!strcmp(opt, "--quiet")) {
            o.verbose = 0;
            flag = 1;
        } else if (!val) {
            ok = 0;
        } else if (!strcmp(opt, "--out")) {
            o.out_dir = val;
        } else if (!strcmp(opt, "--runs")) {
            ok = td_cli_parse_int(val, 1, 1000, &o.runs);
        } else if (!strcmp(opt, "--sections")) {
            ok = parse_sections(val, &o.sections);
        } else if (!strcmp(opt, "--trinidad")) {
            ok = copy_path(o.trinidad, sizeof o.trinidad, val);
        } else if (!strcmp(opt, "--picos")) {
            ok = copy_path(o.picos, sizeof o.picos, val);
        } else if (!strcmp(opt, "--levi")) {
            ok = copy_path(o.levi, sizeof o.levi, val);
        } else if (!strcmp(opt, "--scene-dem")) {
            ok = copy_path(o.scene_dem, sizeof o.scene_dem, val);
        } else if (!strcmp(opt, "--procedural")) {
            ok = td_cli_parse_int(val, 0, 8192, &o.procedural) && (o.procedural == 0 || o.procedural >= 16);
        } else if (!strcmp(opt, "--write-rays")) {
            o.write_rays = val;
        } else if (!strcmp(opt, "--rays-dataset")) {
            o.rays_dataset = val;
        } else {
            ok = 0;
        }
        if (!ok) {
            fprintf(stderr, "terrad-bench: bad or incomplete option %s%s%s\n", opt, val && !flag ? " " : "",
                    val && !flag ? val : "");
            bench_usage(stderr, &defaults);
            goto out;
        }
        if (!flag)
            a++;
    }
    rc = 1;
    if (td_bench_run(&o, &err) != TD_OK) {
        fprintf(stderr, "terrad-bench: %s\n", err.msg);
        goto out;
    }
    if (o.write_rays)
        fprintf(stderr, "terrad-bench: wrote the %s rays to %s\n", o.rays_dataset, o.write_rays);
    else if (o.verbose)
        fprintf(stderr, "terrad-bench: wrote %s/accuracy-vs-time.md\n", o.out_dir);
    rc = 0;
out:
    return rc;
}
