/* test_answer.c: the pick answer (server/answer.c) that /v1/pick sends and `terrad render`
 * writes: a miss carries only its pixel; a hit its point, distance, cell, height error
 * (left out at a void) and, on a georeferenced grid, lon/lat or projected coordinates. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "answer.h"

static double num(json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    assert_true(json_is_number(v));
    return json_number_value(v);
}

static void test_picks(void **state)
{
    td_grid *g = NULL;
    td_err err = {0};
    td_pick pk[3];
    json_t *a, *picks, *o;
    (void)state;

    assert_int_equal(td_grid_create(11, 6, 20.0, 10.0, 8, NULL, &g, &err), TD_OK);
    memset(pk, 0, sizeof pk);
    pk[0].px = 1.5;
    pk[0].py = 2;
    pk[1] = (td_pick){.px = 3, .py = 4, .hit = 1, .p = {100, 30, 250.5}, .distance = 812.25,
                      .height_error_m = 0.125, .ci = 5, .cj = 3};
    pk[2] = pk[1];
    pk[2].height_error_m = NAN;

    a = td_answer_picks("levi", g, pk, 3);
    assert_non_null(a);
    assert_string_equal(json_string_value(json_object_get(a, "dataset")), "levi");
    picks = json_object_get(a, "picks");
    assert_int_equal(json_array_size(picks), 3);

    o = json_array_get(picks, 0);
    assert_int_equal(json_object_size(o), 2);
    assert_true(json_is_false(json_object_get(o, "hit")));
    assert_true(json_real_value(json_array_get(json_object_get(o, "pixel"), 0)) == 1.5);

    o = json_array_get(picks, 1);
    assert_true(json_is_true(json_object_get(o, "hit")));
    assert_true(num(json_object_get(o, "point"), "z") == 250.5);
    assert_true(num(o, "distance") == 812.25);
    assert_true(num(o, "height_error_m") == 0.125);
    assert_int_equal(json_integer_value(json_array_get(json_object_get(o, "cell"), 0)), 5);
    assert_null(json_object_get(o, "lonlat")); /* not georeferenced */
    assert_null(json_object_get(o, "projected"));
    assert_null(json_object_get(json_array_get(picks, 2), "height_error_m")); /* a void */
    json_decref(a);

    g->geo.kind = TD_GEO_LONLAT;
    g->geo.x0 = -105.5;
    g->geo.y0 = 37.0;
    g->geo.dx = g->geo.dy = 0.001;
    a = td_answer_picks("trinidad", g, pk, 2);
    o = json_array_get(json_object_get(a, "picks"), 1);
    /* x 100 m = 5 samples of 20 m east; y 30 m = 3 samples of 10 m north */
    assert_float_equal(json_real_value(json_array_get(json_object_get(o, "lonlat"), 0)), -105.495, 1e-12);
    assert_float_equal(json_real_value(json_array_get(json_object_get(o, "lonlat"), 1)), 37.003, 1e-12);
    json_decref(a);

    g->geo.kind = TD_GEO_PROJECTED;
    a = td_answer_picks("picos", g, pk, 2);
    o = json_array_get(json_object_get(a, "picks"), 1);
    assert_non_null(json_object_get(o, "projected"));
    assert_null(json_object_get(o, "lonlat"));
    json_decref(a);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_picks),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
