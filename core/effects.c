/* effects.c: per-sample arithmetic of the optional effects (see effects.h). */
#include "effects.h"

#include <math.h>

void td_sky_init(td_sky *k, const double s[3])
{
    double sun_el = s[2] < -1.0 ? -1.0 : s[2];
    k->s[0] = s[0], k->s[1] = s[1], k->s[2] = s[2];
    /* warmth: strong when the sun is low, toward the sun, near the horizon */
    k->low = exp(-(sun_el > 0.0 ? sun_el : 0.0) / 0.12); /* compares, not libm's fmax */
}

void td_sky_shade(const td_sky *k, const double d[3], int disc, float rgb[3])
{
    /* display-space colours, squared to linear at the end */
    static const double horizon[3] = {0.80, 0.86, 0.93}, zenith[3] = {0.27, 0.47, 0.80};
    static const double warm[3] = {1.00, 0.62, 0.34};
    const double *s = k->s;
    double e = d[2] < 0.0 ? 0.0 : d[2];
    double t = sqrt(e); /* the blue deepens quickly above the horizon */
    double cosg = d[0] * s[0] + d[1] * s[1] + d[2] * s[2];
    double half = 0.5 * (1.0 + cosg), toward = half * half * half; /* not pow: a call a sample */
    double w = k->low * toward * (1.0 - t);
    double c[3];
    for (int i = 0; i < 3; i++) {
        c[i] = horizon[i] + t * (zenith[i] - horizon[i]);
        c[i] += w * (warm[i] - c[i]);
    }
    if (disc) {
        /* cos^200 by squaring (x^8 x^64 x^128), a few multiplications for pow's call */
        double x = cosg > 0.0 ? cosg : 0.0, x2 = x * x, x4 = x2 * x2, x8 = x4 * x4, x16 = x8 * x8, x32 = x16 * x16;
        double x64 = x32 * x32, x128 = x64 * x64, glow = 0.35 * (x8 * x64 * x128);
        for (int i = 0; i < 3; i++)
            c[i] += glow * (warm[i] * 0.5 + 0.5);
        if (cosg > cos(0.27 * M_PI / 180.0) && s[2] > -0.01) {
            /* brighter than any glow around it, a touch warm */
            c[0] = 1.0;
            c[1] = 0.97;
            c[2] = 0.90;
        }
    }
    for (int i = 0; i < 3; i++) {
        double v = c[i] > 1.0 ? 1.0 : c[i];
        rgb[i] = (float)(v * v);
    }
}

double td_haze_beta(double visibility_km) { return 3.912 / (visibility_km * 1000.0); }

double td_haze_transmittance(double beta0, double z0, double e0, double z1, double len)
{
    const double H = TD_HAZE_SCALE_HEIGHT_M;
    double dz = z1 - z0, tau;
    if (fabs(dz) < 1e-3 * H) {
        tau = beta0 * len * exp(-0.5 * (z0 + z1) / H);
    } else {
        /* integral of beta0 exp(-z(s)/H) ds along the segment, z linear in s */
        tau = beta0 * len * H * (e0 - exp(-z1 / H)) / dz;
    }
    return exp(-tau);
}

double td_water_fresnel(double cos_i)
{
    const double r0 = 0.02;
    double c = cos_i < 0.0 ? 0.0 : (cos_i > 1.0 ? 1.0 : cos_i);
    double m = 1.0 - c;
    return r0 + (1.0 - r0) * m * m * m * m * m;
}

void td_water_tint(const float floor_rgb[3], double depth_path, float rgb[3])
{
    static const float deep[3] = {0.010f, 0.045f, 0.070f};
    static const double absorb[3] = {0.25, 0.06, 0.04}; /* per metre: red goes first */
    for (int k = 0; k < 3; k++) {
        double tr = exp(-absorb[k] * depth_path);
        rgb[k] = (float)(floor_rgb[k] * tr + deep[k] * (1.0 - tr));
    }
}

uint32_t td_hash32(uint32_t x)
{
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

static double radical_inverse2(uint32_t b)
{
    b = (b << 16) | (b >> 16);
    b = ((b & 0x55555555U) << 1) | ((b & 0xAAAAAAAAU) >> 1);
    b = ((b & 0x33333333U) << 2) | ((b & 0xCCCCCCCCU) >> 2);
    b = ((b & 0x0F0F0F0FU) << 4) | ((b & 0xF0F0F0F0U) >> 4);
    b = ((b & 0x00FF00FFU) << 8) | ((b & 0xFF00FF00U) >> 8);
    return (double)b * (1.0 / 4294967296.0);
}

void td_ao_direction(const float nrm[3], int k, int n, uint32_t seed, double d[3])
{
    /* Hammersley point, Cranley-Patterson rotated by the seed */
    double u1 = (k + 0.5) / n + (seed & 0xffff) / 65536.0;
    double u2 = radical_inverse2((uint32_t)k) + (seed >> 16) / 65536.0;
    u1 -= floor(u1);
    u2 -= floor(u2);
    double r = sqrt(u1), phi = 2.0 * M_PI * u2;
    double lx = r * cos(phi), ly = r * sin(phi), lz = sqrt(fmax(0.0, 1.0 - u1));
    /* tangent frame around the normal (Frisvad-style, branch on the sign) */
    double nx = nrm[0], ny = nrm[1], nz = nrm[2];
    double sgn = nz >= 0.0 ? 1.0 : -1.0;
    double a = -1.0 / (sgn + nz), b = nx * ny * a;
    double t[3] = {1.0 + sgn * nx * nx * a, sgn * b, -sgn * nx};
    double bt[3] = {b, sgn + ny * ny * a, -ny};
    double len = 0.0;
    for (int c = 0; c < 3; c++) {
        d[c] = lx * t[c] + ly * bt[c] + lz * (double)nrm[c];
        len += d[c] * d[c];
    }
    len = sqrt(len);
    for (int c = 0; c < 3; c++)
        d[c] /= len;
}

double td_curvature_drop(double dist, double k)
{
    return dist * dist / (2.0 * TD_EARTH_RADIUS_M) * (1.0 - k);
}
