/* harness.h: for the server integration tests: start `terrad serve` on a free loopback
 * port (--listen 127.0.0.1:0; the port is read from its `listening` log line), talk to
 * it with libcurl, stop it with SIGTERM by pid and collect its exit status. */
#ifndef TD_TEST_HARNESS_H
#define TD_TEST_HARNESS_H

#include <stddef.h>
#include <sys/types.h>

typedef struct th_server {
    pid_t pid;
    int port;
    char log[512]; /* stderr of terrad */
} th_server;

/* argv: extra arguments after `serve --listen 127.0.0.1:0`, NULL-terminated; env: extra
 * "K=V" strings, NULL-terminated (may be NULL). Returns 0 when terrad is listening and has
 * loaded its datasets (its `ready` log line; it listens before it loads). */
int th_start(th_server *s, const char *terrad, const char *const *argv, const char *const *env);
/* The same, returning as soon as terrad listens (its datasets may still be loading). */
int th_start_listening(th_server *s, const char *terrad, const char *const *argv,
                       const char *const *env);
/* SIGTERM, wait; returns the exit status (or -1 if it did not exit by itself in 60 s, in
 * which case it was killed). */
int th_stop(th_server *s);
/* Removes the server's log file (call once a test that passed no longer needs it). */
void th_forget(th_server *s);
/* Non-zero if the server's log contains `needle`. */
int th_log_has(const th_server *s, const char *needle);

typedef struct th_resp {
    long status;
    char *body;
    size_t len;
    char *headers; /* raw header block, lower-cased names kept as sent */
    size_t hlen;
} th_resp;

/* One request. `headers` are "Name: value" strings, NULL-terminated (may be NULL).
 * Returns 0 on a transport success (any HTTP status). */
int th_request(const th_server *s, const char *method, const char *path,
               const char *const *headers, const char *body, size_t body_len, th_resp *r);
void th_resp_free(th_resp *r);
/* Value of a response header (case-insensitive name) copied into out; 1 if found. */
int th_header(const th_resp *r, const char *name, char *out, size_t n);
/* system() of a printf-formatted command (up to 2 KiB); its status. */
int th_sh(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* PNG width and height from the IHDR chunk; 1 if the body is a PNG. */
int th_png_size(const th_resp *r, int *w, int *h);

#endif
