/* pano.h: the service's side of panoramas (issue 19): POST /v1/horizon (core/skyline.h:
 * the skyline per azimuth, and with "sun" the sun's path and its rise and set behind the
 * terrain) and POST /v1/peaks (core/peaks.h: the summits a scene's view sees), with the
 * per-dataset cache of summits. Rows of routes.c's table point here. */
#ifndef TD_PANO_H
#define TD_PANO_H

#include "routes.h"

void td_horizon_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);
void td_peaks_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);

#endif
