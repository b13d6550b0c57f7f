/* image.c: PNG and raw encodings of rendered buffers, PNG decoding for drapes and tests
 * (see image.h for the settings and why).
 *
 * Writing uses libpng's full API (the simplified png_image_write_to_memory cannot set
 * the zlib level: its FAST flag means level 3 and no filter), with a write callback
 * that grows a td_buf. libpng reports errors by longjmp: everything that must survive
 * the jump lives in a struct the handler can reach, and the one exit frees it.
 *
 * The image data of RGBA and 16-bit images is deflated by libdeflate, not by libpng's
 * zlib: the rows are filtered here (`sub`, what libpng's PNG_FILTER_SUB writes), the
 * whole stream compressed in one call, and written as IDAT chunks between libpng's IHDR
 * (and tEXt) and IEND (png_write_chunk). Level 1, or 2 where more than 65% of the
 * filtered rows' 8-byte words are 0 (a pixel like the one before it, twice: a sky, flat
 * colour, a map tile mostly outside the data): libdeflate's level 1 inserts every
 * position of a run into its hash table, 256 KiB of zeros 0.70 ms against 0.30 ms at
 * level 2, while level 2 is slower on textured images (the gallery's hillshade 3.9 ->
 * 6.0 ms). Of 14 renders and tiles the threshold picks the faster level for each, or
 * one within 1% (the labelled panorama's 0.67, the sunset's 0.59).
 * Measured on 2026-12-02 (one thread, the shared 2-core VM, terrad's malloc policy;
 * best of 3 x 20, zlib level 1 -> libdeflate): 256 x 256 map tiles, shaded 1.15 -> 0.82
 * ms, terrain-rgb 1.81 -> 0.94 ms (53.4 -> 48.2 kB), terrarium 2.17 -> 1.28 ms; a
 * 512 x 512 render with sky and haze 3.63 -> 2.96 ms (84.7 -> 67.8 kB); the gallery's
 * 480 x 502 hillshade 8.03 -> 4.24 ms (266.8 -> 244.0 kB), its 1800 x 300 panorama 10.66
 * -> 8.40 ms; tiles mostly or wholly outside the data 0.93-1.08x (0.38 -> 0.41 ms for
 * none at all), smaller. The viewsheds' flat
 * gray images stay with zlib's run-length strategy, which libdeflate does not beat
 * (2401 x 1201: 7.6 ms and 91 kB against 9.5 ms and 131 kB at level 1). The whole
 * filtered image is held once, plus the compressed bound: a 4-megapixel RGBA render
 * about 32 MB for the call.
 * Reading uses the simplified API (png_image_*), which converts every colour type. */
#include "image.h"

#include <libdeflate.h>
#include <png.h>
#include <setjmp.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

void td_buf_free(td_buf *b)
{
    if (b) {
        free(b->data);
        b->data = NULL;
        b->len = b->cap = 0;
    }
}

static int buf_append(td_buf *b, const uint8_t *p, size_t n)
{
    int ok = 1;
    size_t need;
    if (!td_add_size(b->len, n, &need)) {
        ok = 0;
    } else if (need > b->cap) {
        size_t cap = b->cap ? b->cap : 65536;
        while (cap < need && cap < SIZE_MAX / 2)
            cap *= 2;
        if (cap < need)
            cap = need;
        uint8_t *q = realloc(b->data, cap);
        if (!q) {
            ok = 0;
        } else {
            b->data = q;
            b->cap = cap;
        }
    }
    if (ok) {
        memcpy(b->data + b->len, p, n);
        b->len = need;
    }
    return ok;
}

typedef struct png_sink {
    td_buf *buf;
    int oom;
} png_sink;

static void sink_write(png_structp png, png_bytep data, png_size_t n)
{
    png_sink *s = png_get_io_ptr(png);
    if (!buf_append(s->buf, data, n)) {
        s->oom = 1;
        png_error(png, "out of memory");
    }
}

static void sink_flush(png_structp png) { (void)png; }

static void on_png_error(png_structp png, png_const_charp msg)
{
    char *dst = png_get_error_ptr(png);
    if (dst) {
        strncpy(dst, msg, 127);
        dst[127] = 0;
    }
    png_longjmp(png, 1);
}

#define TD_IDAT_MAX ((size_t)0x7fffffff)

static void on_png_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

/* The image's rows as PNG's filtered stream into dst ((rowbytes + 1) * height bytes):
 * each row its filter byte (1: sub) and each byte less the one bpp bytes before it (0
 * before the row's first pixel); 16-bit samples big-endian first. Returns how many of
 * each row's whole 8-byte words of filtered bytes are 0 (runs: deflate_image's choice of
 * level), in *words how many there are. */
static size_t filter_sub(const void *pixels, int32_t width, int32_t height, int bit_depth, int channels,
                         size_t rowbytes, uint8_t *restrict dst, size_t *words)
{
    const size_t bpp = (size_t)channels * (size_t)(bit_depth / 8);
    size_t zeros = 0;
    *words = rowbytes / 8 * (size_t)height;
    for (int32_t y = 0; y < height; y++) {
        uint8_t *restrict d = dst + (size_t)y * (rowbytes + 1);
        d[0] = 1;
        d++;
        if (bit_depth == 16) { /* big-endian in place, then the differences from the end */
            const uint16_t *s16 = (const uint16_t *)pixels + (size_t)y * (size_t)width * (size_t)channels;
            for (size_t x = 0; x < (size_t)width * (size_t)channels; x++) {
                d[2 * x] = (uint8_t)(s16[x] >> 8);
                d[2 * x + 1] = (uint8_t)(s16[x] & 0xff);
            }
            for (size_t i = rowbytes; i-- > bpp;)
                d[i] = (uint8_t)(d[i] - d[i - bpp]);
        } else {
            const uint8_t *restrict s = (const uint8_t *)pixels + (size_t)y * rowbytes;
            memcpy(d, s, bpp < rowbytes ? bpp : rowbytes);
            for (size_t i = bpp; i < rowbytes; i++)
                d[i] = (uint8_t)(s[i] - s[i - bpp]);
        }
        for (size_t i = 0; i + 8 <= rowbytes; i += 8) {
            uint64_t u;
            memcpy(&u, d + i, 8);
            zeros += u == 0;
        }
    }
    return zeros;
}

/* The image data's zlib stream (libdeflate, level 1 or 2) of a non-flat image: *z (malloc'd,
 * *zlen bytes), or TD_ENOMEM / TD_ERANGE. */
static td_status deflate_image(const void *pixels, int32_t width, int32_t height, int bit_depth,
                               int channels, size_t rowbytes, uint8_t **z, size_t *zlen, td_err *err)
{
    td_status rc = TD_OK;
    struct libdeflate_compressor *c = NULL;
    uint8_t *f = NULL;
    size_t n = 0, bound;
    *z = NULL;
    *zlen = 0;
    if (!td_mul_size(rowbytes + 1, (size_t)height, &n)) {
        rc = td_err_set(err, TD_ERANGE, "image: %d x %d pixels cannot be encoded", (int)width, (int)height);
        goto out;
    }
    f = malloc(n);
    if (f) { /* mostly runs (sky, flat colour, no data): level 2 (the top of the file) */
        size_t words, zeros = filter_sub(pixels, width, height, bit_depth, channels, rowbytes, f, &words);
        c = libdeflate_alloc_compressor(zeros > words / 20 * 13 ? 2 : 1);
    }
    bound = c ? libdeflate_zlib_compress_bound(c, n) : 0;
    *z = c ? malloc(bound) : NULL;
    if (!*z) {
        rc = td_err_set(err, TD_ENOMEM, "image: no memory to compress %zu bytes", n);
        goto out;
    }
    *zlen = libdeflate_zlib_compress(c, f, n, *z, bound);
    if (*zlen == 0) /* not expected: the bound is libdeflate's own */
        rc = td_err_set(err, TD_EIO, "image: compression failed");
out:
    if (rc != TD_OK) {
        free(*z);
        *z = NULL;
    }
    libdeflate_free_compressor(c);
    free(f);
    return rc;
}

/* bit_depth 8 with 4 or 1 channels, or 16 with 1 channel. `flat`: an image of a few
 * values in large areas (image.h's gray8), deflated by libpng's zlib; the others by
 * deflate_image (the top of the file). */
static td_status encode(const void *pixels, int32_t width, int32_t height, int color_type,
                        int bit_depth, int channels, const char *key, const char *value,
                        int flat, td_buf *out, td_err *err)
{
    volatile td_status rc = TD_OK; /* set after a longjmp */
    char msg[128] = "";
    png_sink sink = {out, 0};
    png_structp png = NULL;
    png_infop info = NULL;
    uint8_t *volatile z = NULL; /* the image data's zlib stream (not flat), zlen bytes */
    volatile size_t zlen = 0;
    size_t bpp = (size_t)channels * (size_t)(bit_depth / 8), rowbytes;

    memset(out, 0, sizeof *out);
    if (width < 1 || height < 1 || !td_mul_size((size_t)width, bpp, &rowbytes)) {
        rc = td_err_set(err, TD_ERANGE, "image: %d x %d pixels cannot be encoded", (int)width,
                        (int)height);
        goto out;
    }
    png = png_create_write_struct(PNG_LIBPNG_VER_STRING, msg, on_png_error, on_png_warning);
    if (png)
        info = png_create_info_struct(png);
    if (!png || !info) {
        rc = td_err_set(err, TD_ENOMEM, "image: cannot create the PNG encoder");
        goto out;
    }
    if (!flat) {
        uint8_t *zd;
        size_t zn;
        rc = deflate_image(pixels, width, height, bit_depth, channels, rowbytes, &zd, &zn, err);
        z = zd;
        zlen = zn;
        if (rc)
            goto out;
    }
    if (setjmp(png_jmpbuf(png))) {
        rc = td_err_set(err, sink.oom ? TD_ENOMEM : TD_EIO, "image: PNG encoding failed: %s", msg);
        goto out;
    }
    png_set_write_fn(png, &sink, sink_write, sink_flush);
    if (flat) { /* libpng's zlib deflates these rows */
        png_set_compression_level(png, 1);
        png_set_compression_strategy(png, Z_RLE);
        png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
    }
    png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, bit_depth, color_type,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (key && value) {
        png_text t;
        memset(&t, 0, sizeof t);
        t.compression = PNG_TEXT_COMPRESSION_NONE;
        t.key = (png_charp)key;
        t.text = (png_charp)value;
        png_set_text(png, info, &t, 1);
    }
    png_write_info(png, info);
    if (flat) {
        for (int32_t y = 0; y < height; y++)
            png_write_row(png, (png_const_bytep)pixels + (size_t)y * rowbytes);
        png_write_end(png, NULL);
    } else { /* the stream in chunks of at most 2^31 - 1 bytes (PNG's limit), then IEND */
        for (size_t at = 0; at < zlen; at += TD_IDAT_MAX)
            png_write_chunk(png, (png_const_bytep) "IDAT", z + at, zlen - at < TD_IDAT_MAX ? zlen - at : TD_IDAT_MAX);
        png_write_chunk(png, (png_const_bytep) "IEND", NULL, 0);
    }
out:
    if (png)
        png_destroy_write_struct(&png, info ? &info : NULL);
    free(z);
    if (rc)
        td_buf_free(out);
    return rc;
}

td_status td_image_encode_rgba(const uint8_t *rgba, int32_t width, int32_t height, td_buf *out,
                               td_err *err)
{
    return encode(rgba, width, height, PNG_COLOR_TYPE_RGBA, 8, 4, NULL, NULL, 0, out, err);
}

td_status td_image_encode_gray16(const uint16_t *v, int32_t width, int32_t height,
                                 const char *key, const char *value, td_buf *out, td_err *err)
{
    return encode(v, width, height, PNG_COLOR_TYPE_GRAY, 16, 1, key, value, 0, out, err);
}

td_status td_image_encode_gray8(const uint8_t *v, int32_t width, int32_t height, td_buf *out,
                                td_err *err)
{
    return encode(v, width, height, PNG_COLOR_TYPE_GRAY, 8, 1, NULL, NULL, 1, out, err);
}

td_status td_image_encode_f32(const float *v, int32_t width, int32_t height, td_buf *out,
                              td_err *err)
{
    td_status rc = TD_OK;
    size_t n, bytes;
    memset(out, 0, sizeof *out);
    if (width < 1 || height < 1 || !td_mul_size((size_t)width, (size_t)height, &n) ||
        !td_mul_size(n, 4, &bytes)) {
        rc = td_err_set(err, TD_ERANGE, "image: %d x %d pixels cannot be encoded", (int)width,
                        (int)height);
        goto out;
    }
    out->data = malloc(bytes);
    if (!out->data) {
        rc = td_err_set(err, TD_ENOMEM, "image: no memory for %zu bytes", bytes);
        goto out;
    }
    for (size_t i = 0; i < n; i++) {
        uint32_t u;
        memcpy(&u, &v[i], 4);
        out->data[4 * i] = (uint8_t)u;
        out->data[4 * i + 1] = (uint8_t)(u >> 8);
        out->data[4 * i + 2] = (uint8_t)(u >> 16);
        out->data[4 * i + 3] = (uint8_t)(u >> 24);
    }
    out->len = out->cap = bytes;
out:
    return rc;
}

static td_status finish_decode(png_image *pi, const char *what, int channels, uint64_t max_pixels,
                               td_image8 **out, td_err *err)
{
    td_status rc = TD_OK;
    td_image8 *img = NULL;
    size_t n, bytes;

    if (channels != 3 && channels != 4) {
        rc = td_err_set(err, TD_EINVAL, "%s: %d channels asked (3 or 4)", what, channels);
        goto out;
    }
    pi->format = channels == 4 ? PNG_FORMAT_RGBA : PNG_FORMAT_RGB;
    if ((uint64_t)pi->width * pi->height > max_pixels || pi->width > INT32_MAX ||
        pi->height > INT32_MAX) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: %u x %u pixels exceeds the limit of %llu", what,
                        (unsigned)pi->width, (unsigned)pi->height, (unsigned long long)max_pixels);
        goto out;
    }
    if (!td_mul_size(pi->width, pi->height, &n) || !td_mul_size(n, (size_t)channels, &bytes)) {
        rc = td_err_set(err, TD_ETOOBIG, "%s: image too large", what);
        goto out;
    }
    img = calloc(1, sizeof *img);
    if (img)
        img->px = malloc(bytes);
    if (!img || !img->px) {
        rc = td_err_set(err, TD_ENOMEM, "%s: no memory for %zu bytes", what, bytes);
        goto out;
    }
    img->width = (int32_t)pi->width;
    img->height = (int32_t)pi->height;
    img->channels = channels;
    if (!png_image_finish_read(pi, NULL, img->px, 0, NULL)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: %s", what, pi->message);
        goto out;
    }
out:
    png_image_free(pi);
    if (rc) {
        td_image_free(img);
        img = NULL;
    }
    *out = img;
    return rc;
}

td_status td_image_load(const char *path, int channels, uint64_t max_pixels, td_image8 **out,
                        td_err *err)
{
    td_status rc = TD_OK;
    png_image pi;
    memset(&pi, 0, sizeof pi);
    pi.version = PNG_IMAGE_VERSION;
    *out = NULL;
    if (!png_image_begin_read_from_file(&pi, path)) {
        rc = td_err_set(err, TD_EFORMAT, "%s: not a readable PNG: %s", path, pi.message);
        png_image_free(&pi);
        goto out;
    }
    rc = finish_decode(&pi, path, channels, max_pixels, out, err);
out:
    return rc;
}

td_status td_image_decode(const uint8_t *data, size_t len, int channels, uint64_t max_pixels,
                          td_image8 **out, td_err *err)
{
    td_status rc = TD_OK;
    png_image pi;
    memset(&pi, 0, sizeof pi);
    pi.version = PNG_IMAGE_VERSION;
    *out = NULL;
    if (!png_image_begin_read_from_memory(&pi, data, len)) {
        rc = td_err_set(err, TD_EFORMAT, "PNG in memory: %s", pi.message);
        png_image_free(&pi);
        goto out;
    }
    rc = finish_decode(&pi, "PNG in memory", channels, max_pixels, out, err);
out:
    return rc;
}

void td_image_free(td_image8 *img)
{
    if (img) {
        free(img->px);
        free(img);
    }
}
