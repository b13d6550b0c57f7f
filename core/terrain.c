/* terrain.c: procedural height fields for tests and benchmarks.
 *
 * Gradient (Perlin-style) noise on an integer lattice, hashed from the seed with
 * splitmix64, summed over octaves (fBm). Ridged octaves use 1 - |n| squared, the usual
 * way to get sharp crests and valleys that stress tracers more than smooth hills. The
 * result is rescaled to [base_m, base_m + relief_m] exactly. */
#include "terrain.h"

#include <math.h>

void td_terrain_params_default(td_terrain_params *p)
{
    p->width = 1025;
    p->height = 1025;
    p->spacing = 30.0;
    p->seed = 1;
    p->octaves = 8;
    p->feature_m = 12000.0;
    p->relief_m = 2500.0;
    p->base_m = 500.0;
    p->ridge = 0.6;
}

static uint64_t splitmix64(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

/* Unit gradient at lattice point (ix, iy) of octave o. */
static void gradient(uint64_t seed, int o, int64_t ix, int64_t iy, double *gx, double *gy)
{
    uint64_t hsh = splitmix64(seed ^ splitmix64((uint64_t)ix * 0x100000001b3ull ^
                                                splitmix64((uint64_t)iy + ((uint64_t)o << 48))));
    double a = (double)(hsh >> 11) * (2.0 * M_PI / 9007199254740992.0);
    *gx = cos(a);
    *gy = sin(a);
}

static double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

/* Gradient noise in about [-0.7, 0.7]. */
static double noise(uint64_t seed, int o, double x, double y)
{
    double fx = floor(x), fy = floor(y);
    int64_t ix = (int64_t)fx, iy = (int64_t)fy;
    double u = x - fx, v = y - fy;
    double g[4][2];
    gradient(seed, o, ix, iy, &g[0][0], &g[0][1]);
    gradient(seed, o, ix + 1, iy, &g[1][0], &g[1][1]);
    gradient(seed, o, ix, iy + 1, &g[2][0], &g[2][1]);
    gradient(seed, o, ix + 1, iy + 1, &g[3][0], &g[3][1]);
    double n00 = g[0][0] * u + g[0][1] * v;
    double n10 = g[1][0] * (u - 1.0) + g[1][1] * v;
    double n01 = g[2][0] * u + g[2][1] * (v - 1.0);
    double n11 = g[3][0] * (u - 1.0) + g[3][1] * (v - 1.0);
    double a = fade(u), b = fade(v);
    double nx0 = n00 + a * (n10 - n00), nx1 = n01 + a * (n11 - n01);
    return nx0 + b * (nx1 - nx0);
}

td_status td_terrain_generate(const td_terrain_params *p, int tile_log2, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    td_grid *g = NULL;
    double lo = INFINITY, hi = -INFINITY;

    *out = NULL;
    if (p->width < 2 || p->height < 2 || p->width > 8192 || p->height > 8192) {
        rc = td_err_set(err, TD_ERANGE, "terrain size %d x %d is outside 2 .. 8192", (int)p->width,
                        (int)p->height);
        goto out;
    }
    if (p->octaves < 1 || p->octaves > 16 || !(p->feature_m > 0.0) || !(p->relief_m >= 0.0) ||
        !isfinite(p->base_m) || !isfinite(p->relief_m) || !(p->ridge >= 0.0 && p->ridge <= 1.0)) {
        rc = td_err_set(err, TD_ERANGE, "terrain parameters out of range");
        goto out;
    }
    rc = td_grid_create(p->width, p->height, p->spacing, p->spacing, tile_log2, NULL, &g, err);
    if (rc != TD_OK)
        goto out;
    for (int32_t j = 0; j < g->h; j++) {
        for (int32_t i = 0; i < g->w; i++) {
            double x = i * p->spacing / p->feature_m, y = j * p->spacing / p->feature_m;
            double sum = 0.0, amp = 1.0, weight = 1.0;
            for (int o = 0; o < p->octaves; o++) {
                double n = noise(p->seed, o, x, y);
                double r = 1.0 - fabs(n) * 1.4;
                r = r * r * weight;
                weight = r < 0.0 ? 0.0 : (r > 1.0 ? 1.0 : r);
                sum += amp * ((1.0 - p->ridge) * n + p->ridge * (r - 0.5));
                amp *= 0.5;
                x *= 2.0;
                y *= 2.0;
            }
            g->z[(size_t)j * (size_t)g->w + (size_t)i] = (float)sum;
            lo = sum < lo ? sum : lo;
            hi = sum > hi ? sum : hi;
        }
    }
    {
        size_t n = (size_t)g->w * (size_t)g->h;
        double scale = hi > lo ? p->relief_m / (hi - lo) : 0.0;
        for (size_t k = 0; k < n; k++)
            g->z[k] = (float)(p->base_m + ((double)g->z[k] - lo) * scale);
    }
    rc = td_grid_finish(g, err);
out:
    if (rc != TD_OK) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}
