/* demasc.h: ESRI ASCII grids (.asc): header (ncols, nrows, xllcorner|xllcenter,
 * yllcorner|yllcenter, cellsize or dx/dy, optional NODATA_value) then nrows lines of
 * ncols numbers, north row first. */
#ifndef TD_DEMASC_H
#define TD_DEMASC_H

#include "dem.h"

td_status td_demasc_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

#endif
