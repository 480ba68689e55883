/*
 * errors: every error path of the C API gives the right status and a message
 * naming the file, texel or argument; nothing crashes, nothing leaks (this
 * program runs under valgrind memcheck in tests/c_programs.rs).
 *
 *   errors DIR [FILE...]
 * DIR is a writable directory for a garbage file; each FILE is a malformed map
 * that must load as ENVLIGHT_ERROR_FORMAT with a message naming it (the tests run
 * this under an address-space limit with files that declare huge sizes).
 * Exit status 0 when every check holds; each failed check prints a line.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "envlight.h"

static int failures = 0;

/* Checks that `status` is `expected` and the last error contains `needle`. */
static void expect(const char *what, envlight_status status, envlight_status expected,
                   const char *needle) {
    char message[1024];
    size_t len = envlight_last_error(message, sizeof message);
    if (status != expected) {
        printf("FAIL %s: status %s, expected %s (%s)\n", what, envlight_status_name(status),
               envlight_status_name(expected), message);
        failures++;
    } else if (needle && !strstr(message, needle)) {
        printf("FAIL %s: message \"%s\" does not name \"%s\"\n", what, message, needle);
        failures++;
    } else if (len != strlen(message) && len < sizeof message) {
        printf("FAIL %s: envlight_last_error returned %zu for \"%s\"\n", what, len, message);
        failures++;
    } else {
        printf("ok   %s: %s: %s\n", what, envlight_status_name(status), message);
    }
}

/* Writes `content` to the file `name` in `dir`, whose path is left in `path` (a
 * buffer of `size` bytes); 0 when the file cannot be written. */
static int write_file(char *path, size_t size, const char *dir, const char *name,
                      const char *content) {
    FILE *f;
    snprintf(path, size, "%s/%s", dir, name);
    f = fopen(path, "wb");
    if (!f) return 0;
    fputs(content, f);
    fclose(f);
    return 1;
}

static void check(const char *what, int ok) {
    if (!ok) {
        printf("FAIL %s\n", what);
        failures++;
    } else {
        printf("ok   %s\n", what);
    }
}

/* Visibility callbacks: every ray escapes; a failure status; a NaN; nothing
 * written at all. */
static int32_t open_sky(void *user, const float *o, const float *d, size_t n, float *t) {
    size_t i;
    (void)user, (void)o, (void)d;
    for (i = 0; i < n; i++) t[i] = 1.0f;
    return ENVLIGHT_OK;
}

static int32_t failing(void *user, const float *o, const float *d, size_t n, float *t) {
    (void)o, (void)d, (void)n, (void)t;
    ++*(int *)user;
    return 3;
}

static int32_t nan_ray(void *user, const float *o, const float *d, size_t n, float *t) {
    open_sky(user, o, d, n, t);
    t[n - 1] = NAN;
    return ENVLIGHT_OK;
}

static int32_t silent(void *user, const float *o, const float *d, size_t n, float *t) {
    (void)user, (void)o, (void)d, (void)n, (void)t;
    return ENVLIGHT_OK;
}

/* The visibility cache's error paths, over `light`; `dir` is writable. */
static void visibility_errors(const envlight_light *light, const char *dir) {
    envlight_product *product = NULL;
    envlight_visibility_cache *cache = (envlight_visibility_cache *)&failures; /* reset to NULL */
    envlight_visibility_options options = envlight_visibility_options_default();
    envlight_visibility_summary summary;
    envlight_sample s;
    float points[6] = {0.0f, 0.0f, 0.0f, 0.5f, 0.0f, 0.0f}, normals[6] = {0, 0, 1, 0, 0, 1};
    float u[2] = {0.5f, 0.5f}, pdf[2];
    char path[4096], garbage[4096];
    int calls = 0;

    expect("visibility: product", envlight_product_new(light, &product), ENVLIGHT_OK, NULL);
    expect("visibility: a failing callback",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, failing, &calls, &cache),
           ENVLIGHT_ERROR_CALLBACK, "status 3");
    check("visibility: out is NULL after a failure, one call", cache == NULL && calls == 1);
    expect("visibility: a NaN transmittance",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, nan_ray, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "transmittance NaN");
    expect("visibility: no transmittance written",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, silent, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "transmittance NaN for ray 0");
    expect("visibility: NULL trace",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, NULL, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "trace is NULL");
    expect("visibility: NULL product",
           envlight_visibility_cache_build(NULL, points, normals, 2, NULL, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "product is NULL");
    expect("visibility: NULL points",
           envlight_visibility_cache_build(product, NULL, normals, 2, NULL, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "points is NULL");
    expect("visibility: NULL out",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, open_sky, NULL, NULL),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "out is NULL");
    options.normal_bins = 0;
    expect("visibility: normal_bins 0",
           envlight_visibility_cache_build(product, points, normals, 2, &options, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "options.normal_bins 0");
    options = envlight_visibility_options_default();
    options.learned_share = 1.0f;
    expect("visibility: learned_share 1",
           envlight_visibility_cache_build(product, points, normals, 2, &options, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "options.learned_share");
    options = envlight_visibility_options_default();
    options.radius = -1.0f;
    expect("visibility: a negative radius",
           envlight_visibility_cache_build(product, points, normals, 2, &options, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "options.radius");
    options = envlight_visibility_options_default();
    options.reserved[1] = 1;
    expect("visibility: reserved",
           envlight_visibility_cache_build(product, points, normals, 2, &options, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "options.reserved");
    points[4] = NAN;
    expect("visibility: a NaN point",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, open_sky, NULL, &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "point 1");
    points[4] = 0.0f;

    expect("visibility: a good cache",
           envlight_visibility_cache_build(product, points, normals, 2, NULL, open_sky, NULL, &cache),
           ENVLIGHT_OK, NULL);
    check("visibility: summary", envlight_visibility_cache_summary(cache, &summary) == ENVLIGHT_OK &&
                                     summary.entries >= 1 && summary.mean_visibility == 1.0);
    expect("visibility: save into a missing folder",
           envlight_visibility_cache_save(cache, "/nonexistent/dir/cache.envlvis", "key"),
           ENVLIGHT_ERROR_NOT_FOUND, "/nonexistent/dir/cache.envlvis");
    expect("visibility: save NULL path", envlight_visibility_cache_save(cache, NULL, "key"),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "path is NULL");
    expect("visibility: save NULL key", envlight_visibility_cache_save(cache, "x", NULL),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "scene_key is NULL");
    snprintf(path, sizeof path, "%s/good.envlvis", dir);
    expect("visibility: save", envlight_visibility_cache_save(cache, path, "scene 1"), ENVLIGHT_OK, NULL);
    envlight_visibility_cache_free(cache);
    expect("visibility: load under another key",
           envlight_visibility_cache_load(path, product, "scene 2", &cache), ENVLIGHT_ERROR_MISMATCH,
           "in scene \"scene 1\", asked for light");
    check("visibility: out is NULL after a mismatch", cache == NULL);
    expect("visibility: load a missing file",
           envlight_visibility_cache_load("/nonexistent/dir/cache.envlvis", product, "k", &cache),
           ENVLIGHT_ERROR_NOT_FOUND, "/nonexistent/dir/cache.envlvis");
    if (write_file(garbage, sizeof garbage, dir, "garbage.envlvis", "envlvis but not a cache"))
        expect("visibility: load a garbage file",
               envlight_visibility_cache_load(garbage, product, "k", &cache), ENVLIGHT_ERROR_FORMAT,
               "garbage.envlvis");
    expect("visibility: load NULL product", envlight_visibility_cache_load(path, NULL, "k", &cache),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "product is NULL");
    expect("visibility: load", envlight_visibility_cache_load(path, product, "scene 1", &cache),
           ENVLIGHT_OK, NULL);
    envlight_product_free(product); /* the cache keeps it */

    check("visibility: sample", envlight_visibility_cache_sample(cache, points, normals, u, &s) &&
                                    s.pdf > 0.0f &&
                                    envlight_visibility_cache_pdf(cache, points, normals, s.direction) ==
                                        s.pdf);
    check("visibility: sample NULL cache is false",
          !envlight_visibility_cache_sample(NULL, points, normals, u, &s) && s.pdf == 0.0f);
    expect("visibility: sample NULL cache message", ENVLIGHT_ERROR_INVALID_ARGUMENT,
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "cache is NULL");
    check("visibility: pdf NULL normal is 0",
          envlight_visibility_cache_pdf(cache, points, NULL, s.direction) == 0.0f);
    expect("visibility: batch NULL directions",
           envlight_visibility_cache_pdf_batch(cache, points, normals, NULL, 2, pdf),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "directions is NULL");
    expect("visibility: batch of 0",
           envlight_visibility_cache_sample_batch(cache, NULL, NULL, NULL, 0, NULL), ENVLIGHT_OK, NULL);
    expect("visibility: summary NULL", envlight_visibility_cache_summary(cache, NULL),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "summary is NULL");
    envlight_visibility_cache_free(cache);
    envlight_visibility_cache_free(NULL);
}

int main(int argc, char **argv) {
    envlight_light *light = (envlight_light *)&failures; /* must be reset to NULL */
    envlight_light_options options = envlight_light_options_default();
    float rgb[8 * 4 * 3];
    char path[4096];
    char tiny[4];
    size_t k;

    if (argc < 2) {
        fprintf(stderr, "usage: errors DIR [FILE...]\n");
        return 2;
    }
    for (k = 0; k < sizeof rgb / sizeof rgb[0]; k++) rgb[k] = 0.25f + 0.01f * (float)k;

    /* Before any failure the message is empty. */
    check("no error yet", envlight_last_error(NULL, 0) == 0);

    /* Files. */
    expect("missing file",
           envlight_light_load("/nonexistent/dir/missing.exr", NULL, &light),
           ENVLIGHT_ERROR_NOT_FOUND, "/nonexistent/dir/missing.exr");
    check("out is NULL after a failure", light == NULL);
    if (!write_file(path, sizeof path, argv[1], "garbage.exr",
                    "v/1\x01 this is not an OpenEXR file, nor any other map"))
        return 2;
    expect("garbage file", envlight_light_load(path, NULL, &light), ENVLIGHT_ERROR_FORMAT,
           "garbage.exr");
    if (!write_file(path, sizeof path, argv[1], "truncated.hdr",
                    "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 8\n\x01\x02"))
        return 2;
    expect("truncated file", envlight_light_load(path, NULL, &light), ENVLIGHT_ERROR_FORMAT,
           "truncated.hdr");
    expect("a directory", envlight_light_load(argv[1], NULL, &light), ENVLIGHT_ERROR_IO, argv[1]);
    for (k = 2; k < (size_t)argc; k++)
        expect(argv[k], envlight_light_load(argv[k], NULL, &light), ENVLIGHT_ERROR_FORMAT,
               argv[k]);

    /* Texels and sizes. */
    rgb[3 * (2 * 8 + 5) + 1] = NAN;
    expect("NaN texel", envlight_light_from_rgb(rgb, 8, 4, NULL, &light),
           ENVLIGHT_ERROR_INVALID_IMAGE, "texel (5, 2)");
    rgb[3 * (2 * 8 + 5) + 1] = INFINITY;
    expect("infinite texel", envlight_light_from_rgb(rgb, 8, 4, NULL, &light),
           ENVLIGHT_ERROR_INVALID_IMAGE, "texel (5, 2)");
    rgb[3 * (2 * 8 + 5) + 1] = -1.0f;
    expect("negative texel", envlight_light_from_rgb(rgb, 8, 4, NULL, &light),
           ENVLIGHT_ERROR_INVALID_IMAGE, "texel (5, 2)");
    rgb[3 * (2 * 8 + 5) + 1] = 0.5f;
    expect("zero width", envlight_light_from_rgb(rgb, 0, 4, NULL, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "width");
    expect("zero height", envlight_light_from_rgb(rgb, 8, 0, NULL, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "height");
    expect("huge size", envlight_light_from_rgb(rgb, 0xffffffffu, 0xffffffffu, NULL, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "too large");

    /* NULL arguments. */
    expect("NULL path", envlight_light_load(NULL, NULL, &light), ENVLIGHT_ERROR_INVALID_ARGUMENT,
           "path");
    expect("NULL out", envlight_light_load("x.exr", NULL, NULL), ENVLIGHT_ERROR_INVALID_ARGUMENT,
           "out");
    expect("NULL rgb", envlight_light_from_rgb(NULL, 8, 4, NULL, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "rgb");

    /* Options. */
    options.sampler = 7;
    expect("bad sampler", envlight_light_from_rgb(rgb, 8, 4, &options, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "options.sampler");
    options = envlight_light_options_default();
    options.scale = -1.0f;
    expect("negative scale", envlight_light_from_rgb(rgb, 8, 4, &options, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "options.scale");
    options = envlight_light_options_default();
    options.table_width = 3;
    expect("table width that does not divide", envlight_light_from_rgb(rgb, 8, 4, &options, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "3");
    options = envlight_light_options_default();
    options.sampler = ENVLIGHT_SAMPLER_ALIAS; /* with the default, bilinear density */
    expect("bilinear density with alias", envlight_light_from_rgb(rgb, 8, 4, &options, &light),
           ENVLIGHT_ERROR_INVALID_ARGUMENT, "alias");

    /* A good light, then bad queries on it. */
    options = envlight_light_options_default();
    expect("good light", envlight_light_from_rgb(rgb, 8, 4, &options, &light), ENVLIGHT_OK, NULL);
    {
        envlight_sample s;
        float u[2] = {0.5f, 0.5f}, d[3] = {0.0f, 0.0f, 1.0f}, l[3];
        float pdf[4];
        envlight_product *product = NULL;
        envlight_gpu_tables *tables = NULL;
        envlight_sun_extraction *sun = NULL;
        envlight_portal_light *portal = NULL;
        float flat[12] = {0};
        size_t words = 1;

        check("sample NULL light is false", !envlight_light_sample(NULL, u, &s) && s.pdf == 0.0f);
        expect("sample NULL light message", ENVLIGHT_ERROR_INVALID_ARGUMENT,
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "light is NULL");
        check("sample NULL u is false", !envlight_light_sample(light, NULL, &s));
        check("sample NULL out is false", !envlight_light_sample(light, u, NULL));
        check("pdf NULL direction is 0", envlight_light_pdf(light, NULL) == 0.0f);
        envlight_light_radiance(light, NULL, l);
        check("radiance NULL direction is black", l[0] == 0.0f && l[1] == 0.0f && l[2] == 0.0f);
        envlight_light_radiance(light, d, NULL);
        check("a good sample", envlight_light_sample(light, u, &s) && s.pdf > 0.0f);
        expect("batch NULL directions", envlight_light_pdf_batch(light, NULL, 4, pdf),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "directions");
        expect("batch NULL out", envlight_light_sample_batch(light, u, 1, NULL),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "out");
        expect("batch NULL light", envlight_light_radiance_batch(NULL, d, 1, l),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "light");
        expect("batch of 0", envlight_light_pdf_batch(light, NULL, 0, NULL), ENVLIGHT_OK, NULL);
        expect("product NULL light", envlight_product_new(NULL, &product),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "light");
        expect("portal: a flat quad", envlight_portal_light_new(light, flat, 1, 0, &portal),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "portal 0");
        expect("portal: none", envlight_portal_light_new(light, flat, 0, 0, &portal),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "count");
        expect("gpu tables: bad format", envlight_light_gpu_tables(light, 9, &tables),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "radiance_format");
        check("gpu buffer of NULL", envlight_gpu_tables_buffer(NULL, 0, &words) == NULL && words == 0);
        expect("sun: NULL out", envlight_light_extract_sun(light, NULL),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "out");
        expect("sun", envlight_light_extract_sun(light, &sun), ENVLIGHT_OK, NULL);
        expect("residual too small", envlight_sun_extraction_residual(sun, rgb, 5),
               ENVLIGHT_ERROR_INVALID_ARGUMENT, "len");
        envlight_sun_extraction_free(sun);
        visibility_errors(light, argv[1]);
        options.sampler = ENVLIGHT_SAMPLER_HIERARCHICAL;
        options.density = ENVLIGHT_DENSITY_PIECEWISE_CONSTANT;
        envlight_light_free(light);
        expect("hierarchical light", envlight_light_from_rgb(rgb, 8, 4, &options, &light), ENVLIGHT_OK,
               NULL);
        expect("gpu tables: hierarchical", envlight_light_gpu_tables(light, 0, &tables),
               ENVLIGHT_ERROR_UNSUPPORTED, "hierarchical");
    }

    /* The message is truncated to the buffer, and the length is the whole one. */
    {
        size_t whole = envlight_last_error(NULL, 0);
        size_t got = envlight_last_error(tiny, sizeof tiny);
        check("truncated message", got == whole && strlen(tiny) == sizeof tiny - 1);
    }

    envlight_light_free(light);
    envlight_light_free(NULL);
    envlight_product_free(NULL);
    envlight_portal_light_free(NULL);
    envlight_sun_extraction_free(NULL);
    envlight_gpu_tables_free(NULL);
    check("version", strcmp(envlight_version(), "0.1.0") >= 0 && ENVLIGHT_VERSION_MAJOR == 0);
    printf("%d failures\n", failures);
    return failures == 0 ? 0 : 1;
}
