/* bench_svg.h: the charts of `terrad bench` as plain SVG (no plotting library): a
 * scatter plot with linear or log axes, one colour per series, a label per point, and
 * the Pareto front (points no other point beats on both axes) drawn as a step line. */
#ifndef TD_BENCH_SVG_H
#define TD_BENCH_SVG_H

#include <stddef.h>

#include "status.h"

typedef struct td_bench_svg_point {
    double x, y;
    int series;        /* index into the chart's series names */
    char label[48];    /* short text beside the point (may be empty) */
} td_bench_svg_point;

typedef struct td_bench_svg_chart {
    const char *title, *xlabel, *ylabel;
    int xlog, ylog;            /* log10 axes */
    double yfloor;             /* log y: values below are drawn on the floor ("<= floor") */
    const char *const *series; /* names, nseries of them */
    int nseries;
    int pareto;                /* draw the front (smaller x and smaller y are better) */
} td_bench_svg_chart;

/* Writes the chart to path. Points with a non-finite coordinate are left out. */
td_status td_bench_svg_write(const char *path, const td_bench_svg_chart *c,
                             const td_bench_svg_point *p, size_t n, td_err *err);

#endif
