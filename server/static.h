/* static.h: the files terrad serves besides its API: the map page (web/: index.html,
 * style.css, js/, favicon.ico) and the Leaflet it loads from npm's install
 * (web/node_modules/leaflet/dist at /vendor/leaflet/). routes.c dispatches to it and
 * turns its refusals into JSON errors; cli_serve.c resolves the two folders at start.
 *
 * Nothing outside those folders is ever read: `.`, `..`, empty and hidden path segments
 * and backslashes are refused, and the file's real path (links followed) must stay
 * inside the folder's. */
#ifndef TD_STATIC_H
#define TD_STATIC_H

#include <limits.h>

#include "http.h"
#include "status.h"

/* URL prefix of the vendored Leaflet files. */
#define TD_STATIC_VENDOR_PREFIX "/vendor/leaflet/"

/* Real paths of the page's folder and of its Leaflet (web_dir/node_modules/leaflet/dist),
 * each "" when absent. */
void td_static_resolve(const char *web_dir, char web[PATH_MAX], char leaflet[PATH_MAX]);

/* 1 when a URL path names one of the page's own files (not its tests, build files or
 * node_modules): /, /index.html, /map.html (the web map), /style.css, /js/..., /favicon.ico. */
int td_static_is_page(const char *path);

/* The Content-Type of a file, by its extension (application/octet-stream if unknown). */
const char *td_static_mime(const char *path);

/* Answers root/rel, where rel is what follows the route's prefix (a folder: its
 * index.html), into r: 200, the file, its type, Cache-Control (a day for vendor files,
 * no-cache for the page's own) and nosniff. Otherwise r is untouched and the status is
 * TD_ENOTFOUND (no root, a refused or absent path, over 64 MiB) or TD_EIO (unreadable),
 * with err's message for the client. */
td_status td_static_serve(const char *root, const char *rel, int vendor, td_http_resp *r, td_err *err);

#endif
