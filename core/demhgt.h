/* demhgt.h: SRTM .hgt tiles: 1201 x 1201 (3") or 3601 x 3601 (1") int16 big-endian
 * samples, north row first, -32768 = void, georeferenced by the file name (N37W106.hgt:
 * south-west sample at 37 N, 106 W). */
#ifndef TD_DEMHGT_H
#define TD_DEMHGT_H

#include "dem.h"

td_status td_demhgt_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err);

/* Parses an SRTM tile name (N37W106.hgt, case-insensitive) into the longitude and
 * latitude of its south-west sample. Returns 1 on success. */
int td_demhgt_parse_name(const char *path, int *lon, int *lat);

#endif
