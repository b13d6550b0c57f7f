/* bench_svg.c: scatter charts as SVG for the benchmark report (see bench_svg.h).
 *
 * Layout: a 760 x 480 canvas, plot area inset for the axis labels, a legend at the top
 * right. Log axes get ticks at the powers of ten (and 2, 5 between them when the range
 * is under three decades); linear axes get five even ticks. Text is escaped for XML.
 * Alternative rejected: gnuplot or a Python plotting library, which would make `make
 * bench` depend on packages the build does not otherwise need. */
#include "bench_svg.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SVG_W 760.0
#define SVG_H 480.0
#define PL 80.0  /* plot left */
#define PR 560.0 /* plot right (legend beyond) */
#define PT 40.0
#define PB 420.0

static const char *const colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd",
                                      "#ff7f0e", "#8c564b", "#e377c2", "#17becf"};

typedef struct axis {
    int log;
    double lo, hi; /* in axis units (log10 if log) */
} axis;

static double axis_val(const axis *a, double v, double floor_)
{
    if (a->log)
        return log10(v > floor_ ? v : floor_);
    return v;
}

static void xml_text(FILE *f, const char *s)
{
    for (; *s; s++) {
        if (*s == '<')
            fputs("&lt;", f);
        else if (*s == '>')
            fputs("&gt;", f);
        else if (*s == '&')
            fputs("&amp;", f);
        else
            fputc(*s, f);
    }
}

static void fit(axis *a, double mn, double mx)
{
    if (a->log) {
        mn = floor(log10(mn));
        mx = ceil(log10(mx));
        if (mx <= mn)
            mx = mn + 1;
    } else {
        double span = mx - mn;
        if (span <= 0)
            span = fabs(mx) > 0 ? fabs(mx) : 1;
        mn -= 0.05 * span;
        mx += 0.05 * span;
        if (mn > 0 && mn < 0.3 * mx)
            mn = 0;
    }
    a->lo = mn;
    a->hi = mx;
}

static double px(const axis *a, double v) { return PL + (v - a->lo) / (a->hi - a->lo) * (PR - PL); }
static double py(const axis *a, double v) { return PB - (v - a->lo) / (a->hi - a->lo) * (PB - PT); }

static void fmt_tick(char *buf, size_t n, double v)
{
    if (v != 0 && (fabs(v) >= 1e5 || fabs(v) < 1e-2))
        snprintf(buf, n, "%.0e", v);
    else
        snprintf(buf, n, "%g", v);
}

static void ticks(FILE *f, const axis *a, int vertical)
{
    int nt = 0;
    double tv[64];
    if (a->log) {
        static const double sub[] = {1, 2, 5};
        int dense = a->hi - a->lo <= 3;
        for (int e = (int)a->lo; e <= (int)a->hi && nt < 60; e++)
            for (int s = 0; s < (dense ? 3 : 1); s++) {
                double v = log10(sub[s]) + e;
                if (v <= a->hi + 1e-9)
                    tv[nt++] = v;
            }
    } else {
        for (int k = 0; k <= 5; k++)
            tv[nt++] = a->lo + (a->hi - a->lo) * k / 5.0;
    }
    for (int k = 0; k < nt; k++) {
        char buf[32];
        fmt_tick(buf, sizeof buf, a->log ? pow(10, tv[k]) : tv[k]);
        if (vertical) {
            double y = py(a, tv[k]);
            fprintf(f, "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/>\n", PL, y, PR, y);
            fprintf(f, "<text x='%.1f' y='%.1f' text-anchor='end' font-size='11'>%s</text>\n", PL - 4,
                    y + 4, buf);
        } else {
            double x = px(a, tv[k]);
            fprintf(f, "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/>\n", x, PT, x, PB);
            fprintf(f, "<text x='%.1f' y='%.1f' text-anchor='middle' font-size='11'>%s</text>\n", x,
                    PB + 15, buf);
        }
    }
}

static int cmp_x(const void *a, const void *b)
{
    const double *p = a, *q = b;
    return p[0] < q[0] ? -1 : p[0] > q[0] ? 1 : (p[1] < q[1] ? -1 : p[1] > q[1]);
}

td_status td_bench_svg_write(const char *path, const td_bench_svg_chart *c,
                             const td_bench_svg_point *p, size_t n, td_err *err)
{
    td_status rc = TD_OK;
    FILE *f = NULL;
    axis ax = {c->xlog, 0, 1}, ay = {c->ylog, 0, 1};
    double xmn = INFINITY, xmx = -INFINITY, ymn = INFINITY, ymx = -INFINITY;
    double *front = NULL;
    size_t nf = 0;

    for (size_t k = 0; k < n; k++) {
        double y = c->ylog && p[k].y < c->yfloor ? c->yfloor : p[k].y;
        if (!isfinite(p[k].x) || !isfinite(p[k].y) || (c->xlog && p[k].x <= 0) || (c->ylog && y <= 0))
            continue;
        xmn = fmin(xmn, p[k].x);
        xmx = fmax(xmx, p[k].x);
        ymn = fmin(ymn, y);
        ymx = fmax(ymx, y);
    }
    if (!(xmn <= xmx)) {
        xmn = c->xlog ? 1 : 0;
        xmx = xmn + 1;
        ymn = c->ylog ? 1 : 0;
        ymx = ymn + 1;
    }
    fit(&ax, xmn, xmx);
    fit(&ay, ymn, ymx);
    f = fopen(path, "w");
    if (!f) {
        rc = td_err_set(err, TD_EIO, "%s: cannot write the chart", path);
        goto out;
    }
    fprintf(f, "<svg xmlns='http://www.w3.org/2000/svg' width='%.0f' height='%.0f' viewBox='0 0 %.0f %.0f' "
               "font-family='sans-serif'>\n", SVG_W, SVG_H, SVG_W, SVG_H);
    fprintf(f, "<rect width='100%%' height='100%%' fill='white'/>\n");
    fprintf(f, "<text x='%.1f' y='22' text-anchor='middle' font-size='14' font-weight='bold'>", SVG_W / 2);
    xml_text(f, c->title);
    fprintf(f, "</text>\n");
    ticks(f, &ax, 0);
    ticks(f, &ay, 1);
    fprintf(f, "<rect x='%.1f' y='%.1f' width='%.1f' height='%.1f' fill='none' stroke='black'/>\n", PL, PT,
            PR - PL, PB - PT);
    fprintf(f, "<text x='%.1f' y='%.1f' text-anchor='middle' font-size='12'>", (PL + PR) / 2, PB + 34);
    xml_text(f, c->xlabel);
    fprintf(f, "</text>\n<text transform='translate(18 %.1f) rotate(-90)' text-anchor='middle' "
               "font-size='12'>", (PT + PB) / 2);
    xml_text(f, c->ylabel);
    fprintf(f, "</text>\n");
    if (c->ylog && c->yfloor > 0)
        fprintf(f, "<text x='%.1f' y='%.1f' font-size='10' fill='#666'>values &lt;= %g drawn at the floor</text>\n",
                PL + 4, PB - 4, c->yfloor);

    /* Pareto front: sort by x, keep points lower than every point left of them */
    if (c->pareto && n > 0) {
        front = malloc(2 * n * sizeof *front);
        if (front) {
            size_t m = 0;
            for (size_t k = 0; k < n; k++) {
                double y = c->ylog && p[k].y < c->yfloor ? c->yfloor : p[k].y;
                if (isfinite(p[k].x) && isfinite(y) && (!c->xlog || p[k].x > 0)) {
                    front[2 * m] = axis_val(&ax, p[k].x, 0);
                    front[2 * m + 1] = axis_val(&ay, y, c->yfloor);
                    m++;
                }
            }
            qsort(front, m, 2 * sizeof *front, cmp_x);
            double best = INFINITY;
            for (size_t k = 0; k < m; k++) {
                if (front[2 * k + 1] < best) {
                    best = front[2 * k + 1];
                    front[2 * nf] = front[2 * k];
                    front[2 * nf + 1] = front[2 * k + 1];
                    nf++;
                }
            }
            if (nf > 0) {
                fprintf(f, "<polyline fill='none' stroke='#999' stroke-dasharray='4 3' points='");
                for (size_t k = 0; k < nf; k++) {
                    if (k > 0)
                        fprintf(f, "%.1f,%.1f ", px(&ax, front[2 * k]), py(&ay, front[2 * k - 1]));
                    fprintf(f, "%.1f,%.1f ", px(&ax, front[2 * k]), py(&ay, front[2 * k + 1]));
                }
                fprintf(f, "'/>\n");
            }
        }
    }
    for (size_t k = 0; k < n; k++) {
        double y = c->ylog && p[k].y < c->yfloor ? c->yfloor : p[k].y;
        const char *col = colours[(p[k].series < 0 ? 0 : p[k].series) % 8];
        double X, Y;
        if (!isfinite(p[k].x) || !isfinite(y) || (c->xlog && p[k].x <= 0))
            continue;
        X = px(&ax, axis_val(&ax, p[k].x, 0));
        Y = py(&ay, axis_val(&ay, y, c->yfloor));
        fprintf(f, "<circle cx='%.1f' cy='%.1f' r='4' fill='%s' fill-opacity='0.8'><title>", X, Y, col);
        xml_text(f, p[k].label);
        fprintf(f, ": %g, %g</title></circle>\n", p[k].x, p[k].y);
        if (p[k].label[0]) {
            fprintf(f, "<text x='%.1f' y='%.1f' font-size='9' fill='%s'>", X + 6, Y - 3, col);
            xml_text(f, p[k].label);
            fprintf(f, "</text>\n");
        }
    }
    for (int s = 0; s < c->nseries; s++) {
        double y = PT + 10 + 18 * s;
        fprintf(f, "<circle cx='%.1f' cy='%.1f' r='5' fill='%s'/>\n", PR + 20, y, colours[s % 8]);
        fprintf(f, "<text x='%.1f' y='%.1f' font-size='12'>", PR + 30, y + 4);
        xml_text(f, c->series[s]);
        fprintf(f, "</text>\n");
    }
    if (c->pareto)
        fprintf(f, "<text x='%.1f' y='%.1f' font-size='11' fill='#666'>- - Pareto front</text>\n", PR + 14,
                PT + 14 + 18 * c->nseries);
    fprintf(f, "</svg>\n");
    if (fclose(f) != 0)
        rc = td_err_set(err, TD_EIO, "%s: cannot write the chart", path);
    f = NULL;
out:
    if (f)
        fclose(f);
    free(front);
    return rc;
}
