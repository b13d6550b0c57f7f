/* log.c: structured one-line logging on stderr (see log.h). The level is a relaxed atomic
 * so a test or a signal handler path can change it without a lock; lines are built in a
 * stack buffer and written with a single write(2) (stderr is a pipe or a terminal; a
 * write of up to PIPE_BUF bytes to a pipe is atomic, longer lines are truncated to it).
 * Rejected: syslog (containers and the tests read stderr), JSON lines (harder to read by
 * eye in a terminal, and `key=value` is what logfmt tools already parse). */
#include "log.h"

#include <limits.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static atomic_int td_log_min = TD_LOG_INFO;

static const char *const td_log_names[] = {
#define TD_X_NAME(e, name) name,
    TD_LOG_LEVEL_LIST(TD_X_NAME)
#undef TD_X_NAME
};

void td_log_set_level(td_log_level lvl)
{
    atomic_store_explicit(&td_log_min, (int)lvl, memory_order_relaxed);
}

const char *td_log_level_name(td_log_level lvl)
{
    return (unsigned)lvl < TD_LOG_LEVEL_COUNT ? td_log_names[lvl] : "unknown";
}

int td_log_level_parse(const char *name, td_log_level *out)
{
    int found = 0;
    for (int i = 0; i < TD_LOG_LEVEL_COUNT && !found; i++) {
        if (!strcmp(name, td_log_names[i])) {
            *out = (td_log_level)i;
            found = 1;
        }
    }
    return found;
}

const char *td_log_quote(char *buf, size_t n, const char *s)
{
    size_t o = 0;
    if (n < 3) {
        if (n)
            buf[0] = '\0';
        return buf;
    }
    buf[o++] = '"';
    for (; s && *s && o + 6 < n; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') {
            buf[o++] = '\\';
            buf[o++] = (char)c;
        } else if (c < 0x20 || c == 0x7f) {
            o += (size_t)snprintf(buf + o, n - o, "\\x%02x", c);
        } else {
            buf[o++] = (char)c;
        }
    }
    buf[o++] = '"';
    buf[o] = '\0';
    return buf;
}

void td_log(td_log_level lvl, const char *event, const char *fmt, ...)
{
    char line[PIPE_BUF];
    size_t n = 0;
    struct timespec ts;
    struct tm tm;
    va_list ap;
    int w;

    if ((int)lvl < atomic_load_explicit(&td_log_min, memory_order_relaxed))
        return;
    clock_gettime(CLOCK_REALTIME, &ts);
    gmtime_r(&ts.tv_sec, &tm);
    n = strftime(line, sizeof line, "%Y-%m-%dT%H:%M:%S", &tm);
    w = snprintf(line + n, sizeof line - n, ".%03ldZ level=%s event=%s ", ts.tv_nsec / 1000000L,
                 td_log_level_name(lvl), event);
    if (w > 0)
        n += (size_t)w < sizeof line - n ? (size_t)w : sizeof line - n - 1;
    va_start(ap, fmt);
    w = vsnprintf(line + n, sizeof line - n, fmt, ap);
    va_end(ap);
    if (w > 0)
        n += (size_t)w < sizeof line - n ? (size_t)w : sizeof line - n - 1;
    if (n >= sizeof line - 1)
        n = sizeof line - 2;
    line[n++] = '\n';
    /* A short or failed write to stderr has nowhere better to be reported. */
    if (write(STDERR_FILENO, line, n) < 0)
        return;
}
