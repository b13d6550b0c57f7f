/* fuzz_edit.c: the heights-edit request of PUT /v1/admin/datasets/{id}/heights (and
 * `terrad render --edit`), as core/gridedit.c takes it: the input's first line holds the
 * query's x, y, w and h (split at spaces, each handed over as the HTTP layer decodes it,
 * missing ones empty), the rest is the body. On a fixed 41 x 29 grid with a void, with a
 * small sample cap so big regions are refused by the cap and not by memory: parse,
 * decode, apply to a copy, the touched tiles and the read-back; what is accepted must
 * read back as it was sent (NaN as NaN), and the original grid must not change. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "gridedit.h"
#include "hash.h"

#define EDIT_MAX_SAMPLES 4096

static td_grid *grid;
static uint64_t grid_hash;

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    if (td_grid_create(41, 29, 30.0, 30.0, 4, NULL, &grid, NULL))
        abort();
    for (int32_t k = 0; k < 41 * 29; k++)
        grid->z[k] = (float)(1000 + (k * 37) % 211);
    grid->z[5 * 41 + 7] = NAN;
    if (td_grid_finish(grid, NULL))
        abort();
    grid_hash = td_fnv1a(TD_FNV1A_INIT, grid->z, sizeof(float) * 41 * 29);
    return 0;
}

/* The accepted edit, applied and read back. */
static void apply(const td_grid_region *r, const float *z)
{
    td_grid *g2 = NULL;
    size_t *tiles = NULL, nt = 0;
    td_err err = {0};
    unsigned char *back = malloc(4 * (size_t)r->w * (size_t)r->h);
    if (!back || td_grid_edit_apply(grid, r, z, &g2, &err) || td_grid_edit_tiles(grid, r, &tiles, &nt, &err) ||
        nt < 1)
        abort();
    td_grid_edit_read(g2, r, back);
    for (size_t k = 0; k < (size_t)r->w * (size_t)r->h; k++) {
        float f;
        memcpy(&f, back + 4 * k, sizeof f);
        if (!(f == z[k] || (isnan(f) && isnan(z[k]))))
            abort(); /* the edit did not land where it was sent */
    }
    if (td_fnv1a(TD_FNV1A_INIT, grid->z, sizeof(float) * 41 * 29) != grid_hash)
        abort(); /* copy-on-write broken: the original changed */
    free(back);
    free(tiles);
    td_grid_free(g2);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char line[128], *q[4] = {"", "", "", ""};
    size_t n = 0;
    td_grid_region r;
    td_err err = {0};
    float *z = NULL;
    if (!grid)
        LLVMFuzzerInitialize(NULL, NULL);
    while (n < size && n < sizeof line - 1 && data[n] != '\n')
        n++;
    memcpy(line, data, n);
    line[n] = '\0';
    char *save = NULL, *tok = strtok_r(line, " ", &save);
    for (int k = 0; k < 4 && tok; k++, tok = strtok_r(NULL, " ", &save))
        q[k] = tok;
    size_t skip = n < size ? n + 1 : n;
    int rc = td_grid_edit_parse(grid, q[0], q[1], q[2], q[3], EDIT_MAX_SAMPLES, &r, &err);
    fuzz_report("region", rc, err.msg);
    if (rc == TD_OK) {
        rc = td_grid_edit_decode(&r, data + skip, size - skip, &z, &err);
        fuzz_report("body", rc, err.msg);
        if (rc == TD_OK)
            apply(&r, z);
    }
    free(z);
    return 0;
}
