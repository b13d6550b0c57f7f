/* test_config.c: the settings of `terrad serve` (server/config.c): defaults, TERRAD_*
 * variables, flags winning over variables, bounds and malformed values refused with the
 * flag or variable named, the admin token only from the environment or a file. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "config.h"

static td_status load(td_config *cfg, char **argv, int argc, td_err *err)
{
    int help = 0;
    memset(cfg, 0, sizeof *cfg);
    return td_config_load(cfg, argc, argv, &help, err);
}

static void clear_env(void)
{
    unsetenv("TERRAD_LISTEN");
    unsetenv("TERRAD_MEMORY_MB");
    unsetenv("TERRAD_ADMIN_TOKEN");
    unsetenv("TERRAD_ADMIN_TOKEN_FILE");
    unsetenv("TERRAD_RENDER_TIMEOUT");
}

static void test_defaults(void **state)
{
    td_config cfg;
    td_err err;
    char *argv[] = {"serve", NULL};
    (void)state;
    clear_env();
    assert_int_equal(load(&cfg, argv, 1, &err), TD_OK);
    assert_string_equal(cfg.listen, "127.0.0.1:8080");
    assert_string_equal(cfg.host, "127.0.0.1");
    assert_int_equal(cfg.port, 8080);
    assert_int_equal(cfg.memory_mb, 1024);
    assert_int_equal(cfg.queue, 16);
    assert_null(cfg.admin_token); /* admin routes off */
    td_config_free(&cfg);
}

static void test_env_then_flags(void **state)
{
    td_config cfg;
    td_err err;
    char *argv[] = {"serve", "--memory-mb", "64", "--listen", "127.0.0.1:0", NULL};
    (void)state;
    clear_env();
    setenv("TERRAD_MEMORY_MB", "32", 1);
    setenv("TERRAD_LISTEN", "127.0.0.1:9999", 1);
    setenv("TERRAD_RENDER_TIMEOUT", "2.5", 1);
    setenv("TERRAD_ADMIN_TOKEN", "s3cret", 1);
    assert_int_equal(load(&cfg, argv, 5, &err), TD_OK);
    assert_int_equal(cfg.memory_mb, 64); /* the flag wins */
    assert_int_equal(cfg.port, 0);
    assert_true(cfg.render_timeout_s == 2.5); /* from the environment */
    assert_non_null(cfg.admin_token);
    assert_string_equal(cfg.admin_token, "s3cret");
    td_config_free(&cfg);
    clear_env();
}

static void test_refusals_name_the_setting(void **state)
{
    td_config cfg;
    td_err err;
    (void)state;
    clear_env();
    {
        char *argv[] = {"serve", "--memory-mb", "0", NULL};
        assert_int_equal(load(&cfg, argv, 3, &err), TD_EINVAL);
        assert_non_null(strstr(err.msg, "--memory-mb"));
        td_config_free(&cfg);
    }
    {
        char *argv[] = {"serve", "--queue", "12x", NULL};
        assert_int_equal(load(&cfg, argv, 3, &err), TD_EINVAL);
        assert_non_null(strstr(err.msg, "--queue"));
        td_config_free(&cfg);
    }
    {
        char *argv[] = {"serve", "--no-such-flag", NULL};
        assert_int_equal(load(&cfg, argv, 2, &err), TD_EINVAL);
        assert_non_null(strstr(err.msg, "--no-such-flag"));
        td_config_free(&cfg);
    }
    {
        char *argv[] = {"serve", NULL};
        setenv("TERRAD_MEMORY_MB", "lots", 1);
        assert_int_equal(load(&cfg, argv, 1, &err), TD_EINVAL);
        assert_non_null(strstr(err.msg, "TERRAD_MEMORY_MB"));
        td_config_free(&cfg);
        clear_env();
    }
    {
        char *argv[] = {"serve", "--listen", "127.0.0.1:99999", NULL};
        assert_int_equal(load(&cfg, argv, 3, &err), TD_EINVAL);
        assert_non_null(strstr(err.msg, "--listen"));
        td_config_free(&cfg);
    }
}

static void test_token_file(void **state)
{
    td_config cfg;
    td_err err;
    char path[] = "/tmp/terrad-token-XXXXXX";
    int fd = mkstemp(path);
    (void)state;
    clear_env();
    assert_true(fd >= 0);
    assert_int_equal(write(fd, "t0ken\n", 6), 6);
    close(fd);
    char *argv[] = {"serve", "--admin-token-file", path, NULL};
    assert_int_equal(load(&cfg, argv, 3, &err), TD_OK);
    assert_non_null(cfg.admin_token);
    assert_string_equal(cfg.admin_token, "t0ken"); /* the newline is not part of it */
    td_config_free(&cfg);
    unlink(path);
    char *missing[] = {"serve", "--admin-token-file", "/nonexistent/token", NULL};
    assert_int_equal(load(&cfg, missing, 3, &err), TD_EIO);
    assert_non_null(strstr(err.msg, "/nonexistent/token"));
    td_config_free(&cfg);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_defaults),
        cmocka_unit_test(test_env_then_flags),
        cmocka_unit_test(test_refusals_name_the_setting),
        cmocka_unit_test(test_token_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
