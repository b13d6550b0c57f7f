/* maptile.c: the pixels of a Web Mercator map tile (maptile.h).
 *
 * Called by server/maps.c once per tile (on a render worker, one thread), by the map
 * benchmark and the tests. A shaded pixel costs one vertical ray and at most one shadow
 * ray, as an orthographic render's pixel with shadows (render.c), but at positions the
 * map projection gives rather than on the dataset frame's square lattice; an encoded
 * pixel costs one surface evaluation. Nothing is allocated. */
#include "maptile.h"

#include <math.h>
#include <string.h>

#include "shade.h"

static const char *const style_names[TD_MAPSTYLE_COUNT] = {
#define TD_X_NAME(e, name) name,
    TD_MAPSTYLE_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_mapstyle_name(td_mapstyle s)
{
    return (unsigned)s < TD_MAPSTYLE_COUNT ? style_names[s] : "?";
}

td_status td_mapstyle_parse(const char *name, td_mapstyle *out)
{
    int i = td_name_index(style_names, TD_MAPSTYLE_COUNT, name);
    if (i >= 0)
        *out = (td_mapstyle)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

void td_maptile_spec_default(td_maptile_spec *s)
{
    memset(s, 0, sizeof *s);
    s->style = TD_MAPSTYLE_SHADED;
    s->surface = TD_SURFACE_BILINEAR;
    s->method = TD_METHOD_AUTO;
    td_shade_sun_dir(315.0, 45.0, s->sun);
    s->shadows = 1;
    s->ambient = 0.25;
    s->lod_pixels = 1.0;
}

int td_maptile_level(const td_grid *base, const td_lod *lod, double foot_m, double lod_pixels)
{
    double cell = base->sx < base->sy ? base->sx : base->sy, foot = foot_m * lod_pixels;
    int l = 0;
    while (lod && lod_pixels > 0.0 && l < lod->levels && ldexp(cell, l + 1) <= foot)
        l++;
    return l;
}

/* The grid's cell holding (x, y), clamped to its border cells. */
static void cell_of(const td_grid *g, double x, double y, int32_t *ci, int32_t *cj)
{
    double i = floor(x / g->sx), j = floor(y / g->sy);
    *ci = i < 0 ? 0 : i > g->w - 2 ? g->w - 2 : (int32_t)i;
    *cj = j < 0 ? 0 : j > g->h - 2 ? g->h - 2 : (int32_t)j;
}

/* An encoded height (see maptile.h); NaN: no data. */
static void encode(td_mapstyle style, double h, uint8_t *o)
{
    double u = style == TD_MAPSTYLE_TERRAIN_RGB ? ((isnan(h) ? 0.0 : h) + 10000.0) * 10.0
                                                : ((isnan(h) ? 0.0 : h) + 32768.0) * 256.0;
    uint32_t v;
    u = nearbyint(u);
    v = u < 0.0 ? 0u : u > 16777215.0 ? 16777215u : (uint32_t)u;
    o[0] = (uint8_t)(v >> 16);
    o[1] = (uint8_t)(v >> 8);
    o[2] = (uint8_t)v;
    o[3] = isnan(h) ? 0 : 255;
}

double td_maptile_decode(td_mapstyle style, const uint8_t px[4])
{
    double v = (double)px[0] * 65536.0 + (double)px[1] * 256.0 + (double)px[2];
    if (px[3] == 0)
        return NAN;
    return style == TD_MAPSTYLE_TERRAIN_RGB ? -10000.0 + v * 0.1 : v / 256.0 - 32768.0;
}

/* One shaded pixel at (x, y) on view lv (level `level`). */
static void shade(const td_view *lv, int level, const td_sunlit *lit, const td_maptile_spec *s, double x,
                  double y, uint8_t *o, td_ray *rays, td_maptile_stats *st)
{
    const td_grid *g = lv->grid;
    td_ray r = {{x, y, (double)g->zmax + 1.0}, {0.0, 0.0, -1.0}, 0.0, (double)g->zmax - (double)g->zmin + 2.0};
    td_hit h;
    double ns, l = 1.0, v;
    if (rays) {
        rays[0] = r;
        rays[1].tmax = -1.0;
    }
    td_trace(lv, s->method, s->surface, &r, &h);
    st->primary_rays++;
    st->steps += h.steps;
    memset(o, 0, 4);
    if (!(h.t < INFINITY))
        return;
    ns = h.n[0] * s->sun[0] + h.n[1] * s->sun[1] + h.n[2] * s->sun[2];
    if (ns <= 0.0 || s->sun[2] <= 0.0) {
        l = 0.0; /* turned away from the sun, or the sun is down: dark whatever lies between */
    } else if (s->shadows) {
        /* from just above the hit, along its normal (render.c's offset) */
        double eps = 0.02 * fmin(g->sx, g->sy);
        uint32_t steps = 0;
        td_ray sr = {{h.p[0] + eps * h.n[0], h.p[1] + eps * h.n[1], h.p[2] + eps * h.n[2]},
                     {s->sun[0], s->sun[1], s->sun[2]}, 0.0, INFINITY};
        l = td_occluded(lv, s->method, s->surface, &sr, level == 0 ? lit : NULL, &steps) ? 0.0 : 1.0;
        if (rays)
            rays[1] = sr;
        st->shadow_rays++;
        st->steps += steps;
    }
    v = s->ambient + (1.0 - s->ambient) * (ns > 0.0 ? ns : 0.0) * l;
    v = nearbyint(255.0 * (v < 0.0 ? 0.0 : v > 1.0 ? 1.0 : v));
    o[0] = o[1] = o[2] = (uint8_t)v;
    o[3] = 255;
    st->pixels_with_data++;
}

td_status td_maptile_render(const td_view *v, const td_lod *lod, const td_sunlit *lit,
                            const td_maptile_spec *s, const double *xy, int px, double foot_m,
                            uint8_t *rgba, td_ray *rays, td_maptile_stats *st, td_err *err)
{
    const td_grid *base = v->grid;
    const double W = (double)(base->w - 1) * base->sx, H = (double)(base->h - 1) * base->sy;
    int level = td_maptile_level(base, lod, foot_m, s->lod_pixels);
    const td_view *lv = level ? &lod->view[level] : v;
    size_t n = (size_t)px * (size_t)px;

    memset(st, 0, sizeof *st);
    st->level = level;
    if ((unsigned)s->style >= TD_MAPSTYLE_COUNT || (unsigned)s->surface >= TD_SURFACE_COUNT ||
        (unsigned)s->method >= TD_METHOD_COUNT || !(s->ambient >= 0.0 && s->ambient <= 1.0))
        return td_err_set(err, TD_EINVAL, "map tile: bad style, surface, method or ambient");
    for (size_t k = 0; k < n; k++) {
        double x = xy[2 * k], y = xy[2 * k + 1];
        uint8_t *o = &rgba[4 * k];
        int inside = x >= 0.0 && x <= W && y >= 0.0 && y <= H; /* false for NaN */
        if (s->style == TD_MAPSTYLE_SHADED) {
            if (rays)
                rays[2 * k].tmax = rays[2 * k + 1].tmax = -1.0;
            if (inside)
                shade(lv, level, lit, s, x, y, o, rays ? &rays[2 * k] : NULL, st);
            else
                memset(o, 0, 4);
        } else {
            double h = NAN;
            if (inside) {
                int32_t ci, cj;
                cell_of(lv->grid, x, y, &ci, &cj);
                h = td_surface_height(lv->grid, s->surface, ci, cj, x, y);
            }
            st->pixels_with_data += !isnan(h);
            encode(s->style, h, o);
        }
    }
    return TD_OK;
}
