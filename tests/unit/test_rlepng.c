/* test_rlepng.c: the run-length PNG writer (core/rlepng.c). Every image is read back two
 * ways: the concatenated IDATs inflated by zlib (which checks the adler32) must be the
 * rows each behind a filter byte 0, and libpng (td_image_decode, which checks every CRC)
 * must give the same pixels. Images: viewshed-like runs of 0, 128 and 255 across rows,
 * one pixel, one column, all zeros (one run through every filter byte), runs of the
 * lengths where the copies split (1 .. 3, 258 .. 261, 516, 517), noise (all 256 literals)
 * and literals counted in Fibonacci numbers (a Huffman tree deeper than deflate's 15
 * bits, which the writer must flatten). The viewshed-like image must also be about as
 * small as zlib's own run-length strategy makes it (within 3%). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>
#include <zlib.h>

#include "image.h"
#include "rlepng.h"

static uint32_t be32(const uint8_t *d)
{
    return (uint32_t)d[0] << 24 | (uint32_t)d[1] << 16 | (uint32_t)d[2] << 8 | d[3];
}

/* Encodes px, checks the container and both decodings; returns the PNG's size. */
static size_t check(const uint8_t *px, int32_t w, int32_t h)
{
    td_buf b;
    td_err err = {0};
    td_image8 *img = NULL;
    size_t n = (size_t)(w + 1) * (size_t)h, zlen = 0, at = 8;
    uint8_t *z = NULL, *raw = malloc(n + 1);
    uLongf got = (uLongf)n + 1;
    assert_int_equal(td_rlepng_gray8(px, w, h, &b, &err), TD_OK);
    assert_memory_equal(b.data, "\x89PNG\r\n\x1a\n", 8);
    assert_int_equal(be32(b.data + 16), (uint32_t)w);
    assert_int_equal(be32(b.data + 20), (uint32_t)h);
    assert_int_equal(b.data[24], 8); /* bit depth */
    assert_int_equal(b.data[25], 0); /* gray */
    z = malloc(b.len);
    while (at + 12 <= b.len) { /* the IDATs' data, in order */
        uint32_t len = be32(b.data + at);
        if (!memcmp(b.data + at + 4, "IDAT", 4)) {
            memcpy(z + zlen, b.data + at + 8, len);
            zlen += len;
        }
        at += 12 + (size_t)len;
    }
    assert_int_equal(at, b.len);
    assert_memory_equal(b.data + b.len - 12 + 4, "IEND", 4);
    assert_int_equal(uncompress(raw, &got, z, (uLong)zlen), Z_OK);
    assert_int_equal(got, n);
    for (int32_t y = 0; y < h; y++) {
        assert_int_equal(raw[(size_t)y * (size_t)(w + 1)], 0);
        assert_memory_equal(raw + (size_t)y * (size_t)(w + 1) + 1, px + (size_t)y * (size_t)w, (size_t)w);
    }
    assert_int_equal(td_image_decode(b.data, b.len, 3, (uint64_t)1 << 30, &img, &err), TD_OK);
    assert_int_equal(img->width, w);
    assert_int_equal(img->height, h);
    for (size_t k = 0; k < (size_t)w * (size_t)h; k++)
        assert_int_equal(img->px[3 * k], px[k]);
    td_image_free(img);
    free(z);
    free(raw);
    n = b.len;
    td_buf_free(&b);
    return n;
}

static uint32_t rng(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s >> 8;
}

/* zlib's size for the same rows: level 1, Z_RLE, as image.c's gray8 did. */
static size_t zlib_rle_size(const uint8_t *px, int32_t w, int32_t h)
{
    size_t n = (size_t)(w + 1) * (size_t)h;
    uint8_t *raw = malloc(n), *out = malloc(n + n / 100 + 1024);
    z_stream s;
    memset(&s, 0, sizeof s);
    for (int32_t y = 0; y < h; y++) {
        raw[(size_t)y * (size_t)(w + 1)] = 0;
        memcpy(raw + (size_t)y * (size_t)(w + 1) + 1, px + (size_t)y * (size_t)w, (size_t)w);
    }
    assert_int_equal(deflateInit2(&s, 1, Z_DEFLATED, 15, 8, Z_RLE), Z_OK);
    s.next_in = raw;
    s.avail_in = (uInt)n;
    s.next_out = out;
    s.avail_out = (uInt)(n + n / 100 + 1024);
    assert_int_equal(deflate(&s, Z_FINISH), Z_STREAM_END);
    n = s.total_out;
    deflateEnd(&s);
    free(raw);
    free(out);
    return n;
}

static void test_viewshed_like(void **state)
{
    (void)state;
    const int32_t w = 613, h = 301;
    uint8_t *px = malloc((size_t)w * h);
    static const uint8_t vals[3] = {0, 255, 128};
    uint32_t s = 7;
    for (size_t k = 0; k < (size_t)w * h;) { /* runs of 1 .. 1500 bytes, across rows */
        size_t run = 1 + rng(&s) % (rng(&s) % 4 ? 60 : 1500);
        uint8_t v = vals[rng(&s) % 3];
        for (; run > 0 && k < (size_t)w * h; run--)
            px[k++] = v;
    }
    size_t ours = check(px, w, h), theirs = zlib_rle_size(px, w, h) + 8 + 25 + 12 + 12;
    assert_true(ours <= theirs + theirs * 3 / 100);
    free(px);
}

static void test_small_shapes(void **state)
{
    (void)state;
    uint8_t one = 7, col[1000], zeros[500 * 40];
    memset(zeros, 0, sizeof zeros);
    for (int k = 0; k < 1000; k++)
        col[k] = k % 300 < 150 ? 0 : 9; /* a column: each row's filter byte between pixels */
    check(&one, 1, 1);
    check(col, 1, 1000);
    check(col, 1000, 1);
    check(zeros, 500, 40);
}

static void test_run_lengths(void **state)
{
    (void)state;
    static const int lens[] = {1, 2, 3, 4, 257, 258, 259, 260, 261, 262, 515, 516, 517, 518, 1, 2, 3};
    uint8_t px[8000];
    size_t k = 0;
    for (size_t i = 0; i < sizeof lens / sizeof lens[0]; i++)
        for (int j = 0; j < lens[i]; j++)
            px[k++] = (uint8_t)(i % 2 ? 255 : 1 + i);
    while (k < sizeof px)
        px[k++] = 128;
    check(px, 4000, 2);
    check(px, 80, 100);
}

static void test_noise(void **state)
{
    (void)state;
    uint8_t px[97 * 53];
    uint32_t s = 11;
    for (size_t k = 0; k < sizeof px; k++)
        px[k] = (uint8_t)rng(&s);
    check(px, 97, 53);
}

/* 24 byte values counted 1, 1, 2, 3, 5, ... (Fibonacci), arranged so no two neighbours are
 * equal (each the most frequent value left that differs from the one before): their
 * Huffman tree is 16 deep (with the filter bytes and the end of block), over deflate's
 * limit of 15: without the flattening the stream does not inflate (tried). */
static void test_deep_tree(void **state)
{
    (void)state;
    enum { K = 24 };
    size_t left[K], total = 0, k = 0;
    int prev = -1;
    for (int i = 0; i < K; i++) {
        left[i] = i < 2 ? 1 : left[i - 1] + left[i - 2];
        total += left[i];
    }
    uint8_t *px = malloc(total);
    for (; k < total; k++) {
        int best = -1;
        for (int i = 0; i < K; i++)
            if (i != prev && left[i] && (best < 0 || left[i] > left[best]))
                best = i;
        if (best < 0)
            best = prev; /* only the one before is left: a run */
        px[k] = (uint8_t)(10 * best + 3);
        left[best]--;
        prev = best;
    }
    check(px, (int32_t)total, 1);
    check(px, 1000, (int32_t)(total / 1000));
    free(px);
}

static void test_refusals(void **state)
{
    (void)state;
    td_buf b;
    td_err err = {0};
    uint8_t px = 0;
    assert_int_equal(td_rlepng_gray8(&px, 0, 1, &b, &err), TD_ERANGE);
    assert_int_equal(td_rlepng_gray8(&px, 1, 0, &b, &err), TD_ERANGE);
    assert_null(b.data);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_viewshed_like), cmocka_unit_test(test_small_shapes),
        cmocka_unit_test(test_run_lengths),   cmocka_unit_test(test_noise),
        cmocka_unit_test(test_deep_tree),     cmocka_unit_test(test_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
