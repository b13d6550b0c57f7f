/* horizon.c: the conservative horizon of a wedge of camera rays (see horizon.h for the
 * proof). Called by render.c's primary stage, one wedge per slice of a pixel block.
 *
 * Bins, near to far, each a distance range and the running maximum of the elevation
 * bounds up to it:
 *
 *     d[0]=0      d[1]        d[2]                d[3]             ...  d[n]
 *       | bin 0    | bin 1     | bin 2 (coarse)     | bin 3          |
 *       p[0]       p[1]        p[2]                 p[3]   (non-decreasing)
 *
 * A bin's bound is td_view_max over its bounding box (at most 16 samples or max-mipmap
 * blocks a tile). Coarse bins: the extension
 * keeps a level like the hierarchical walk does (up after a bin it could take whole, down
 * after one it could not), so a stretch far below the asking ray costs a few bins.
 *
 * Measured: see render.c's top comment and docs/accuracy-vs-time.md (camera views). */
#include "horizon.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "maxmip.h"

#define TD_HORIZON_LMAX 8 /* coarsest bin: 2^8 cells deep */

static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

/* The elevation bound of the wedge's bin [d0, d1] (see horizon.h). */
static double bin_bound(const td_horizon *h, double d0, double d1)
{
    const double dirs[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
    double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY, pad, m, e;
    const double *c[2] = {h->c0, h->c1};
    for (int k = 0; k < 4; k++) {
        double r = (k & 2) ? d1 : d0;
        double x = h->ex + r * c[k & 1][0], y = h->ey + r * c[k & 1][1];
        x0 = dmin(x0, x), x1 = dmax(x1, x), y0 = dmin(y0, y), y1 = dmax(y1, y);
    }
    for (int k = 0; k < 4; k++) {
        if (h->axis[k]) {
            double x = h->ex + d1 * dirs[k][0], y = h->ey + d1 * dirs[k][1];
            x0 = dmin(x0, x), x1 = dmax(x1, x), y0 = dmin(y0, y), y1 = dmax(y1, y);
        }
    }
    pad = 1e-9 * d1 + 1e-6;
    m = td_view_max(h->v, td_view_cell(x0 - pad, h->isx), td_view_cell(x1 + pad, h->isx), td_view_cell(y0 - pad, h->isy),
                td_view_cell(y1 + pad, h->isy));
    if (m == -INFINITY) {
        e = -INFINITY;
    } else {
        double rise = m + h->zeps - h->ez;
        e = rise >= 0.0 ? (d0 > 0.0 ? rise / d0 : INFINITY) : rise / d1;
    }
    return e;
}

int td_horizon_begin(td_horizon *h, const td_view *v, const double o[3], double az0, double az1)
{
    const td_grid *g = v->grid;
    int ok = az1 >= az0 && az1 - az0 < 0.5 * M_PI && isfinite(az0) && isfinite(az1) && !isnan(g->zmax);
    memset(h, 0, offsetof(td_horizon, d));
    if (ok) {
        double gx = (g->w - 1) * g->sx, gy = (g->h - 1) * g->sy;
        h->v = v;
        h->ex = o[0];
        h->ey = o[1];
        h->ez = o[2];
        h->az0 = az0 - 1e-9;
        h->az1 = az1 + 1e-9;
        h->c0[0] = cos(h->az0), h->c0[1] = sin(h->az0);
        h->c1[0] = cos(h->az1), h->c1[1] = sin(h->az1);
        for (int k = 0; k < 4; k++) { /* axis direction k*pi/2 (mod 2pi) inside the wedge */
            double a = k * 0.5 * M_PI;
            a += 2.0 * M_PI * ceil((h->az0 - a) / (2.0 * M_PI));
            h->axis[k] = a <= h->az1;
        }
        h->cell = g->sx < g->sy ? g->sx : g->sy;
        h->isx = 1.0 / g->sx;
        h->isy = 1.0 / g->sy;
        h->width = h->az1 - h->az0;
        h->zeps = 1e-6 * (1.0 + dmax(fabs((double)g->zmin), fabs((double)g->zmax)));
        h->ztop = g->zmax;
        h->dmax = 0.0;
        for (int k = 0; k < 4; k++)
            h->dmax = dmax(h->dmax, hypot(((k & 1) ? gx : 0.0) - o[0], ((k & 2) ? gy : 0.0) - o[1]));
        h->d[0] = 0.0;
    }
    h->lev = 1;
    return ok;
}

/* Can terrain at horizontal distance d0 or beyond reach elevation e? */
static int reachable(const td_horizon *h, double d0, double e)
{
    double rise = h->ztop + h->zeps - h->ez;
    double best = rise >= 0.0 ? (d0 > 0.0 ? rise / d0 : INFINITY) : rise / h->dmax;
    return best >= e;
}

/* Appends one bin: as deep as the current level allows while it stays below e, else
 * a fine one. */
static void append_bin(td_horizon *h, double e)
{
    double d0 = h->d[h->n], b, d1;
    for (;;) {
        if (h->lev > 0) {
            d1 = d0 + h->cell * (double)(1 << h->lev);
            b = bin_bound(h, d0, d1);
            if (b < e) {
                h->lev = h->lev < TD_HORIZON_LMAX ? h->lev + 1 : h->lev;
                break;
            }
            h->lev--;
        } else {
            d1 = d0 + dmax(h->cell, h->width * d0);
            b = bin_bound(h, d0, d1);
            h->lev = b < e; /* coarse again only past where the asking rays start */
            break;
        }
    }
    h->p[h->n] = h->n > 0 ? dmax(h->p[h->n - 1], b) : b;
    h->d[++h->n] = d1;
    h->done = d1 >= h->dmax;
}

double td_horizon_extend(td_horizon *h, double e_lo, uint32_t *steps)
{
    double at = INFINITY;
    uint32_t built = 0;
    while (!h->done && h->n < TD_HORIZON_BINS) {
        if (!reachable(h, h->d[h->n], e_lo))
            break; /* a miss: nothing left can rise to the ray */
        append_bin(h, e_lo);
        built++;
        if (h->p[h->n - 1] >= e_lo) {
            h->last = h->n - 1;
            at = h->d[h->n - 1];
            break;
        }
    }
    if (at == INFINITY && !h->done && h->n == TD_HORIZON_BINS)
        at = h->d[h->n]; /* out of bins: nothing before their end */
    *steps += built;
    return at;
}
