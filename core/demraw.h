/* demraw.h: raw float32 little-endian grids with a JSON sidecar (`dem.f32` + `dem.json`),
 * row 0 north. The sidecar keys are listed in dem.h. */
#ifndef TD_DEMRAW_H
#define TD_DEMRAW_H

#include "demutil.h"

td_status td_demraw_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

/* The pieces of the loader that terrad prepare's streaming reader (prepared.c) shares:
 * the sidecar, the limits and a file whose size is exactly what the sidecar says, all
 * checked before any allocation (f left open for the rows); the rules for its samples
 * (voids, NaN, infinities); and file row r read into row (w samples, byte order fixed,
 * rules applied) from where f stands. */
td_status td_demraw_open(const char *path, const td_dem_opts *o, td_demside *sc, FILE **f,
                         td_err *err);
void td_demraw_rules(const td_demside *sc, td_demutil_f32 *p);
td_status td_demraw_row(const char *path, const td_demutil_f32 *p, FILE *f, float *row, int32_t w,
                        int32_t r, td_err *err);

#endif
