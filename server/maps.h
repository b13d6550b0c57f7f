/* maps.h: Web Mercator map tiles and TileJSON for any web map (issue 17).
 *
 *   GET /v1/maps/{dataset}/{style}/{z}/{x}/{y}.png   (y may end in @2x: 512 pixels)
 *   GET /v1/maps/{dataset}/{style}.json              TileJSON 3.0.0
 *
 * styles (core/maptile.h): shaded (?azimuth=&elevation= or ?time=, &shadows=, &ambient=),
 * terrain-rgb and terrarium; all take &surface=, &method= (shaded) and &lod=.
 * The handlers run in routes.c's table. Tiles are traced on the render workers
 * (td_http_defer) like renders: a full queue answers 503 with Retry-After, a tile wholly
 * outside the dataset 404 (MapLibre treats a 404 tile as empty without an error event).
 * Each dataset's CRS and transformations (core/mercator.h) are made once, on first use,
 * and kept in the td_maps cache; each tile clones them (OGR objects are not
 * thread-safe). docs/api.md has the parameters, headers and errors. */
#ifndef TD_MAPS_H
#define TD_MAPS_H

#include "routes.h"

typedef struct td_maps td_maps;

td_maps *td_maps_create(void);
void td_maps_free(td_maps *m);

/* URL prefix of MapLibre GL JS's files (web/node_modules/maplibre-gl/dist). */
#define TD_MAPS_VENDOR_PREFIX "/vendor/maplibre-gl/"

/* The handlers (rows of routes.c's table). */
void td_maps_tile_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);
void td_maps_tilejson_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);
/* GET /vendor/maplibre-gl/...: the web map page's MapLibre (static.h's rules). */
void td_maps_vendor_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg);

#endif
