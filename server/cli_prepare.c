/* cli_prepare.c: `terrad prepare DEM OUT_DIR`: writes the prepared form of a DEM
 * (core/prepared.h) that `terrad serve --data` serves in constant start time. It streams
 * (.f32 and GDAL rasters a chunk of rows at a time; .asc, .hgt and .png through their
 * whole-file loaders), shows a progress bar on a terminal, and continues where a killed
 * or stopped run left off (the folder's prepare.state).
 *
 * Exit status: 0 done (or already done), 1 failure or stopped (--stop-after), 2 usage. */
#include "cli.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <jansson.h>

#include "clock.h"
#include "planes.h"
#include "prepared.h"

typedef struct prep_bar {
    int tty;
    double t0, last;
    int64_t chunks, stop_after;
    int structures; /* the bar is the structures' */
    uint64_t row_bytes;
} prep_bar;

static int progress(void *cls, int64_t done, int64_t total, int32_t width_samples)
{
    prep_bar *b = cls;
    double now = td_clock_s(), el = now - b->t0;
    if (width_samples == 0) { /* the tiles' structures: tile rows */
        if (b->tty && !b->structures && b->chunks)
            fputc('\n', stderr); /* keep the heights' bar */
        b->structures = 1;
        if (b->tty && (now - b->last > 0.2 || done == total)) {
            int width = 40, fill = total ? (int)(width * done / total) : width;
            fprintf(stderr, "\r[%.*s%*s] %3d%%  structures: %lld of %lld tile rows ", fill,
                    "########################################", width - fill, "",
                    total ? (int)(100 * done / total) : 100, (long long)done, (long long)total);
            fflush(stderr);
            b->last = now;
        }
        b->chunks++;
        return b->stop_after > 0 && b->chunks >= b->stop_after;
    }
    b->row_bytes = (uint64_t)width_samples * 4u;
    if (b->tty && (now - b->last > 0.2 || done == total)) {
        int width = 40, fill = total ? (int)(width * done / total) : width;
        double mb = (double)done * (double)b->row_bytes / 1048576.0;
        fprintf(stderr, "\r[%.*s%*s] %3d%%  %.0f MiB  %.0f MiB/s ", fill,
                "########################################", width - fill, "",
                total ? (int)(100 * done / total) : 100, mb, el > 0 ? mb / el : 0.0);
        fflush(stderr);
        b->last = now;
    }
    b->chunks++;
    return b->stop_after > 0 && b->chunks >= b->stop_after;
}

static void usage(FILE *f)
{
    fprintf(f, "usage: terrad prepare DEM OUT_DIR [--tile-size N] [--spacing SX[,SY]] [--chunk-rows N]\n"
               "                      [--block-size B] [--planes-k K] [--threads N] [--stop-after CHUNKS] [--quiet]\n"
               "Writes DEM (any format terrad reads) into OUT_DIR as terrad's prepared form:\n"
               "heights.f32 and heights.blk (memory-mapped by terrad serve), the levels lodK.f32,\n"
               "tiles.bin, every tile's max-mipmap and parameter planes (accel.tab, accel.bin,\n"
               "built after the heights on every core) and the index terrad.json.\n"
               "A run that is killed or stopped continues where it left off when run again.\n"
               "  --tile-size N      cells per tile side, a power of two (default 256)\n"
               "  --spacing SX[,SY]  metres between samples when the DEM does not say\n"
               "  --chunk-rows N     rows per chunk (checksum and resume unit; default the tile size)\n"
               "  --block-size B     cells per block side of heights.blk, a power of two 4..256 (default 32)\n"
               "  --planes-k K       slices of the tiles' parameter planes, 1..255 (default 16); 0: no planes\n"
               "                     (max-mipmaps only: parametric then walks cell by cell; auto never reads them)\n"
               "  --threads N        threads that build the structures (default one a core)\n"
               "  --stop-after K     stop after K chunks, tile rows of structures included (to try resuming)\n"
               "  --quiet            no progress bar\n");
}

static int parse_spacing(const char *s, double sp[2])
{
    char *end = NULL;
    sp[0] = strtod(s, &end);
    sp[1] = sp[0];
    if (end && *end == ',')
        sp[1] = strtod(end + 1, &end);
    return end && *end == '\0' && sp[0] > 0 && sp[1] > 0;
}

/* The options into o and b; 0, or 2 for a usage error (printed), or -1 for --help. */
static int parse_args(int argc, char **argv, const char **pos, td_prepare_opts *o, prep_bar *b)
{
    int npos = 0, rc = 0, v = 0;
    for (int i = 1; i < argc && rc == 0; i++) {
        const char *a = argv[i], *next = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            rc = -1;
        } else if (!strcmp(a, "--quiet")) {
            b->tty = 0;
        } else if (!strcmp(a, "--tile-size") && next && td_cli_parse_int(next, 2, 65536, &v) && !(v & (v - 1))) {
            o->dem.tile_log2 = 0;
            while ((1 << o->dem.tile_log2) < v)
                o->dem.tile_log2++;
            i++;
        } else if (!strcmp(a, "--block-size") && next &&
                   td_cli_parse_int(next, 1 << TD_PREPARED_BLOCK_LOG2_MIN, 1 << TD_PREPARED_BLOCK_LOG2_MAX, &v) &&
                   !(v & (v - 1))) {
            while ((1 << o->block_log2) < v)
                o->block_log2++;
            i++;
        } else if (!strcmp(a, "--chunk-rows") && next && td_cli_parse_int(next, 1, 1 << 20, &v)) {
            o->chunk_rows = v;
            i++;
        } else if (!strcmp(a, "--planes-k") && next && td_cli_parse_int(next, 0, TD_PLANES_K_MAX, &v)) {
            o->planes_k = v ? v : TD_PREPARE_NO_PLANES;
            i++;
        } else if (!strcmp(a, "--threads") && next && td_cli_parse_int(next, 1, 64, &v)) {
            o->threads = v;
            i++;
        } else if (!strcmp(a, "--stop-after") && next && td_cli_parse_int(next, 1, 1 << 30, &v)) {
            b->stop_after = v;
            i++;
        } else if (!strcmp(a, "--spacing") && next && parse_spacing(next, o->dem.spacing)) {
            i++;
        } else if (a[0] != '-' && npos < 2) {
            pos[npos++] = a;
        } else {
            fprintf(stderr, "terrad prepare: bad or incomplete option '%s'\n", a);
            rc = 2;
        }
    }
    if (rc == 0 && npos != 2) {
        fprintf(stderr, "terrad prepare: give DEM and OUT_DIR\n");
        rc = 2;
    }
    if (rc == 2)
        usage(stderr);
    return rc;
}

int td_cli_prepare(int argc, char **argv)
{
    int rc = 1;
    const char *pos[2] = {NULL, NULL};
    td_prepare_opts o;
    td_prepare_result res;
    prep_bar b;
    td_err e = {0};
    td_status st;
    double t;

    memset(&o, 0, sizeof o);
    memset(&b, 0, sizeof b);
    td_dem_opts_default(&o.dem);
    b.tty = isatty(2);
    rc = parse_args(argc, argv, pos, &o, &b);
    if (rc) {
        if (rc == -1)
            usage(stdout);
        rc = rc == -1 ? 0 : rc;
        goto out;
    }
    o.progress = progress;
    o.cls = &b;
    b.t0 = b.last = td_clock_s();
    st = td_prepare(pos[0], pos[1], &o, &res, &e);
    t = td_clock_s() - b.t0;
    if (b.tty && b.chunks)
        fputc('\n', stderr);
    if (st) {
        fprintf(stderr, "terrad prepare: %s\n", e.msg);
        rc = 1;
        goto out;
    }
    {
        double mib = (double)(res.bytes - (uint64_t)res.resumed_rows * (uint64_t)res.w * 4u) / 1048576.0;
        json_t *j = json_pack("{s:s, s:s, s:I, s:I, s:I, s:b, s:I, s:b, s:i, s:f, s:f}", "dem", pos[0], "out", pos[1],
                              "width", (json_int_t)res.w, "height", (json_int_t)res.h,
                              "bytes", (json_int_t)res.bytes, "already", res.already,
                              "resumed_rows", (json_int_t)res.resumed_rows, "streamed", res.streamed,
                              "levels", res.levels,
                              "seconds", t, "mib_per_s", t > 0 && !res.already ? mib / t : 0.0);
        char *text = j ? json_dumps(j, JSON_COMPACT) : NULL;
        if (text)
            printf("%s\n", text);
        free(text);
        json_decref(j);
    }
    rc = 0;
out:
    return rc;
}
