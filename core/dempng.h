/* dempng.h: heights packed in PNG pixels, with an encoding that is always given (option or
 * the `<name>.json` sidecar), never guessed: gray16, terrain-rgb, terrarium, rgb-div. */
#ifndef TD_DEMPNG_H
#define TD_DEMPNG_H

#include "dem.h"

td_status td_dempng_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

#endif
