/* answer.c: the JSON answers shared by `terrad serve` and `terrad render` (see answer.h). */
#include "answer.h"

#include <math.h>

json_t *td_answer_picks(const char *dataset, const td_grid *g, const td_pick *pk, int n)
{
    json_t *arr = json_array();
    for (int i = 0; arr && i < n; i++) {
        json_t *o;
        if (!pk[i].hit) {
            o = json_pack("{s:[f,f],s:b}", "pixel", pk[i].px, pk[i].py, "hit", 0);
        } else {
            o = json_pack("{s:[f,f],s:b,s:{s:f,s:f,s:f},s:f,s:[i,i]}", "pixel", pk[i].px, pk[i].py,
                          "hit", 1, "point", "x", pk[i].p[0], "y", pk[i].p[1], "z", pk[i].p[2],
                          "distance", pk[i].distance, "cell", (int)pk[i].ci, (int)pk[i].cj);
            if (o && !isnan(pk[i].height_error_m))
                json_object_set_new(o, "height_error_m", json_real(pk[i].height_error_m));
            if (o && g->geo.kind != TD_GEO_NONE) {
                double gx = g->geo.x0 + pk[i].p[0] / g->sx * g->geo.dx;
                double gy = g->geo.y0 + pk[i].p[1] / g->sy * g->geo.dy;
                json_object_set_new(o, g->geo.kind == TD_GEO_LONLAT ? "lonlat" : "projected",
                                    json_pack("[f,f]", gx, gy));
            }
        }
        json_array_append_new(arr, o);
    }
    return json_pack("{s:s,s:o}", "dataset", dataset, "picks", arr);
}
