/* test_robust.c: what a client gets when its body is refused, over raw sockets (issue 15,
 * point 3), and the listener while datasets load (point 4).
 *
 * Lingering close: a client that sends the whole body and only then reads must read the
 * answer (413 over the cap, 415 for a body that is not JSON, 401 on an admin route with a
 * body and a wrong token), by Content-Length and chunked; a client that says
 * `Expect: 100-continue` gets its 413 without sending the body; and the discarding is
 * bounded: a body far over the lingering bound is cut off (the client cannot send it all).
 *
 * Loading: terrad listens before it loads its datasets; while they load /healthz is 200,
 * /readyz and the data routes 503 with Retry-After; once loaded /readyz is 200. The load
 * is held by TERRAD_TEST_LOAD_GATE (cli_serve.c waits while that file exists), so the
 * test does not depend on how long a load takes. */
#define _GNU_SOURCE /* strcasestr */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>
#include <errno.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <time.h>
#include <unistd.h>

#include "harness.h"

#define TOKEN "robust-token-0123456789"
#define MAX_BODY_KB 64

static th_server S;

static int setup(void **state)
{
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--max-body-kb", "64",
                          "--render-workers", "1", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=" TOKEN, NULL};
    (void)state;
    return th_start(&S, TERRAD_BIN, args, env);
}

static int teardown(void **state)
{
    (void)state;
    int rc = th_stop(&S);
    if (rc == 0)
        th_forget(&S);
    return rc;
}

static int connect_to(int port)
{
    struct sockaddr_in a;
    struct timeval tv = {20, 0};
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    assert_true(fd >= 0);
    memset(&a, 0, sizeof a);
    a.sin_family = AF_INET;
    a.sin_port = htons((uint16_t)port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(connect(fd, (struct sockaddr *)&a, sizeof a), 0);
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    return fd;
}

/* Sends all n bytes; returns how many went out before an error (EPIPE, ECONNRESET). */
static size_t send_all(int fd, const char *p, size_t n)
{
    size_t done = 0;
    while (done < n) {
        ssize_t k = send(fd, p + done, n - done, MSG_NOSIGNAL);
        if (k <= 0)
            break;
        done += (size_t)k;
    }
    return done;
}

/* Reads until the answer's headers and Content-Length bytes of body are in (or EOF);
 * returns the status (0 if none could be read) and the text in out. */
static int read_answer(int fd, char *out, size_t outsz)
{
    size_t n = 0;
    int status = 0;
    while (n + 1 < outsz) {
        char *hend, *cl;
        ssize_t k = recv(fd, out + n, outsz - 1 - n, 0);
        if (k <= 0)
            break;
        n += (size_t)k;
        out[n] = '\0';
        hend = strstr(out, "\r\n\r\n");
        cl = strcasestr(out, "\r\nContent-Length:");
        if (hend && cl && cl < hend && n >= (size_t)(hend + 4 - out) + strtoul(cl + 17, NULL, 10))
            break;
    }
    out[n] = '\0';
    if (n > 12 && !strncmp(out, "HTTP/1.1 ", 9))
        status = atoi(out + 9);
    return status;
}

/* A body of n bytes (not JSON: refused for its size or its type before it is parsed). */
static char *body_of(size_t n)
{
    char *b = malloc(n);
    assert_non_null(b);
    memset(b, 'x', n);
    return b;
}

/* Sends headers then the whole body (by Content-Length), then reads: the status. */
static int post_whole(const char *path, const char *extra_headers, size_t n, char *ans, size_t anssz)
{
    char head[512];
    char *b = body_of(n);
    int fd = connect_to(S.port), status;
    snprintf(head, sizeof head, "POST %s HTTP/1.1\r\nHost: x\r\n%sContent-Length: %zu\r\n\r\n", path,
             extra_headers, n);
    assert_int_equal(send_all(fd, head, strlen(head)), strlen(head));
    assert_int_equal(send_all(fd, b, n), n);
    status = read_answer(fd, ans, anssz);
    close(fd);
    free(b);
    return status;
}

static void test_413_after_whole_body(void **state)
{
    char ans[8192];
    (void)state;
    /* 12 MiB at a 64 KiB cap (more than loopback's socket buffers hold, about 4 MiB: a
       server that stops reading makes the client's send fail): the whole body goes out,
       then the 413 is read */
    assert_int_equal(post_whole("/v1/render", "Content-Type: application/json\r\n", (size_t)12 << 20, ans,
                                sizeof ans),
                     413);
    assert_non_null(strstr(ans, "body_too_large"));
    /* just over the cap, and the same on the pick route */
    assert_int_equal(post_whole("/v1/pick", "Content-Type: application/json\r\n",
                                ((size_t)MAX_BODY_KB << 10) + 1, ans, sizeof ans),
                     413);
}

static void test_413_chunked(void **state)
{
    const char *head = "POST /v1/render HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                       "Transfer-Encoding: chunked\r\n\r\n";
    char chunk_head[32], ans[8192];
    char *b = body_of(32768);
    int fd = connect_to(S.port);
    (void)state;
    assert_int_equal(send_all(fd, head, strlen(head)), strlen(head));
    snprintf(chunk_head, sizeof chunk_head, "%x\r\n", 32768);
    for (int k = 0; k < 64; k++) { /* 2 MiB in 32 KiB chunks */
        assert_int_equal(send_all(fd, chunk_head, strlen(chunk_head)), strlen(chunk_head));
        assert_int_equal(send_all(fd, b, 32768), 32768);
        assert_int_equal(send_all(fd, "\r\n", 2), 2);
    }
    assert_int_equal(send_all(fd, "0\r\n\r\n", 5), 5);
    assert_int_equal(read_answer(fd, ans, sizeof ans), 413);
    close(fd);
    free(b);
}

static void test_415_and_401_with_body(void **state)
{
    char ans[8192];
    (void)state;
    assert_int_equal(post_whole("/v1/render", "Content-Type: text/plain\r\n", 60000, ans, sizeof ans), 415);
    assert_non_null(strstr(ans, "unsupported_media_type"));
    assert_int_equal(post_whole("/v1/admin/preload",
                                "Content-Type: application/json\r\nAuthorization: Bearer wrong\r\n", 60000,
                                ans, sizeof ans),
                     401);
    assert_non_null(strstr(ans, "unauthorized"));
    /* over the cap with a wrong token: refused for its size, still readable */
    assert_int_equal(post_whole("/v1/admin/preload",
                                "Content-Type: application/json\r\nAuthorization: Bearer wrong\r\n",
                                (size_t)1 << 20, ans, sizeof ans),
                     413);
}

/* Expect: 100-continue: the 413 comes before any byte of the body is sent. */
static void test_413_expect_continue(void **state)
{
    const char *head = "POST /v1/render HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                       "Expect: 100-continue\r\nContent-Length: 4194304\r\n\r\n";
    char ans[8192];
    int fd = connect_to(S.port);
    (void)state;
    assert_int_equal(send_all(fd, head, strlen(head)), strlen(head));
    assert_int_equal(read_answer(fd, ans, sizeof ans), 413);
    close(fd);
}

/* The discarding is bounded (16 MiB, http.c): a 256 MiB body is cut off by the server, so
 * the client cannot send it all; the server answers and stays up. */
static void test_linger_bounded(void **state)
{
    const size_t total = (size_t)256 << 20, piece = (size_t)1 << 20;
    char head[256];
    char *b = body_of(piece);
    size_t sent = 0;
    int fd = connect_to(S.port);
    (void)state;
    snprintf(head, sizeof head,
             "POST /v1/render HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: %zu\r\n\r\n",
             total);
    assert_int_equal(send_all(fd, head, strlen(head)), strlen(head));
    while (sent < total) {
        size_t k = send_all(fd, b, piece);
        sent += k;
        if (k < piece)
            break;
    }
    print_message("  sent %zu of %zu bytes before the server stopped reading\n", sent, total);
    assert_true(sent < total);
    close(fd);
    free(b);
    /* still serving */
    {
        th_resp r;
        assert_int_equal(th_request(&S, "GET", "/healthz", NULL, NULL, 0, &r), 0);
        assert_int_equal(r.status, 200);
        th_resp_free(&r);
    }
}

/* --- loading ------------------------------------------------------------------------- */

static long get_status(const th_server *s, const char *path, char *retry_after, size_t n)
{
    th_resp r;
    long st;
    assert_int_equal(th_request(s, "GET", path, NULL, NULL, 0, &r), 0);
    st = r.status;
    if (retry_after && !th_header(&r, "Retry-After", retry_after, n))
        retry_after[0] = '\0';
    th_resp_free(&r);
    return st;
}

static void test_healthz_while_loading(void **state)
{
    char gate[256], gate_env[300], ra[32];
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", NULL};
    const char *env[] = {gate_env, NULL};
    th_server L;
    FILE *f;
    int ready = 0;
    (void)state;
    snprintf(gate, sizeof gate, "%s/terrad-load-gate-%ld", P_tmpdir, (long)getpid());
    snprintf(gate_env, sizeof gate_env, "TERRAD_TEST_LOAD_GATE=%s", gate);
    f = fopen(gate, "w");
    assert_non_null(f);
    fclose(f);
    assert_int_equal(th_start_listening(&L, TERRAD_BIN, args, env), 0); /* nothing loaded */
    assert_false(th_log_has(&L, "datasets_ready"));
    assert_int_equal(get_status(&L, "/healthz", NULL, 0), 200);
    assert_int_equal(get_status(&L, "/readyz", ra, sizeof ra), 503);
    assert_string_equal(ra, "1");
    assert_int_equal(get_status(&L, "/v1/datasets", ra, sizeof ra), 503);
    assert_string_equal(ra, "1");
    assert_int_equal(get_status(&L, "/v1/render?dataset=levi&camera.position.x=1&camera.position.y=2"
                                    "&camera.position.z=900", NULL, 0),
                     503);
    assert_int_equal(get_status(&L, "/healthz", NULL, 0), 200);
    unlink(gate); /* the load goes on */
    for (int k = 0; k < 600 && !ready; k++) {
        struct timespec nap = {0, 50 * 1000 * 1000};
        ready = get_status(&L, "/readyz", NULL, 0) == 200;
        if (!ready)
            nanosleep(&nap, NULL);
    }
    assert_true(ready);
    assert_true(th_log_has(&L, "datasets_ready"));
    assert_int_equal(get_status(&L, "/v1/datasets", NULL, 0), 200);
    assert_int_equal(th_stop(&L), 0);
    th_forget(&L);
}

int main(void)
{
    const struct CMUnitTest linger[] = {
        cmocka_unit_test(test_413_after_whole_body),
        cmocka_unit_test(test_413_chunked),
        cmocka_unit_test(test_415_and_401_with_body),
        cmocka_unit_test(test_413_expect_continue),
        cmocka_unit_test(test_linger_bounded),
    };
    const struct CMUnitTest loading[] = {
        cmocka_unit_test(test_healthz_while_loading),
    };
    int failed = cmocka_run_group_tests_name("linger", linger, setup, teardown);
    failed += cmocka_run_group_tests_name("loading", loading, NULL, NULL);
    return failed;
}
