/* vs_fixture.h: the viewshed unit tests' grid (test_viewshed.c, test_vsweep.c): a grid the
 * test fills, then finished with max-mipmaps and planes (one thread) and a view of it. */
#ifndef VS_FIXTURE_H
#define VS_FIXTURE_H

#include "accel.h"

typedef struct fixture {
    td_grid *g;
    td_accel *a;
    td_view v;
} fixture;

/* After fx->g's heights are written: stats, acceleration, view. */
static void fixture_finish(fixture *fx)
{
    td_accel_opts o;
    assert_int_equal(td_grid_finish(fx->g, NULL), TD_OK);
    td_accel_opts_default(&o);
    o.maxmip = 1;
    o.planes = 1;
    o.threads = 1;
    assert_int_equal(td_accel_build(fx->g, &o, &fx->a, NULL, NULL), TD_OK);
    fx->v.grid = fx->g;
    fx->v.accel = fx->a->tiles;
}

static void unmake(fixture *fx)
{
    td_accel_free(fx->a);
    td_grid_free(fx->g);
}

#endif
