/* fuzz_raw.c: raw float32 + JSON sidecar (core/demraw.c, the sidecar reader of
 * core/demutil.c). The first two bytes (little-endian) give the sidecar's length L; the
 * next L bytes are r.json, the rest r.f32. */
#include "dem.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char p[600], q[600];
    size_t len;
    td_dem_opts o;
    td_grid *g = NULL;
    td_err err;
    td_status rc;

    if (size < 2)
        return 0;
    len = (size_t)data[0] | (size_t)data[1] << 8;
    if (len > size - 2)
        len = size - 2;
    fuzz_write("r.json", data + 2, len, q, sizeof q);
    fuzz_write("r.f32", data + 2 + len, size - 2 - len, p, sizeof p);
    td_dem_opts_default(&o);
    o.limits.max_bytes = FUZZ_BUDGET_BYTES;
    rc = td_dem_load(p, &o, &g, &err);
    fuzz_report("raw", rc, err.msg);
    td_grid_free(g);
    return 0;
}
