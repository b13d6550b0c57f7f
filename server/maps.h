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

#include "maptile.h"

typedef struct td_maps td_maps;

/* The query parameters: X(enum, name, shaded only). */
#define TD_MAPS_PARAM_LIST(X)                                                  \
    X(TD_MAPS_P_AZIMUTH, "azimuth", 1)                                         \
    X(TD_MAPS_P_ELEVATION, "elevation", 1)                                     \
    X(TD_MAPS_P_TIME, "time", 1)                                               \
    X(TD_MAPS_P_SHADOWS, "shadows", 1)                                         \
    X(TD_MAPS_P_AMBIENT, "ambient", 1)                                         \
    X(TD_MAPS_P_METHOD, "method", 1)                                           \
    X(TD_MAPS_P_SURFACE, "surface", 0)                                         \
    X(TD_MAPS_P_LOD, "lod", 0)

enum {
#define TD_X_ENUM(e, name, shaded_only) e,
    TD_MAPS_PARAM_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_MAPS_PARAM_COUNT
};

/* A parsed query: the tile spec, the sun as asked (true north) and the canonical text of
 * what changes pixels (the ETag's). */
typedef struct td_maps_query {
    td_maptile_spec spec;
    const char *value[TD_MAPS_PARAM_COUNT]; /* as given, or NULL */
    double azimuth, elevation;              /* the sun, true azimuth (degrees) */
    double time_s;                          /* ?time=, or NAN */
    char canon[256];
    char field[32], msg[300];               /* the error */
} td_maps_query;

/* Parses a tile's or TileJSON's query (decoded key/value pairs) for `style`: centre is the
 * dataset's lon/lat (for ?time=), grid_north the azimuth of true north in its frame
 * (mercator.h). 0, or -1 with mq->field (may be empty) and mq->msg. Pure: the fuzz
 * target calls it (tests/fuzz/fuzz_maps.c). */
int td_maps_parse_query(const char *const *keys, const char *const *values, size_t n, td_mapstyle style,
                        const double centre[2], double grid_north, td_maps_query *mq);

/* The lon/lat of dataset di's centre and the azimuth of true north in its frame
 * (td_merc_proj_grid_north), from the cache: what a render's effects.sun.time needs. 0, or
 * -1 with the reason (no georeference, no CRS PROJ knows) in msg. */
int td_maps_centre(td_maps *m, const td_dataset_info *di, double centre[2], double *grid_north, char *msg,
                   size_t n);

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
