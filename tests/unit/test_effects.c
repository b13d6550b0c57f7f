/* test_effects.c: the per-sample effect functions (core/effects.c): the sky's colours
 * (bluer up, warmer toward a low sun, the disc only where asked), td_sky_shade under a
 * sun prepared once giving td_sky_color's colours bit for bit, the haze's transmittance
 * (Koschmieder's 2% at the visibility, the closed form over a sloping segment against a
 * sum of many short level steps, td_haze_transmittance_e0 equal to the plain one), the
 * water's Fresnel term and tint, and the ambient-occlusion directions (unit, over the
 * normal). */
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

static void test_sky_colours(void **state)
{
    (void)state;
    double sun[3], up[3] = {0.0, 0.0, 1.0}, flat[3], away[3], toward[3];
    float c_up[3], c_flat[3], c_away[3], c_toward[3], c_disc[3], c_nodisc[3];
    unit(270.0, 3.0, sun); /* a sunset in the west */
    unit(90.0, 0.0, away);
    unit(270.0, 0.0, toward);
    unit(0.0, 0.0, flat);
    td_sky_color(up, sun, 0, c_up);
    td_sky_color(flat, sun, 0, c_flat);
    td_sky_color(away, sun, 0, c_away);
    td_sky_color(toward, sun, 0, c_toward);
    /* the zenith is bluer and darker in red than the horizon */
    assert_true(c_up[2] > c_up[0] && c_up[0] < c_flat[0]);
    /* toward the low sun the horizon is warmer (more red, less blue) than away from it */
    assert_true(c_toward[0] > c_away[0] && c_toward[2] < c_away[2]);
    /* the disc: only with `disc`, the fixed warm white squared to linear */
    td_sky_color(sun, sun, 1, c_disc);
    td_sky_color(sun, sun, 0, c_nodisc);
    assert_float_equal(c_disc[0], 1.0f, 0.0f);
    assert_float_equal(c_disc[1], (float)(0.97 * 0.97), 0.0f);
    assert_float_equal(c_disc[2], (float)(0.90 * 0.90), 0.0f);
    assert_true(c_nodisc[1] < c_disc[1]);
    /* below the horizon: the horizon's colour (no darker sky under it) */
    double down[3], level[3];
    unit(10.0, -30.0, down);
    unit(10.0, 0.0, level);
    float c_down[3], c_level[3];
    td_sky_color(down, sun, 0, c_down);
    td_sky_color(level, sun, 0, c_level);
    for (int k = 0; k < 3; k++)
        assert_true(fabsf(c_down[k] - c_level[k]) < 0.05f);
}

/* td_sky_shade after td_sky_init: the same bytes as td_sky_color, for suns from below the
 * horizon to the zenith and directions all round, with and without the disc. */
static void test_sky_prepared_same(void **state)
{
    (void)state;
    for (double sel = -10.0; sel <= 90.0; sel += 12.5) {
        double s[3];
        td_sky k;
        unit(123.0, sel, s);
        td_sky_init(&k, s);
        for (double az = 0.0; az < 360.0; az += 17.0)
            for (double el = -40.0; el <= 90.0; el += 9.0)
                for (int disc = 0; disc < 2; disc++) {
                    double d[3];
                    float a[3], b[3];
                    unit(az, el, d);
                    td_sky_color(d, s, disc, a);
                    td_sky_shade(&k, d, disc, b);
                    assert_memory_equal(a, b, sizeof a);
                }
        /* the sun's own direction, where the disc is drawn */
        float a[3], b[3];
        td_sky_color(s, s, 1, a);
        td_sky_shade(&k, s, 1, b);
        assert_memory_equal(a, b, sizeof a);
    }
}

static void test_haze(void **state)
{
    (void)state;
    const double V = 20.0, beta0 = td_haze_beta(V), H = TD_HAZE_SCALE_HEIGHT_M;
    /* Koschmieder: 2% contrast left over the visibility, level at the reference height */
    assert_true(fabs(td_haze_transmittance(beta0, 0.0, 0.0, V * 1000.0) - 0.02) < 1e-3);
    assert_float_equal(td_haze_transmittance(beta0, 100.0, 900.0, 0.0), 1.0, 0.0);
    /* thinner air higher up: a level segment at 3 km lets more through */
    assert_true(td_haze_transmittance(beta0, 3000.0, 3000.0, 5000.0) >
                td_haze_transmittance(beta0, 0.0, 0.0, 5000.0));
    /* the closed form over a climbing segment against many short level steps */
    const double z0 = 200.0, z1 = 2600.0, len = 30000.0;
    double tau = 0.0;
    const int n = 200000;
    for (int i = 0; i < n; i++) {
        double z = z0 + (z1 - z0) * (i + 0.5) / n;
        tau += beta0 * exp(-z / H) * len / n;
    }
    assert_true(fabs(td_haze_transmittance(beta0, z0, z1, len) - exp(-tau)) < 1e-9);
    /* with the start's exp given: the same bits, level or not, up or down */
    static const double zs[][2] = {{0.0, 0.0}, {200.0, 2600.0}, {2600.0, 200.0}, {1000.0, 1000.5}, {-50.0, 4000.0}};
    for (size_t k = 0; k < sizeof zs / sizeof zs[0]; k++) {
        double a = td_haze_transmittance(beta0, zs[k][0], zs[k][1], len);
        double b = td_haze_transmittance_e0(beta0, zs[k][0], exp(-zs[k][0] / H), zs[k][1], len);
        assert_memory_equal(&a, &b, sizeof a);
    }
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
        cmocka_unit_test(test_sky_prepared_same),
        cmocka_unit_test(test_haze),
        cmocka_unit_test(test_water),
        cmocka_unit_test(test_ao_directions),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
