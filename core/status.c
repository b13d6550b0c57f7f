/* status.c: names of status codes, the error record, checked size arithmetic. */
#include "status.h"

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

static const char *const td_status_texts[] = {
#define TD_X_TEXT(code, text, json) text,
    TD_STATUS_LIST(TD_X_TEXT)
#undef TD_X_TEXT
};

static const char *const td_status_jsons[] = {
#define TD_X_JSON(code, text, json) json,
    TD_STATUS_LIST(TD_X_JSON)
#undef TD_X_JSON
};

const char *td_status_text(td_status st)
{
    return (unsigned)st < TD_STATUS_COUNT ? td_status_texts[st] : "unknown status";
}

const char *td_status_json(td_status st)
{
    return (unsigned)st < TD_STATUS_COUNT ? td_status_jsons[st] : "unknown";
}

td_status td_err_set(td_err *err, td_status st, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->msg, sizeof err->msg, fmt, ap);
        va_end(ap);
        err->field[0] = '\0';
    }
    return st;
}

td_status td_err_field(td_err *err, td_status st, const char *field, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        int n = snprintf(err->msg, sizeof err->msg, "%s: ", field);
        size_t used = n < 0 ? 0 : ((size_t)n < sizeof err->msg ? (size_t)n : sizeof err->msg - 1);
        va_start(ap, fmt);
        vsnprintf(err->msg + used, sizeof err->msg - used, fmt, ap);
        va_end(ap);
        snprintf(err->field, sizeof err->field, "%s", field);
    }
    return st;
}

int td_name_index(const char *const *names, int n, const char *name)
{
    int found = -1;
    for (int i = 0; name && i < n && found < 0; i++)
        if (!strcmp(name, names[i]))
            found = i;
    return found;
}

int td_mul_size(size_t a, size_t b, size_t *out)
{
    int ok = !(a != 0 && b > SIZE_MAX / a);
    if (ok)
        *out = a * b;
    return ok;
}

int td_add_size(size_t a, size_t b, size_t *out)
{
    int ok = b <= SIZE_MAX - a;
    if (ok)
        *out = a + b;
    return ok;
}
