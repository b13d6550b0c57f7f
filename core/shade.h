/* shade.h: the always-on, cheap part of rendering a hit: its normal, its colour
 * (hypsometric tint or a texture drape) and Lambert + ambient lighting.
 *
 * Normals come from the surface that was hit (td_hit.n: flat per triangle or plane top,
 * analytic on bilinear patches), or, with smooth normals, from central differences at
 * the cell's four samples interpolated bilinearly across the cell. Colours are linear
 * floats 0..1 (display values squared: gamma 2, cheap both ways and close to sRGB); the
 * renderer takes the square root when it converts to 8 bits. */
#ifndef TD_SHADE_H
#define TD_SHADE_H

#include "image.h"
#include "trace.h"

/* Unit vector toward the sun (azimuth clockwise from north, elevation above horizon). */
void td_shade_sun_dir(double azimuth_deg, double elevation_deg, double d[3]);

/* Hypsometric tint for t = (z - zmin) / (zmax - zmin) in 0..1 (clamped): green
 * lowlands, yellow-brown slopes, grey rock, white summits. */
void td_shade_hypsometric(double t, float rgb[3]);

/* Smooth normal at (x, y) inside cell (ci, cj): bilinear blend of the four corner
 * normals from central differences (one-sided at the grid edge, flat at voids). */
void td_shade_smooth_normal(const td_grid *g, int32_t ci, int32_t cj, double x, double y,
                            float n[3]);

/* Colour of a drape image at (x, y): the image covers the grid exactly, row 0 north;
 * bilinear filtering; outside the grid the edge colour. */
void td_shade_drape(const td_image8 *img, const td_grid *g, double x, double y, float rgb[3]);

/* Lambert + ambient: albedo * (ambient * occlusion + (1 - ambient) * max(0, n.sun) * lit). */
void td_shade_light(const float albedo[3], const float n[3], const double sun[3], double ambient,
                    double occlusion, double lit, float rgb[3]);

#endif
