/* image.h: encoding rendered buffers (RGBA8 PNG, 16-bit depth PNG, raw float32 depth)
 * into memory, and decoding a PNG into RGB8 for texture drapes.
 *
 * Encoding is set for speed: deflate level 1 (libdeflate's, image.c says why) and the
 * `sub` filter only (rendered terrain is smooth horizontally, so `sub` roughly halves
 * the size of `none` for a few percent of the time; adaptive filtering costs several
 * times more and gains little at level 1). Output goes to a growable buffer owned by
 * the caller (td_buf_free). */
#ifndef TD_IMAGE_H
#define TD_IMAGE_H

#include <stdint.h>
#include <stddef.h>

#include "status.h"

typedef struct td_buf {
    uint8_t *data;
    size_t len, cap;
} td_buf;

void td_buf_free(td_buf *b);

/* An 8-bit image with 3 (RGB) or 4 (RGBA) channels, rows top to bottom. */
typedef struct td_image8 {
    int32_t width, height;
    int channels;
    uint8_t *px; /* width*height*channels */
} td_image8;

/* RGBA8, rows top to bottom, straight (not premultiplied) alpha. */
td_status td_image_encode_rgba(const uint8_t *rgba, int32_t width, int32_t height, td_buf *out,
                               td_err *err);

/* 16-bit grayscale PNG. When key is non-NULL a tEXt chunk key=value is added (the depth
 * scale, so a reader can turn units back into metres). */
td_status td_image_encode_gray16(const uint16_t *v, int32_t width, int32_t height,
                                 const char *key, const char *value, td_buf *out, td_err *err);

/* 8-bit grayscale PNG, rows top to bottom (viewsheds: three values in large areas). Set
 * for such images: zlib's run-length strategy and no filter, against level 1 with `sub`
 * on trinidad's viewshed (2.9 M pixels) 6.4 against 9.6 ms and 91 against 184 kB. */
td_status td_image_encode_gray8(const uint8_t *v, int32_t width, int32_t height, td_buf *out,
                                td_err *err);

/* Raw little-endian float32, width*height values, rows top to bottom. */
td_status td_image_encode_f32(const float *v, int32_t width, int32_t height, td_buf *out,
                              td_err *err);

/* Decodes any PNG (gray, palette, RGB, RGBA, 8 or 16 bit) to 8-bit RGB (channels 3) or
 * RGBA (channels 4), refusing images over max_pixels before allocating. From a file or
 * from memory. */
td_status td_image_load(const char *path, int channels, uint64_t max_pixels, td_image8 **out,
                        td_err *err);
td_status td_image_decode(const uint8_t *data, size_t len, int channels, uint64_t max_pixels,
                          td_image8 **out, td_err *err);
void td_image_free(td_image8 *img);

#endif
