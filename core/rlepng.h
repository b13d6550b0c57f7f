/* rlepng.h: an 8-bit gray PNG of an image made of long runs of equal bytes (a viewshed:
 * 0, 255 and 128 in large areas), written without libpng.
 *
 * What zlib's Z_RLE strategy would write (each run of equal bytes of the unfiltered rows a
 * literal and copies at distance 1), but the runs found 8 bytes at a time instead of one,
 * and the zlib stream's adler32 summed a run at a time in closed form: trinidad's
 * viewshed (2401 x 1201) took 6.5-7 ms through libpng and zlib, most of it Z_RLE's scan
 * byte by byte. The codes are Huffman codes made for the image (one dynamic deflate
 * block), so the file stays about as small as zlib's (the fixed codes, tried on
 * 2026-11-30, made trinidad's 91 kB 225 kB). Called by server/viewshed.c
 * (td_vs_encode: the service's and the CLI's viewshed picture); tested by decoding
 * (tests/unit/test_rlepng.c). */
#ifndef TD_RLEPNG_H
#define TD_RLEPNG_H

#include <stdint.h>

#include "image.h"
#include "status.h"

/* The PNG (8-bit gray, no filter, no interlace) of px's height rows of width bytes, row 0
 * on top, into *out (td_buf_free). TD_ERANGE for an empty or oversized image, TD_ENOMEM. */
td_status td_rlepng_gray8(const uint8_t *px, int32_t width, int32_t height, td_buf *out,
                          td_err *err);

#endif
