/* log.h: one-line structured logs on stderr, `key=value` pairs after a timestamp, a
 * level and an event name, so a line can be grepped, cut and parsed without a schema:
 *
 *   2025-01-01T12:00:00.123Z level=info event=access method=GET path="/healthz" ...
 *
 * Each line is formatted into a local buffer and written with one write(2), so lines
 * from concurrent threads never interleave. Values that may hold spaces, quotes or
 * control characters (paths, messages) go through td_log_quote first. */
#ifndef TD_LOG_H
#define TD_LOG_H

#include <stddef.h>

#define TD_LOG_LEVEL_LIST(X)                                                   \
    X(TD_LOG_DEBUG, "debug")                                                   \
    X(TD_LOG_INFO, "info")                                                     \
    X(TD_LOG_WARN, "warn")                                                     \
    X(TD_LOG_ERROR, "error")

typedef enum td_log_level {
#define TD_X_ENUM(e, name) e,
    TD_LOG_LEVEL_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_LOG_LEVEL_COUNT
} td_log_level;

/* Lines below `lvl` are dropped (default: info). */
void td_log_set_level(td_log_level lvl);
/* Parses a level name; returns 0 and leaves *out on an unknown name. */
int td_log_level_parse(const char *name, td_log_level *out);
const char *td_log_level_name(td_log_level lvl);

/* Writes one line: timestamp, level, event, then the printf-formatted pairs. */
void td_log(td_log_level lvl, const char *event, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* Writes `s` into buf (size n) as a double-quoted value with `"`, `\` and control
 * characters escaped, truncated to fit; returns buf. */
const char *td_log_quote(char *buf, size_t n, const char *s);

#endif
