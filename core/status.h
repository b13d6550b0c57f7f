/* status.h: the status codes every core function returns, and the error record that
 * carries a human-readable reason back to the caller (core never logs; the caller
 * decides what to do with the message).
 *
 * The list is one X-macro table, so the enum, its name and its JSON spelling cannot
 * drift apart (after libuv's uv.h). */
#ifndef TD_STATUS_H
#define TD_STATUS_H

#include <stddef.h>

#define TD_STATUS_LIST(X)                                                      \
    X(TD_OK, "ok", "ok")                                                       \
    X(TD_EIO, "input/output error", "io")                                      \
    X(TD_EFORMAT, "malformed input", "format")                                 \
    X(TD_ERANGE, "value out of range", "range")                                \
    X(TD_ETOOBIG, "exceeds configured limits", "too_big")                      \
    X(TD_ENOMEM, "out of memory", "no_memory")                                 \
    X(TD_EINVAL, "invalid argument", "invalid")                                \
    X(TD_EUNSUPPORTED, "unsupported", "unsupported")                           \
    X(TD_ENOTFOUND, "not found", "not_found")                                  \
    X(TD_ECANCELED, "cancelled", "cancelled")                                 \
    X(TD_EAGAIN, "not ready yet", "not_ready") /* e.g. a prepared dataset being verified */

typedef enum td_status {
#define TD_X_ENUM(code, text, json) code,
    TD_STATUS_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_STATUS_COUNT
} td_status;

/* Caller-supplied error record: functions that fail fill `msg` with a reason that
 * names the file or field at fault. When a field of the caller's input is at fault
 * (a scene's `quality.samples`), `field` holds its JSON path, so a caller answers with
 * it without reading the text (the HTTP error's `field`); else it is "". A NULL td_err
 * is allowed everywhere. */
typedef struct td_err {
    char msg[512];
    char field[64];
} td_err;

const char *td_status_text(td_status st);
const char *td_status_json(td_status st);

/* Formats the message into err (if non-NULL), clears its field and returns st, so a
 * failing path can write `rc = td_err_set(err, TD_EFORMAT, "%s: ...", path); goto out;`. */
td_status td_err_set(td_err *err, td_status st, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* The same for an input field at fault: err->field = field, and the message is
 * "field: " followed by the formatted text, so whoever prints only the message still
 * reads which field. `rc = td_err_field(err, TD_ERANGE, "quality.samples", "%d is
 * outside 1 .. 8", n);` */
td_status td_err_field(td_err *err, td_status st, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

/* Index of `name` in the n names of an X-macro table, or -1 (also for a NULL name). */
int td_name_index(const char *const *names, int n, const char *name);

/* Checked size arithmetic: return 0 on overflow, 1 otherwise. */
int td_mul_size(size_t a, size_t b, size_t *out);
int td_add_size(size_t a, size_t b, size_t *out);

#endif
