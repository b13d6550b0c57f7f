/* dem.c: the entry point of the DEM loaders (see dem.h): options, encoding names, and
 * the dispatch by file extension to one loader per format (demraw.c, demasc.c,
 * demhgt.c, dempng.c, demgdal.c).
 *
 * The format is chosen by the extension only. Sniffing contents was rejected: a PNG's
 * pixels do not say how heights are packed (a wrong guess gives wrong heights without
 * an error), and an extension that lies gives a clear "malformed" message from the
 * loader it picked. Extensions we do not read ourselves go to GDAL when it is built in. */
#include "dem.h"

#include <string.h>
#include <sys/stat.h>

#include "demasc.h"
#include "demgdal.h"
#include "demhgt.h"
#include "dempng.h"
#include "demraw.h"
#include "demutil.h"

typedef td_status (*td_dem_loader)(const char *path, const td_dem_opts *o, td_grid **out,
                                   td_err *err);

/* Extension -> loader; one table so that td_dem_load and td_dem_recognised agree. */
#define TD_DEM_FORMAT_LIST(X)                                                  \
    X("f32", td_demraw_load)                                                   \
    X("asc", td_demasc_load)                                                   \
    X("hgt", td_demhgt_load)                                                   \
    X("png", td_dempng_load)

static const struct {
    const char *ext;
    td_dem_loader load;
} td_dem_formats[] = {
#define TD_X_FORMAT(ext, fn) {ext, fn},
    TD_DEM_FORMAT_LIST(TD_X_FORMAT)
#undef TD_X_FORMAT
};

static const char *const td_dem_encoding_names[] = {
#define TD_X_NAME(e, name) name,
    TD_DEM_ENCODING_LIST(TD_X_NAME)
#undef TD_X_NAME
};

void td_dem_opts_default(td_dem_opts *o)
{
    memset(o, 0, sizeof *o);
    o->encoding = TD_ENC_NONE;
    o->scale = 1.0;
    o->offset = 0.0;
    o->divisor = 11983.0;
    o->tile_log2 = TD_TILE_LOG2_DEFAULT;
    td_grid_limits_default(&o->limits);
}

const char *td_dem_encoding_name(td_dem_encoding e)
{
    return (unsigned)e < TD_ENC_COUNT ? td_dem_encoding_names[e] : "unknown";
}

td_status td_dem_encoding_parse(const char *name, td_dem_encoding *out)
{
    int i = td_name_index(td_dem_encoding_names, TD_ENC_COUNT, name);
    if (i >= 0)
        *out = (td_dem_encoding)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

int td_dem_have_gdal(void)
{
#ifdef TERRAD_HAVE_GDAL
    return 1;
#else
    return 0;
#endif
}

static td_dem_loader find_loader(const char *path)
{
    char ext[16];
    td_dem_loader fn = NULL;
    td_demutil_ext(path, ext, sizeof ext);
    for (size_t k = 0; k < sizeof td_dem_formats / sizeof td_dem_formats[0] && !fn; k++)
        if (!strcmp(ext, td_dem_formats[k].ext))
            fn = td_dem_formats[k].load;
    return fn;
}

td_status td_dem_load(const char *path, const td_dem_opts *opts, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    td_dem_opts dflt;
    td_dem_loader fn;
    struct stat st;
    char ext[16];

    *out = NULL;
    if (!opts) {
        td_dem_opts_default(&dflt);
        opts = &dflt;
    }
    if (!path || !*path) {
        rc = td_err_set(err, TD_EINVAL, "no DEM file given");
        goto out;
    }
    if (stat(path, &st) != 0) {
        rc = td_err_set(err, TD_ENOTFOUND, "%s: no such file", path);
        goto out;
    }
    if (S_ISDIR(st.st_mode)) {
        rc = td_err_set(err, TD_EINVAL, "%s: is a directory, not a DEM file", path);
        goto out;
    }
    fn = find_loader(path);
    td_demutil_ext(path, ext, sizeof ext);
    if (!strcmp(ext, "json")) {
        rc = td_err_set(err, TD_EINVAL,
                        "%s: a JSON sidecar, not a DEM: load the .f32 or .png file beside it", path);
    } else if (fn) {
        rc = fn(path, opts, out, err);
    } else if (td_dem_have_gdal() || td_demgdal_recognised(path)) {
        /* with GDAL: anything else is GDAL's to identify; without: a clear refusal */
        rc = td_demgdal_load(path, opts, out, err);
    } else {
        rc = td_err_set(err, TD_EUNSUPPORTED,
                        "%s: unsupported format '.%s' (terrad reads .f32 + .json, .asc, .hgt, .png%s)",
                        path, ext, td_dem_have_gdal() ? " and what GDAL reads" : "");
    }
out:
    return rc;
}

int td_dem_recognised(const char *path)
{
    int ok = 0;
    char ext[16], side[4096];
    struct stat st;
    td_demutil_ext(path, ext, sizeof ext);
    if (!strcmp(ext, "png"))
        ok = td_demutil_sidecar_path(path, side, sizeof side) && stat(side, &st) == 0;
    else
        ok = find_loader(path) != NULL || (td_dem_have_gdal() && td_demgdal_recognised(path));
    return ok;
}
