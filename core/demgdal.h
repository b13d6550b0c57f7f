/* demgdal.h: GeoTIFF and the other raster formats of GDAL, when terrad is built with
 * libgdal (TERRAD_HAVE_GDAL); without it, td_demgdal_load refuses with TD_EUNSUPPORTED and
 * says why. */
#ifndef TD_DEMGDAL_H
#define TD_DEMGDAL_H

#include "dem.h"

td_status td_demgdal_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

/* Non-zero for the extensions of common GDAL raster formats (.tif, .tiff, .vrt, .img,
 * ...), whether or not GDAL is built in. */
int td_demgdal_recognised(const char *path);

#endif
