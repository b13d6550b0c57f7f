/* harness.c: see harness.h. */
#define _GNU_SOURCE
#include "harness.h"

#include <curl/curl.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static void nap_ms(int ms)
{
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

int th_log_has(const th_server *s, const char *needle)
{
    FILE *f = fopen(s->log, "r");
    char line[8192];
    int found = 0;
    while (f && !found && fgets(line, sizeof line, f))
        found = strstr(line, needle) != NULL;
    if (f)
        fclose(f);
    return found;
}

/* Whether the server logged `event=ready` (its datasets are loaded). */
static int logged_ready(const th_server *s)
{
    return th_log_has(s, "event=ready ");
}

static int read_port(const th_server *s)
{
    FILE *f = fopen(s->log, "r");
    char line[8192];
    int port = 0;
    while (f && !port && fgets(line, sizeof line, f)) {
        char *p = strstr(line, "event=listening");
        if (p && (p = strstr(p, " port=")))
            port = atoi(p + 6);
    }
    if (f)
        fclose(f);
    return port;
}

/* Servers still running when the test process exits (a failed assertion jumps past
 * th_stop) are killed at exit, so no terrad outlives its test. */
static pid_t th_live[32];

static void th_kill_live(void)
{
    for (int i = 0; i < 32; i++)
        if (th_live[i] > 0) {
            kill(th_live[i], SIGKILL);
            waitpid(th_live[i], NULL, 0);
            th_live[i] = 0;
        }
}

static void th_track(pid_t pid, pid_t old)
{
    static int registered;
    if (!registered) {
        atexit(th_kill_live);
        registered = 1;
    }
    for (int i = 0; i < 32; i++)
        if (th_live[i] == old) {
            th_live[i] = pid;
            break;
        }
}

static int start(th_server *s, const char *terrad, const char *const *argv, const char *const *env,
                 int until_ready)
{
    const char *args[64];
    int n = 0;
    static int seq;
    memset(s, 0, sizeof *s);
    snprintf(s->log, sizeof s->log, "%s/terrad-test-%ld-%d.log", P_tmpdir, (long)getpid(), seq++);
    args[n++] = terrad;
    args[n++] = "serve";
    args[n++] = "--listen";
    args[n++] = "127.0.0.1:0";
    for (int i = 0; argv && argv[i] && n < 62; i++)
        args[n++] = argv[i];
    args[n] = NULL;
    s->pid = fork();
    if (s->pid == 0) {
        int fd = open(s->log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd >= 0) {
            dup2(fd, 2);
            dup2(fd, 1);
        }
        for (int i = 0; env && env[i]; i++)
            putenv((char *)env[i]);
        execv(terrad, (char *const *)args);
        _exit(127);
    }
    if (s->pid < 0)
        return -1;
    th_track(s->pid, 0);
    for (int i = 0; i < 400 && !s->port; i++) {
        int st;
        if (waitpid(s->pid, &st, WNOHANG) == s->pid) {
            th_track(0, s->pid);
            s->pid = 0;
            return -1;
        }
        nap_ms(25);
        s->port = read_port(s);
    }
    for (int i = 0; s->port && until_ready && i < 2400 && !logged_ready(s); i++)
        nap_ms(25);
    return s->port && (!until_ready || logged_ready(s)) ? 0 : -1;
}

int th_start(th_server *s, const char *terrad, const char *const *argv, const char *const *env)
{
    return start(s, terrad, argv, env, 1);
}

int th_start_listening(th_server *s, const char *terrad, const char *const *argv,
                       const char *const *env)
{
    return start(s, terrad, argv, env, 0);
}

int th_stop(th_server *s)
{
    int st = 0, rc = -1;
    if (s->pid <= 0)
        return -1;
    kill(s->pid, SIGTERM);
    for (int i = 0; i < 2400; i++) {
        if (waitpid(s->pid, &st, WNOHANG) == s->pid) {
            rc = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
            break;
        }
        nap_ms(25);
    }
    if (rc == -1) {
        kill(s->pid, SIGKILL);
        waitpid(s->pid, &st, 0);
    }
    th_track(0, s->pid);
    s->pid = 0;
    return rc;
}

void th_forget(th_server *s)
{
    unlink(s->log);
}

typedef struct th_acc {
    char *p;
    size_t len;
} th_acc;

static size_t acc_write(char *data, size_t size, size_t nmemb, void *cls)
{
    th_acc *a = cls;
    size_t n = size * nmemb;
    char *np = realloc(a->p, a->len + n + 1);
    if (!np)
        return 0;
    memcpy(np + a->len, data, n);
    a->p = np;
    a->len += n;
    a->p[a->len] = '\0';
    return n;
}

int th_request(const th_server *s, const char *method, const char *path,
               const char *const *headers, const char *body, size_t body_len, th_resp *r)
{
    CURL *c = curl_easy_init();
    struct curl_slist *hl = NULL;
    char url[2048];
    th_acc b = {NULL, 0}, h = {NULL, 0};
    CURLcode cc;

    memset(r, 0, sizeof *r);
    if (!c)
        return -1;
    snprintf(url, sizeof url, "http://127.0.0.1:%d%s", s->port, path);
    curl_easy_setopt(c, CURLOPT_URL, url);
    curl_easy_setopt(c, CURLOPT_PATH_AS_IS, 1L);
    curl_easy_setopt(c, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(c, CURLOPT_TIMEOUT, 120L);
    curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, acc_write);
    curl_easy_setopt(c, CURLOPT_WRITEDATA, &b);
    curl_easy_setopt(c, CURLOPT_HEADERFUNCTION, acc_write);
    curl_easy_setopt(c, CURLOPT_HEADERDATA, &h);
    if (!strcmp(method, "HEAD"))
        curl_easy_setopt(c, CURLOPT_NOBODY, 1L);
    else
        curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
    if (body) {
        curl_easy_setopt(c, CURLOPT_POSTFIELDS, body);
        curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE, (long)body_len);
    }
    hl = curl_slist_append(hl, "Expect:");
    for (int i = 0; headers && headers[i]; i++)
        hl = curl_slist_append(hl, headers[i]);
    curl_easy_setopt(c, CURLOPT_HTTPHEADER, hl);
    cc = curl_easy_perform(c);
    if (cc == CURLE_OK)
        curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, &r->status);
    r->body = b.p ? b.p : calloc(1, 1);
    r->len = b.len;
    r->headers = h.p ? h.p : calloc(1, 1);
    r->hlen = h.len;
    curl_slist_free_all(hl);
    curl_easy_cleanup(c);
    return cc == CURLE_OK ? 0 : -1;
}

void th_resp_free(th_resp *r)
{
    free(r->body);
    free(r->headers);
    memset(r, 0, sizeof *r);
}

int th_header(const th_resp *r, const char *name, char *out, size_t n)
{
    const char *p = r->headers;
    size_t nl = strlen(name);
    while (p && *p) {
        const char *eol = strstr(p, "\r\n");
        if (!strncasecmp(p, name, nl) && p[nl] == ':') {
            const char *v = p + nl + 1;
            size_t len;
            while (*v == ' ')
                v++;
            len = eol ? (size_t)(eol - v) : strlen(v);
            if (len >= n)
                len = n - 1;
            memcpy(out, v, len);
            out[len] = '\0';
            return 1;
        }
        p = eol ? eol + 2 : NULL;
    }
    return 0;
}

int th_sh(const char *fmt, ...)
{
    char cmd[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    return system(cmd);
}

int th_png_size(const th_resp *r, int *w, int *h)
{
    const unsigned char *b = (const unsigned char *)r->body;
    static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (r->len < 24 || memcmp(b, sig, 8) || memcmp(b + 12, "IHDR", 4))
        return 0;
    *w = (b[16] << 24) | (b[17] << 16) | (b[18] << 8) | b[19];
    *h = (b[20] << 24) | (b[21] << 16) | (b[22] << 8) | b[23];
    return 1;
}
