/* test_effects.c: the per-sample effect functions (core/effects.c): the sky's colours
 * (bluer up, warmer toward a low sun, the disc only where asked) and the haze's
 * transmittance (Koschmieder's 2% at the visibility, the closed form over a sloping segment
 * against a sum of many short level steps), both also against values written down from the
 * code before the sun's terms were computed once a render (commit 0eb2413: the renders'
 * colours did not change), the water's Fresnel term and tint, and the ambient-occlusion
 * directions (unit, over the normal). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "effects.h"

static void unit(double az_deg, double el_deg, double v[3])
{
    double az = az_deg * M_PI / 180.0, el = el_deg * M_PI / 180.0;
    v[0] = sin(az) * cos(el);
    v[1] = cos(az) * cos(el);
    v[2] = sin(el);
}

/* The sky's colour along d under sun s */
static void sky(const double d[3], const double s[3], int disc, float rgb[3])
{
    td_sky k;
    td_sky_init(&k, s);
    td_sky_shade(&k, d, disc, rgb);
}

/* A haze transmittance with the start's exp computed here */
static double haze(double beta0, double z0, double z1, double len)
{
    return td_haze_transmittance(beta0, z0, exp(-z0 / TD_HAZE_SCALE_HEIGHT_M), z1, len);
}

static void test_sky_colours(void **state)
{
    (void)state;
    double sun[3], up[3] = {0.0, 0.0, 1.0}, flat[3], away[3], toward[3];
    float c_up[3], c_flat[3], c_away[3], c_toward[3], c_disc[3], c_nodisc[3];
    unit(270.0, 3.0, sun); /* a sunset in the west */
    unit(90.0, 0.0, away);
    unit(270.0, 0.0, toward);
    unit(0.0, 0.0, flat);
    sky(up, sun, 0, c_up);
    sky(flat, sun, 0, c_flat);
    sky(away, sun, 0, c_away);
    sky(toward, sun, 0, c_toward);
    /* the zenith is bluer and darker in red than the horizon */
    assert_true(c_up[2] > c_up[0] && c_up[0] < c_flat[0]);
    /* toward the low sun the horizon is warmer (more red, less blue) than away from it */
    assert_true(c_toward[0] > c_away[0] && c_toward[2] < c_away[2]);
    /* the disc: only with `disc`, the fixed warm white squared to linear */
    sky(sun, sun, 1, c_disc);
    sky(sun, sun, 0, c_nodisc);
    assert_float_equal(c_disc[0], 1.0f, 0.0f);
    assert_float_equal(c_disc[1], (float)(0.97 * 0.97), 0.0f);
    assert_float_equal(c_disc[2], (float)(0.90 * 0.90), 0.0f);
    assert_true(c_nodisc[1] < c_disc[1]);
    /* below the horizon: the horizon's colour (no darker sky under it) */
    double down[3], level[3];
    unit(10.0, -30.0, down);
    unit(10.0, 0.0, level);
    float c_down[3], c_level[3];
    sky(down, sun, 0, c_down);
    sky(level, sun, 0, c_level);
    for (int k = 0; k < 3; k++)
        assert_true(fabsf(c_down[k] - c_level[k]) < 0.05f);
}

/* Within a float's rounding of what the code at commit 0eb2413 gave (sun azimuth
 * and elevation, direction azimuth and elevation, disc; printed with %a from that code). */
static void test_sky_values_kept(void **state)
{
    (void)state;
    static const struct {
        double sun_az, sun_el, az, el;
        int disc;
        float rgb[3];
    } cases[] = {
        {270, 3, 270, 0, 0, {0x1.b9ea6ep-1f, 0x1.fd2bfep-2f, 0x1.350172p-2f}},
        {270, 3, 90, 0, 0, {0x1.47ae14p-1f, 0x1.7aacdap-1f, 0x1.bad42cp-1f}},
        {270, 3, 10, 45, 1, {0x1.0a69bp-3f, 0x1.22d078p-2f, 0x1.54e22p-1f}},
        {270, 3, 270, 3, 1, {0x1p+0f, 0x1.e1bda6p-1f, 0x1.9eb852p-1f}},
        {123, 60, 300, -20, 1, {0x1.47ae22p-1f, 0x1.7aaccap-1f, 0x1.bad4p-1f}},
        {123, -5, 200, 80, 0, {0x1.34f35p-4f, 0x1.ca61ap-3f, 0x1.482e3cp-1f}},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        double s[3], d[3];
        float rgb[3];
        unit(cases[i].sun_az, cases[i].sun_el, s);
        unit(cases[i].az, cases[i].el, d);
        sky(d, s, cases[i].disc, rgb);
        for (int k = 0; k < 3; k++)
            assert_true(fabsf(rgb[k] - cases[i].rgb[k]) <= 0x1p-23f * cases[i].rgb[k]);
    }
}

static void test_haze(void **state)
{
    (void)state;
    const double V = 20.0, beta0 = td_haze_beta(V), H = TD_HAZE_SCALE_HEIGHT_M;
    /* Koschmieder: 2% contrast left over the visibility, level at the reference height */
    assert_true(fabs(haze(beta0, 0.0, 0.0, V * 1000.0) - 0.02) < 1e-3);
    assert_float_equal(haze(beta0, 100.0, 900.0, 0.0), 1.0, 0.0);
    /* thinner air higher up: a level segment at 3 km lets more through */
    assert_true(haze(beta0, 3000.0, 3000.0, 5000.0) >
                haze(beta0, 0.0, 0.0, 5000.0));
    /* the closed form over a climbing segment against many short level steps */
    const double z0 = 200.0, z1 = 2600.0, len = 30000.0;
    double tau = 0.0;
    const int n = 200000;
    for (int i = 0; i < n; i++) {
        double z = z0 + (z1 - z0) * (i + 0.5) / n;
        tau += beta0 * exp(-z / H) * len / n;
    }
    assert_true(fabs(haze(beta0, z0, z1, len) - exp(-tau)) < 1e-9);
    /* what the code at commit 0eb2413 gave (z0, z1, len at 20 km visibility),
       level or not, up or down, within a few of the double's roundings */
    static const double kept[][4] = {{200, 2600, 30000, 0x1.3c1c892e87dcep-4},
                                     {2600, 200, 30000, 0x1.3c1c892e87dcep-4},
                                     {1000, 1000.5, 12000, 0x1.32eaf546167d3p-2},
                                     {-50, 4000, 5000, 0x1.690aa8b8ac27dp-1}};
    for (size_t k = 0; k < sizeof kept / sizeof kept[0]; k++)
        assert_true(fabs(haze(td_haze_beta(20.0), kept[k][0], kept[k][1], kept[k][2]) - kept[k][3]) <=
                    0x1p-50 * kept[k][3]);
}

static void test_water(void **state)
{
    (void)state;
    assert_float_equal(td_water_fresnel(1.0), 0.02, 1e-15);
    assert_float_equal(td_water_fresnel(0.0), 1.0, 1e-15);
    assert_true(td_water_fresnel(0.3) > td_water_fresnel(0.8));
    const float floor_rgb[3] = {0.5f, 0.4f, 0.3f};
    float shallow[3], deep[3];
    td_water_tint(floor_rgb, 0.0, shallow);
    td_water_tint(floor_rgb, 500.0, deep);
    for (int k = 0; k < 3; k++)
        assert_float_equal(shallow[k], floor_rgb[k], 1e-6);
    assert_true(deep[0] < 0.02f && deep[2] > deep[0]); /* red goes first; the water's colour stays */
}

static void test_ao_directions(void **state)
{
    (void)state;
    const float nrm[3] = {0.3f, -0.2f, 0.9327379f};
    for (uint32_t seed = 0; seed < 50; seed++)
        for (int k = 0; k < 16; k++) {
            double d[3];
            td_ao_direction(nrm, k, 16, td_hash32(seed), d);
            assert_true(fabs(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - 1.0) < 1e-9);
            assert_true(d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2] > 0.0);
        }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sky_colours),
        cmocka_unit_test(test_sky_values_kept),
        cmocka_unit_test(test_haze),
        cmocka_unit_test(test_water),
        cmocka_unit_test(test_ao_directions),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
