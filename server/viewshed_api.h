/* viewshed_api.h: the service's and the CLI's side of core/viewshed.h: POST /v1/viewshed and
 * POST /v1/los (request parsing, the worker's job, the answers), and the answer builders
 * `terrad viewshed` shares with them (the PNG and the figures' JSON). */
#ifndef TD_VIEWSHED_API_H
#define TD_VIEWSHED_API_H

#include <jansson.h>

#include "image.h"
#include "routes.h"
#include "viewshed.h"

/* The picture of a viewshed's output (counts, file order; modified in place): for one
 * observer 255 seen, 0 not, 128 outside; for several the count, 255 outside. */
td_status td_vs_encode(const td_grid *g, int nobs, uint8_t *counts, td_buf *out, td_err *err);

/* The figures of a viewshed (the json format's body, the CLI's --stats). */
json_t *td_vs_answer(const char *dataset, const td_grid *g, const td_viewshed_opts *o,
                     const td_viewshed_stats *st, const uint8_t *counts);

/* A line of sight's answer. */
json_t *td_los_answer(const char *dataset, const td_los_opts *o, const td_los_result *r);

/* The handlers (rows of routes.c's table). */
void td_vs_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);
void td_los_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);

#endif
