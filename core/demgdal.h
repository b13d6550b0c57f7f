/* demgdal.h: GeoTIFF and the other raster formats of GDAL, when terrad is built with
 * libgdal (TERRAD_HAVE_GDAL); without it, td_demgdal_load refuses with TD_EUNSUPPORTED and
 * says why. */
#ifndef TD_DEMGDAL_H
#define TD_DEMGDAL_H

#include "dem.h"

td_status td_demgdal_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

/* Streaming (terrad prepare, prepared.c): the raster's shape and georeference at open,
 * then its rows a band at a time through GDAL's block cache, never the whole grid. Without
 * GDAL, open refuses as td_demgdal_load does. */
typedef struct td_demgdal_stream td_demgdal_stream;
td_status td_demgdal_stream_open(const char *path, const td_dem_opts *o, td_demgdal_stream **out,
                                 td_grid *shape, td_err *err);
/* File rows r0 .. r0+n-1 (row 0 north) into dst (n*w floats, north row first), each
 * checked and converted as td_demgdal_load does. */
td_status td_demgdal_stream_rows(td_demgdal_stream *s, int32_t r0, int32_t n, float *dst,
                                 td_err *err);
void td_demgdal_stream_close(td_demgdal_stream *s);

/* Non-zero for the extensions of common GDAL raster formats (.tif, .tiff, .vrt, .img,
 * ...), whether or not GDAL is built in. */
int td_demgdal_recognised(const char *path);

#endif
