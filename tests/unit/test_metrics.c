/* test_metrics.c: the Prometheus text of server/metrics.c: requests counted by route
 * and status, the render histogram cumulative by method with +Inf, sum and count, rays
 * and steps summed, the values passed in at scrape time, and every sample line a
 * well-formed `terrad_` series with a HELP and TYPE before it. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "metrics.h"

static const char *const routes[] = {"render", "healthz"};

/* The value of the series line that starts with `series ` (exact name and labels). */
static double value_of(const char *text, const char *series)
{
    size_t n = strlen(series);
    const char *p = text;
    double v = -1.0;
    while (p && *p) {
        if (!strncmp(p, series, n) && p[n] == ' ') {
            v = strtod(p + n + 1, NULL);
            break;
        }
        p = strchr(p, '\n');
        p = p ? p + 1 : NULL;
    }
    return v;
}

static void test_counts_and_histogram(void **state)
{
    td_metrics *m = td_metrics_create(routes, 2);
    td_metrics_ext ext;
    size_t len = 0;
    (void)state;
    assert_non_null(m);
    memset(&ext, 0, sizeof ext);
    ext.queue_depth = 3;
    ext.queue_capacity = 18;
    ext.datasets = 2;
    ext.resident_bytes = 12345;
    td_metrics_request(m, 0, 200);
    td_metrics_request(m, 0, 200);
    td_metrics_request(m, 0, 400);
    td_metrics_request(m, 1, 200);
    td_metrics_render(m, TD_METHOD_HIERARCHICAL, 0.02, 1000, 5000);  /* bucket 0.025 */
    td_metrics_render(m, TD_METHOD_HIERARCHICAL, 3.0, 2000, 7000);   /* bucket 5 */
    td_metrics_render(m, TD_METHOD_PARAMETRIC, 100.0, 10, 20);       /* only +Inf */
    char *t = td_metrics_format(m, &ext, &len);
    assert_non_null(t);
    assert_int_equal(strlen(t), len);
    assert_true(value_of(t, "terrad_requests_total{route=\"render\",status=\"200\"}") == 2.0);
    assert_true(value_of(t, "terrad_requests_total{route=\"render\",status=\"400\"}") == 1.0);
    assert_true(value_of(t, "terrad_requests_total{route=\"healthz\",status=\"200\"}") == 1.0);
    assert_true(value_of(t, "terrad_render_seconds_bucket{method=\"hierarchical\",le=\"0.01\"}") == 0.0);
    assert_true(value_of(t, "terrad_render_seconds_bucket{method=\"hierarchical\",le=\"0.025\"}") == 1.0);
    assert_true(value_of(t, "terrad_render_seconds_bucket{method=\"hierarchical\",le=\"5\"}") == 2.0);
    assert_true(value_of(t, "terrad_render_seconds_bucket{method=\"hierarchical\",le=\"+Inf\"}") == 2.0);
    assert_true(value_of(t, "terrad_render_seconds_count{method=\"hierarchical\"}") == 2.0);
    double sum = value_of(t, "terrad_render_seconds_sum{method=\"hierarchical\"}");
    assert_true(sum > 3.0199 && sum < 3.0201);
    assert_true(value_of(t, "terrad_render_seconds_bucket{method=\"parametric\",le=\"30\"}") == 0.0);
    assert_true(value_of(t, "terrad_render_seconds_bucket{method=\"parametric\",le=\"+Inf\"}") == 1.0);
    assert_true(value_of(t, "terrad_rays_total") == 3010.0);
    assert_true(value_of(t, "terrad_steps_total") == 12020.0);
    assert_true(value_of(t, "terrad_render_queue_depth") == 3.0);
    assert_true(value_of(t, "terrad_datasets") == 2.0);
    assert_true(value_of(t, "terrad_resident_bytes") == 12345.0);

    /* every sample line is a terrad_ series whose family was announced by HELP and TYPE */
    for (char *line = strtok(t, "\n"); line; line = strtok(NULL, "\n")) {
        if (line[0] == '#') {
            assert_true(!strncmp(line, "# HELP terrad_", 14) || !strncmp(line, "# TYPE terrad_", 14));
        } else {
            assert_int_equal(strncmp(line, "terrad_", 7), 0);
            assert_non_null(strchr(line, ' '));
        }
    }
    free(t);
    td_metrics_free(m);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_counts_and_histogram),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
