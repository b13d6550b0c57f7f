/* limit.c: the table of limit.h and core's range check on it (td_render's
 * check_scene, td_render_pick). */
#include "limit.h"

static const td_limit_row td_limit_rows[TD_LIMIT_COUNT] = {
#define TD_X_ROW(id, path, min, api_max, max) [id] = {path, min, api_max, max},
    TD_LIMIT_LIST(TD_X_ROW)
#undef TD_X_ROW
};

const td_limit_row *td_limit_get(td_limit id)
{
    return (unsigned)id < TD_LIMIT_COUNT ? &td_limit_rows[id] : NULL;
}

td_status td_limit_check(td_limit id, double v, td_err *err)
{
    td_status rc = TD_OK;
    const td_limit_row *l = td_limit_get(id);
    if (!l)
        rc = td_err_set(err, TD_EINVAL, "limit %d: no such limit", (int)id);
    else if (!(v >= l->min && v <= l->max))
        rc = td_err_field(err, TD_ERANGE, l->path, "%g is outside %g .. %g", v, l->min, l->max);
    return rc;
}
