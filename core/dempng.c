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
 * their south-based place; an interlaced PNG's Adam7 passes are read the same way, one pass
 * row at a time, each pixel decoded straight to its place in the grid (libpng's interlace
 * handling is not used: it would need the whole image in a buffer as large as the grid).
 * libpng reports errors by longjmp: everything the error path frees lives in a context
 * struct so no local is clobbered across setjmp.
 *
 * Memory follows the data, not the header: before the grid is allocated, IHDR's size is
 * checked against the limits, against what the file's bytes can decompress to (deflate
 * expands at most 1032:1, so a 51-byte file cannot hold 16000 x 16000 pixels), and the grid
 * together with the decode buffers (ours and libpng's rows) against the byte budget, so a
 * decompression bomb is refused by the budget with a message naming the file and sizes. */
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
    long long file_bytes;          /* the file's size, for the decompression bound */
    png_structp png;
    png_infop info;
    unsigned char *row;            /* one (pass) row of transformed pixels */
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

/* Decodes w raw pixels into heights dst[0], dst[step], ... Returns 0 if a height is not a
 * float. */
static int decode_row(const png_params *p, const unsigned char *src, int channels, int32_t w,
                      float *dst, size_t step)
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
            dst[(size_t)i * step] = NAN;
        else if (fabs(m) <= FLT_MAX)
            dst[(size_t)i * step] = (float)m;
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

/* Reads the pixels into the grid's south-based rows, one (pass) row at a time through
 * c->row. A plain PNG is one pass of every row and column; an interlaced one is Adam7's
 * seven passes, pass row r holding image row start_row + r*row_step at columns start_col,
 * start_col + col_step, ... (libpng skips empty passes as we do). */
static td_status read_pixels(png_ctx *c, const png_params *p, const png_shape *s, td_err *err)
{
    td_status rc = TD_OK;
    const int passes = s->interlaced ? 7 : 1;

    c->row = malloc(png_get_rowbytes(c->png, c->info));
    if (!c->row) {
        rc = td_err_set(err, TD_ENOMEM, "%s: out of memory for a row", c->path);
        goto out;
    }
    for (int pass = 0; pass < passes && rc == TD_OK; pass++) {
        uint32_t r0 = s->interlaced ? PNG_PASS_START_ROW(pass) : 0;
        uint32_t c0 = s->interlaced ? PNG_PASS_START_COL(pass) : 0;
        uint32_t rstep = s->interlaced ? 1u << PNG_PASS_ROW_SHIFT(pass) : 1;
        uint32_t cstep = s->interlaced ? 1u << PNG_PASS_COL_SHIFT(pass) : 1;
        uint32_t rows = s->interlaced ? PNG_PASS_ROWS((uint32_t)s->h, pass) : (uint32_t)s->h;
        uint32_t cols = s->interlaced ? PNG_PASS_COLS((uint32_t)s->w, pass) : (uint32_t)s->w;
        if (rows == 0 || cols == 0)
            continue;
        for (uint32_t k = 0; k < rows && rc == TD_OK; k++) {
            int32_t r = (int32_t)(r0 + k * rstep);
            png_read_row(c->png, c->row, NULL);
            if (!decode_row(p, c->row, s->channels, (int32_t)cols, td_demutil_file_row(c->g, r) + c0,
                            cstep))
                rc = td_err_set(err, TD_ERANGE, "%s: row %ld decodes to a height beyond float range",
                                c->path, (long)r);
        }
    }
out:
    return rc;
}

/* Opens the file, checks the signature and makes libpng's read and info structs. */
static td_status png_open(png_ctx *c, td_err *err)
{
    td_status rc;
    unsigned char sig[8];

    struct stat st;

    rc = td_demutil_open(c->path, &c->f, &st, err);
    if (rc == TD_OK)
        c->file_bytes = (long long)st.st_size;
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

/* Deflate expands at most 1032:1 (a 258-byte match in about 2 bits), whatever the encoder. */
#define TD_PNG_DEFLATE_RATIO 1032u

/* Can the file hold IHDR's pixels? They are at least w*h*bits/8 bytes once decompressed
 * (Adam7 or not; filter bytes come on top), which the file's bytes times deflate's largest
 * ratio must reach. A header claiming more is refused before anything is allocated. */
static td_status png_fits_file(const png_ctx *c, const png_shape *s, int depth, int ctype,
                               td_err *err)
{
    td_status rc = TD_OK;
    const unsigned chans = ctype == PNG_COLOR_TYPE_GRAY_ALPHA ? 2u :
                           ctype == PNG_COLOR_TYPE_RGB ? 3u :
                           ctype == PNG_COLOR_TYPE_RGB_ALPHA ? 4u : 1u;
    const uint64_t bits = (uint64_t)depth * chans;
    const uint64_t need = ((uint64_t)s->w * (uint64_t)s->h * bits + 7u) / 8u;
    const uint64_t most = (uint64_t)(c->file_bytes > 0 ? c->file_bytes : 0) * TD_PNG_DEFLATE_RATIO;
    if (need > most)
        rc = td_err_set(err, TD_EFORMAT,
                        "%s: its header claims %ld x %ld pixels of %llu bits (%llu bytes decompressed), "
                        "more than its %lld bytes can hold (at most %llu): truncated or corrupt",
                        c->path, (long)s->w, (long)s->h, (unsigned long long)bits,
                        (unsigned long long)need, c->file_bytes, (unsigned long long)most);
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
    if (rc == TD_OK)
        rc = png_fits_file(c, s, depth, ctype, err);
    if (rc != TD_OK)
        goto out;
    if (p->enc != TD_ENC_GRAY16 && depth <= 8 && ctype == PNG_COLOR_TYPE_PALETTE)
        png_set_palette_to_rgb(c->png);
    if (p->enc != TD_ENC_GRAY16 && depth == 8 && (ctype & PNG_COLOR_MASK_COLOR) &&
        png_get_valid(c->png, c->info, PNG_INFO_tRNS))
        png_set_tRNS_to_alpha(c->png);
    png_read_update_info(c->png, c->info);
    depth = png_get_bit_depth(c->png, c->info);
    ctype = png_get_color_type(c->png, c->info);
    rc = png_channels(c->path, p->enc, depth, ctype, &s->channels, err);
    if (rc == TD_OK &&
        png_get_rowbytes(c->png, c->info) != (size_t)w * (size_t)s->channels * (size_t)(depth / 8))
        rc = td_err_set(err, TD_EFORMAT, "%s: unexpected row size", c->path);
    /* our row and libpng's two (the row being unfiltered and the previous one), each
       a transformed row at most, with libpng's padding */
    if (rc == TD_OK)
        rc = td_demutil_check_budget(c->path, o, s->w, s->h,
                                     3u * ((uint64_t)png_get_rowbytes(c->png, c->info) + 64u),
                                     "decode buffers", err);
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
        rc = read_pixels(c, &p, &s, err);
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
        g = c->g;
        free(c);
    }
    return td_demutil_deliver(path, rc, g, out, err);
}
