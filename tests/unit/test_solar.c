/* test_solar.c: NOAA's solar position (core/solar.c) against NREL's SPA worked example
 * (Reda and Andreas 2004, NREL/TP-560-34302: Golden, Colorado, 2003-10-17 12:30:30 -07:00,
 * topocentric zenith 50.11162, azimuth 194.34024; sunrise 06:12:43, transit 11:46:04,
 * sunset 17:18:51 local), polar day and night, the direction vector and ISO 8601 parsing. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>

#include <cmocka.h>

#include "solar.h"

#define GOLDEN_LAT 39.742476
#define GOLDEN_LON -105.1786

static double when(const char *iso)
{
    double t = 0.0;
    td_err err;
    assert_int_equal(td_solar_parse_time(iso, "time", &t, &err), TD_OK);
    return t;
}

static void test_spa_example(void **state)
{
    (void)state;
    td_sun sun;
    assert_int_equal(td_solar_position(GOLDEN_LAT, GOLDEN_LON, when("2003-10-17T12:30:30-07:00"),
                                       &sun, NULL),
                     TD_OK);
    /* SPA's zenith is refracted (820 hPa, 11 C) and topocentric: the sun as seen. */
    assert_true(fabs(sun.azimuth_deg - 194.34024) < 0.01);
    assert_true(fabs(90.0 - (sun.elevation_deg + sun.refraction_deg) - 50.11162) < 0.01);
    assert_true(sun.refraction_deg > 0.015 && sun.refraction_deg < 0.025);
}

static void test_spa_day(void **state)
{
    (void)state;
    td_sun_day day;
    double midnight = when("2003-10-17T00:00:00-07:00");
    assert_int_equal(td_solar_day(GOLDEN_LAT, GOLDEN_LON, midnight, &day, NULL), TD_OK);
    assert_int_equal(day.polar, 0);
    assert_true(fabs(day.rise_s - when("2003-10-17T06:12:43-07:00")) < 30.0);
    assert_true(fabs(day.noon_s - when("2003-10-17T11:46:04-07:00")) < 30.0);
    assert_true(fabs(day.set_s - when("2003-10-17T17:18:51-07:00")) < 30.0);
    /* At sunrise the sun's centre is 0.833 degrees below the astronomical horizon. */
    td_sun sun;
    td_solar_position(GOLDEN_LAT, GOLDEN_LON, day.rise_s, &sun, NULL);
    assert_true(fabs(sun.elevation_deg + 0.833) < 0.01);
    assert_true(sun.azimuth_deg > 90.0 && sun.azimuth_deg < 120.0); /* east, south of it */
}

static void test_polar(void **state)
{
    (void)state;
    td_sun_day day;
    assert_int_equal(td_solar_day(80.0, 15.0, when("2026-06-21"), &day, NULL), TD_OK);
    assert_int_equal(day.polar, 1);
    assert_int_equal(td_solar_day(80.0, 15.0, when("2026-12-21"), &day, NULL), TD_OK);
    assert_int_equal(day.polar, -1);
    assert_int_equal(td_solar_day(-80.0, 15.0, when("2026-12-21"), &day, NULL), TD_OK);
    assert_int_equal(day.polar, 1);
    /* Equinox noon on the equator: the sun near the zenith. */
    td_sun sun;
    td_solar_position(0.0, 0.0, when("2026-03-20T12:07:00Z"), &sun, NULL);
    assert_true(sun.elevation_deg > 89.5);
}

static void test_direction(void **state)
{
    (void)state;
    double d[3];
    td_solar_direction(90.0, 0.0, d); /* east, on the horizon */
    assert_true(fabs(d[0] - 1.0) < 1e-12 && fabs(d[1]) < 1e-12 && fabs(d[2]) < 1e-12);
    td_solar_direction(180.0, 30.0, d); /* south, 30 degrees up */
    assert_true(fabs(d[1] + cos(30.0 * M_PI / 180.0)) < 1e-12 && fabs(d[2] - 0.5) < 1e-12);
}

static void test_parse(void **state)
{
    (void)state;
    assert_true(when("1970-01-01") == 0.0);
    assert_true(when("1970-01-02T00:00Z") == 86400.0);
    assert_true(when("2026-06-21T18:00:00+02:00") == when("2026-06-21T16:00:00Z"));
    assert_true(when("2026-06-21T18:00:00-0530") == when("2026-06-21T23:30:00"));
    assert_true(when("2024-02-29T00:00:00.5Z") == when("2024-02-29") + 0.5);
    assert_true(when("2000-03-01") - when("2000-02-28") == 2 * 86400.0); /* 2000 leap */
    static const char *bad[] = {"",           "2026-02-30",       "2100-02-29",
                                "2026-13-01", "2026-06-21T24:00", "2026-6-21",
                                "tomorrow",   "2026-06-21T18:00Zx", "2026-06-21T18:00+15:00"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        td_err err;
        double t;
        assert_int_equal(td_solar_parse_time(bad[i], "time", &t, &err), TD_EFORMAT);
        assert_string_equal(err.field, "time");
    }
    td_err err;
    td_sun sun;
    assert_int_equal(td_solar_position(91.0, 0.0, 0.0, &sun, &err), TD_ERANGE);
    assert_string_equal(err.field, "lat");
    assert_int_equal(td_solar_position(0.0, NAN, 0.0, &sun, &err), TD_ERANGE);
    assert_string_equal(err.field, "lon");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_spa_example), cmocka_unit_test(test_spa_day),
        cmocka_unit_test(test_polar),       cmocka_unit_test(test_direction),
        cmocka_unit_test(test_parse),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
