/* answer.h: JSON answers that the service and the CLI both give, built by one function
 * each so that `terrad render` writes what POST /v1/render and /v1/pick send (the shapes
 * are in docs/api.md). Pure: no I/O; the caller serialises (routes.c compact, cli_render.c
 * indented). */
#ifndef TD_ANSWER_H
#define TD_ANSWER_H

#include <jansson.h>

#include "grid.h"
#include "render.h"

/* {"dataset": dataset, "picks": [one object per pick]}: a miss is {"pixel": [px, py],
 * "hit": false}; a hit adds "point" {x, y, z} (dataset frame, metres), "distance",
 * "cell" [i, j], "height_error_m" (left out at a void) and, on a georeferenced grid,
 * "lonlat" or "projected" [x, y]. A new reference, or NULL out of memory. */
json_t *td_answer_picks(const char *dataset, const td_grid *g, const td_pick *pk, int n);

#endif
