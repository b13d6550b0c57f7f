/* demasc.c: the ESRI ASCII grid loader.
 *
 * The file is read in one pass through a 64 KiB buffer and a whitespace tokenizer (no
 * copy of the whole text: an .asc is 5-10 bytes per sample, several times the grid).
 * Header keys are case-insensitive, in any order, each at most once; the first token
 * that does not start with a letter begins the data. Every value must be a finite
 * decimal number (strtod on a token of digits, sign, point and exponent only, so "nan",
 * "inf", hex and "12abc" are refused with their line), and there must be exactly
 * ncols*nrows of them. Values equal to NODATA_value become NaN (voids).
 *
 * Georeference: xllcorner/yllcorner is the outer corner of the south-west cell, so its
 * sample sits half a cell in; xllcenter/yllcenter is the sample itself.
 * Lon/lat or projected: a `<name>.prj` beside the file decides when present (PROJCS ->
 * projected, GEOGCS alone -> lon/lat). Without one, the grid is taken as lon/lat when
 * both cell sizes are below 0.1 and the whole extent lies within [-180, 180] x [-90, 90]
 * (no DEM in metres has cells under 10 cm over such a small area near (0, 0) without a
 * .prj in practice; --spacing overrides the metres if it does). Lon/lat grids get their
 * spacing in metres at the centre latitude (td_grid_lonlat_spacing); otherwise the cell
 * size times the .prj's linear unit is the spacing in metres: the projected CRS's last
 * UNIT["name", metres] (WKT1: the GEOGCS's angular unit comes before it) or LENGTHUNIT
 * (WKT2), e.g. 0.3048006096 for US survey feet; without one, metres. A unit that is
 * there but not a positive number is refused, naming the .prj, and so is a .prj whose CRS
 * does not fit the coordinates (asc_prj_fits). Heights are taken as metres whatever the
 * unit (a .prj has no vertical unit).
 *
 * Memory follows the data: before the grid is allocated, the header's ncols*nrows must fit
 * in what is left of the file (asc_fits_file), so a short file claiming a huge grid is
 * refused without the allocation. Only regular files are read (the size must be known). */
#include "demasc.h"

#include <ctype.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "demutil.h"

#define TD_ASC_TOKEN_MAX 64
#define TD_ASC_PRJ_MAX 8192

typedef struct asc_reader {
    FILE *f;
    long long size;   /* the file's bytes (a regular file) */
    long long taken;  /* bytes read into buf so far */
    size_t len, pos;
    long line;
    char buf[1 << 16];
} asc_reader;

static inline int asc_getc(asc_reader *r)
{
    int c = EOF;
    if (r->pos == r->len) {
        r->len = fread(r->buf, 1, sizeof r->buf, r->f);
        r->taken += (long long)r->len;
        r->pos = 0;
    }
    if (r->pos < r->len)
        c = (unsigned char)r->buf[r->pos++];
    return c;
}

/* isspace in the C locale (terrad sets no other), without its table lookup per byte. */
static inline int asc_space(int c) { return c == ' ' || (c >= '\t' && c <= '\r'); }

/* The byte-by-byte path of asc_token (a token that reaches the buffer's end). */
static int asc_token_slow(asc_reader *r, char *tok)
{
    int c, k = 0, res = 0;
    do {
        c = asc_getc(r);
        if (c == '\n')
            r->line++;
    } while (c != EOF && asc_space(c));
    while (c != EOF && !asc_space(c)) {
        if (k < TD_ASC_TOKEN_MAX - 1)
            tok[k] = (char)c;
        k++;
        c = asc_getc(r);
    }
    if (c == '\n')
        r->line++;
    if (k > 0) {
        res = k < TD_ASC_TOKEN_MAX ? 1 : -1;
        tok[k < TD_ASC_TOKEN_MAX ? k : TD_ASC_TOKEN_MAX - 1] = '\0';
    }
    return res;
}

/* Next whitespace-separated token: 1 found, 0 end of file, -1 longer than the buffer.
 * The common case, a token and the byte after it inside the buffer, is scanned in place;
 * one that reaches the buffer's end takes the byte-by-byte path. */
static int asc_token(asc_reader *r, char *tok)
{
    int res = 1;
    size_t p = r->pos, s;
    while (p < r->len && asc_space((unsigned char)r->buf[p]))
        r->line += r->buf[p++] == '\n';
    for (s = p; p < r->len && !asc_space((unsigned char)r->buf[p]); p++)
        ;
    if (p < r->len && p > s && p - s < TD_ASC_TOKEN_MAX) {
        memcpy(tok, r->buf + s, p - s);
        tok[p - s] = '\0';
        r->line += r->buf[p] == '\n';
        r->pos = p + 1;
    } else {
        r->pos = s; /* the spaces before it are counted */
        res = asc_token_slow(r, tok);
    }
    return res;
}

#define TD_ASC_KEY_LIST(X)                                                     \
    X(K_NCOLS, "ncols")                                                        \
    X(K_NROWS, "nrows")                                                        \
    X(K_XLLCORNER, "xllcorner")                                                \
    X(K_YLLCORNER, "yllcorner")                                                \
    X(K_XLLCENTER, "xllcenter")                                                \
    X(K_YLLCENTER, "yllcenter")                                                \
    X(K_CELLSIZE, "cellsize")                                                  \
    X(K_DX, "dx")                                                              \
    X(K_DY, "dy")                                                              \
    X(K_NODATA, "nodata_value")

enum {
#define TD_X_ENUM(k, name) k,
    TD_ASC_KEY_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    K_COUNT
};

static const char *const asc_key_names[] = {
#define TD_X_NAME(k, name) name,
    TD_ASC_KEY_LIST(TD_X_NAME)
#undef TD_X_NAME
};

/* The number after the unit's name in `UNIT["name", value` at u; 0 if unreadable. */
static double prj_unit_value(const char *u)
{
    double v = 0.0;
    const char *q = strchr(u, '"');
    q = q ? strchr(q + 1, '"') : NULL;
    if (q) {
        char *end = NULL;
        q++;
        while (*q == ' ' || *q == ',')
            q++;
        v = strtod(q, &end);
        if (end == q || !isfinite(v) || !(v > 0.0) || v > 1e6)
            v = 0.0;
    }
    return v;
}

/* The projected CRS's linear unit in WKT text: in WKT1 the UNIT that is a direct child of
 * PROJCS (the GEOGCS's angular unit is a grandchild; a compound CRS's vertical unit lies
 * outside PROJCS), in WKT2 the last LENGTHUNIT inside PROJCRS (the coordinate system's,
 * or its axes'). Brackets inside quoted names do not count. NULL if there is none. */
static const char *prj_linear_unit(const char *text)
{
    const char *wkt2 = strstr(text, "PROJCRS[");
    const char *crs = wkt2 ? wkt2 : strstr(text, "PROJCS[");
    const char *key = wkt2 ? "LENGTHUNIT[" : "UNIT[";
    const size_t klen = strlen(key);
    const char *u = NULL;
    if (crs) {
        int depth = 0, quoted = 0, closed = 0;
        for (const char *p = crs + strcspn(crs, "["); *p && !closed; p++) {
            if (*p == '"')
                quoted = !quoted;
            else if (!quoted && (*p == '[' || *p == '('))
                depth++;
            else if (!quoted && (*p == ']' || *p == ')'))
                closed = --depth == 0;
            else if (!quoted && !strncmp(p, key, klen) && !isalpha((unsigned char)p[-1]) && (wkt2 || depth == 1))
                u = p;
        }
    }
    return u;
}

/* Reads `<name>.prj` beside the file (its path into prj), if there is one: *kind 1
 * geographic, 0 projected, -1 none or undecided; *unit_m the projected CRS's linear unit in
 * metres (1 if none). */
static td_status asc_prj_read(const char *path, char prj[TD_DEMUTIL_PATH_MAX], int *kind,
                              double *unit_m, td_err *err)
{
    td_status rc = TD_OK;
    char text[TD_ASC_PRJ_MAX];
    size_t n;
    FILE *f = NULL;
    char *dot = NULL;
    *kind = -1;
    *unit_m = 1.0;
    if (snprintf(prj, TD_DEMUTIL_PATH_MAX, "%s", path) < TD_DEMUTIL_PATH_MAX - 4)
        dot = strrchr(prj, '.');
    if (dot && !strchr(dot, '/')) {
        strcpy(dot, ".prj"); /* fits: the path had room for 4 more bytes */
        f = fopen(prj, "rb");
    }
    if (f) {
        n = fread(text, 1, sizeof text - 1, f);
        text[n] = '\0';
        fclose(f);
        if (strstr(text, "PROJCS") || strstr(text, "PROJCRS"))
            *kind = 0;
        else if (strstr(text, "GEOGCS") || strstr(text, "GEOGCRS"))
            *kind = 1;
    }
    if (*kind == 0) {
        const char *u = prj_linear_unit(text);
        if (u) {
            *unit_m = prj_unit_value(u);
            if (*unit_m == 0.0)
                rc = td_err_set(err, TD_EFORMAT, "%s: the linear unit in %s is not a positive number of metres",
                                path, prj);
        }
    }
    return rc;
}

/* What the header said: kv[key] is valid where seen[key]. */
typedef struct asc_header {
    double kv[K_COUNT];
    int seen[K_COUNT];
} asc_header;

static td_status asc_open(const char *path, asc_reader **out, td_err *err)
{
    td_status rc = TD_OK;
    asc_reader *r = calloc(1, sizeof *r);
    if (!r) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
    } else {
        struct stat st;
        r->line = 1;
        rc = td_demutil_open(path, &r->f, &st, err);
        if (rc == TD_OK && !S_ISREG(st.st_mode))
            rc = td_err_set(err, TD_EINVAL, "%s: not a regular file", path);
        r->size = rc == TD_OK ? (long long)st.st_size : 0;
    }
    *out = r;
    return rc;
}

static void asc_close(asc_reader *r)
{
    if (r && r->f)
        fclose(r->f);
    free(r);
}

/* Index of a header key (case-insensitive), or -1. */
static int asc_key(const char *tok)
{
    int key = -1;
    for (int q = 0; q < K_COUNT && key < 0; q++)
        if (!strcasecmp(tok, asc_key_names[q]))
            key = q;
    return key;
}

/* Header: key value pairs until a token that does not start with a letter, which is left
 * in tok as the first data token. */
static td_status asc_read_header(const char *path, asc_reader *r, asc_header *hd, char *tok,
                                 td_err *err)
{
    td_status rc = TD_OK;
    char val[TD_ASC_TOKEN_MAX];
    int t = asc_token(r, tok);
    memset(hd, 0, sizeof *hd);
    while (rc == TD_OK && t > 0 && isalpha((unsigned char)tok[0])) {
        int key = asc_key(tok);
        if (key < 0)
            rc = td_err_set(err, TD_EFORMAT, "%s: line %ld: unknown header key '%s'", path, r->line,
                            tok);
        else if (hd->seen[key])
            rc = td_err_set(err, TD_EFORMAT, "%s: line %ld: header key '%s' given twice", path,
                            r->line, tok);
        else if (asc_token(r, val) != 1 || !td_demutil_parse_double(val, &hd->kv[key]))
            rc = td_err_set(err, TD_EFORMAT, "%s: line %ld: header key '%s' needs a finite number",
                            path, r->line, tok);
        else
            hd->seen[key] = 1;
        if (rc == TD_OK)
            t = asc_token(r, tok);
    }
    if (rc == TD_OK && t == 0)
        rc = td_err_set(err, TD_EFORMAT, "%s: ends in the header (no data)", path);
    return rc;
}

/* Can the rest of the file hold ncols*nrows values? Each takes a character and all but the
 * last a separator, so from the first data token (in tok, just read) to the end there must
 * be 2n - 1 bytes: a 65-byte file claiming 16000 x 16000 is refused before the grid (1 GB)
 * is allocated, and the grid is never more than twice the file. */
static td_status asc_fits_file(const char *path, const asc_reader *r, const char *tok,
                               int32_t w, int32_t h, td_err *err)
{
    td_status rc = TD_OK;
    const long long consumed = r->taken - (long long)(r->len - r->pos);
    const long long left = r->size - consumed + (long long)strlen(tok) + 1;
    const unsigned long long n = (unsigned long long)w * (unsigned long long)h;
    if (left < 0 || (unsigned long long)left < 2 * n - 1)
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: its header claims %ld x %ld = %llu values, but the %lld bytes after it hold "
                        "at most %llu: truncated, or the header is wrong",
                        path, (long)w, (long)h, n, left > 0 ? left : 0LL,
                        left > 0 ? ((unsigned long long)left + 1) / 2 : 0ULL);
    return rc;
}

/* ncols and nrows: integers of at least 2, within the limits. */
static td_status asc_size(const char *path, const td_dem_opts *o, const asc_header *hd,
                          int32_t *w, int32_t *h, td_err *err)
{
    td_status rc = TD_OK;
    const double nc = hd->kv[K_NCOLS], nr = hd->kv[K_NROWS];
    if (!hd->seen[K_NCOLS] || !hd->seen[K_NROWS]) {
        rc = td_err_set(err, TD_EFORMAT, "%s: header lacks ncols or nrows", path);
    } else if (nc != floor(nc) || nr != floor(nr) || nc < 2 || nr < 2 || nc > INT32_MAX ||
               nr > INT32_MAX) {
        rc = td_err_set(err, TD_EFORMAT, "%s: ncols %g, nrows %g: need integers of at least 2", path,
                        nc, nr);
    } else {
        *w = (int32_t)nc;
        *h = (int32_t)nr;
        rc = td_demutil_check_limits(path, o, *w, *h, err);
    }
    return rc;
}

/* Cell size (cellsize, or dx and dy) and the south-west sample: a corner is half a cell
 * out from it, a center is the sample itself. */
static td_status asc_cell(const char *path, const asc_header *hd, td_georef *geo, td_err *err)
{
    td_status rc = TD_OK;
    const int *seen = hd->seen;
    const double *kv = hd->kv;
    if (seen[K_CELLSIZE] && !seen[K_DX] && !seen[K_DY]) {
        geo->dx = geo->dy = kv[K_CELLSIZE];
    } else if (!seen[K_CELLSIZE] && seen[K_DX] && seen[K_DY]) {
        geo->dx = kv[K_DX];
        geo->dy = kv[K_DY];
    } else {
        rc = td_err_set(err, TD_EFORMAT, "%s: header needs cellsize, or dx and dy (not both)", path);
    }
    if (rc == TD_OK && !(geo->dx > 0.0 && geo->dy > 0.0))
        rc = td_err_set(err, TD_ERANGE, "%s: cell size %g x %g is not positive", path, geo->dx,
                        geo->dy);
    if (rc == TD_OK &&
        (seen[K_XLLCORNER] == seen[K_XLLCENTER] || seen[K_YLLCORNER] == seen[K_YLLCENTER]))
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: header needs one of xllcorner/xllcenter and one of yllcorner/yllcenter",
                        path);
    if (rc == TD_OK) {
        geo->x0 = seen[K_XLLCORNER] ? kv[K_XLLCORNER] + 0.5 * geo->dx : kv[K_XLLCENTER];
        geo->y0 = seen[K_YLLCORNER] ? kv[K_YLLCORNER] + 0.5 * geo->dy : kv[K_YLLCENTER];
    }
    return rc;
}

/* Whether the grid's extent reads as lon/lat degrees: every cell's outer edge within
 * longitude -180 .. 360 (some global grids count 0 .. 360) and latitude -90 .. 90. */
static int asc_extent_lonlat(const td_georef *geo, int32_t w, int32_t h)
{
    const double tol = 1e-9;
    return geo->x0 - 0.5 * geo->dx >= -180.0 - tol && geo->x0 + ((double)w - 0.5) * geo->dx <= 360.0 + tol &&
           geo->y0 - 0.5 * geo->dy >= -90.0 - tol && geo->y0 + ((double)h - 0.5) * geo->dy <= 90.0 + tol;
}

/* A .prj whose CRS does not fit the coordinates is refused, naming it: a geographic CRS over
 * an extent that is not degrees (projected coordinates: the spacing would be taken at a
 * meaningless latitude), or a projected one over what can only be degrees (cells under a
 * centimetre, after the unit, whose extent reads as lon/lat: a DEM's cells in metres are
 * not that small over such an area near the CRS's origin). */
static td_status asc_prj_fits(const char *path, const char *prj, int geographic, double unit_m,
                              const td_georef *geo, int32_t w, int32_t h, td_err *err)
{
    td_status rc = TD_OK;
    const int lonlat = asc_extent_lonlat(geo, w, h);
    if (geographic && !lonlat)
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: %s says geographic (lon/lat degrees), but the grid's extent %g .. %g x %g .. %g "
                        "is not degrees: projected coordinates? fix or remove the .prj",
                        path, prj, geo->x0 - 0.5 * geo->dx, geo->x0 + ((double)w - 0.5) * geo->dx,
                        geo->y0 - 0.5 * geo->dy, geo->y0 + ((double)h - 0.5) * geo->dy);
    else if (!geographic && lonlat && geo->dx * unit_m < 0.01 && geo->dy * unit_m < 0.01)
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: %s says projected, but cells of %g x %g m over an extent that reads as lon/lat "
                        "are degrees: fix or remove the .prj",
                        path, prj, geo->dx * unit_m, geo->dy * unit_m);
    return rc;
}

/* Lon/lat or projected (the .prj, else the extent; see the top of the file) and the
 * spacing in metres. */
static td_status asc_georef(const char *path, const td_dem_opts *o, const asc_header *hd,
                            int32_t w, int32_t h, td_georef *geo, double *sx, double *sy,
                            td_err *err)
{
    td_status rc;
    int geographic, prj;
    double unit_m = 1.0;
    char prj_path[TD_DEMUTIL_PATH_MAX];
    td_demside sc;

    memset(geo, 0, sizeof *geo);
    rc = asc_cell(path, hd, geo, err);
    if (rc == TD_OK)
        rc = asc_prj_read(path, prj_path, &prj, &unit_m, err);
    if (rc == TD_OK && prj >= 0)
        rc = asc_prj_fits(path, prj_path, prj, unit_m, geo, w, h, err);
    if (rc != TD_OK)
        goto out;
    if (prj >= 0)
        geographic = prj;
    else
        geographic = geo->dx < 0.1 && geo->dy < 0.1 && geo->x0 - 0.5 * geo->dx >= -180.0 &&
                     geo->x0 + ((double)w - 0.5) * geo->dx <= 180.0 &&
                     geo->y0 - 0.5 * geo->dy >= -90.0 && geo->y0 + ((double)h - 0.5) * geo->dy <= 90.0;
    geo->kind = geographic ? TD_GEO_LONLAT : TD_GEO_PROJECTED;
    memset(&sc, 0, sizeof sc);
    if (!geographic) {
        sc.has_spacing = 1;
        sc.spacing[0] = geo->dx * unit_m;
        sc.spacing[1] = geo->dy * unit_m;
    }
    rc = td_demutil_spacing(path, o, &sc, geo, w, h, sx, sy, err);
out:
    return rc;
}

/* The common data token, [-+]digits[.digits] (18 significant digits taken), as the float
 * asc_value stores ((float) of strtod's double), without strtod; 0 when not sure (the
 * caller then takes strtod's path). Up to 15 digits: the digits as an integer below 2^53
 * over an exact power of ten, one correctly rounded division, is strtod's double
 * (Clinger's fast path). Longer ones (picos has "2244.5900000000001455"): the first 18
 * significant digits over the power of ten, in double, are within 2^-51.9 of the decimal
 * (two roundings and the digits cut, under 1e-17), so the decimal and strtod's double
 * (within 2^-53 of it) both round to the float of that value whenever it is 2^-49 of
 * itself away from a midpoint between floats. NODATA is compared likewise (too close: not
 * sure). Several times faster than strtod; tests/unit/test_dem.c holds it to strtod. */
static int asc_fast_value(const char *tok, const asc_header *hd, float *out)
{
    static const double p10[19] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8, 1e9,
                                   1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18};
    const char *p = tok + (*tok == '-' || *tok == '+');
    uint64_t m = 0;
    int nd = 0, nf = -1, ok, cut = 0;
    for (; *p; p++) {
        if (*p >= '0' && *p <= '9' && nd < 18) { /* leading zeros are not counted */
            m = m * 10 + (uint64_t)(*p - '0');
            nd += m > 0;
            nf += nf >= 0;
        } else if (*p >= '0' && *p <= '9' && nf >= 0) {
            cut = 1; /* a fraction digit past the 18th */
        } else if (*p == '.' && nf < 0) {
            nf = 0;
        } else {
            break;
        }
    }
    ok = *p == '\0' && p > tok + (*tok == '-' || *tok == '+') + (nf == 0) && nf <= 18;
    if (ok) {
        double x = (double)m / p10[nf > 0 ? nf : 0], tol = fabs(x) * 0x1p-49, nv = hd->kv[K_NODATA];
        x = *tok == '-' ? -x : x;
        if (nd <= 15 && !cut) { /* exact: strtod's double */
            *out = hd->seen[K_NODATA] && x == nv ? NAN : (float)x;
        } else {
            float f = (float)x, n0, n1;
            uint32_t b;
            memcpy(&b, &f, sizeof b);
            b--; /* the floats on either side of f (f is finite, not 0: checked below) */
            memcpy(&n0, &b, sizeof b);
            b += 2;
            memcpy(&n1, &b, sizeof b);
            ok = f != 0.0f && fabs(x - ((double)f + (double)n0) / 2) > tol &&
                 fabs(x - ((double)f + (double)n1) / 2) > tol &&
                 !(hd->seen[K_NODATA] && fabs(x - nv) <= tol + fabs(nv) * 0x1p-49);
            *out = f;
        }
    }
    return ok;
}

/* One data value: a finite decimal; NODATA_value becomes NaN; it must fit a float. */
static td_status asc_value(const char *path, const asc_reader *r, const asc_header *hd, int t,
                           const char *tok, float *out, td_err *err)
{
    td_status rc = TD_OK;
    double v;
    if (t > 0 && asc_fast_value(tok, hd, out))
        rc = TD_OK; /* the common token, without strtod */
    else if (t < 0 || !td_demutil_parse_double(tok, &v))
        rc = td_err_set(err, TD_EFORMAT, "%s: line %ld: '%s' is not a finite number", path, r->line,
                        tok);
    else if (hd->seen[K_NODATA] && v == hd->kv[K_NODATA])
        *out = NAN;
    else if (fabs(v) > FLT_MAX)
        rc = td_err_set(err, TD_ERANGE, "%s: line %ld: %s does not fit a float", path, r->line, tok);
    else
        *out = (float)v;
    return rc;
}

/* Exactly ncols*nrows values, north row first, into their south-based place; tok holds the
 * first one already. */
static td_status asc_read_data(const char *path, asc_reader *r, const asc_header *hd, char *tok,
                               td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    size_t k = 0;
    int t = 1;
    for (int32_t row = 0; row < g->h && rc == TD_OK; row++) {
        float *dst = td_demutil_file_row(g, row);
        for (int32_t i = 0; i < g->w && rc == TD_OK; i++, k++) {
            if (k > 0)
                t = asc_token(r, tok);
            if (t == 0)
                rc = td_err_set(err, TD_EFORMAT, "%s: truncated: %zu of %ld x %ld values", path, k,
                                (long)g->w, (long)g->h);
            else
                rc = asc_value(path, r, hd, t, tok, &dst[i], err);
        }
    }
    if (rc == TD_OK && asc_token(r, tok) != 0)
        rc = td_err_set(err, TD_EFORMAT, "%s: line %ld: more than %ld x %ld values", path, r->line,
                        (long)g->w, (long)g->h);
    if (rc == TD_OK && ferror(r->f))
        rc = td_err_set(err, TD_EIO, "%s: read error", path);
    return rc;
}

td_status td_demasc_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc;
    asc_reader *r = NULL;
    td_grid *g = NULL;
    asc_header hd;
    char tok[TD_ASC_TOKEN_MAX];
    int32_t w = 0, h = 0;
    double sx = 0, sy = 0;
    td_georef geo;

    rc = asc_open(path, &r, err);
    if (rc == TD_OK)
        rc = asc_read_header(path, r, &hd, tok, err);
    if (rc == TD_OK)
        rc = asc_size(path, o, &hd, &w, &h, err);
    if (rc == TD_OK)
        rc = asc_fits_file(path, r, tok, w, h, err);
    if (rc == TD_OK)
        rc = asc_georef(path, o, &hd, w, h, &geo, &sx, &sy, err);
    if (rc == TD_OK)
        rc = td_demutil_create(path, o, w, h, sx, sy, &geo, &g, err);
    if (rc == TD_OK)
        rc = asc_read_data(path, r, &hd, tok, g, err);
    asc_close(r);
    return td_demutil_deliver(path, rc, g, out, err);
}
