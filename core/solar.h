/* solar.h: where the sun is, for a place on the earth and an instant (UTC).
 *
 * NOAA's solar position algorithm (the Global Monitoring Laboratory's solar calculator,
 * after Meeus, "Astronomical Algorithms"): good to about 0.01 degree in position and a
 * minute in sunrise and sunset for years 1800-2100, far below what a DEM's cell resolves.
 * Map tiles (`?time=` on /v1/maps), scenes' sun and panoramas' sun paths (/v1/horizon) all
 * read the sun here, so one date gives one sun everywhere.
 *
 * Angles in degrees. Azimuth clockwise from true north (90 = east), elevation above the
 * astronomical horizon. Instants are seconds since 1970-01-01T00:00:00Z (leap seconds not
 * counted, as POSIX time), as a double so they carry fractions. */
#ifndef TD_SOLAR_H
#define TD_SOLAR_H

#include "status.h"

typedef struct td_sun {
    double azimuth_deg;     /* [0, 360), clockwise from north */
    double elevation_deg;   /* geometric: the direction terrain shadows are cast along */
    double refraction_deg;  /* standard-atmosphere refraction there (NOAA's fit): the sun
                               is SEEN at elevation_deg + refraction_deg */
    double declination_deg;
    double eqtime_min;      /* equation of time: apparent minus mean solar time */
} td_sun;

/* The sun seen from latitude lat_deg [-90, 90], longitude lon_deg [-180, 360) at unix_s.
 * TD_ERANGE naming "lat" or "lon" (or "time" for a non-finite instant). */
td_status td_solar_position(double lat_deg, double lon_deg, double unix_s, td_sun *out,
                            td_err *err);

/* A day's astronomical events for the UTC calendar day that contains day_s: solar noon,
 * and sunrise and sunset as the instants the sun's centre is 0.833 degrees below the
 * astronomical horizon (refraction and the sun's radius: the almanac's definition). When
 * the sun does not cross that line, polar is +1 (up all day) or -1 (down all day) and
 * rise_s = set_s = noon_s. Each event is refined once at its own instant (the sun's
 * declination moves during the day). */
typedef struct td_sun_day {
    double noon_s, rise_s, set_s;
    int polar;
} td_sun_day;
td_status td_solar_day(double lat_deg, double lon_deg, double day_s, td_sun_day *out,
                       td_err *err);

/* The sun at unix_s seen from a grid's centre (lon_deg, lat_deg), its azimuth turned into
 * the grid's frame: a true azimuth A is A + grid_north_deg there (td_merc_proj_grid_north:
 * the CRS's meridian convergence; 0 for lon/lat grids), so *azimuth_deg is what a scene's
 * effects.sun.azimuth means, in [0, 360). *elevation_deg is geometric. Errors as
 * td_solar_position's. */
td_status td_solar_in_grid(double lon_deg, double lat_deg, double grid_north_deg, double unix_s,
                           double *azimuth_deg, double *elevation_deg, td_err *err);

/* Unit vector toward the sun in the dataset frame (x east, y north, z up) for an azimuth
 * and elevation in degrees. */
void td_solar_direction(double azimuth_deg, double elevation_deg, double dir[3]);

/* Parses an ISO 8601 instant: "YYYY-MM-DD" (midnight UTC), "YYYY-MM-DDThh:mm",
 * "YYYY-MM-DDThh:mm:ss[.fff]", each optionally followed by "Z" or an offset "+hh:mm" /
 * "-hh:mm" / "+hhmm" (no suffix means UTC). Years 1000-9999. TD_EFORMAT naming `field`
 * when the text is not such an instant (month 13, 30 February, 24:01 ...). */
td_status td_solar_parse_time(const char *text, const char *field, double *unix_s,
                              td_err *err);

#endif
