/* beam.c: the floor of a descending beam of camera rays (see beam.h for the proof).
 * Called by render.c's primary stage for the slices of a pixel block that the horizon
 * cannot bound. A few max-mipmap queries a slice, shared by all its rays.
 *
 * Measured: see render.c's top comment and docs/accuracy-vs-time.md (camera views). */
#include "beam.h"

#include <math.h>

/* The highest cell corner under the box of the beam's points between heights zlo and zhi,
 * or -inf if no cell with terrain lies under it. */
static double beam_box_max(const td_view *v, const double o[3], const double (*d)[3], int nd, double zlo,
                           double zhi)
{
    const td_grid *g = v->grid;
    double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    for (int k = 0; k < nd; k++) {
        for (int e = 0; e < 2; e++) {
            double s = (o[2] - (e ? zhi : zlo)) / -d[k][2];
            double x = o[0] + s * d[k][0], y = o[1] + s * d[k][1];
            x0 = fmin(x0, x), x1 = fmax(x1, x), y0 = fmin(y0, y), y1 = fmax(y1, y);
        }
    }
    double pad = 1e-9 * fmax(fmax(fabs(x0), fabs(x1)), fmax(fabs(y0), fabs(y1))) + 1e-6;
    const double isx = 1.0 / g->sx, isy = 1.0 / g->sy;
    return td_view_max(v, td_view_cell(x0 - pad, isx), td_view_cell(x1 + pad, isx), td_view_cell(y0 - pad, isy),
                       td_view_cell(y1 + pad, isy));
}

double td_beam_floor(const td_view *v, const double o[3], const double (*d)[3], int nd, uint32_t *steps)
{
    const td_grid *g = v->grid;
    double zhi = INFINITY, run = 0.0; /* the corners' largest horizontal run a metre of descent */
    int ok = nd > 0 && !isnan(g->zmax) && isfinite(o[0]) && isfinite(o[1]) && isfinite(o[2]);
    for (int k = 0; k < nd; k++) {
        ok = ok && d[k][2] < 0.0 && isfinite(d[k][0]) && isfinite(d[k][1]);
        run = ok ? fmax(run, hypot(d[k][0], d[k][1]) / -d[k][2]) : run;
    }
    if (ok) {
        const double zeps = 1e-6 * (1.0 + fmax(fabs((double)g->zmin), fabs((double)g->zmax)));
        const double zlo = (double)g->zmin - zeps;
        /* a band's box reaches TD_BEAM_BAND_CELLS cells past the beam's footprint */
        double band = TD_BEAM_BAND_CELLS * fmin(g->sx, g->sy) / fmax(run, 1e-300);
        zhi = fmin(o[2], (double)g->zmax + zeps);
        for (int round = 0; round < TD_BEAM_ROUNDS && zhi > zlo; round++) {
            /* the first round over every height the rays may meet terrain at, then bands */
            double zb = round == 0 ? zlo : fmax(zlo, zhi - band);
            double m = beam_box_max(v, o, d, nd, zb, zhi);
            (*steps)++;
            /* no terrain under the band's box, or all of it below the band: the rays
               cross the band freely (below zlo, the walls of the solid surfaces); the
               next band twice as deep */
            band *= m + zeps < zb ? 2.0 : 1.0;
            m = m == -INFINITY ? zb : fmax(m + zeps, zb);
            if (m >= zhi)
                break;
            zhi = m;
        }
    }
    return zhi;
}
