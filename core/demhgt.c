/* demhgt.c: the SRTM .hgt loader.
 *
 * The format has no header: the size is known from the file length (1201^2 or 3601^2
 * samples of 2 bytes; anything else is refused as truncated or not SRTM) and the place
 * from the name. Tiles are one degree square and share their edge rows and columns with
 * their neighbours, so the sample step is 1/(n-1) degree. Rows are converted one at a
 * time into their south-based place (grid.h). Spacing in metres is taken at the tile's
 * centre latitude unless given explicitly.
 *
 * Any int16 is a well-formed sample, so corruption shows only in the values: heights
 * outside [-12000, 9000] m (below the deepest trench, above Everest) are refused, which
 * also catches a little-endian file passed off as SRTM. */
#include "demhgt.h"

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

#include "demutil.h"

#define TD_HGT_MAX_SIDE 3601
#define TD_HGT_LOWEST (-12000)
#define TD_HGT_HIGHEST 9000

int td_demhgt_parse_name(const char *path, int *lon, int *lat)
{
    const char *b = td_demutil_basename(path);
    int ok = strlen(b) >= 8 && b[7] == '.';
    int la = 0, lo = 0;
    if (ok) {
        char ns = (char)toupper((unsigned char)b[0]), ew = (char)toupper((unsigned char)b[3]);
        ok = (ns == 'N' || ns == 'S') && (ew == 'E' || ew == 'W') && isdigit((unsigned char)b[1]) &&
             isdigit((unsigned char)b[2]) && isdigit((unsigned char)b[4]) &&
             isdigit((unsigned char)b[5]) && isdigit((unsigned char)b[6]);
        if (ok) {
            la = (b[1] - '0') * 10 + (b[2] - '0');
            lo = (b[4] - '0') * 100 + (b[5] - '0') * 10 + (b[6] - '0');
            la = ns == 'S' ? -la : la;
            lo = ew == 'W' ? -lo : lo;
            ok = la >= -90 && la < 90 && lo >= -180 && lo < 180;
        }
    }
    if (ok) {
        *lon = lo;
        *lat = la;
    }
    return ok;
}

/* The tile's side from the file's length (1201 or 3601 samples), within the limits. */
static td_status hgt_side(const char *path, const td_dem_opts *o, const struct stat *st,
                          int32_t *side, td_err *err)
{
    td_status rc = TD_OK;
    *side = 0;
    if (S_ISREG(st->st_mode) && st->st_size == (off_t)1201 * 1201 * 2)
        *side = 1201;
    else if (S_ISREG(st->st_mode) && st->st_size == (off_t)3601 * 3601 * 2)
        *side = 3601;
    if (!*side)
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: %lld bytes: an SRTM tile has 1201 x 1201 or 3601 x 3601 int16 samples "
                        "(2884802 or 25934402 bytes); truncated or not SRTM",
                        path, (long long)st->st_size);
    else
        rc = td_demutil_check_limits(path, o, *side, *side, err);
    return rc;
}

/* Lon/lat of the south-west sample from the name, one degree over side - 1 steps. */
static void hgt_georef(int lon, int lat, int32_t side, td_georef *geo)
{
    memset(geo, 0, sizeof *geo);
    geo->kind = TD_GEO_LONLAT;
    geo->x0 = lon;
    geo->y0 = lat;
    geo->dx = geo->dy = 1.0 / (double)(side - 1);
    snprintf(geo->crs, sizeof geo->crs, "EPSG:4326 (SRTM, WGS84 lon/lat)");
}

/* One row of big-endian int16 into heights: -32768 is a void, an implausible height is
 * refused. */
static td_status hgt_decode_row(const char *path, const unsigned char *src, int32_t side,
                                int32_t r, float *dst, td_err *err)
{
    td_status rc = TD_OK;
    for (int32_t i = 0; i < side && rc == TD_OK; i++) {
        int v = (int16_t)(uint16_t)((src[2 * i] << 8) | src[2 * i + 1]);
        if (v != -32768 && (v < TD_HGT_LOWEST || v > TD_HGT_HIGHEST))
            rc = td_err_set(err, TD_ERANGE,
                            "%s: implausible height %d m at column %ld, row %ld (corrupt tile, "
                            "or not big-endian?)",
                            path, v, (long)i, (long)r);
        else
            dst[i] = v == -32768 ? NAN : (float)v;
    }
    return rc;
}

static td_status hgt_read(const char *path, FILE *f, td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    unsigned char row[2 * TD_HGT_MAX_SIDE];
    for (int32_t r = 0; r < g->h && rc == TD_OK; r++) {
        rc = td_demutil_read_row(path, f, row, 2, (size_t)g->w, r, err);
        if (rc == TD_OK)
            rc = hgt_decode_row(path, row, g->w, r, td_demutil_file_row(g, r), err);
    }
    return rc;
}

td_status td_demhgt_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    td_grid *g = NULL;
    FILE *f = NULL;
    struct stat st;
    int lon = 0, lat = 0;
    int32_t side = 0;
    double sx = 0, sy = 0;
    td_georef geo;

    if (!td_demhgt_parse_name(path, &lon, &lat))
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: not an SRTM tile name (like N37W106.hgt) to take its place from", path);
    if (rc == TD_OK)
        rc = td_demutil_open(path, &f, &st, err);
    if (rc == TD_OK)
        rc = hgt_side(path, o, &st, &side, err);
    if (rc == TD_OK) {
        hgt_georef(lon, lat, side, &geo);
        rc = td_demutil_spacing(path, o, NULL, &geo, side, side, &sx, &sy, err);
    }
    if (rc == TD_OK)
        rc = td_demutil_create(path, o, side, side, sx, sy, &geo, &g, err);
    if (rc == TD_OK)
        rc = hgt_read(path, f, g, err);
    if (f)
        fclose(f);
    return td_demutil_deliver(path, rc, g, out, err);
}
