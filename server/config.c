/* config.c: settings of `terrad serve` from defaults, TERRAD_* variables and flags (see
 * config.h). The X-macro table becomes a descriptor array (name, flag, variable, type,
 * offset into td_config, bounds) and one setter parses every value, so a default string,
 * an environment value and a flag go through the same checks. */
#include "config.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

typedef enum td_config_kind { TD_CFG_STR, TD_CFG_INT, TD_CFG_DBL } td_config_kind;

typedef struct td_config_desc {
    const char *name, *flag, *env, *dflt;
    td_config_kind kind;
    size_t off;
    double lo, hi;
    const char *help;
} td_config_desc;

static const td_config_desc td_config_descs[] = {
#define TD_X_DESC(field, type, flag, env, dflt, lo, hi, help)                               \
    {#field, flag, env, dflt, TD_CFG_##type, offsetof(td_config, field), lo, hi, help},
    TD_CONFIG_LIST(TD_X_DESC)
#undef TD_X_DESC
};

#define TD_CONFIG_N (sizeof td_config_descs / sizeof td_config_descs[0])

static td_status set_value(td_config *cfg, const td_config_desc *d, const char *src,
                           const char *v, td_err *err)
{
    td_status rc = TD_OK;
    char *end = NULL;
    void *p = (char *)cfg + d->off;

    errno = 0;
    if (d->kind == TD_CFG_STR) {
        char *copy = strdup(v);
        if (!copy) {
            rc = td_err_set(err, TD_ENOMEM, "out of memory for %s", src);
            goto out;
        }
        free(*(char **)p);
        *(char **)p = copy;
    } else if (d->kind == TD_CFG_INT) {
        long x = strtol(v, &end, 10);
        if (errno || end == v || *end || x < (long)d->lo || x > (long)d->hi) {
            rc = td_err_set(err, TD_EINVAL, "%s: '%s' is not an integer in [%ld, %ld]", src, v,
                            (long)d->lo, (long)d->hi);
            goto out;
        }
        *(long *)p = x;
    } else {
        double x = strtod(v, &end);
        if (errno || end == v || *end || !isfinite(x) || x < d->lo || x > d->hi) {
            rc = td_err_set(err, TD_EINVAL, "%s: '%s' is not a number in [%g, %g]", src, v, d->lo,
                            d->hi);
            goto out;
        }
        *(double *)p = x;
    }
out:
    return rc;
}

static td_status read_token_file(const char *path, char **out, td_err *err)
{
    td_status rc = TD_OK;
    char buf[1024];
    size_t n = 0;
    FILE *f = fopen(path, "rb");

    if (!f) {
        rc = td_err_set(err, TD_EIO, "--admin-token-file %s: %s", path, strerror(errno));
        goto out;
    }
    n = fread(buf, 1, sizeof buf - 1, f);
    if (ferror(f) || !feof(f)) {
        rc = td_err_set(err, TD_EINVAL, "--admin-token-file %s: unreadable or longer than %zu bytes",
                        path, sizeof buf - 2);
        goto out;
    }
    while (n && isspace((unsigned char)buf[n - 1]))
        n--;
    buf[n] = '\0';
    *out = n ? strdup(buf) : NULL;
    if (n && !*out)
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the admin token");
out:
    if (f)
        fclose(f);
    return rc;
}

static td_status split_listen(td_config *cfg, td_err *err)
{
    td_status rc = TD_OK;
    const char *colon = strrchr(cfg->listen, ':');
    const char *host = cfg->listen;
    size_t hlen = colon ? (size_t)(colon - host) : 0;
    char *end = NULL;
    long port = -1;

    if (colon) {
        errno = 0;
        port = strtol(colon + 1, &end, 10);
        if (errno || end == colon + 1 || *end)
            port = -1;
    }
    if (hlen >= 2 && host[0] == '[' && host[hlen - 1] == ']') {
        host++;
        hlen -= 2;
    }
    if (!colon || port < 0 || port > 65535 || hlen == 0 || hlen >= sizeof cfg->host) {
        rc = td_err_set(err, TD_EINVAL, "--listen: '%s' is not HOST:PORT with PORT in [0, 65535]",
                        cfg->listen);
        goto out;
    }
    memcpy(cfg->host, host, hlen);
    cfg->host[hlen] = '\0';
    cfg->port = (int)port;
out:
    return rc;
}

td_status td_config_load(td_config *cfg, int argc, char **argv, int *help, td_err *err)
{
    td_status rc = TD_OK;
    char src[160];

    memset(cfg, 0, sizeof *cfg);
    *help = 0;
    for (size_t i = 0; i < TD_CONFIG_N && rc == TD_OK; i++) {
        snprintf(src, sizeof src, "default of %s", td_config_descs[i].flag);
        rc = set_value(cfg, &td_config_descs[i], src, td_config_descs[i].dflt, err);
    }
    for (size_t i = 0; i < TD_CONFIG_N && rc == TD_OK; i++) {
        const char *v = getenv(td_config_descs[i].env);
        if (v) {
            snprintf(src, sizeof src, "%s", td_config_descs[i].env);
            rc = set_value(cfg, &td_config_descs[i], src, v, err);
        }
    }
    for (int a = 1; a < argc && rc == TD_OK; a++) {
        const char *arg = argv[a], *eq = strchr(arg, '='), *val = NULL;
        size_t flen = eq ? (size_t)(eq - arg) : strlen(arg);
        const td_config_desc *d = NULL;

        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) {
            *help = 1;
            goto out;
        }
        for (size_t i = 0; i < TD_CONFIG_N && !d; i++)
            if (strlen(td_config_descs[i].flag) == flen && !strncmp(arg, td_config_descs[i].flag, flen))
                d = &td_config_descs[i];
        if (!d) {
            rc = td_err_set(err, TD_EINVAL, "unknown option '%s' (see terrad serve --help)", arg);
            goto out;
        }
        if (eq) {
            val = eq + 1;
        } else if (a + 1 < argc) {
            val = argv[++a];
        } else {
            rc = td_err_set(err, TD_EINVAL, "%s needs a value", d->flag);
            goto out;
        }
        rc = set_value(cfg, d, d->flag, val, err);
    }
    if (rc)
        goto out;
    rc = split_listen(cfg, err);
    if (rc)
        goto out;
    if (cfg->tile_size & (cfg->tile_size - 1)) {
        rc = td_err_set(err, TD_EINVAL, "--tile-size: %ld is not a power of two", cfg->tile_size);
        goto out;
    }
    if (strcmp(cfg->preload, "all") && strcmp(cfg->preload, "none")) {
        rc = td_err_set(err, TD_EINVAL, "--preload: '%s' is neither 'all' nor 'none'", cfg->preload);
        goto out;
    }
    {
        td_log_level lvl;
        if (!td_log_level_parse(cfg->log_level, &lvl)) {
            rc = td_err_set(err, TD_EINVAL, "--log-level: '%s' is not debug, info, warn or error",
                            cfg->log_level);
            goto out;
        }
    }
    if (cfg->admin_token_file[0]) {
        rc = read_token_file(cfg->admin_token_file, &cfg->admin_token, err);
    } else {
        const char *t = getenv("TERRAD_ADMIN_TOKEN");
        if (t && *t && !(cfg->admin_token = strdup(t)))
            rc = td_err_set(err, TD_ENOMEM, "out of memory for the admin token");
    }
out:
    return rc;
}

void td_config_free(td_config *cfg)
{
    for (size_t i = 0; i < TD_CONFIG_N; i++)
        if (td_config_descs[i].kind == TD_CFG_STR) {
            char **p = (char **)((char *)cfg + td_config_descs[i].off);
            free(*p);
            *p = NULL;
        }
    free(cfg->admin_token);
    cfg->admin_token = NULL;
}

void td_config_usage(FILE *f)
{
    fprintf(f, "usage: terrad serve [options]\n\n"
               "Serves rendered views, map tiles and dataset metadata over HTTP.\n"
               "Every option may also come from its environment variable; flags win.\n"
               "The admin token comes from TERRAD_ADMIN_TOKEN or --admin-token-file.\n\n");
    for (size_t i = 0; i < TD_CONFIG_N; i++) {
        const td_config_desc *d = &td_config_descs[i];
        fprintf(f, "  %-22s %s\n  %-22s (%s, default '%s')\n", d->flag, d->help, "", d->env,
                d->dflt);
    }
}

void td_config_log(const td_config *cfg)
{
    char line[3072];
    size_t n = 0;

    for (size_t i = 0; i < TD_CONFIG_N && n < sizeof line; i++) {
        const td_config_desc *d = &td_config_descs[i];
        const void *p = (const char *)cfg + d->off;
        char q[512];
        int w = 0;
        if (d->kind == TD_CFG_STR)
            w = snprintf(line + n, sizeof line - n, "%s=%s ", d->name,
                         td_log_quote(q, sizeof q, *(char *const *)p));
        else if (d->kind == TD_CFG_INT)
            w = snprintf(line + n, sizeof line - n, "%s=%ld ", d->name, *(const long *)p);
        else
            w = snprintf(line + n, sizeof line - n, "%s=%g ", d->name, *(const double *)p);
        if (w > 0)
            n += (size_t)w;
    }
    if (n < sizeof line)
        snprintf(line + n, sizeof line - n, "admin_token=%s", cfg->admin_token ? "set" : "unset");
    td_log(TD_LOG_INFO, "config", "%s", line);
}
