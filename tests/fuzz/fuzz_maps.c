/* fuzz_maps.c: the map tiles' query parser (server/maps.c, td_maps_parse_query) as the
 * tile and TileJSON routes call it. The first byte chooses the style (mod 3: shaded,
 * terrain-rgb, terrarium) and the dataset frame's grid north (the byte / 3, in tenths of a
 * degree, so UTM-like convergences are reached); the rest is split at '&' into at most 32
 * key=value pairs as the HTTP layer hands them over (decoded; a pair without '=' has no
 * value). The sun of ?time= is computed at trinidad's centre. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "maps.h"

#define QUERY_MAX 32

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const double centre[2] = {-105.486, 37.578};
    char *text, *keys[QUERY_MAX], *values[QUERY_MAX];
    size_t n;
    td_maps_query mq;
    td_mapstyle style;
    double north;
    int rc;
    if (size < 1)
        return 0;
    style = (td_mapstyle)(data[0] % 3);
    north = (double)(data[0] / 3) * 0.1 - 4.0;
    text = malloc(size);
    if (!text)
        abort();
    memcpy(text, data + 1, size - 1);
    text[size - 1] = '\0';
    n = fuzz_split_query(text, keys, values, QUERY_MAX, NULL); /* NULL: a key without a value */
    rc = td_maps_parse_query((const char *const *)keys, (const char *const *)values, n, style, centre, north, &mq);
    /* an accepted query is a tile spec maptile accepts: a unit sun, ambient and lod in range */
    if (rc == 0 && (!(fabs(mq.spec.sun[0] * mq.spec.sun[0] + mq.spec.sun[1] * mq.spec.sun[1] +
                            mq.spec.sun[2] * mq.spec.sun[2] - 1.0) < 1e-9) ||
                    !(mq.spec.ambient >= 0.0 && mq.spec.ambient <= 1.0) ||
                    !(mq.spec.lod_pixels >= 0.0 && mq.spec.lod_pixels <= 64.0)))
        abort();
    fuzz_report("maps query", rc, mq.msg);
    free(text);
    return 0;
}
