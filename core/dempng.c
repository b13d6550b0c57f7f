/* dempng.c: the PNG loader (libpng).
 *
 * A PNG does not say how its pixels hold heights, and every packing decodes to plausible
 * numbers under every other one, so the encoding must be stated: by option, or by the
 * sidecar `<name>.json` (keys encoding, scale, offset, divisor, spacing_m, nodata,
 * origin; see dem.h). Without one the file is refused, naming the flag and the key.
 *
 *   gray16       16-bit grayscale             m = v*scale + offset
 *   terrain-rgb  8-bit RGB(A), Mapbox         m = -10000 + (R*65536 + G*256 + B) * 0.1
 *   terrarium    8-bit RGB(A), Mapzen         m = R*256 + G + B/256 - 32768
 *   rgb-div      8-bit RGB(A), e.g. Levi      m = (R*65536 + G*256 + B) / divisor
 *
 * Voids: a pixel whose alpha is 0, or whose raw value (v, or R*65536+G*256+B) equals the
 * declared nodata. Palette PNGs (what lossless optimisers such as optipng make of a tile with
 * few colours) are expanded to RGB by libpng, and a tRNS chunk to alpha, so a transparent
 * palette entry or colour is a void. Rows are decoded one at a time (one row buffer) into
 * their south-based place; an interlaced PNG is only complete after its last pass, so it is
 * read whole into one buffer first, which must fit the same byte budget as the grid.
 * libpng reports errors by longjmp: everything the error path frees lives in a context
 * struct so no local is clobbered across setjmp. IHDR sizes are checked against the
 * limits before the row buffer or grid is allocated. */
#include "dempng.h"

#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <png.h>

#include "demutil.h"

typedef struct png_ctx {
    const char *path;
    FILE *f;
    png_structp png;
    png_infop info;
    unsigned char *row;            /* one row, or the whole image if interlaced */
    png_bytepp rows;               /* row pointers into it, interlaced only */
    td_grid *g;
    char msg[256];
    jmp_buf jmp;
} png_ctx;

static void png_ctx_error(png_structp png, png_const_charp msg)
{
    png_ctx *c = png_get_error_ptr(png);
    snprintf(c->msg, sizeof c->msg, "%s", msg);
    longjmp(c->jmp, 1);
}

static void png_ctx_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg; /* core never logs; warnings do not change the decoded values */
}

typedef struct png_params {
    td_dem_encoding enc;
    double scale, offset, divisor;
    int has_nodata;
    double nodata;
} png_params;

static td_status resolve_params(const char *path, const td_dem_opts *o, const td_demside *sc,
                                png_params *p, td_err *err)
{
    td_status rc = TD_OK;
    p->enc = o->encoding != TD_ENC_NONE ? o->encoding : sc->encoding;
    p->scale = (o->given & TD_DEM_GIVEN_SCALE) || !sc->has_scale ? o->scale : sc->scale;
    p->offset = (o->given & TD_DEM_GIVEN_OFFSET) || !sc->has_offset ? o->offset : sc->offset;
    p->divisor = (o->given & TD_DEM_GIVEN_DIVISOR) || !sc->has_divisor ? o->divisor : sc->divisor;
    p->has_nodata = o->has_nodata || sc->nodata_kind == TD_NODATA_VALUE;
    p->nodata = o->has_nodata ? o->nodata : sc->nodata;
    if (p->enc == TD_ENC_NONE || (unsigned)p->enc >= TD_ENC_COUNT) {
        rc = td_err_set(err, TD_EINVAL,
                        "%s: a PNG's height encoding is never guessed: give --encoding "
                        "(gray16, terrain-rgb, terrarium, rgb-div) or \"encoding\" in %s",
                        path, sc->path);
    } else if (p->enc == TD_ENC_GRAY16 && (!isfinite(p->scale) || p->scale == 0.0 ||
                                           !isfinite(p->offset))) {
        rc = td_err_set(err, TD_ERANGE, "%s: gray16 scale %g and offset %g must be finite, scale non-zero",
                        path, p->scale, p->offset);
    } else if (p->enc == TD_ENC_RGB_DIV && !(isfinite(p->divisor) && p->divisor > 0.0)) {
        rc = td_err_set(err, TD_ERANGE, "%s: rgb-div divisor %g must be positive and finite", path,
                        p->divisor);
    } else if (p->has_nodata && !isfinite(p->nodata)) {
        rc = td_err_set(err, TD_ERANGE, "%s: nodata must be finite", path);
    }
    return rc;
}

/* Decodes one row of raw pixels into heights. Returns 0 if a height is not a float. */
static int decode_row(const png_params *p, const unsigned char *src, int channels, int32_t w,
                      float *dst)
{
    int ok = 1;
    for (int32_t i = 0; i < w && ok; i++) {
        const unsigned char *px = src + (size_t)i * (size_t)channels * (p->enc == TD_ENC_GRAY16 ? 2u : 1u);
        double raw, m;
        int transparent = 0;
        if (p->enc == TD_ENC_GRAY16) {
            raw = (double)((px[0] << 8) | px[1]);
            transparent = channels == 2 && ((px[2] << 8) | px[3]) == 0;
            m = raw * p->scale + p->offset;
        } else {
            raw = (double)(((uint32_t)px[0] << 16) | ((uint32_t)px[1] << 8) | px[2]);
            transparent = channels == 4 && px[3] == 0;
            if (p->enc == TD_ENC_TERRAIN_RGB)
                m = -10000.0 + raw * 0.1;
            else if (p->enc == TD_ENC_TERRARIUM)
                m = px[0] * 256.0 + px[1] + px[2] / 256.0 - 32768.0;
            else
                m = raw / p->divisor;
        }
        if (transparent || (p->has_nodata && raw == p->nodata))
            dst[i] = NAN;
        else if (fabs(m) <= FLT_MAX)
            dst[i] = (float)m;
        else
            ok = 0;
    }
    return ok;
}

/* What the header leaves after the transformations: one layout per encoding. */
typedef struct png_shape {
    int32_t w, h;
    int interlaced;
    int channels; /* gray16: 1 or 2 (alpha); the RGB encodings: 3 or 4 (alpha) */
} png_shape;

/* Reads the pixels into the grid's south-based rows: one row at a time, or, for an
 * interlaced PNG, the whole image first (all passes) within the byte budget. */
static td_status read_pixels(png_ctx *c, const td_dem_opts *o, const png_params *p,
                             const png_shape *s, td_err *err)
{
    td_status rc = TD_OK;
    size_t rowbytes = png_get_rowbytes(c->png, c->info);
    size_t nrows = s->interlaced ? (size_t)s->h : 1;

    if (nrows > SIZE_MAX / rowbytes ||
        (o->limits.max_bytes && (uint64_t)rowbytes * nrows > o->limits.max_bytes)) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: decoding needs %lu x %lu bytes, over the budget of %llu",
                        c->path, (unsigned long)rowbytes, (unsigned long)nrows,
                        (unsigned long long)o->limits.max_bytes);
        goto out;
    }
    c->row = malloc(rowbytes * nrows);
    c->rows = s->interlaced ? malloc(nrows * sizeof *c->rows) : NULL;
    if (!c->row || (s->interlaced && !c->rows)) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory for %s", c->path,
                        s->interlaced ? "the image" : "a row");
        goto out;
    }
    if (s->interlaced) {
        for (size_t r = 0; r < nrows; r++)
            c->rows[r] = c->row + r * rowbytes;
        png_read_image(c->png, c->rows);
    }
    for (int32_t r = 0; r < s->h && rc == TD_OK; r++) {
        unsigned char *src = s->interlaced ? c->rows[r] : c->row;
        if (!s->interlaced)
            png_read_row(c->png, src, NULL);
        if (!decode_row(p, src, s->channels, s->w, td_demutil_file_row(c->g, r)))
            rc = td_err_set(err, TD_ERANGE, "%s: row %ld decodes to a height beyond float range", c->path, (long)r);
    }
out:
    return rc;
}

/* Opens the file, checks the signature and makes libpng's read and info structs. */
static td_status png_open(png_ctx *c, td_err *err)
{
    td_status rc;
    unsigned char sig[8];

    rc = td_demutil_open(c->path, &c->f, NULL, err);
    if (rc == TD_OK && (fread(sig, 1, 8, c->f) != 8 || png_sig_cmp(sig, 0, 8)))
        rc = td_err_set(err, TD_EFORMAT, "%s: not a PNG file (bad signature)", c->path);
    if (rc == TD_OK) {
        c->png = png_create_read_struct(PNG_LIBPNG_VER_STRING, c, png_ctx_error, png_ctx_warning);
        c->info = c->png ? png_create_info_struct(c->png) : NULL;
        if (!c->info)
            rc = td_err_set(err, TD_ENOMEM, "%s: out of memory for libpng", c->path);
    }
    return rc;
}

/* The channels of the transformed layout, or a refusal naming what the file has. */
static td_status png_channels(const char *path, td_dem_encoding enc, int depth, int ctype,
                              int *channels, td_err *err)
{
    td_status rc = TD_OK;
    if (enc == TD_ENC_GRAY16) {
        if (depth != 16 || (ctype != PNG_COLOR_TYPE_GRAY && ctype != PNG_COLOR_TYPE_GRAY_ALPHA))
            rc = td_err_set(err, TD_EFORMAT,
                            "%s: encoding gray16 needs a 16-bit grayscale PNG, this one has %d-bit %s",
                            path, depth, ctype == PNG_COLOR_TYPE_PALETTE ? "palette" :
                            ctype & PNG_COLOR_MASK_COLOR ? "colour" : "grayscale");
        else
            *channels = ctype == PNG_COLOR_TYPE_GRAY ? 1 : 2;
    } else {
        if (depth != 8 || (ctype != PNG_COLOR_TYPE_RGB && ctype != PNG_COLOR_TYPE_RGB_ALPHA))
            rc = td_err_set(err, TD_EFORMAT,
                            "%s: encoding %s needs an 8-bit RGB, RGBA or palette PNG, this one has %d-bit %s%s",
                            path, td_dem_encoding_name(enc), depth,
                            ctype & PNG_COLOR_MASK_COLOR ? "colour" : "grayscale",
                            ctype & PNG_COLOR_MASK_ALPHA ? " with alpha" : "");
        else
            *channels = ctype == PNG_COLOR_TYPE_RGB ? 3 : 4;
    }
    return rc;
}

/* IHDR: the size within the limits, then the transformations to one layout per encoding
 * (palette to RGB, tRNS to alpha, interlace handling). libpng's errors longjmp to the
 * setjmp in load. */
static td_status png_header(png_ctx *c, const td_dem_opts *o, const png_params *p, png_shape *s,
                            td_err *err)
{
    td_status rc;
    png_uint_32 w = 0, h = 0;
    int depth = 0, ctype = 0, interlace = 0;

    /* libpng's own size limits (default 1e6) would refuse big IHDRs as "invalid"; lift them
       to the format's maximum so that our check below refuses them as too big, by name.
       png_read_info allocates nothing per row or pixel. */
    png_set_user_limits(c->png, 0x7fffffffu, 0x7fffffffu);
    png_init_io(c->png, c->f);
    png_set_sig_bytes(c->png, 8);
    png_read_info(c->png, c->info);
    png_get_IHDR(c->png, c->info, &w, &h, &depth, &ctype, &interlace, NULL, NULL);
    s->w = (int32_t)w;
    s->h = (int32_t)h;
    s->interlaced = interlace != PNG_INTERLACE_NONE;
    rc = td_demutil_check_limits(c->path, o, s->w, s->h, err);
    if (rc != TD_OK)
        goto out;
    if (p->enc != TD_ENC_GRAY16 && depth <= 8 && ctype == PNG_COLOR_TYPE_PALETTE)
        png_set_palette_to_rgb(c->png);
    if (p->enc != TD_ENC_GRAY16 && depth == 8 && (ctype & PNG_COLOR_MASK_COLOR) &&
        png_get_valid(c->png, c->info, PNG_INFO_tRNS))
        png_set_tRNS_to_alpha(c->png);
    if (s->interlaced)
        (void)png_set_interlace_handling(c->png);
    png_read_update_info(c->png, c->info);
    depth = png_get_bit_depth(c->png, c->info);
    ctype = png_get_color_type(c->png, c->info);
    rc = png_channels(c->path, p->enc, depth, ctype, &s->channels, err);
    if (rc == TD_OK &&
        png_get_rowbytes(c->png, c->info) != (size_t)w * (size_t)s->channels * (size_t)(depth / 8))
        rc = td_err_set(err, TD_EFORMAT, "%s: unexpected row size", c->path);
out:
    return rc;
}

/* Everything from the sidecar to the last row, into c->g; the caller frees what c holds.
 * Only rc is written after setjmp and read after a longjmp. */
static td_status load(png_ctx *c, const td_dem_opts *o, td_err *err)
{
    td_status rc;
    const char *path = c->path;
    td_demside sc;
    png_params p;
    png_shape s;
    double sx = 0, sy = 0;

    rc = td_demutil_sidecar_read(path, 0, 0, &sc, err);
    if (rc == TD_OK)
        rc = resolve_params(path, o, &sc, &p, err);
    if (rc == TD_OK)
        rc = png_open(c, err);
    if (rc != TD_OK)
        goto out;
    if (setjmp(c->jmp)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: corrupt or truncated PNG (libpng: %s)", path, c->msg);
        goto out;
    }
    rc = png_header(c, o, &p, &s, err);
    if (rc == TD_OK)
        rc = td_demutil_side_georef(path, o, &sc, s.w, s.h, &sx, &sy, err);
    if (rc == TD_OK)
        rc = td_demutil_create(path, o, s.w, s.h, sx, sy, &sc.geo, &c->g, err);
    if (rc == TD_OK)
        rc = read_pixels(c, o, &p, &s, err);
    if (rc == TD_OK)
        png_read_end(c->png, NULL);
out:
    return rc;
}

td_status td_dempng_load(const char *path, const td_dem_opts *o, td_grid **out, td_err *err)
{
    td_status rc;
    td_grid *g = NULL;
    png_ctx *c = calloc(1, sizeof *c);

    if (!c) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory", path);
    } else {
        c->path = path;
        rc = load(c, o, err);
        if (c->png)
            png_destroy_read_struct(&c->png, c->info ? &c->info : NULL, NULL);
        if (c->f)
            fclose(c->f);
        free(c->row);
        free(c->rows);
        g = c->g;
        free(c);
    }
    return td_demutil_deliver(path, rc, g, out, err);
}
