/* config.h: the settings of `terrad serve`, from defaults, then TERRAD_* environment
 * variables, then command-line flags (later wins). One X-macro table lists every
 * setting once: its field, type, flag, variable, default, bounds and help, so the
 * parser, the --help text and the start-up log line cannot drift apart.
 *
 * The admin token is never a flag (it would show in `ps`): it comes from
 * TERRAD_ADMIN_TOKEN or from the file named by --admin-token-file, and is printed only
 * as set/unset. */
#ifndef TD_CONFIG_H
#define TD_CONFIG_H

#include <stdio.h>

#include "status.h"

#ifndef TERRAD_SOURCE_DIR
#define TERRAD_SOURCE_DIR "."
#endif

/* X(field, type, flag, env, default, min, max, help); min/max bound INT and DBL. */
#define TD_CONFIG_LIST(X)                                                                  \
    X(listen, STR, "--listen", "TERRAD_LISTEN", "127.0.0.1:8080", 0, 0,                    \
      "address:port to listen on (port 0 picks a free one)")                               \
    X(data_dir, STR, "--data", "TERRAD_DATA", "", 0, 0,                                    \
      "directory whose recognised DEM files and folders become datasets")                  \
    X(demo_dir, STR, "--demo-dir", "TERRAD_DEMO_DIR", TERRAD_SOURCE_DIR "/data", 0, 0,     \
      "built-in demo datasets (empty: none)")                                              \
    X(web_dir, STR, "--web-dir", "TERRAD_WEB_DIR", TERRAD_SOURCE_DIR "/web", 0, 0,         \
      "static files of the web page served at /")                                          \
    X(cache_dir, STR, "--cache", "TERRAD_CACHE", "", 0, 0,                                 \
      "directory of the on-disk cache of built acceleration (empty: none)")                \
    X(admin_token_file, STR, "--admin-token-file", "TERRAD_ADMIN_TOKEN_FILE", "", 0, 0,    \
      "file holding the admin bearer token (else TERRAD_ADMIN_TOKEN; none: admin off)")    \
    X(preload, STR, "--preload", "TERRAD_PRELOAD", "all", 0, 0,                            \
      "acceleration built at start: all (every tile, within the budget) or none")          \
    X(log_level, STR, "--log-level", "TERRAD_LOG_LEVEL", "info", 0, 0,                     \
      "debug, info, warn or error")                                                        \
    X(memory_mb, INT, "--memory-mb", "TERRAD_MEMORY_MB", "1024", 1, 1048576,               \
      "memory budget for heights and acceleration, MiB")                                   \
    X(threads, INT, "--threads", "TERRAD_THREADS", "0", 0, 256,                            \
      "HTTP threads (0: one per core)")                                                    \
    X(render_workers, INT, "--render-workers", "TERRAD_RENDER_WORKERS", "0", 0, 256,       \
      "renders running at once (0: one per core)")                                         \
    X(queue, INT, "--queue", "TERRAD_QUEUE", "16", 0, 100000,                              \
      "renders waiting beyond those running; more are refused with 503")                   \
    X(max_body_kb, INT, "--max-body-kb", "TERRAD_MAX_BODY_KB", "64", 1, 65536,             \
      "largest request body, KiB (more: 413)")                                             \
    X(max_edit_kb, INT, "--max-edit-kb", "TERRAD_MAX_EDIT_KB", "16384", 1, 1048576,        \
      "largest heights edit (PUT body), KiB: 4 bytes a sample (more: 413)")               \
    X(max_pixels, INT, "--max-pixels", "TERRAD_MAX_PIXELS", "4194304", 1, 268435456,       \
      "largest image, pixels")                                                             \
    X(max_samples, INT, "--max-samples", "TERRAD_MAX_SAMPLES", "16", 1, 1024,              \
      "most samples per pixel")                                                            \
    X(render_timeout_s, DBL, "--render-timeout", "TERRAD_RENDER_TIMEOUT", "30", 0.001,     \
      86400.0, "render deadline, seconds")                                                 \
    X(pagein_timeout_s, DBL, "--pagein-timeout", "TERRAD_PAGEIN_TIMEOUT", "10", 0.0,       \
      86400.0, "most a render may wait for pages of prepared datasets, seconds (0: only --render-timeout)") \
    X(conn_timeout_s, INT, "--conn-timeout", "TERRAD_CONN_TIMEOUT", "30", 1, 86400,        \
      "idle connection timeout, seconds")                                                  \
    X(per_ip, INT, "--per-ip-connections", "TERRAD_PER_IP_CONNECTIONS", "64", 1, 65536,    \
      "most connections from one address")                                                 \
    X(shutdown_s, DBL, "--shutdown-timeout", "TERRAD_SHUTDOWN_TIMEOUT", "10", 0.0, 3600.0, \
      "on SIGTERM/SIGINT, how long in-flight requests may finish, seconds")                \
    X(tile_size, INT, "--tile-size", "TERRAD_TILE_SIZE", "256", 2, 65536,                  \
      "cells per tile side (a power of two)")                                              \
    X(planes_k, INT, "--planes-k", "TERRAD_PLANES_K", "16", 1, 255,                        \
      "height slices of the parameter planes")                                             \
    X(cors_origins, STR, "--cors-origins", "TERRAD_CORS_ORIGINS", "*", 0, 0,               \
      "origins allowed to read the non-admin API from browsers: *, a comma-separated list, or empty") \
    X(isometric_lod, INT, "--isometric-lod", "TERRAD_ISOMETRIC_LOD", "0", 0, 1,            \
      "1: keep isometric twins of the levels of detail too (quality.lod_grid)")

#define TD_CONFIG_TYPE_STR char *
#define TD_CONFIG_TYPE_INT long
#define TD_CONFIG_TYPE_DBL double

typedef struct td_config {
#define TD_X_FIELD(field, type, flag, env, dflt, lo, hi, help) TD_CONFIG_TYPE_##type field;
    TD_CONFIG_LIST(TD_X_FIELD)
#undef TD_X_FIELD
    char *admin_token; /* NULL: admin routes off */
    char host[256];    /* split from listen */
    int port;
} td_config;

/* Fills cfg from defaults, the environment and argv (argv[0] is the subcommand name).
 * Returns TD_OK, or TD_EINVAL with a message naming the flag or variable at fault.
 * Sets *help when --help was given (cfg is then only partly filled). */
td_status td_config_load(td_config *cfg, int argc, char **argv, int *help, td_err *err);
void td_config_free(td_config *cfg);
void td_config_usage(FILE *f);
/* Logs the effective settings as one line (the token as set/unset). */
void td_config_log(const td_config *cfg);

#endif
