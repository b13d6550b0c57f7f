/* vs_terrains.h: the exact terrains of the viewshed's tests (test_vsweep.c's
 * test_exact_terrains, tests/fuzz/fuzz_viewshed.c): planes, and on them a saddle of
 * |i - i0| |j - j0|, one hyperbolic paraboloid, a checkerboard on a ridge, a plateau with
 * straight edges, or terraces. Small integer and quarter coefficients, so that float
 * heights hold them exactly or nearly: segments lie in the surface's planes, leave the eye
 * along them, graze the plateau's edges. */
#ifndef VS_TERRAINS_H
#define VS_TERRAINS_H

#include <math.h>
#include <stdlib.h>

enum { VS_T_PLANE, VS_T_SADDLE, VS_T_HYPAR, VS_T_CHECKER, VS_T_PLATEAU, VS_T_TERRACES, VS_T_COUNT };

/* Sample (i, j)'s height on terrain `kind`: 200 + a i + b j, and c, d and the centre
 * (i0, j0) for the shapes on it. */
static inline double vs_exact_z(int kind, double a, double b, double c, double d, int i0, int j0, int i, int j)
{
    double z = 200.0 + a * i + b * j;
    if (kind == VS_T_SADDLE)
        z += c * abs(i - i0) * abs(j - j0);
    else if (kind == VS_T_HYPAR)
        z += c * (i - i0) * (j - j0);
    else if (kind == VS_T_CHECKER)
        z += d * ((i + j) & 1) + c * abs(i - i0);
    else if (kind == VS_T_PLATEAU)
        z += abs(i - i0) + abs(j - j0) < 6 ? 5.0 * d : 0.0;
    else if (kind == VS_T_TERRACES)
        z = floor(z / 4.0) * 4.0 + c * ((i * 7 + j * 3) % 5);
    return z;
}

#endif
