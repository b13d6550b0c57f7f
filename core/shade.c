/* shade.c: normals, colours and lighting of a hit (see shade.h).
 *
 * The hypsometric ramp is a handful of stops interpolated linearly, after the usual
 * relief-map palettes (Imhof-like: green, yellow, brown, grey, white). It is relative to
 * the dataset's own range, so a 300 m fell and a 4000 m range both use the whole ramp;
 * an absolute palette was rejected because it paints Levi entirely green. */
#include "shade.h"

#include <math.h>

#define TD_DEG (M_PI / 180.0)

void td_shade_sun_dir(double azimuth_deg, double elevation_deg, double d[3])
{
    double a = azimuth_deg * TD_DEG, e = elevation_deg * TD_DEG;
    d[0] = sin(a) * cos(e);
    d[1] = cos(a) * cos(e);
    d[2] = sin(e);
}

void td_shade_hypsometric(double t, float rgb[3])
{
    static const float stops[][4] = {
        {0.00f, 0.33f, 0.52f, 0.30f}, /* low green */
        {0.25f, 0.55f, 0.66f, 0.38f}, /* light green */
        {0.45f, 0.80f, 0.75f, 0.50f}, /* yellow-tan */
        {0.65f, 0.62f, 0.50f, 0.36f}, /* brown */
        {0.85f, 0.60f, 0.58f, 0.56f}, /* rock grey */
        {1.00f, 0.96f, 0.96f, 0.98f}, /* snow */
    };
    const int n = (int)(sizeof stops / sizeof stops[0]);
    if (!(t > 0.0))
        t = 0.0;
    if (t > 1.0)
        t = 1.0;
    int k = 0;
    while (k < n - 2 && t > stops[k + 1][0])
        k++;
    float a = (float)((t - stops[k][0]) / (stops[k + 1][0] - stops[k][0]));
    for (int c = 0; c < 3; c++) {
        float s = stops[k][c + 1] + a * (stops[k + 1][c + 1] - stops[k][c + 1]);
        rgb[c] = s * s; /* display value to linear shading space (gamma 2) */
    }
}

/* Central-difference normal at sample (i, j), not normalised. */
static void vertex_normal(const td_grid *g, int32_t i, int32_t j, double n[3])
{
    int32_t i0 = i > 0 ? i - 1 : i, i1 = i < g->w - 1 ? i + 1 : i;
    int32_t j0 = j > 0 ? j - 1 : j, j1 = j < g->h - 1 ? j + 1 : j;
    double zx0 = td_grid_sample(g, i0, j), zx1 = td_grid_sample(g, i1, j);
    double zy0 = td_grid_sample(g, i, j0), zy1 = td_grid_sample(g, i, j1);
    double gx = (zx1 - zx0) / ((i1 - i0) * g->sx), gy = (zy1 - zy0) / ((j1 - j0) * g->sy);
    if (!isfinite(gx))
        gx = 0.0;
    if (!isfinite(gy))
        gy = 0.0;
    n[0] = -gx;
    n[1] = -gy;
    n[2] = 1.0;
}

void td_shade_smooth_normal(const td_grid *g, int32_t ci, int32_t cj, double x, double y,
                            float n[3])
{
    double n00[3], n10[3], n01[3], n11[3], m[3], len = 0.0;
    double u = x / g->sx - ci, v = y / g->sy - cj;
    u = u < 0.0 ? 0.0 : (u > 1.0 ? 1.0 : u);
    v = v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v);
    vertex_normal(g, ci, cj, n00);
    vertex_normal(g, ci + 1, cj, n10);
    vertex_normal(g, ci, cj + 1, n01);
    vertex_normal(g, ci + 1, cj + 1, n11);
    for (int k = 0; k < 3; k++) {
        m[k] = (1 - v) * ((1 - u) * n00[k] + u * n10[k]) + v * ((1 - u) * n01[k] + u * n11[k]);
        len += m[k] * m[k];
    }
    len = sqrt(len);
    for (int k = 0; k < 3; k++)
        n[k] = (float)(m[k] / len);
}

void td_shade_drape(const td_image8 *img, const td_grid *g, double x, double y, float rgb[3])
{
    double fu = x / ((g->w - 1) * g->sx) * img->width - 0.5;
    double fv = (1.0 - y / ((g->h - 1) * g->sy)) * img->height - 0.5;
    double mu = img->width - 1, mv = img->height - 1;
    fu = fu < 0.0 ? 0.0 : (fu > mu ? mu : fu);
    fv = fv < 0.0 ? 0.0 : (fv > mv ? mv : fv);
    int32_t i = (int32_t)fu, j = (int32_t)fv;
    int32_t i1 = i < img->width - 1 ? i + 1 : i, j1 = j < img->height - 1 ? j + 1 : j;
    double a = fu - i, b = fv - j;
    int ch = img->channels;
    const uint8_t *p00 = img->px + ((size_t)j * img->width + i) * ch;
    const uint8_t *p10 = img->px + ((size_t)j * img->width + i1) * ch;
    const uint8_t *p01 = img->px + ((size_t)j1 * img->width + i) * ch;
    const uint8_t *p11 = img->px + ((size_t)j1 * img->width + i1) * ch;
    for (int c = 0; c < 3; c++) {
        double s = (1 - b) * ((1 - a) * p00[c] + a * p10[c]) + b * ((1 - a) * p01[c] + a * p11[c]);
        /* display value to linear shading space (gamma 2, as the output's encoding) */
        s /= 255.0;
        rgb[c] = (float)(s * s);
    }
}

void td_shade_light(const float albedo[3], const float n[3], const double sun[3], double ambient,
                    double occlusion, double lit, float rgb[3])
{
    double ndl = n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2];
    if (ndl < 0.0)
        ndl = 0.0;
    double k = ambient * occlusion + (1.0 - ambient) * ndl * lit;
    for (int c = 0; c < 3; c++)
        rgb[c] = (float)(albedo[c] * k);
}
