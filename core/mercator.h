/* mercator.h: Web Mercator (EPSG:3857) XYZ tiles over a georeferenced grid.
 *
 * Callers: the map tile and TileJSON routes (server/maps.c), the map benchmark and the
 * tests. Two parts:
 *   - the tile math of the OpenStreetMap XYZ scheme (tile z/x/y -> its bounds in EPSG:3857
 *     metres, the size of a pixel, the zoom that fits a ground resolution): arithmetic on
 *     the square of side 2 * pi * 6378137 m, no projection formula;
 *   - every coordinate change between EPSG:3857, the dataset's CRS and lon/lat through
 *     GDAL's OGR coordinate transformation (PROJ): no hand-written projection code.
 *
 * A dataset's CRS (td_merc_crs_resolve): the file's own (GDAL: GeoTIFF, an .asc's .prj,
 * SRTM), else the sidecar's `crs` text when PROJ understands it ("EPSG:32613", WKT, a PROJ
 * string), else, for lon/lat grids, WGS84 (EPSG:4326; datum shifts to WGS84, tens of
 * metres for NAD27, are not applied). A projected grid with none of these has no map.
 *
 * Pixel positions (td_merc_positions): pixel centres of the tile in EPSG:3857 go to the
 * dataset frame (grid.h: x = (X - x0) / dx * sx, y likewise, X the CRS coordinate).
 * PROJ costs about 1 us a point from 3857 to UTM (60 ms for a 256 x 256 tile, more than
 * the trace), so a lattice every 8 pixels is transformed exactly and the pixels between
 * are interpolated bilinearly; the lattice cells' centres are transformed too, and if any
 * is further than TD_MERC_LATTICE_TOL pixels from the interpolation (strong distortion,
 * a tile crossing the CRS's area of use) every pixel is transformed exactly instead.
 *
 * A td_merc_proj holds OGR objects that are not thread-safe: one per thread (clone it). */
#ifndef TD_MERCATOR_H
#define TD_MERCATOR_H

#include <stddef.h>
#include <stdint.h>

#include "grid.h"

#define TD_MERC_HALF 20037508.342789244 /* pi * 6378137: half the side of the square, m */
#define TD_MERC_MAX_ZOOM 24
#define TD_MERC_LATTICE 8               /* pixels between exactly transformed points */
#define TD_MERC_LATTICE_TOL 0.01        /* pixels: interpolation error allowed */

/* Bounds of tile z/x/y in EPSG:3857 metres: west, south, east, north. Rows go south from
 * the north edge (y = 0 at the top), as in OpenStreetMap's scheme. */
void td_merc_tile_bounds(int z, int32_t x, int32_t y, double b[4]);

/* Side of one pixel in EPSG:3857 metres at zoom z for tiles of `px` pixels. */
double td_merc_pixel_m(int z, int px);

/* The smallest zoom whose 256-pixel tiles' pixels are no larger on the ground than
 * ground_m at latitude lat_deg (clamped to [0, TD_MERC_MAX_ZOOM]). */
int td_merc_zoom_for(double ground_m, double lat_deg);

/* The tiles x0, y0, x1, y1 (inclusive) at zoom z that meet the EPSG:3857 box m (west,
 * south, east, north), clamped to the zoom's range. */
void td_merc_tile_range(const double m[4], int z, int32_t r[4]);

typedef struct td_merc_proj td_merc_proj;

/* Builds the transformations for grid g (its georef) read from `path` (the DEM file; may
 * be NULL). TD_EUNSUPPORTED when the grid has no georeference or no CRS PROJ knows, or
 * the build has no GDAL. */
td_status td_merc_proj_create(const char *path, const td_grid *g, td_merc_proj **out, td_err *err);
/* A copy for another thread. */
td_status td_merc_proj_clone(const td_merc_proj *p, td_merc_proj **out, td_err *err);
void td_merc_proj_free(td_merc_proj *p);

/* The CRS's description (WKT) and a short name, for logs and TileJSON. */
const char *td_merc_proj_name(const td_merc_proj *p);

/* The azimuth (degrees clockwise) of true north from the dataset frame's y axis at the
 * grid's centre: 0 for lon/lat grids, the meridian convergence for projected ones (about
 * -1.5 degrees in UTM zone 13N at 105.5 W). A true azimuth A is A + this in the frame. */
double td_merc_proj_grid_north(const td_merc_proj *p);

/* The grid's extent (its sample positions) as a lon/lat box and an EPSG:3857 box (west,
 * south, east, north), from 64 points along each edge, and the lon/lat of its centre.
 * Computed once by td_merc_proj_create. */
void td_merc_proj_bounds(const td_merc_proj *p, double ll[4], double merc[4], double centre[2]);

/* Dataset-frame positions of the pixel centres of tile z/x/y of px x px pixels: xy[2k],
 * xy[2k+1] for pixel k (row-major from the north-west); NaN where PROJ fails. *exact is
 * set to 1 when every pixel was transformed (see the top of the file), 0 when the
 * lattice was interpolated. *foot_m is the smallest distance between neighbouring pixel
 * centres in the dataset frame, metres (what one pixel covers on the ground). */
td_status td_merc_positions(td_merc_proj *p, int z, int32_t x, int32_t y, int px, double *xy,
                            int *exact, double *foot_m, td_err *err);

/* Lon/lat of a dataset-frame point (for tests and the solar position). */
td_status td_merc_to_lonlat(td_merc_proj *p, double x, double y, double ll[2], td_err *err);

#endif
