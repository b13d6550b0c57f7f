/* fuzz_terrain.h: what the fuzz targets that trace small grids (fuzz_viewshed.c,
 * fuzz_render.c) read from their input: bytes and doubles, the heights of a grid (one of
 * the exact terrains of tests/unit/vs_terrains.h, or the input's own bytes) and its voids.
 * An input that ends early reads zeros, so a shorter input is still a case. */
#ifndef TD_FUZZ_TERRAIN_H
#define TD_FUZZ_TERRAIN_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "grid.h"
#include "../unit/vs_terrains.h"

typedef struct fuzz_reader {
    const uint8_t *p;
    size_t n, at;
} fuzz_reader;

/* The next byte, 0 past the end */
static inline unsigned fuzz_byte(fuzz_reader *r) { return r->at < r->n ? r->p[r->at++] : 0u; }

/* The next 8 bytes as a double (0 past the end) */
static inline double fuzz_double(fuzz_reader *r)
{
    uint8_t b[8];
    double d;
    for (int k = 0; k < 8; k++)
        b[k] = (uint8_t)fuzz_byte(r);
    memcpy(&d, b, sizeof d);
    return d;
}

/* Heights: one of vs_terrains.h's exact terrains, or (the kind after them) the input's
 * bytes, a byte a sample in 0.25 m steps. */
static inline void fuzz_fill(td_grid *g, fuzz_reader *r)
{
    int kind = (int)(fuzz_byte(r) % (VS_T_COUNT + 1));
    double a = (double)(fuzz_byte(r) % 7) - 3.0, b = (double)(fuzz_byte(r) % 7) - 3.0;
    double c = ((double)(fuzz_byte(r) % 9) - 4.0) * 0.25, d = (double)(fuzz_byte(r) % 3);
    int i0 = (int)(fuzz_byte(r) % (unsigned)g->w), j0 = (int)(fuzz_byte(r) % (unsigned)g->h);
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] =
                (float)(kind == VS_T_COUNT ? 200.0 + 0.25 * ((double)fuzz_byte(r) - 128.0)
                                           : vs_exact_z(kind, a, b, c, d, i0, j0, i, j));
}

/* A grid of 2 .. max_side samples a side from the next three bytes (width, height, then
 * spacing 10, 7.5, 1 or 1000 m with rows 1, 4/3, 5/3 or 3/4 of it: lines that are not
 * representable; tiles of 8, 16 or 32 cells), filled by fuzz_fill; NULL if it cannot be
 * made (a harness failure). */
static inline td_grid *fuzz_grid(fuzz_reader *r, int32_t max_side)
{
    static const double sxs[] = {10.0, 7.5, 1.0, 1000.0}, aspect[] = {1.0, 4.0 / 3.0, 5.0 / 3.0, 0.75};
    td_grid *g = NULL;
    int32_t w = 2 + (int32_t)(fuzz_byte(r) % (unsigned)(max_side - 1));
    int32_t h = 2 + (int32_t)(fuzz_byte(r) % (unsigned)(max_side - 1));
    unsigned sp = fuzz_byte(r);
    double sx = sxs[sp % 4], sy = sx * aspect[(sp >> 2) % 4];
    if (td_grid_create(w, h, sx, sy, 3 + (int)((sp >> 4) % 3), NULL, &g, NULL) == TD_OK)
        fuzz_fill(g, r);
    return g;
}

/* Voids, from byte v: v % 4 = 0 none, 1 a rectangle (from the four bytes of rect), 2 the
 * samples with (5 i + 3 j + v / 4) % 7 == 0, 3 a row and a column through the grid's
 * middle. */
static inline void fuzz_holes(td_grid *g, unsigned v, const uint8_t *rect)
{
    int32_t w = g->w, h = g->h;
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++) {
            int hole = 0;
            if (v % 4 == 1)
                hole = i >= rect[0] % w && i <= rect[0] % w + rect[1] % 6 && j >= rect[2] % h &&
                       j <= rect[2] % h + rect[3] % 6;
            else if (v % 4 == 2)
                hole = (5 * i + 3 * j + (int)(v / 4)) % 7 == 0;
            else if (v % 4 == 3)
                hole = i == w / 2 || j == h / 2;
            if (hole)
                g->z[(size_t)j * (size_t)w + (size_t)i] = NAN;
        }
}

#endif
