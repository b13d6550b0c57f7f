/* demraw.h: raw float32 little-endian grids with a JSON sidecar (`dem.f32` + `dem.json`),
 * row 0 north. The sidecar keys are listed in dem.h. */
#ifndef TD_DEMRAW_H
#define TD_DEMRAW_H

#include "dem.h"

td_status td_demraw_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

#endif
