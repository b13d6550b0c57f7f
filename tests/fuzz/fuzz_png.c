/* fuzz_png.c: the PNG loader (core/dempng.c): every encoding, plain, palette, tRNS and
 * Adam7-interlaced files. The first byte chooses the encoding (bits 0-1: gray16,
 * terrain-rgb, terrarium, rgb-div), bit 2 a nodata value (the second byte), bit 3 a
 * spacing from the options (else the loader must refuse or find one); the rest is the
 * PNG file. */
#include "dem.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const td_dem_encoding enc[4] = {TD_ENC_GRAY16, TD_ENC_TERRAIN_RGB, TD_ENC_TERRARIUM,
                                           TD_ENC_RGB_DIV};
    char p[600];
    td_dem_opts o;
    td_grid *g = NULL;
    td_err err;
    td_status rc;
    uint8_t mode;

    if (size < 2)
        return 0;
    mode = data[0];
    fuzz_write("g.png", data + 2, size - 2, p, sizeof p);
    td_dem_opts_default(&o);
    o.limits.max_bytes = FUZZ_BUDGET_BYTES;
    o.encoding = enc[mode & 3];
    o.has_nodata = (mode & 4) != 0;
    o.nodata = data[1];
    if (!(mode & 8))
        o.spacing[0] = o.spacing[1] = 30.0;
    rc = td_dem_load(p, &o, &g, &err);
    fuzz_report("png", rc, err.msg);
    td_grid_free(g);
    return 0;
}
