/* demutil.c: the parts every DEM loader shares (see demutil.h): the JSON sidecar read
 * with jansson (the only JSON core reads), spacing and georeference resolution, opening
 * and row reading, and grid creation/finishing whose messages name the file.
 *
 * The sidecar is read strictly for the keys we use (a wrong type is an error naming the
 * key) and leniently for the rest, so the descriptive JSONs that come with real data
 * (min, max, source, licence...) load as they are. */
#include "demutil.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <jansson.h>


#define TD_SIDECAR_MAX_BYTES (1u << 20) /* a sidecar is a few hundred bytes */

static void name_file(const char *path, td_err *err);

const char *td_demutil_basename(const char *path)
{
    const char *slash = strrchr(path, '/');
    return slash ? slash + 1 : path;
}

void td_demutil_ext(const char *path, char *out, size_t outsz)
{
    const char *base = td_demutil_basename(path);
    const char *dot = strrchr(base, '.');
    size_t k = 0;
    if (outsz > 0) {
        if (dot && dot != base) {
            for (const char *p = dot + 1; *p && k + 1 < outsz; p++)
                out[k++] = (char)tolower((unsigned char)*p);
        }
        out[k] = '\0';
    }
}

int td_demutil_sidecar_path(const char *path, char *out, size_t outsz)
{
    const char *base = td_demutil_basename(path);
    const char *dot = strrchr(base, '.');
    size_t stem = dot && dot != base ? (size_t)(dot - path) : strlen(path);
    int ok = stem + 6 <= outsz; /* ".json" + NUL */
    if (ok) {
        memcpy(out, path, stem);
        memcpy(out + stem, ".json", 6);
    }
    return ok;
}

int td_demutil_parse_double(const char *tok, double *out)
{
    int ok = 1;
    char *end = NULL;
    double v;
    /* Only digits, sign, point and exponent: strtod would also take nan, inf and hex. */
    for (const char *p = tok; *p && ok; p++)
        ok = isdigit((unsigned char)*p) || *p == '+' || *p == '-' || *p == '.' || *p == 'e' ||
             *p == 'E';
    if (ok && *tok) {
        errno = 0;
        v = strtod(tok, &end);
        ok = end != tok && *end == '\0' && errno != ERANGE && isfinite(v);
        if (ok)
            *out = v;
    } else {
        ok = 0;
    }
    return ok;
}

/* A JSON number that is finite; ints and reals alike. */
static int json_finite(const json_t *v, double *out)
{
    int ok = json_is_number(v);
    if (ok) {
        *out = json_number_value(v);
        ok = isfinite(*out);
    }
    return ok;
}

static td_status side_number(const td_demside *sc, json_t *root, const char *key, int *has,
                             double *out, td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(root, key);
    if (v && !json_is_null(v)) {
        if (!json_finite(v, out))
            rc = td_err_set(err, TD_EFORMAT, "%s: key '%s' must be a finite number", sc->path, key);
        else
            *has = 1;
    }
    return rc;
}

static td_status side_size(td_demside *sc, json_t *root, const char *key, int32_t *out, td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(root, key);
    if (!json_is_integer(v)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: key '%s' must be an integer number of samples",
                        sc->path, key);
    } else if (json_integer_value(v) < 2 || json_integer_value(v) > INT32_MAX) {
        rc = td_err_set(err, TD_ERANGE, "%s: %s %lld is out of range (2 .. %ld)", sc->path, key,
                        (long long)json_integer_value(v), (long)INT32_MAX);
    } else {
        *out = (int32_t)json_integer_value(v);
    }
    return rc;
}

static td_status side_spacing(td_demside *sc, json_t *root, td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(root, "spacing_m");
    double a = 0.0, b = 0.0;
    if (!v || json_is_null(v))
        goto out;
    if (json_is_array(v)) {
        if (json_array_size(v) != 2 || !json_finite(json_array_get(v, 0), &a) ||
            !json_finite(json_array_get(v, 1), &b))
            rc = td_err_set(err, TD_EFORMAT, "%s: spacing_m must be a number or [sx, sy]", sc->path);
    } else if (json_finite(v, &a)) {
        b = a;
    } else {
        rc = td_err_set(err, TD_EFORMAT, "%s: spacing_m must be a number or [sx, sy]", sc->path);
    }
    if (rc == TD_OK && !(a > 0.0 && b > 0.0))
        rc = td_err_set(err, TD_ERANGE, "%s: spacing_m %g x %g is not positive", sc->path, a, b);
    if (rc == TD_OK) {
        sc->has_spacing = 1;
        sc->spacing[0] = a;
        sc->spacing[1] = b;
    }
out:
    return rc;
}

static td_status side_nodata(td_demside *sc, json_t *root, td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(root, "nodata");
    if (!v) {
        sc->nodata_kind = TD_NODATA_ABSENT;
    } else if (json_is_null(v)) {
        sc->nodata_kind = TD_NODATA_NULL;
    } else if (json_is_string(v) && !strcmp(json_string_value(v), "nan")) {
        sc->nodata_kind = TD_NODATA_NAN;
    } else if (json_finite(v, &sc->nodata)) {
        sc->nodata_kind = TD_NODATA_VALUE;
    } else {
        rc = td_err_set(err, TD_EFORMAT, "%s: nodata must be a number, null or \"nan\"", sc->path);
    }
    return rc;
}

/* A key that, when present, must be the string `want` (the only layout we read). */
static td_status side_fixed(const td_demside *sc, json_t *root, const char *key, const char *want,
                            td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(root, key);
    if (v && (!json_is_string(v) || strcmp(json_string_value(v), want)))
        rc = td_err_set(err, TD_EUNSUPPORTED, "%s: %s must be \"%s\"", sc->path, key, want);
    return rc;
}

static td_status side_strings(td_demside *sc, json_t *root, td_err *err)
{
    td_status rc = TD_OK;
    json_t *v = json_object_get(root, "encoding");
    if (v) {
        if (!json_is_string(v) || td_dem_encoding_parse(json_string_value(v), &sc->encoding) != TD_OK ||
            sc->encoding == TD_ENC_NONE)
            rc = td_err_set(err, TD_EFORMAT,
                            "%s: encoding must be one of gray16, terrain-rgb, terrarium, rgb-div",
                            sc->path);
    }
    if (rc == TD_OK)
        rc = side_fixed(sc, root, "dtype", "float32", err);
    if (rc == TD_OK)
        rc = side_fixed(sc, root, "byte_order", "little", err);
    return rc;
}

static td_status side_origin(td_demside *sc, json_t *root, td_err *err)
{
    td_status rc = TD_OK;
    json_t *o = json_object_get(root, "origin");
    json_t *crs;
    double lon = 0, lat = 0, dlon = 0, dlat = 0, x = 0, y = 0;
    int ll, pr;
    if (!o || json_is_null(o))
        goto out;
    if (!json_is_object(o)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: origin must be an object", sc->path);
        goto out;
    }
    ll = json_object_get(o, "lon_west") || json_object_get(o, "lat_north") ||
         json_object_get(o, "dlon_deg") || json_object_get(o, "dlat_deg");
    pr = json_object_get(o, "x_ul") || json_object_get(o, "y_ul");
    if (ll) {
        if (!json_finite(json_object_get(o, "lon_west"), &lon) ||
            !json_finite(json_object_get(o, "lat_north"), &lat) ||
            !json_finite(json_object_get(o, "dlon_deg"), &dlon) ||
            !json_finite(json_object_get(o, "dlat_deg"), &dlat)) {
            rc = td_err_set(err, TD_EFORMAT,
                            "%s: a lon/lat origin needs numbers lon_west, lat_north, dlon_deg, dlat_deg",
                            sc->path);
            goto out;
        }
        if (!(lon >= -180.0 && lon <= 180.0 && lat >= -90.0 && lat <= 90.0 && dlon > 0.0 &&
              dlat > 0.0 && dlon < 10.0 && dlat < 10.0)) {
            rc = td_err_set(err, TD_ERANGE, "%s: lon/lat origin out of range", sc->path);
            goto out;
        }
        sc->geo.kind = TD_GEO_LONLAT;
        sc->geo.x0 = lon;
        sc->geo.y0 = lat;
        sc->geo.dx = dlon;
        sc->geo.dy = dlat;
    } else if (pr) {
        if (!json_finite(json_object_get(o, "x_ul"), &x) || !json_finite(json_object_get(o, "y_ul"), &y)) {
            rc = td_err_set(err, TD_EFORMAT, "%s: a projected origin needs numbers x_ul, y_ul", sc->path);
            goto out;
        }
        sc->geo.kind = TD_GEO_PROJECTED;
        sc->geo.x0 = x;
        sc->geo.y0 = y;
        /* dx, dy: the spacing, filled in by the loader once it is known */
    }
    crs = json_object_get(o, "crs");
    if (sc->geo.kind != TD_GEO_NONE && json_is_string(crs))
        snprintf(sc->geo.crs, sizeof sc->geo.crs, "%s", json_string_value(crs));
out:
    return rc;
}

td_status td_demutil_sidecar_read(const char *path, int required, int need_size, td_demside *sc,
                                  td_err *err)
{
    td_status rc = TD_OK;
    json_t *root = NULL;
    json_error_t jerr;
    struct stat st;
    int has = 0;

    memset(sc, 0, sizeof *sc);
    sc->scale = 1.0;
    if (!td_demutil_sidecar_path(path, sc->path, sizeof sc->path)) {
        rc = td_err_set(err, TD_EINVAL, "%s: path too long", path);
        goto out;
    }
    if (stat(sc->path, &st) != 0) {
        if (required)
            rc = td_err_set(err, TD_ENOTFOUND, "%s: its sidecar %s is missing (%s)", path, sc->path,
                            strerror(errno));
        goto out;
    }
    if (!S_ISREG(st.st_mode) || st.st_size > (off_t)TD_SIDECAR_MAX_BYTES) {
        rc = td_err_set(err, TD_EFORMAT, "%s: not a regular file of at most %u bytes", sc->path,
                        TD_SIDECAR_MAX_BYTES);
        goto out;
    }
    root = json_load_file(sc->path, JSON_REJECT_DUPLICATES, &jerr);
    if (!root) {
        rc = td_err_set(err, TD_EFORMAT, "%s: line %d: %s", sc->path, jerr.line, jerr.text);
        goto out;
    }
    if (!json_is_object(root)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: not a JSON object", sc->path);
        goto out;
    }
    sc->present = 1;
    if (need_size) {
        rc = side_size(sc, root, "width", &sc->width, err);
        if (rc == TD_OK)
            rc = side_size(sc, root, "height", &sc->height, err);
        if (rc != TD_OK)
            goto out;
        sc->has_size = 1;
    }
    rc = side_spacing(sc, root, err);
    if (rc == TD_OK)
        rc = side_nodata(sc, root, err);
    if (rc == TD_OK)
        rc = side_strings(sc, root, err);
    if (rc == TD_OK)
        rc = side_number(sc, root, "scale", &sc->has_scale, &sc->scale, err);
    if (rc == TD_OK)
        rc = side_number(sc, root, "offset", &sc->has_offset, &sc->offset, err);
    if (rc == TD_OK)
        rc = side_number(sc, root, "divisor", &has, &sc->divisor, err);
    sc->has_divisor = has;
    if (rc == TD_OK)
        rc = side_origin(sc, root, err);
out:
    json_decref(root);
    if (rc != TD_OK)
        name_file(path, err); /* the data file first, then the sidecar at fault */
    return rc;
}

/* Turns a georef whose y0 is the north row (as files store it) into grid.h's south-west
 * convention, for a grid of h rows. */
static void georef_from_north(td_georef *geo, int32_t h)
{
    if (geo->kind != TD_GEO_NONE)
        geo->y0 -= (double)(h - 1) * geo->dy;
}

td_status td_demutil_spacing(const char *path, const td_dem_opts *o, const td_demside *sc,
                             const td_georef *geo, int32_t w, int32_t h, double *sx, double *sy,
                             td_err *err)
{
    td_status rc = TD_OK;
    (void)w;
    if (o->spacing[0] > 0.0) {
        *sx = o->spacing[0];
        *sy = o->spacing[1] > 0.0 ? o->spacing[1] : o->spacing[0];
    } else if (sc && sc->has_spacing) {
        *sx = sc->spacing[0];
        *sy = sc->spacing[1];
    } else if (geo && geo->kind == TD_GEO_LONLAT) {
        double lat_c = geo->y0 + 0.5 * (double)(h - 1) * geo->dy; /* y0: south row */
        td_grid_lonlat_spacing(lat_c, geo->dx, geo->dy, sx, sy);
    } else {
        rc = td_err_set(err, TD_EINVAL,
                        "%s: spacing unknown: give it as spacing_m in the sidecar or with --spacing",
                        path);
    }
    if (rc == TD_OK && !(*sx > 0.0 && *sy > 0.0 && isfinite(*sx) && isfinite(*sy)))
        rc = td_err_set(err, TD_ERANGE, "%s: spacing %g x %g m is not positive and finite", path,
                        *sx, *sy);
    return rc;
}

/* Prefixes err->msg with "path: " unless it already starts with path (the end of a long
 * message is cut to fit). */
static void name_file(const char *path, td_err *err)
{
    size_t pl = strlen(path), cap = sizeof err->msg;
    if (err && strncmp(err->msg, path, pl) != 0 && pl + 3 < cap) {
        size_t ml = strnlen(err->msg, cap - 1);
        if (ml > cap - 1 - (pl + 2))
            ml = cap - 1 - (pl + 2);
        memmove(err->msg + pl + 2, err->msg, ml);
        err->msg[pl + 2 + ml] = '\0';
        memcpy(err->msg, path, pl);
        err->msg[pl] = ':';
        err->msg[pl + 1] = ' ';
    }
}

td_status td_demutil_check_limits(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                                  td_err *err)
{
    td_status rc = TD_OK;
    int tl = o->tile_log2 ? o->tile_log2 : TD_TILE_LOG2_DEFAULT;
    if (w < 2 || h < 2) {
        rc = td_err_set(err, TD_EFORMAT, "%s: grid of %ld x %ld samples has no cell", path,
                        (long)w, (long)h);
    } else if (w > o->limits.max_width || h > o->limits.max_height) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: grid of %ld x %ld samples exceeds the limit of %ld x %ld",
                        path, (long)w, (long)h, (long)o->limits.max_width, (long)o->limits.max_height);
    } else if (o->limits.max_bytes && td_grid_bytes(w, h, tl) > o->limits.max_bytes) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: grid of %ld x %ld samples needs %llu bytes, over the budget of %llu",
                        path, (long)w, (long)h, (unsigned long long)td_grid_bytes(w, h, tl),
                        (unsigned long long)o->limits.max_bytes);
    }
    return rc;
}

td_status td_demutil_check_budget(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                                  uint64_t extra, const char *what, td_err *err)
{
    td_status rc = TD_OK;
    const uint64_t grid = td_grid_bytes(w, h, o->tile_log2 ? o->tile_log2 : TD_TILE_LOG2_DEFAULT);
    const uint64_t max = o->limits.max_bytes;
    if (max && (grid > max || extra > max - grid))
        rc = td_err_set(err, TD_ETOOBIG,
                        "%s: grid of %ld x %ld samples (%llu bytes) and %s (%llu bytes) need %llu bytes, "
                        "over the budget of %llu",
                        path, (long)w, (long)h, (unsigned long long)grid, what,
                        (unsigned long long)extra, (unsigned long long)(grid + extra),
                        (unsigned long long)max);
    return rc;
}

td_status td_demutil_side_georef(const char *path, const td_dem_opts *o, td_demside *sc,
                                 int32_t w, int32_t h, double *sx, double *sy, td_err *err)
{
    td_status rc;
    /* a lon/lat origin moves south first: the spacing is taken at its centre latitude */
    if (sc->geo.kind == TD_GEO_LONLAT)
        georef_from_north(&sc->geo, h);
    rc = td_demutil_spacing(path, o, sc, &sc->geo, w, h, sx, sy, err);
    /* a projected origin has no step of its own until the spacing is known */
    if (rc == TD_OK && sc->geo.kind == TD_GEO_PROJECTED) {
        sc->geo.dx = *sx;
        sc->geo.dy = *sy;
        georef_from_north(&sc->geo, h);
    }
    return rc;
}

td_status td_demutil_create(const char *path, const td_dem_opts *o, int32_t w, int32_t h,
                            double sx, double sy, const td_georef *geo, td_grid **out,
                            td_err *err)
{
    int tl = o->tile_log2 ? o->tile_log2 : TD_TILE_LOG2_DEFAULT;
    td_status rc = td_grid_create(w, h, sx, sy, tl, &o->limits, out, err);
    if (rc != TD_OK)
        name_file(path, err);
    else if (geo)
        (*out)->geo = *geo;
    return rc;
}

float *td_demutil_file_row(const td_grid *g, int32_t r)
{
    return g->z + (size_t)(g->h - 1 - r) * (size_t)g->w;
}

td_status td_demutil_open(const char *path, FILE **f, struct stat *st, td_err *err)
{
    td_status rc = TD_OK;
    *f = fopen(path, "rb");
    if (!*f || (st && fstat(fileno(*f), st) != 0))
        rc = td_err_set(err, TD_EIO, "%s: cannot open (%s)", path, strerror(errno));
    return rc;
}

td_status td_demutil_read_row(const char *path, FILE *f, void *dst, size_t size, size_t n,
                              int32_t r, td_err *err)
{
    td_status rc = TD_OK;
    if (fread(dst, size, n, f) != n)
        rc = td_err_set(err, TD_EIO, "%s: read failed at row %ld (%s)", path, (long)r,
                        ferror(f) ? strerror(errno) : "file shrank while reading");
    return rc;
}

/* What p does to this row when it has no scale (1) and an offset of +-0 (the common raw
 * float32 file), and every sample but the nodata value is finite and within max_abs:
 * 1 leaves every sample as it is (no nodata, no zero: a -0.0 would come out +0.0 with
 * offset +0), 2 turns the nodata samples into NaN and adds the offset to the others (which
 * changes only the zeros' signs: what the full rule's v * 1 + offset does); 0 otherwise:
 * the full rule, with its messages. Comparisons in float against max_abs rounded down (the
 * same answers as in double), no branch: 4 instructions a sample against the full rule's
 * 31 (trinidad's 2.9 M samples: 89 -> 25 M). Until 2026-12-02 a row with a void or a zero
 * (every row of picos's, in its frame of nodata; an SRTM tile's coast) took the full rule:
 * picos's load 0.99-1.06 -> 0.55-0.60 ms (td_dem_load warm, its heights on a huge page). */
static int f32_row_fast(const td_demutil_f32 *p, const float *row, int32_t w)
{
    float lim = (float)p->max_abs, nd = p->has_nodata && isfinite(p->nodata) ? p->nodata : NAN;
    int other = p->scale != 1.0 || p->offset != 0.0 || !(p->max_abs >= 0.0), special = 0;
    if ((double)lim > p->max_abs)
        lim = nextafterf(lim, 0.0f);
    for (int32_t i = 0; i < w; i++) {
        float v = row[i];
        int void_ = v == nd;
        other |= !(fabsf(v) <= lim) & !void_;
        special |= void_ | (v == 0.0f);
    }
    return other ? 0 : special ? 2 : 1;
}

td_status td_demutil_f32_row(const char *path, const td_demutil_f32 *p, float *row, int32_t w,
                             int32_t r, td_err *err)
{
    td_status rc = TD_OK;
    int fast = f32_row_fast(p, row, w);
    if (fast == 2) {
        float nd = p->nodata, off = (float)p->offset;
        for (int32_t i = 0; i < w; i++)
            row[i] = row[i] == nd ? NAN : row[i] + off;
    }
    if (fast)
        w = 0;
    for (int32_t i = 0; i < w && rc == TD_OK; i++) {
        float v = row[i];
        double m;
        if (isnan(v)) {
            if (!p->nan_void)
                rc = td_err_set(err, TD_EFORMAT, "%s: NaN sample at column %ld, row %ld%s", path,
                                (long)i, (long)r, p->nan_why);
        } else if (isinf(v) && p->inf_refused) {
            rc = td_err_set(err, TD_ERANGE, "%s: infinite sample at column %ld, row %ld", path,
                            (long)i, (long)r);
        } else if (p->has_nodata && v == p->nodata) {
            row[i] = NAN;
        } else {
            m = (double)v * p->scale + p->offset;
            if (!isfinite(m) || fabs(m) > p->max_abs)
                rc = td_err_set(err, TD_ERANGE, "%s: sample at column %ld, row %ld is not finite",
                                path, (long)i, (long)r);
            else
                row[i] = (float)m;
        }
    }
    return rc;
}

td_status td_demutil_deliver(const char *path, td_status rc, td_grid *g, td_grid **out,
                             td_err *err)
{
    if (rc == TD_OK) {
        rc = td_grid_finish(g, err);
        if (rc != TD_OK)
            name_file(path, err);
    }
    if (rc != TD_OK) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}
