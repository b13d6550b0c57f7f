/* solar.c: NOAA's solar position, sunrise and sunset, and ISO 8601 instants (see solar.h).
 *
 * The position follows the NOAA solar calculator's equations (Meeus ch. 25 in its low-
 * precision form): the sun's geometric mean longitude and anomaly in Julian centuries from
 * J2000, the equation of centre, the apparent longitude (nutation and aberration in one
 * term), the obliquity, then declination and the equation of time; the local hour angle
 * from true solar time gives elevation and azimuth. Azimuth is taken with atan2 (Meeus'
 * form), not NOAA's arccos with a quadrant test, so it has no loss of precision near
 * north and south. Checked in tests/unit/test_solar.c against NREL's SPA worked example
 * (Reda and Andreas 2004). */
#include "solar.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define DEG (3.14159265358979323846 / 180.0)
#define DAY_S 86400.0

/* The sun's declination (degrees) and the equation of time (minutes) at an instant. */
static void sun_orbit(double unix_s, double *decl_deg, double *eqtime_min)
{
    double jd = unix_s / DAY_S + 2440587.5;
    double t = (jd - 2451545.0) / 36525.0;
    double l0 = fmod(280.46646 + t * (36000.76983 + t * 0.0003032), 360.0);
    double m = 357.52911 + t * (35999.05029 - 0.0001537 * t);
    double e = 0.016708634 - t * (0.000042037 + 0.0000001267 * t);
    double c = sin(m * DEG) * (1.914602 - t * (0.004817 + 0.000014 * t)) +
               sin(2.0 * m * DEG) * (0.019993 - 0.000101 * t) + sin(3.0 * m * DEG) * 0.000289;
    double omega = 125.04 - 1934.136 * t;
    double lambda = l0 + c - 0.00569 - 0.00478 * sin(omega * DEG);
    double eps0 = 23.0 + (26.0 + (21.448 - t * (46.815 + t * (0.00059 - t * 0.001813))) / 60.0) / 60.0;
    double eps = eps0 + 0.00256 * cos(omega * DEG);
    double y = tan(eps * DEG / 2.0);
    y *= y;
    *decl_deg = asin(sin(eps * DEG) * sin(lambda * DEG)) / DEG;
    *eqtime_min = 4.0 / DEG *
                  (y * sin(2.0 * l0 * DEG) - 2.0 * e * sin(m * DEG) +
                   4.0 * e * y * sin(m * DEG) * cos(2.0 * l0 * DEG) -
                   0.5 * y * y * sin(4.0 * l0 * DEG) - 1.25 * e * e * sin(2.0 * m * DEG));
}

/* NOAA's fit of standard-atmosphere refraction (degrees) at a geometric elevation. */
static double refraction(double elev_deg)
{
    double r = 0.0;
    double te = tan(elev_deg * DEG);
    if (elev_deg > 85.0)
        r = 0.0;
    else if (elev_deg > 5.0)
        r = 58.1 / te - 0.07 / (te * te * te) + 0.000086 / (te * te * te * te * te);
    else if (elev_deg > -0.575)
        r = 1735.0 +
            elev_deg * (-518.2 + elev_deg * (103.4 + elev_deg * (-12.79 + elev_deg * 0.711)));
    else
        r = -20.774 / te;
    return r / 3600.0;
}

static td_status check_place(double lat_deg, double lon_deg, double unix_s, td_err *err)
{
    td_status rc = TD_OK;
    if (!(lat_deg >= -90.0 && lat_deg <= 90.0))
        rc = td_err_field(err, TD_ERANGE, "lat", "%g is outside -90 .. 90 degrees", lat_deg);
    else if (!(lon_deg >= -180.0 && lon_deg < 360.0))
        rc = td_err_field(err, TD_ERANGE, "lon", "%g is outside -180 .. 360 degrees", lon_deg);
    else if (!isfinite(unix_s) || fabs(unix_s) > 1e13)
        rc = td_err_field(err, TD_ERANGE, "time", "%g s is not an instant", unix_s);
    return rc;
}

td_status td_solar_position(double lat_deg, double lon_deg, double unix_s, td_sun *out,
                            td_err *err)
{
    td_status rc = check_place(lat_deg, lon_deg, unix_s, err);
    if (rc)
        goto out;
    double decl, eqt;
    sun_orbit(unix_s, &decl, &eqt);
    double day_min = fmod(unix_s, DAY_S) / 60.0;
    if (day_min < 0.0)
        day_min += 1440.0;
    double tst = fmod(day_min + eqt + 4.0 * lon_deg, 1440.0); /* true solar time, min */
    if (tst < 0.0)
        tst += 1440.0;
    double ha = (tst / 4.0 - 180.0) * DEG; /* hour angle, 0 at solar noon */
    double phi = lat_deg * DEG, d = decl * DEG;
    double sin_el = sin(phi) * sin(d) + cos(phi) * cos(d) * cos(ha);
    double elev = asin(fmax(-1.0, fmin(1.0, sin_el))) / DEG;
    /* Meeus 13.5: azimuth from south, westward; +180 turns it to from north, eastward. */
    double az = atan2(sin(ha), cos(ha) * sin(phi) - tan(d) * cos(phi)) / DEG + 180.0;
    if (az >= 360.0)
        az -= 360.0;
    out->azimuth_deg = az;
    out->elevation_deg = elev;
    out->refraction_deg = refraction(elev);
    out->declination_deg = decl;
    out->eqtime_min = eqt;
out:
    return rc;
}

/* Hour angle (degrees) at which the sun's centre is at -0.833 degrees for a declination,
 * or +-1 in *polar when it never is. */
static double rise_angle(double lat_deg, double decl_deg, int *polar)
{
    double phi = lat_deg * DEG, d = decl_deg * DEG;
    double c = cos(90.833 * DEG) / (cos(phi) * cos(d)) - tan(phi) * tan(d);
    double ha = 0.0;
    *polar = 0;
    if (c <= -1.0)
        *polar = 1;
    else if (c >= 1.0)
        *polar = -1;
    else
        ha = acos(c) / DEG;
    return ha;
}

/* The instant (s) of noon (sign 0), sunrise (-1) or sunset (+1) near guess_s on the UTC
 * day starting at day0_s, with the sun's orbit taken at guess_s. */
static double day_event(double lat_deg, double lon_deg, double day0_s, double guess_s,
                        int sign, int *polar)
{
    double decl, eqt;
    sun_orbit(guess_s, &decl, &eqt);
    double ha = sign ? rise_angle(lat_deg, decl, polar) : 0.0;
    return day0_s + 60.0 * (720.0 - 4.0 * lon_deg - eqt + sign * 4.0 * ha);
}

td_status td_solar_day(double lat_deg, double lon_deg, double day_s, td_sun_day *out,
                       td_err *err)
{
    td_status rc = check_place(lat_deg, lon_deg, day_s, err);
    if (rc)
        goto out;
    double day0 = floor(day_s / DAY_S) * DAY_S;
    int polar = 0, p_rise = 0, p_set = 0;
    double noon = day_event(lat_deg, lon_deg, day0, day0 + DAY_S / 2, 0, &polar);
    noon = day_event(lat_deg, lon_deg, day0, noon, 0, &polar);
    double rise = day_event(lat_deg, lon_deg, day0, noon, -1, &p_rise);
    double set = day_event(lat_deg, lon_deg, day0, noon, +1, &p_set);
    if (!p_rise)
        rise = day_event(lat_deg, lon_deg, day0, rise, -1, &p_rise);
    if (!p_set)
        set = day_event(lat_deg, lon_deg, day0, set, +1, &p_set);
    out->noon_s = noon;
    out->polar = p_rise ? p_rise : p_set;
    out->rise_s = out->polar ? noon : rise;
    out->set_s = out->polar ? noon : set;
out:
    return rc;
}

td_status td_solar_in_grid(double lon_deg, double lat_deg, double grid_north_deg, double unix_s,
                           double *azimuth_deg, double *elevation_deg, td_err *err)
{
    td_sun sun;
    td_status rc = td_solar_position(lat_deg, lon_deg, unix_s, &sun, err);
    if (!rc) {
        double az = fmod(sun.azimuth_deg + grid_north_deg, 360.0);
        *azimuth_deg = az < 0.0 ? az + 360.0 : az;
        *elevation_deg = sun.elevation_deg;
    }
    return rc;
}

void td_solar_direction(double azimuth_deg, double elevation_deg, double dir[3])
{
    double ce = cos(elevation_deg * DEG);
    dir[0] = sin(azimuth_deg * DEG) * ce;
    dir[1] = cos(azimuth_deg * DEG) * ce;
    dir[2] = sin(elevation_deg * DEG);
}

/* Days from 1970-01-01 to a proleptic Gregorian date (Hinnant's days_from_civil). */
static long days_from_civil(long y, long m, long d)
{
    y -= m <= 2;
    long era = (y >= 0 ? y : y - 399) / 400;
    long yoe = y - era * 400;
    long doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
    long doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    return era * 146097 + doe - 719468;
}

static int month_days(int y, int m)
{
    static const int days[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    int leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    return days[m - 1] + (m == 2 && leap);
}

/* Reads exactly n digits at *p into *v and advances; 0 if they are not there. */
static int digits(const char **p, int n, int *v)
{
    int ok = 1;
    *v = 0;
    for (int i = 0; i < n && ok; i++) {
        char c = (*p)[i];
        ok = c >= '0' && c <= '9';
        *v = *v * 10 + (c - '0');
    }
    if (ok)
        *p += n;
    return ok;
}

/* The "Z" / "+hh:mm" / "-hhmm" suffix (or none) into seconds east of UTC. */
static int zone_suffix(const char *p, int *east_s)
{
    int ok = 1, hh = 0, mm = 0;
    *east_s = 0;
    if (*p == 'Z' || *p == 'z') {
        ok = p[1] == '\0';
    } else if (*p == '+' || *p == '-') {
        int sign = *p == '-' ? -1 : 1;
        p++;
        ok = digits(&p, 2, &hh);
        if (ok && *p == ':')
            p++;
        ok = ok && digits(&p, 2, &mm) && *p == '\0' && hh <= 14 && mm < 60;
        *east_s = sign * (hh * 3600 + mm * 60);
    } else {
        ok = *p == '\0';
    }
    return ok;
}

td_status td_solar_parse_time(const char *text, const char *field, double *unix_s,
                              td_err *err)
{
    td_status rc = TD_OK;
    const char *p = text ? text : "";
    int y = 0, mo = 0, d = 0, h = 0, mi = 0, s = 0, east = 0;
    double frac = 0.0;
    int ok = digits(&p, 4, &y) && *p++ == '-' && digits(&p, 2, &mo) && *p++ == '-' &&
             digits(&p, 2, &d);
    ok = ok && y >= 1000 && mo >= 1 && mo <= 12 && d >= 1 && d <= month_days(y, mo);
    if (ok && (*p == 'T' || *p == 't' || *p == ' ')) {
        p++;
        ok = digits(&p, 2, &h) && *p++ == ':' && digits(&p, 2, &mi);
        if (ok && *p == ':') {
            p++;
            ok = digits(&p, 2, &s);
            if (ok && *p == '.') {
                double scale = 0.1;
                for (p++; *p >= '0' && *p <= '9'; p++, scale /= 10)
                    frac += (*p - '0') * scale;
            }
        }
        ok = ok && h < 24 && mi < 60 && s < 60;
    }
    ok = ok && zone_suffix(p, &east);
    if (!ok)
        rc = td_err_field(err, TD_EFORMAT, field ? field : "time",
                          "'%.40s' is not an ISO 8601 date or instant "
                          "(e.g. 2026-06-21 or 2026-06-21T18:00:00Z)",
                          text ? text : "");
    else
        *unix_s = (double)days_from_civil(y, mo, d) * DAY_S + h * 3600.0 + mi * 60.0 + s +
                  frac - east;
    return rc;
}
