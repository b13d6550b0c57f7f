/* effects.h: the optional parts of a render, as pure per-sample functions the renderer
 * calls only when the scene asks for the effect (render.c owns the passes, the rays
 * and their counts; nothing here traces or allocates).
 *
 * - sky: a vertical gradient (horizon to zenith) warming toward the sun when it is low,
 *   plus the sun's disc (0.27 degrees radius) and a glow around it.
 * - haze: aerial perspective. Koschmieder's law gives the extinction at the reference
 *   height from the meteorological visibility V: beta0 = 3.912 / V (2% contrast). The
 *   extinction falls with height as exp(-(z - zref) / Hs) (aerosol scale height
 *   Hs = 1500 m), and the optical depth of a straight segment has a closed form. The
 *   in-scattered colour is the sky's horizon colour in the view's azimuth.
 * - water: Schlick's Fresnel term for water (n = 1.33, R0 = 0.02) and the depth tint
 *   (Beer-Lambert attenuation along the underwater path toward a water colour).
 * - ambient occlusion: cosine-weighted hemisphere directions from a Hammersley set,
 *   rotated per pixel by a hash (deterministic: the same image for any thread count).
 * - curvature: the drop d^2 / 2R * (1 - k) of a point at horizontal distance d. */
#ifndef TD_EFFECTS_H
#define TD_EFFECTS_H

#include <stdint.h>

#define TD_EARTH_RADIUS_M 6371000.0
#define TD_HAZE_SCALE_HEIGHT_M 1500.0

/* The sky, for every direction under one sun: the terms of the sun alone computed once
 * (td_sky_init; a render's haze stage called exp for the sun's warmth at every sample),
 * then td_sky_shade gives the colour (linear) seen along unit direction d, the sun along
 * unit s. With `disc` zero, no sun disc or glow (for reflections and the haze colour). */
typedef struct td_sky {
    double s[3]; /* the sun, unit */
    double low;  /* the warmth's strength for the sun's height */
} td_sky;
void td_sky_init(td_sky *k, const double s[3]);
void td_sky_shade(const td_sky *k, const double d[3], int disc, float rgb[3]);

/* Transmittance of a straight segment of length len (metres) from height z0 to z1,
 * both relative to the reference height of beta0 (extinction per metre there), with
 * e0 = exp(-z0 / TD_HAZE_SCALE_HEIGHT_M) given (segments that share their start, as a
 * perspective camera's, compute it once). */
double td_haze_transmittance(double beta0, double z0, double e0, double z1, double len);

/* Extinction per metre for a visibility in km. */
double td_haze_beta(double visibility_km);

/* Schlick's approximation for an air-water interface; cos_i = |cos| of incidence. */
double td_water_fresnel(double cos_i);

/* Colour seen through `depth_path` metres of water over `floor_rgb` (linear). */
void td_water_tint(const float floor_rgb[3], double depth_path, float rgb[3]);

/* The k-th of n cosine-weighted directions around unit normal nrm, rotated by the
 * 32-bit `seed` (e.g. a hash of the pixel). Returns a unit vector with d.n > 0. */
void td_ao_direction(const float nrm[3], int k, int n, uint32_t seed, double d[3]);

/* A well-mixed 32-bit hash (for per-pixel seeds). */
uint32_t td_hash32(uint32_t x);

/* Drop of the terrain seen at horizontal distance dist: dist^2 / (2R) * (1 - k). */
double td_curvature_drop(double dist, double k);

#endif
