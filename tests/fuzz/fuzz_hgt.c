/* fuzz_hgt.c: the SRTM .hgt loader (core/demhgt.c). A tile must be exactly 1201^2 or 3601^2
 * int16 samples, which no fuzzer input is, so the first byte chooses: bit 0 set, the rest
 * of the input repeated to fill a 1201 x 1201 tile (the samples' decoding and the grid's
 * finishing); clear, the rest as the whole file (the size checks). Bit 1 set takes the
 * next 7 bytes as the name before ".hgt" (the name parser), else N37W105.hgt. */
#include <stdlib.h>
#include <string.h>

#include "dem.h"
#include "fuzz.h"

#define HGT_BYTES ((size_t)1201 * 1201 * 2)

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char name[16] = "N37W105.hgt", p[600];
    uint8_t mode = size ? data[0] : 0;
    const uint8_t *rest = size ? data + 1 : data;
    size_t n = size ? size - 1 : 0;
    td_dem_opts o;
    td_grid *g = NULL;
    td_err err;
    td_status rc;

    if ((mode & 2) && n >= 7) {
        for (int k = 0; k < 7; k++)
            name[k] = rest[k] == '/' || rest[k] == 0 ? '_' : (char)rest[k];
        rest += 7;
        n -= 7;
    }
    if (mode & 1) {
        uint8_t *tile = calloc(HGT_BYTES, 1);
        if (!tile)
            abort();
        for (size_t k = 0; n && k < HGT_BYTES; k += n)
            memcpy(tile + k, rest, HGT_BYTES - k < n ? HGT_BYTES - k : n);
        fuzz_write(name, tile, HGT_BYTES, p, sizeof p);
        free(tile);
    } else {
        fuzz_write(name, rest, n, p, sizeof p);
    }
    td_dem_opts_default(&o);
    o.limits.max_bytes = FUZZ_BUDGET_BYTES;
    rc = td_dem_load(p, &o, &g, &err);
    fuzz_report("hgt", rc, err.msg);
    td_grid_free(g);
    fuzz_remove(name);
    return 0;
}
