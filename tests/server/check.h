/* check.h: assertions on terrad's JSON answers shared by the server tests (cmocka and
 * jansson; include after <cmocka.h>). */
#ifndef TD_TEST_CHECK_H
#define TD_TEST_CHECK_H

#include <jansson.h>

#include "harness.h"

/* The body as JSON (the test fails when it is not). */
static inline json_t *body_json(const th_resp *r)
{
    json_error_t e;
    json_t *j = json_loadb(r->body, r->len, 0, &e);
    if (!j)
        fail_msg("not JSON (%s): %.*s", e.text, (int)(r->len > 200 ? 200 : r->len), r->body);
    return j;
}

/* Asserts a JSON error with this status and code (and field, if given). */
static inline void assert_error(const th_resp *r, long status, const char *code, const char *field)
{
    json_t *j, *e;
    if (r->status != status)
        fail_msg("status %ld, expected %ld: %.*s", r->status, status, (int)r->len, r->body);
    j = body_json(r);
    e = json_object_get(j, "error");
    assert_non_null(e);
    assert_string_equal(json_string_value(json_object_get(e, "code")), code);
    assert_non_null(json_string_value(json_object_get(e, "message")));
    if (field)
        assert_string_equal(json_string_value(json_object_get(e, "field")), field);
    json_decref(j);
}

#endif
