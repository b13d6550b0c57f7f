/* cors.h: Cross-Origin Resource Sharing for the read-only API, so that map pages served
 * from other origins can use terrad's map tiles, TileJSON, renders and picks.
 *
 * Called by routes.c's dispatch for every route that is neither admin nor the web page.
 * --cors-origins (TERRAD_CORS_ORIGINS) is `*` (any origin, the default), a comma-separated
 * list of origins (`https://a.example,http://localhost:5173`: the request's Origin is
 * echoed when listed, with Vary: Origin), or empty (no CORS headers). Admin routes never
 * get CORS headers, whatever the setting: a browser page on another origin cannot read
 * their answers or send them a bearer token in a preflighted request. */
#ifndef TD_CORS_H
#define TD_CORS_H

#include "http.h"

/* Adds Access-Control-Allow-Origin (and Vary, Expose-Headers) when the request's Origin
 * is allowed. For a preflight (OPTIONS with Access-Control-Request-Method) answers 204
 * with the allowed methods (`allow`, the route's) and headers and returns 1; else 0. */
int td_cors_apply(const char *origins, td_http_req *q, td_http_resp *r, const char *allow);

#endif
