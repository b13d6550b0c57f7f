/* test_image.c: encodings (core/image.c): RGBA8 PNG and 16-bit depth PNG decode back to
 * the same values (read with libpng directly, not with our decoder), the depth PNG
 * carries its scale, images a row or a column wide and the viewshed's 8-bit gray round
 * trip too, the fast settings (deflate level 1 is smaller than none, no interlace), raw float32 is little-endian; decoding refuses garbage and oversize
 * images before allocating. */
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "image.h"

typedef struct reader {
    const uint8_t *p;
    size_t len, off;
} reader;

static void read_cb(png_structp png, png_bytep out, png_size_t n)
{
    reader *r = png_get_io_ptr(png);
    if (r->off + n > r->len)
        png_error(png, "short");
    memcpy(out, r->p + r->off, n);
    r->off += n;
}

/* Decodes a PNG with libpng's low-level API: width, height, depth, colour type and the
 * raw rows (16-bit samples big-endian, as stored). */
static uint8_t *raw_decode(const td_buf *b, png_uint_32 *w, png_uint_32 *h, int *depth,
                           int *ctype, char *text, size_t cap)
{
    reader r = {b->data, b->len, 0};
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    uint8_t *volatile px = NULL;
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, NULL);
        free(px);
        return NULL;
    }
    png_set_read_fn(png, &r, read_cb);
    png_read_info(png, info);
    int interlace;
    png_get_IHDR(png, info, w, h, depth, ctype, &interlace, NULL, NULL);
    assert_int_equal(interlace, PNG_INTERLACE_NONE);
    size_t rb = png_get_rowbytes(png, info);
    px = malloc(rb * *h);
    for (png_uint_32 y = 0; y < *h; y++)
        png_read_row(png, px + y * rb, NULL);
    png_read_end(png, info);
    png_textp t;
    int nt = 0;
    text[0] = 0;
    if (png_get_text(png, info, &t, &nt) > 0 && nt > 0)
        snprintf(text, cap, "%s=%s", t[0].key, t[0].text);
    png_destroy_read_struct(&png, &info, NULL);
    return px;
}

static void test_rgba_round_trip(void **state)
{
    const int32_t W = 37, H = 23;
    uint8_t *img = malloc((size_t)W * H * 4);
    td_buf b;
    td_err err = {0};
    png_uint_32 w, h;
    int depth, ctype;
    char text[64];
    (void)state;
    for (int i = 0; i < W * H * 4; i++)
        img[i] = (uint8_t)((i * 37) ^ (i >> 3));
    assert_int_equal(td_image_encode_rgba(img, W, H, &b, &err), TD_OK);
    assert_true(b.len > 8 && !memcmp(b.data, "\x89PNG", 4));
    uint8_t *px = raw_decode(&b, &w, &h, &depth, &ctype, text, sizeof text);
    assert_non_null(px);
    assert_int_equal(w, W);
    assert_int_equal(h, H);
    assert_int_equal(depth, 8);
    assert_int_equal(ctype, PNG_COLOR_TYPE_RGBA);
    assert_memory_equal(px, img, (size_t)W * H * 4);
    /* and our own decoder agrees */
    td_image8 *d = NULL;
    assert_int_equal(td_image_decode(b.data, b.len, 4, 1u << 20, &d, &err), TD_OK);
    assert_int_equal(d->width, W);
    assert_int_equal(d->channels, 4);
    assert_memory_equal(d->px, img, (size_t)W * H * 4);
    td_image_free(d);
    /* RGB decoding drops alpha */
    assert_int_equal(td_image_decode(b.data, b.len, 3, 1u << 20, &d, &err), TD_OK);
    assert_int_equal(d->channels, 3);
    td_image_free(d);
    free(px);
    td_buf_free(&b);
    free(img);
}

/* Images a row or a column wide (libdeflate's path filters each row from its second
 * pixel on: a row of one pixel is its filter byte and the pixel) and the viewshed's flat
 * 8-bit gray (libpng's zlib), each read back whole by libpng, which checks every chunk's
 * CRC and the IEND after the data. */
static void test_thin_images_and_gray8(void **state)
{
    const int32_t sizes[][2] = {{1, 1}, {1, 5}, {5, 1}, {2, 3}, {300, 2}};
    td_err err = {0};
    char text[64];
    (void)state;
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        const int32_t W = sizes[k][0], H = sizes[k][1];
        uint8_t img[300 * 5 * 4], g8[300 * 5];
        uint16_t g16[300 * 5];
        td_buf b;
        png_uint_32 w, h;
        int depth, ctype;
        for (int i = 0; i < W * H * 4; i++)
            img[i] = (uint8_t)(i * 53 + 11 * (int)k);
        for (int i = 0; i < W * H; i++) {
            g8[i] = (uint8_t)(i % 3 == 0 ? 255 : (i % 3 == 1 ? 0 : 128));
            g16[i] = (uint16_t)(i * 4099 + 3);
        }
        assert_int_equal(td_image_encode_rgba(img, W, H, &b, &err), TD_OK);
        uint8_t *px = raw_decode(&b, &w, &h, &depth, &ctype, text, sizeof text);
        assert_non_null(px);
        assert_true(w == (png_uint_32)W && h == (png_uint_32)H && depth == 8 && ctype == PNG_COLOR_TYPE_RGBA);
        assert_memory_equal(px, img, (size_t)W * H * 4);
        free(px);
        td_buf_free(&b);
        assert_int_equal(td_image_encode_gray16(g16, W, H, NULL, NULL, &b, &err), TD_OK);
        px = raw_decode(&b, &w, &h, &depth, &ctype, text, sizeof text);
        assert_non_null(px);
        assert_true(depth == 16 && ctype == PNG_COLOR_TYPE_GRAY && text[0] == 0);
        for (int i = 0; i < W * H; i++)
            assert_int_equal((px[2 * i] << 8) | px[2 * i + 1], g16[i]);
        free(px);
        td_buf_free(&b);
        assert_int_equal(td_image_encode_gray8(g8, W, H, &b, &err), TD_OK);
        px = raw_decode(&b, &w, &h, &depth, &ctype, text, sizeof text);
        assert_non_null(px);
        assert_true(depth == 8 && ctype == PNG_COLOR_TYPE_GRAY);
        assert_memory_equal(px, g8, (size_t)W * H);
        free(px);
        td_buf_free(&b);
    }
}

static void test_fast_settings_compress(void **state)
{
    /* a smooth gradient: level 1 + sub must be well under the raw size */
    const int32_t W = 256, H = 128;
    uint8_t *img = malloc((size_t)W * H * 4);
    td_buf b;
    td_err err = {0};
    (void)state;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            uint8_t *p = img + 4 * ((size_t)y * W + x);
            p[0] = (uint8_t)x;
            p[1] = (uint8_t)(y * 2);
            p[2] = 128;
            p[3] = 255;
        }
    assert_int_equal(td_image_encode_rgba(img, W, H, &b, &err), TD_OK);
    assert_true(b.len < (size_t)W * H * 4 / 8);
    td_buf_free(&b);
    free(img);
}

static void test_gray16_and_scale(void **state)
{
    const int32_t W = 19, H = 11;
    uint16_t v[19 * 11];
    td_buf b;
    td_err err = {0};
    png_uint_32 w, h;
    int depth, ctype;
    char text[64];
    (void)state;
    for (int i = 0; i < W * H; i++)
        v[i] = (uint16_t)(i * 311 + 7);
    v[5] = 65535;
    assert_int_equal(td_image_encode_gray16(v, W, H, "depth_scale_m", "0.25", &b, &err), TD_OK);
    uint8_t *px = raw_decode(&b, &w, &h, &depth, &ctype, text, sizeof text);
    assert_non_null(px);
    assert_int_equal(depth, 16);
    assert_int_equal(ctype, PNG_COLOR_TYPE_GRAY);
    assert_string_equal(text, "depth_scale_m=0.25");
    for (int i = 0; i < W * H; i++)
        assert_int_equal((px[2 * i] << 8) | px[2 * i + 1], v[i]);
    free(px);
    td_buf_free(&b);
}

static void test_f32_little_endian(void **state)
{
    float v[3] = {1.0f, -2.5f, INFINITY};
    td_buf b;
    td_err err = {0};
    (void)state;
    assert_int_equal(td_image_encode_f32(v, 3, 1, &b, &err), TD_OK);
    assert_int_equal(b.len, 12);
    static const uint8_t want[12] = {0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x20, 0xc0,
                                     0x00, 0x00, 0x80, 0x7f};
    assert_memory_equal(b.data, want, 12);
    td_buf_free(&b);
}

static void test_decode_refusals(void **state)
{
    td_image8 *d = (td_image8 *)0x1;
    td_err err = {0};
    uint8_t junk[64];
    uint8_t img[16 * 16 * 4];
    td_buf b;
    (void)state;
    memset(junk, 0x5a, sizeof junk);
    assert_int_equal(td_image_decode(junk, sizeof junk, 3, 1u << 20, &d, &err), TD_EFORMAT);
    assert_null(d);
    memset(img, 200, sizeof img);
    assert_int_equal(td_image_encode_rgba(img, 16, 16, &b, &err), TD_OK);
    /* 256 pixels over a limit of 255 */
    assert_int_equal(td_image_decode(b.data, b.len, 3, 255, &d, &err), TD_ETOOBIG);
    assert_null(d);
    /* truncated */
    assert_int_not_equal(td_image_decode(b.data, b.len / 2, 3, 1u << 20, &d, &err), TD_OK);
    assert_null(d);
    assert_int_equal(td_image_load("/nonexistent/x.png", 3, 1u << 20, &d, &err), TD_EFORMAT);
    assert_non_null(strstr(err.msg, "/nonexistent/x.png"));
    td_buf_free(&b);
    assert_int_equal(td_image_encode_rgba(img, 0, 16, &b, &err), TD_ERANGE);
    assert_null(b.data);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_rgba_round_trip),
        cmocka_unit_test(test_thin_images_and_gray8),
        cmocka_unit_test(test_fast_settings_compress),
        cmocka_unit_test(test_gray16_and_scale),
        cmocka_unit_test(test_f32_little_endian),
        cmocka_unit_test(test_decode_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
