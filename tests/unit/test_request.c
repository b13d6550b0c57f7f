/* test_request.c: scene JSON and query parameters -> struct td_scene
 * (server/request.c): a full scene reads every field; defaults fill the rest; each kind
 * of bad input (malformed, duplicate key, unknown key, wrong type, NaN/inf/overflow,
 * out of range, oversize image, bad id) is refused with the right status and the
 * field's path; the query form agrees with the JSON form; every range of the table of
 * limits (core/limit.h) is the parser's, at both ends, with the service's maximum by
 * default and core's when a caller raises td_request_limits; a pick's body
 * defaults to format pick. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include <jansson.h>

#include "limit.h"
#include "lod.h"
#include "request.h"

static td_scene scene; /* large (pick list): keep it off the stack */

static td_status parse(const char *json, td_request_error *e)
{
    td_request_limits lim;
    td_request_limits_default(&lim);
    memset(e, 0, sizeof *e);
    return td_request_parse_scene(json, strlen(json), &lim, &scene, e);
}

static void test_full_scene(void **state)
{
    td_request_error e;
    (void)state;
    const char *j =
        "{\"dataset\": \"trinidad\","
        " \"camera\": {\"position\": {\"x\": 52000, \"y\": 31000, \"z\": 4100},"
        "   \"heading\": 54.6, \"pitch\": -5, \"roll\": 1.5, \"fov\": 60, \"projection\": \"perspective\"},"
        " \"image\": {\"width\": 640, \"height\": 480, \"format\": \"png\"},"
        " \"quality\": {\"method\": \"parametric\", \"surface\": \"triangle\", \"samples\": 2,"
        "   \"lod\": false, \"smooth_normals\": true},"
        " \"effects\": {\"sun\": {\"azimuth\": 315, \"elevation\": 35}, \"shadows\": true,"
        "   \"haze\": {\"visibility_km\": 80}, \"sky\": true, \"water\": {\"level\": 1500},"
        "   \"ambient_occlusion\": {\"rays\": 12, \"radius\": 300}, \"curvature\": {\"k\": 0.2},"
        "   \"ambient\": 0.3, \"drape\": \"levi-ortho\"}}";
    assert_int_equal(parse(j, &e), TD_OK);
    assert_string_equal(scene.dataset, "trinidad");
    assert_int_equal(scene.camera.pos_kind, TD_POS_XYZ);
    assert_float_equal(scene.camera.x, 52000, 0);
    assert_float_equal(scene.camera.z, 4100, 0);
    assert_float_equal(scene.camera.heading, 54.6, 0);
    assert_float_equal(scene.camera.pitch, -5, 0);
    assert_float_equal(scene.camera.roll, 1.5, 0);
    assert_int_equal(scene.camera.photogrammetric, 0);
    assert_int_equal(scene.image.width, 640);
    assert_int_equal(scene.quality.method, TD_METHOD_PARAMETRIC);
    assert_int_equal(scene.quality.surface, TD_SURFACE_TRIANGLE);
    assert_int_equal(scene.quality.samples, 2);
    assert_int_equal(scene.quality.smooth_normals, 1);
    assert_true(scene.effects.shadows && scene.effects.haze && scene.effects.sky);
    assert_float_equal(scene.effects.haze_visibility_km, 80, 0);
    assert_int_equal(scene.effects.water, 1);
    assert_float_equal(scene.effects.water_level, 1500, 0);
    assert_int_equal(scene.effects.ambient_occlusion, 12);
    assert_float_equal(scene.effects.ao_radius, 300, 0);
    assert_int_equal(scene.effects.curvature, 1);
    assert_float_equal(scene.effects.curvature_k, 0.2, 0);
    assert_float_equal(scene.effects.ambient, 0.3, 0);
    assert_string_equal(scene.effects.drape, "levi-ortho");
}

static void test_defaults_and_variants(void **state)
{
    td_request_error e;
    (void)state;
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"position\":{\"lon\":-105.5,\"lat\":37.6,\"agl\":300}}}", &e), TD_OK);
    assert_int_equal(scene.camera.pos_kind, TD_POS_LONLAT_AGL);
    assert_float_equal(scene.camera.fov, 60, 0);
    assert_int_equal(scene.image.width, 640);
    assert_int_equal(scene.image.height, 480);
    assert_int_equal(scene.image.format, TD_FORMAT_PNG);
    assert_int_equal(scene.quality.method, TD_METHOD_AUTO);
    assert_int_equal(scene.quality.surface, TD_SURFACE_BILINEAR);
    assert_int_equal(scene.quality.samples, 1);
    assert_false(scene.effects.shadows || scene.effects.haze || scene.effects.sky ||
                 scene.effects.water || scene.effects.curvature);
    assert_int_equal(scene.effects.ambient_occlusion, 0);
    assert_float_equal(scene.effects.curvature_k, 0.13, 0);
    /* curvature: true keeps the default k; haze: true the default visibility */
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"agl\":3}},"
                           "\"effects\":{\"curvature\":true,\"haze\":true,\"ambient_occlusion\":6}}", &e), TD_OK);
    assert_int_equal(scene.camera.pos_kind, TD_POS_XY_AGL);
    assert_true(scene.effects.curvature && scene.effects.haze);
    assert_float_equal(scene.effects.curvature_k, 0.13, 0);
    assert_float_equal(scene.effects.haze_visibility_km, 80, 0);
    assert_int_equal(scene.effects.ambient_occlusion, 6);
    /* the silhouette method (issue 13) parses through the method table */
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                           "\"quality\":{\"method\":\"silhouette\"}}", &e), TD_OK);
    assert_int_equal(scene.quality.method, TD_METHOD_SILHOUETTE);
    /* photogrammetric camera */
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3},"
                           "\"tilt\":60,\"swing\":180,\"azimuth\":30,\"focal_mm\":150,\"pixel_mm\":0.02}}", &e), TD_OK);
    assert_int_equal(scene.camera.photogrammetric, 1);
    assert_float_equal(scene.camera.tilt, 60, 0);
    assert_float_equal(scene.camera.focal_mm, 150, 0);
    /* orthographic needs no position */
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"projection\":\"orthographic\","
                           "\"extent\":[0,0,100,50]},\"image\":{\"width\":256,\"height\":256}}", &e), TD_OK);
    assert_int_equal(scene.camera.projection, TD_PROJ_ORTHOGRAPHIC);
    assert_float_equal(scene.camera.extent[2], 100, 0);
    /* pick */
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                           "\"image\":{\"format\":\"pick\"},\"pick\":[[10,20],[639,479.5]]}", &e), TD_OK);
    assert_int_equal(scene.npick, 2);
    assert_float_equal(scene.pick[1][1], 479.5, 0);
    /* levels of detail on the isometric lattice (square by default) */
    assert_int_equal(scene.quality.lod_grid, TD_LOD_GRID_SQUARE);
    assert_int_equal(parse("{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                           "\"quality\":{\"lod\":true,\"lod_grid\":\"isometric\"}}", &e), TD_OK);
    assert_int_equal(scene.quality.lod_grid, TD_LOD_GRID_ISOMETRIC);
}

static void expect(const char *json, td_status st, const char *field, const char *msg_part)
{
    td_request_error e;
    td_status got = parse(json, &e);
    if (got != st || strcmp(e.field, field) || (msg_part && !strstr(e.message, msg_part)))
        print_error("for %s\n got %d field '%s' message '%s'\n", json, (int)got, e.field, e.message);
    assert_int_equal(got, st);
    assert_string_equal(e.field, field);
    if (msg_part)
        assert_non_null(strstr(e.message, msg_part));
}

#define CAM "\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}}"

static void test_refusals(void **state)
{
    (void)state;
    expect("{\"dataset\":\"a\",", TD_EFORMAT, "", NULL);
    expect("[1,2]", TD_EINVAL, "", "object");
    expect("{" CAM "}", TD_EINVAL, "dataset", "required");
    expect("{\"dataset\":\"a\"}", TD_EINVAL, "camera", "required");
    expect("{\"dataset\":\"a\",\"camera\":{}}", TD_EINVAL, "camera.position", "required");
    /* duplicate keys, named by their path */
    expect("{\"dataset\":\"a\",\"camera\":{\"fov\":50,\"fov\":60,\"position\":{\"x\":1,\"y\":2,\"z\":3}}}",
           TD_EINVAL, "camera.fov", "duplicate");
    expect("{\"dataset\":\"a\",\"dataset\":\"b\"," CAM "}", TD_EINVAL, "dataset", "duplicate");
    /* unknown keys */
    expect("{\"dataset\":\"a\"," CAM ",\"colour\":1}", TD_EINVAL, "colour", "unknown");
    expect("{\"dataset\":\"a\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3},\"zoom\":2}}", TD_EINVAL,
           "camera.zoom", "unknown");
    expect("{\"dataset\":\"a\"," CAM ",\"effects\":{\"haze\":{\"visibility\":3}}}", TD_EINVAL,
           "effects.haze.visibility", "unknown");
    /* wrong types */
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"width\":\"640\"}}", TD_EINVAL, "image.width", "integer");
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"width\":640.5}}", TD_EINVAL, "image.width", "integer");
    expect("{\"dataset\":\"a\"," CAM ",\"effects\":{\"shadows\":1}}", TD_EINVAL, "effects.shadows", "boolean");
    expect("{\"dataset\":7," CAM "}", TD_EINVAL, "dataset", "string");
    expect("{\"dataset\":\"a\",\"camera\":{\"position\":{\"x\":\"1\",\"y\":2,\"z\":3}}}", TD_EINVAL,
           "camera.position.x", "number");
    /* NaN, infinity, overflow: not JSON; the path of the field is still named */
    expect("{\"dataset\":\"a\",\"camera\":{\"fov\":NaN," "\"position\":{\"x\":1,\"y\":2,\"z\":3}}}",
           TD_EFORMAT, "camera.fov", NULL);
    expect("{\"dataset\":\"a\",\"camera\":{\"position\":{\"x\":1e999,\"y\":2,\"z\":3}}}", TD_EFORMAT,
           "camera.position.x", NULL);
    /* out of range */
    expect("{\"dataset\":\"a\",\"camera\":{\"fov\":200,\"position\":{\"x\":1,\"y\":2,\"z\":3}}}", TD_ERANGE,
           "camera.fov", "outside");
    expect("{\"dataset\":\"a\",\"camera\":{\"pitch\":-91,\"position\":{\"x\":1,\"y\":2,\"z\":3}}}", TD_ERANGE,
           "camera.pitch", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"quality\":{\"samples\":9}}", TD_ERANGE, "quality.samples", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"effects\":{\"sun\":{\"elevation\":95}}}", TD_ERANGE,
           "effects.sun.elevation", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"effects\":{\"ambient_occlusion\":1000}}", TD_ERANGE,
           "effects.ambient_occlusion", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"width\":0}}", TD_ERANGE, "image.width", NULL);
    expect("{\"dataset\":\"a\",\"camera\":{\"position\":{\"lon\":1,\"lat\":95,\"alt\":3}}}", TD_ERANGE,
           "camera.position.lat", NULL);
    /* names */
    expect("{\"dataset\":\"a\"," CAM ",\"quality\":{\"method\":\"magic\"}}", TD_EINVAL, "quality.method", "magic");
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"format\":\"jpeg\"}}", TD_EINVAL, "image.format", NULL);
    /* oversize image: each side within limits, the product over */
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"width\":4096,\"height\":4096,\"format\":\"png\"}," 
           "\"quality\":{\"samples\":1}}", TD_OK, "", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"width\":4096,\"height\":4097}}", TD_ERANGE,
           "image.height", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"width\":4096,\"height\":4096},\"quality\":{\"samples\":3}}",
           TD_ETOOBIG, "quality.samples", "exceeds");
    /* inconsistent camera */
    expect("{\"dataset\":\"a\",\"camera\":{\"position\":{\"x\":1,\"y\":2}}}", TD_EINVAL,
           "camera.position", "height");
    expect("{\"dataset\":\"a\",\"camera\":{\"position\":{\"x\":1,\"lat\":2,\"z\":3}}}", TD_EINVAL,
           "camera.position", NULL);
    expect("{\"dataset\":\"a\",\"camera\":{\"fov\":50,\"tilt\":30,\"position\":{\"x\":1,\"y\":2,\"z\":3}}}",
           TD_EINVAL, "camera", "one");
    expect("{\"dataset\":\"a\",\"camera\":{\"extent\":[0,0,1,1],\"position\":{\"x\":1,\"y\":2,\"z\":3}}}",
           TD_EINVAL, "camera.extent", "orthographic");
    expect("{\"dataset\":\"a\",\"camera\":{\"projection\":\"orthographic\",\"extent\":[5,0,1,1]}}",
           TD_ERANGE, "camera.extent", NULL);
    /* level of detail: a boolean or pixels per coarse cell in 0.25 .. 64 */
    expect("{\"dataset\":\"a\"," CAM ",\"quality\":{\"lod\":100}}", TD_ERANGE, "quality.lod", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"quality\":{\"lod\":\"yes\"}}", TD_EINVAL, "quality.lod", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"quality\":{\"lod_grid\":\"hexagonal\"}}", TD_EINVAL,
           "quality.lod_grid", "square or isometric");
    expect("{\"dataset\":\"a\"," CAM ",\"quality\":{\"lod_grid\":1}}", TD_EINVAL, "quality.lod_grid", NULL);
    /* ids: no paths from the network */
    expect("{\"dataset\":\"../etc/passwd\"," CAM "}", TD_EINVAL, "dataset", "id");
    expect("{\"dataset\":\"a\"," CAM ",\"effects\":{\"drape\":\"/etc/x.png\"}}", TD_EINVAL, "effects.drape", NULL);
    /* pick */
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"format\":\"pick\"},\"pick\":[[1,2],[700,3]]}", TD_ERANGE,
           "pick[1]", "outside");
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"format\":\"pick\"},\"pick\":[[1,\"x\"]]}", TD_EINVAL,
           "pick[0][1]", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"image\":{\"format\":\"pick\"}}", TD_EINVAL, "pick", NULL);
    expect("{\"dataset\":\"a\"," CAM ",\"pick\":[[1,2]]}", TD_EINVAL, "pick", "format");
}

static void test_paths_allowed_for_cli(void **state)
{
    td_request_limits lim;
    td_request_error e;
    const char *j = "{\"dataset\":\"../data/x.f32\"," CAM "}";
    (void)state;
    td_request_limits_default(&lim);
    lim.allow_paths = 1;
    assert_int_equal(td_request_parse_scene(j, strlen(j), &lim, &scene, &e), TD_OK);
    assert_string_equal(scene.dataset, "../data/x.f32");
}

static td_status query(const char *const *kv, size_t n, td_request_error *e)
{
    const char *k[32], *v[32];
    for (size_t i = 0; i < n; i++) {
        k[i] = kv[2 * i];
        v[i] = kv[2 * i + 1];
    }
    memset(e, 0, sizeof *e);
    return td_request_parse_query(k, v, n, NULL, &scene, e);
}

/* POST /v1/pick's body: format pick unless the body names one; otherwise the same rules
 * (and the same errors) as a render's scene. */
static void test_pick_body(void **state)
{
    td_request_limits lim;
    td_request_error e;
    const char *no_format = "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                            "\"pick\":[[10,20]]}";
    const char *no_format_img = "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                                "\"image\":{\"width\":64,\"height\":32},\"pick\":[[10,20]]}";
    const char *png = "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                      "\"image\":{\"format\":\"png\"}}";
    const char *no_pixels = "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}}}";
    const char *bad_image = "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}},"
                            "\"image\":5,\"pick\":[[1,2]]}";
    (void)state;
    td_request_limits_default(&lim);

    assert_int_equal(td_request_parse_pick(no_format, strlen(no_format), &lim, &scene, &e), TD_OK);
    assert_int_equal(scene.image.format, TD_FORMAT_PICK);
    assert_int_equal(scene.npick, 1);
    assert_int_equal(td_request_parse_pick(no_format_img, strlen(no_format_img), &lim, &scene, &e), TD_OK);
    assert_int_equal(scene.image.format, TD_FORMAT_PICK);
    assert_int_equal(scene.image.width, 64);
    /* the same body as a render's scene needs the format */
    assert_int_equal(td_request_parse_scene(no_format, strlen(no_format), &lim, &scene, &e), TD_EINVAL);
    assert_string_equal(e.field, "pick");
    /* a format given is kept (the route refuses a pick without pixels) */
    assert_int_equal(td_request_parse_pick(png, strlen(png), &lim, &scene, &e), TD_OK);
    assert_int_equal(scene.image.format, TD_FORMAT_PNG);
    assert_int_equal(scene.npick, 0);
    assert_int_equal(td_request_parse_pick(no_pixels, strlen(no_pixels), &lim, &scene, &e), TD_EINVAL);
    assert_string_equal(e.field, "pick");
    assert_non_null(strstr(e.message, "needs a list of pixels"));
    assert_int_equal(td_request_parse_pick(bad_image, strlen(bad_image), &lim, &scene, &e), TD_EINVAL);
    assert_string_equal(e.field, "image");
    assert_int_equal(td_request_parse_pick("{\"a\":1,\"a\":2}", 13, &lim, &scene, &e), TD_EINVAL);
    assert_string_equal(e.field, "a");
}

static void test_query(void **state)
{
    td_request_error e;
    (void)state;
    const char *ok[] = {"dataset", "trinidad", "camera.position.x", "52000", "camera.position.y",
                        "31000", "camera.position.z", "4100", "camera.heading", "54.6",
                        "image.width", "320", "effects.shadows", "true",
                        "effects.haze.visibility_km", "40", "quality.surface", "triangle"};
    assert_int_equal(query(ok, 9, &e), TD_OK);
    assert_string_equal(scene.dataset, "trinidad");
    assert_float_equal(scene.camera.x, 52000, 0);
    assert_float_equal(scene.camera.heading, 54.6, 0);
    assert_int_equal(scene.image.width, 320);
    assert_int_equal(scene.effects.shadows, 1);
    assert_int_equal(scene.effects.haze, 1);
    assert_float_equal(scene.effects.haze_visibility_km, 40, 0);
    assert_int_equal(scene.quality.surface, TD_SURFACE_TRIANGLE);

    const char *ortho[] = {"dataset", "levi", "camera.projection", "orthographic",
                           "camera.extent", "0,0,8000,8000"};
    assert_int_equal(query(ortho, 3, &e), TD_OK);
    assert_float_equal(scene.camera.extent[3], 8000, 0);

    const char *dup[] = {"dataset", "a", "camera.position.x", "1", "camera.position.x", "2"};
    assert_int_equal(query(dup, 3, &e), TD_EINVAL);
    assert_string_equal(e.field, "camera.position.x");

    const char *nan[] = {"dataset", "a", "camera.position.x", "1", "camera.position.y", "2",
                         "camera.position.z", "3", "camera.fov", "nan"};
    assert_int_equal(query(nan, 5, &e), TD_ERANGE);
    assert_string_equal(e.field, "camera.fov");

    const char *bad[] = {"dataset", "a", "camera.position.x", "1", "camera.position.y", "2",
                         "camera.position.z", "3", "image.width", "64x"};
    assert_int_equal(query(bad, 5, &e), TD_EFORMAT);
    assert_string_equal(e.field, "image.width");

    const char *unk[] = {"dataset", "a", "camera.position.x", "1", "camera.position.y", "2",
                         "camera.position.z", "3", "effects.glitter", "true"};
    assert_int_equal(query(unk, 5, &e), TD_EINVAL);
    assert_string_equal(e.field, "effects.glitter");

    const char *mixed[] = {"dataset", "a", "effects.haze", "true", "effects.haze.visibility_km", "3"};
    assert_int_equal(query(mixed, 3, &e), TD_EINVAL);
    assert_string_equal(e.field, "effects.haze.visibility_km");
}


/* Parses the scene the JSON tree root spells (and frees the tree). */
static td_status parse_tree(json_t *root, const td_request_limits *lim, td_request_error *e)
{
    char *text = json_dumps(root, 0);
    assert_non_null(text);
    memset(e, 0, sizeof *e);
    td_status st = td_request_parse_scene(text, strlen(text), lim, &scene, e);
    free(text);
    json_decref(root);
    return st;
}

/* A scene with one more field, given by its dotted path (a JSON integer when v is whole,
 * so integer fields read it). */
static td_status parse_field(const char *path, double v, const td_request_limits *lim,
                             td_request_error *e)
{
    json_t *root = json_pack("{s:s,s:{s:{s:i,s:i,s:i}}}", "dataset", "levi", "camera", "position",
                             "x", 1, "y", 2, "z", 3);
    json_t *o = root;
    char buf[128], *save = NULL;
    snprintf(buf, sizeof buf, "%s", path);
    char *key = strtok_r(buf, ".", &save);
    for (char *next = strtok_r(NULL, ".", &save); next; next = strtok_r(NULL, ".", &save)) {
        json_t *child = json_object_get(o, key);
        if (!child) {
            child = json_object();
            json_object_set_new(o, key, child);
        }
        o = child;
        key = next;
    }
    json_object_set_new(o, key, v == floor(v) ? json_integer((json_int_t)v) : json_real(v));
    return parse_tree(root, lim, e);
}

static void accepts(const char *path, double v, const td_request_limits *lim)
{
    td_request_error e;
    td_status st = parse_field(path, v, lim, &e);
    if (st != TD_OK)
        print_error("%s = %g: %s: %s\n", path, v, e.field, e.message);
    assert_int_equal(st, TD_OK);
}

static void refuses(const char *path, double v, const td_request_limits *lim, td_status want)
{
    td_request_error e;
    td_status st = parse_field(path, v, lim, &e);
    if (st != want || strcmp(e.field, path))
        print_error("%s = %g: got %d, field '%s': %s\n", path, v, (int)st, e.field, e.message);
    assert_int_equal(st, want);
    assert_string_equal(e.field, path);
}

/* A pick of n pixels. */
static td_status parse_pick(int n, const td_request_limits *lim, td_request_error *e)
{
    json_t *px = json_array();
    for (int i = 0; i < n; i++)
        json_array_append_new(px, json_pack("[i,i]", i % 640, i / 640));
    json_t *root = json_pack("{s:s,s:{s:{s:i,s:i,s:i}},s:{s:s},s:o}", "dataset", "levi", "camera",
                             "position", "x", 1, "y", 2, "z", 3, "image", "format", "pick", "pick", px);
    return parse_tree(root, lim, e);
}

static void test_limits_table(void **state)
{
    td_request_limits lim, wide;
    td_request_error e;
    (void)state;
    td_request_limits_default(&lim);
    assert_int_equal(lim.max_width, td_limit_get(TD_LIMIT_WIDTH)->api_max);
    assert_int_equal(lim.max_height, td_limit_get(TD_LIMIT_HEIGHT)->api_max);
    assert_int_equal(lim.max_samples, td_limit_get(TD_LIMIT_SAMPLES)->api_max);
    assert_int_equal(lim.max_ao_rays, td_limit_get(TD_LIMIT_AO_RAYS)->api_max);
    assert_int_equal(lim.max_pick, td_limit_get(TD_LIMIT_PICK)->api_max);
    /* a caller that raises the limits to core's (as `terrad render` does) */
    wide = lim;
    wide.max_width = (int32_t)td_limit_get(TD_LIMIT_WIDTH)->max;
    wide.max_height = (int32_t)td_limit_get(TD_LIMIT_HEIGHT)->max;
    wide.max_samples = (int)td_limit_get(TD_LIMIT_SAMPLES)->max;
    wide.max_ao_rays = (int)td_limit_get(TD_LIMIT_AO_RAYS)->max;
    wide.max_pick = (int)td_limit_get(TD_LIMIT_PICK)->max;
    wide.max_pixels = UINT64_MAX;
    wide.max_samples_total = UINT64_MAX;

    for (int id = 0; id < TD_LIMIT_COUNT; id++) {
        const td_limit_row *l = td_limit_get((td_limit)id);
        assert_non_null(l);
        assert_true(l->min <= l->api_max && l->api_max <= l->max);
        if (id == TD_LIMIT_PICK)
            continue; /* a count, not a value: below */
        accepts(l->path, l->min, &lim);
        accepts(l->path, l->api_max, &lim);
        refuses(l->path, l->min - 1.0, &lim, TD_ERANGE);
        refuses(l->path, l->api_max + 1.0, &lim, TD_ERANGE);
        accepts(l->path, l->max, &wide);
        refuses(l->path, l->max + 1.0, &wide, TD_ERANGE);
    }
    assert_null(td_limit_get(TD_LIMIT_COUNT));

    const td_limit_row *pk = td_limit_get(TD_LIMIT_PICK);
    assert_int_equal(parse_pick((int)pk->api_max, &lim, &e), TD_OK);
    assert_int_equal(parse_pick((int)pk->api_max + 1, &lim, &e), TD_ETOOBIG);
    assert_string_equal(e.field, pk->path);
    assert_int_equal(parse_pick((int)pk->max, &wide, &e), TD_OK);
    assert_int_equal(parse_pick((int)pk->max + 1, &wide, &e), TD_ETOOBIG);
    assert_string_equal(e.field, pk->path);
}

/* The cylindrical camera (issue 19): fov up to 360 and fov_v for it only, curvature on
 * by default for it and off when the scene says so. */
static void test_cylindrical(void **state)
{
    td_request_error e;
    (void)state;
    assert_int_equal(parse("{\"dataset\":\"d\",\"camera\":{\"projection\":\"cylindrical\",\"position\":"
                           "{\"x\":1,\"y\":2,\"z\":3},\"fov\":360,\"fov_v\":40}}", &e), TD_OK);
    assert_int_equal(scene.camera.projection, TD_PROJ_CYLINDRICAL);
    assert_true(scene.camera.fov == 360.0 && scene.camera.fov_v == 40.0);
    assert_int_equal(scene.effects.curvature, 1);
    assert_true(scene.effects.curvature_k == 0.13);
    assert_int_equal(parse("{\"dataset\":\"d\",\"camera\":{\"projection\":\"cylindrical\",\"position\":"
                           "{\"x\":1,\"y\":2,\"z\":3}},\"effects\":{\"curvature\":false}}", &e), TD_OK);
    assert_int_equal(scene.effects.curvature, 0);
    assert_int_equal(parse("{\"dataset\":\"d\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3}}}", &e), TD_OK);
    assert_int_equal(scene.effects.curvature, 0); /* perspective: off unless asked */
    assert_int_not_equal(parse("{\"dataset\":\"d\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3},"
                               "\"fov\":360}}", &e), TD_OK);
    assert_string_equal(e.field, "camera.fov");
    assert_int_not_equal(parse("{\"dataset\":\"d\",\"camera\":{\"position\":{\"x\":1,\"y\":2,\"z\":3},"
                               "\"fov_v\":30}}", &e), TD_OK);
    assert_string_equal(e.field, "camera.fov_v");
    assert_int_not_equal(parse("{\"dataset\":\"d\",\"camera\":{\"projection\":\"cylindrical\"}}", &e), TD_OK);
    assert_string_equal(e.field, "camera.position");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_full_scene),
        cmocka_unit_test(test_defaults_and_variants),
        cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_paths_allowed_for_cli),
        cmocka_unit_test(test_pick_body),
        cmocka_unit_test(test_query),
        cmocka_unit_test(test_limits_table),
        cmocka_unit_test(test_cylindrical),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
