/* fuzz_asc.c: the ESRI ASCII grid loader (core/demasc.c), with and without a .prj. The
 * input is the .asc's bytes, optionally followed by the line "%%PRJ%%" and the .prj's
 * bytes (written beside it as g.prj; without the marker there is no .prj). */
#define _GNU_SOURCE /* memmem, memrchr */
#include <string.h>

#include "dem.h"
#include "fuzz.h"

#define PRJ_MARK "\n%%PRJ%%\n"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char p[600], q[600];
    const uint8_t *mark = memmem(data, size, PRJ_MARK, sizeof PRJ_MARK - 1);
    size_t n = mark ? (size_t)(mark - data) : size;
    td_dem_opts o;
    td_grid *g = NULL;
    td_err err;
    td_status rc;

    if (mark)
        fuzz_write("g.prj", mark + sizeof PRJ_MARK - 1, size - n - (sizeof PRJ_MARK - 1), q, sizeof q);
    else
        fuzz_remove("g.prj");
    fuzz_write("g.asc", data, n, p, sizeof p);
    td_dem_opts_default(&o);
    o.limits.max_bytes = FUZZ_BUDGET_BYTES;
    rc = td_dem_load(p, &o, &g, &err);
    fuzz_report("asc", rc, err.msg);
    td_grid_free(g);
    return 0;
}
