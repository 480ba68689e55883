/*
 * visibility: a visibility cache through the C API, built with a C callback that
 * traces a room lit through one window. Prints rows for tests/c_programs.rs to
 * compare with the Rust library bit for bit, and checks on its own that the batch
 * calls equal the single ones, that each sample's pdf is the pdf of its
 * direction, that THREADS threads querying the one cache at once get exactly
 * the single-threaded rows, that the cache outlives its product sampler's
 * handle, and that a saved cache loads back the same (and not under another
 * scene key).
 *
 *   visibility MAP INPUTS DIR
 *   MAP and INPUTS as for rows.c; DIR: a writable directory for the saved cache.
 *
 * The room is the box [-1, 1]^2 x [0, 2], open only through a window in its +x
 * wall (|y| < 0.4, 0.6 < z < 1.4); the cache is built from 20 x 20 points on its
 * floor (normal +z) and 20 x 20 on its -x wall (normal +x), with the default
 * options but seed 7 and 2 rays per patch. Query point k: for k % 6 = 0, 1 the
 * floor at (a, b, 0), normal +z; 2, 3 the wall at (-1, a, b + 1), normal +x; 4
 * outside the room at (5 + a, b, 3), normal +z; 5 the floor with the normal
 * (0, 0, 3) for k % 12 = 5 and (0, 0, 0) for k % 12 = 11; with
 * a = (k % 19) / 10 - 0.9 and b = (k % 17) / 9 - 0.9.
 *
 * Rows: "V k ok dx dy dz pdf r g b" the sample at query point k for u[k];
 * "W k pdf" the pdf of directions[k] there; "Y entries bytes radius
 * mean_visibility rays" the summary; "T rays" the rays the callback traced.
 * Floats as the hex of their bits.
 */
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "envlight.h"

#define PROGRAM "visibility"
#include "common.h"

/* The time at which a ray from o along d leaves the slab [lo, hi]. */
static float exit_time(float o, float d, float lo, float hi) {
    if (d > 0.0f) return (hi - o) / d;
    if (d < 0.0f) return (lo - o) / d;
    return INFINITY;
}

/* 1 when the ray from o (inside the room) along d leaves through the window. */
static float room(const float *o, const float *d) {
    float tx = exit_time(o[0], d[0], -1.0f, 1.0f);
    float ty = exit_time(o[1], d[1], -1.0f, 1.0f);
    float tz = exit_time(o[2], d[2], 0.0f, 2.0f);
    float y = o[1] + d[1] * tx, z = o[2] + d[2] * tx;
    int window = d[0] > 0.0f && tx <= ty && tx <= tz;
    return window && fabsf(y) < 0.4f && z > 0.6f && z < 1.4f ? 1.0f : 0.0f;
}

/* What the callback saw. */
typedef struct {
    uint64_t rays;
    uint32_t calls;
} tracer;

/* The room as an envlight_visibility_trace; `user` is a tracer. */
static int32_t trace(void *user, const float *origins, const float *directions, size_t count,
                     float *transmittance) {
    tracer *t = user;
    size_t i;
    t->rays += count;
    t->calls++;
    for (i = 0; i < count; i++) transmittance[i] = room(origins + 3 * i, directions + 3 * i);
    return ENVLIGHT_OK;
}

/* The build's points: the room's floor and its -x wall. */
static size_t room_points(float *points, float *normals) {
    size_t n = 0;
    int i, j;
    for (i = 0; i < 20; i++) {
        for (j = 0; j < 20; j++) {
            float a = ((float)i + 0.5f) / 10.0f - 1.0f, b = ((float)j + 0.5f) / 10.0f - 1.0f;
            float floor_p[3] = {a, b, 0.0f}, up[3] = {0.0f, 0.0f, 1.0f};
            float wall_p[3] = {-1.0f, a, b + 1.0f}, east[3] = {1.0f, 0.0f, 0.0f};
            memcpy(points + 3 * n, floor_p, sizeof floor_p);
            memcpy(normals + 3 * n, up, sizeof up);
            n++;
            memcpy(points + 3 * n, wall_p, sizeof wall_p);
            memcpy(normals + 3 * n, east, sizeof east);
            n++;
        }
    }
    return n;
}

/* Query point k and its normal (see the top of this file). */
static void query_point(uint32_t k, float *p, float *n) {
    float a = (float)(k % 19) / 10.0f - 0.9f, b = (float)(k % 17) / 9.0f - 0.9f;
    p[0] = a;
    p[1] = b;
    p[2] = 0.0f;
    n[0] = 0.0f;
    n[1] = 0.0f;
    n[2] = 1.0f;
    switch (k % 6) {
    case 2:
    case 3:
        p[0] = -1.0f;
        p[1] = a;
        p[2] = b + 1.0f;
        n[0] = 1.0f;
        n[2] = 0.0f;
        break;
    case 4:
        p[0] = 5.0f + a;
        p[2] = 3.0f;
        break;
    case 5:
        n[2] = k % 12 == 5 ? 3.0f : 0.0f;
        break;
    default:
        break;
    }
}

enum { WORDS = 9 };

/* The single calls' rows of `cache` at every query point: WORDS words each. */
static void rows(const envlight_visibility_cache *cache, const float *points, const float *normals,
                 const float *u, const float *dirs, uint32_t n, uint32_t *words) {
    uint32_t k;
    int i;
    for (k = 0; k < n; k++) {
        uint32_t *w = words + (size_t)WORDS * k;
        const float *p = points + 3 * (size_t)k, *nrm = normals + 3 * (size_t)k;
        envlight_sample s;
        bool ok = envlight_visibility_cache_sample(cache, p, nrm, u + 2 * (size_t)k, &s);
        float again = envlight_visibility_cache_pdf(cache, p, nrm, s.direction);
        if (bits(again) != bits(s.pdf)) {
            fprintf(stderr, "visibility: row %u: the pdf of the sample's direction is %g, not %g\n",
                    k, again, s.pdf);
            exit(1);
        }
        w[0] = ok;
        for (i = 0; i < 3; i++) w[1 + i] = bits(s.direction[i]);
        w[4] = bits(s.pdf);
        for (i = 0; i < 3; i++) w[5 + i] = bits(s.radiance[i]);
        w[8] = bits(envlight_visibility_cache_pdf(cache, p, nrm, dirs + 3 * (size_t)k));
    }
}

/* Threads querying one cache at once. */
#define THREADS 4

typedef struct {
    const envlight_visibility_cache *cache;
    const float *points, *normals, *u, *dirs;
    uint32_t n;
    uint32_t *words;
} pass;

static void *run_pass(void *arg) {
    pass *p = arg;
    rows(p->cache, p->points, p->normals, p->u, p->dirs, p->n, p->words);
    return NULL;
}

/* 1 when THREADS threads, each computing every row, all get `words`. */
static int threads_agree(const pass *base, const uint32_t *words) {
    pthread_t ids[THREADS];
    pass passes[THREADS];
    size_t bytes = sizeof *words * WORDS * base->n;
    int t, same = 1;
    for (t = 0; t < THREADS; t++) {
        passes[t] = *base;
        passes[t].words = malloc(bytes);
        if (pthread_create(&ids[t], NULL, run_pass, &passes[t]) != 0) fail("pthread_create");
    }
    for (t = 0; t < THREADS; t++) {
        pthread_join(ids[t], NULL);
        same = same && memcmp(passes[t].words, words, bytes) == 0;
        free(passes[t].words);
    }
    return same;
}

int main(int argc, char **argv) {
    envlight_light *light = NULL;
    envlight_product *product = NULL;
    envlight_visibility_cache *cache = NULL, *loaded = NULL;
    envlight_visibility_options options = envlight_visibility_options_default();
    envlight_visibility_summary summary;
    tracer traced = {0, 0};
    float build_points[3 * 800], build_normals[3 * 800];
    size_t size, count;
    char *inputs, path[4096], message[1024];
    uint32_t n, k, *words, *again;
    const float *u, *dirs;
    float *points, *normals, *pdf;
    envlight_sample *samples;

    if (argc != 4) {
        fprintf(stderr, "usage: visibility MAP INPUTS DIR\n");
        return 2;
    }
    light = open_light(argv[1]);
    if (envlight_product_new(light, &product) != ENVLIGHT_OK) fail("envlight_product_new");
    envlight_light_free(light); /* the product keeps it */

    count = room_points(build_points, build_normals);
    options.seed = 7;
    options.rays_per_patch = 2;
    if (envlight_visibility_cache_build(product, build_points, build_normals, count, &options, trace,
                                        &traced, &cache) != ENVLIGHT_OK)
        fail("envlight_visibility_cache_build");
    if (envlight_visibility_cache_summary(cache, &summary) != ENVLIGHT_OK) fail("summary");
    if (summary.rays != traced.rays || traced.calls == 0) {
        fprintf(stderr, "visibility: the summary counts %llu rays, the callback saw %llu\n",
                (unsigned long long)summary.rays, (unsigned long long)traced.rays);
        return 1;
    }

    inputs = read_file(argv[2], &size);
    memcpy(&n, inputs, sizeof n);
    u = (const float *)(inputs + 4);
    dirs = u + 2 * (size_t)n;
    points = malloc(sizeof *points * 3 * n);
    normals = malloc(sizeof *normals * 3 * n);
    for (k = 0; k < n; k++) query_point(k, points + 3 * (size_t)k, normals + 3 * (size_t)k);
    words = malloc(sizeof *words * WORDS * n);
    again = malloc(sizeof *again * WORDS * n);
    rows(cache, points, normals, u, dirs, n, words);
    {
        pass base = {0};
        base.cache = cache;
        base.points = points;
        base.normals = normals;
        base.u = u;
        base.dirs = dirs;
        base.n = n;
        if (!threads_agree(&base, words)) {
            fprintf(stderr, "visibility: %d threads did not get the single-threaded rows\n", THREADS);
            return 1;
        }
    }

    /* The batch calls give the single calls' rows. */
    samples = malloc(sizeof *samples * n);
    pdf = malloc(sizeof *pdf * n);
    if (envlight_visibility_cache_sample_batch(cache, points, normals, u, n, samples) != ENVLIGHT_OK)
        fail("sample_batch");
    if (envlight_visibility_cache_pdf_batch(cache, points, normals, dirs, n, pdf) != ENVLIGHT_OK)
        fail("pdf_batch");
    for (k = 0; k < n; k++) {
        const uint32_t *w = words + (size_t)WORDS * k;
        const envlight_sample *s = &samples[k];
        if ((uint32_t)(s->pdf > 0.0f) != w[0] || bits(s->direction[0]) != w[1] ||
            bits(s->direction[1]) != w[2] || bits(s->direction[2]) != w[3] || bits(s->pdf) != w[4] ||
            bits(s->radiance[0]) != w[5] || bits(s->radiance[1]) != w[6] ||
            bits(s->radiance[2]) != w[7] || bits(pdf[k]) != w[8]) {
            fprintf(stderr, "visibility: batch row %u differs from the single calls\n", k);
            return 1;
        }
    }

    /* Saved and loaded back: the same rows; under another key, a mismatch. */
    snprintf(path, sizeof path, "%s/room.envlvis", argv[3]);
    if (envlight_visibility_cache_save(cache, path, "room v1") != ENVLIGHT_OK) fail("save");
    if (envlight_visibility_cache_load(path, product, "room v1", &loaded) != ENVLIGHT_OK) fail("load");
    rows(loaded, points, normals, u, dirs, n, again);
    if (memcmp(words, again, sizeof *words * WORDS * n) != 0) {
        fprintf(stderr, "visibility: the loaded cache's rows differ from the saved one's\n");
        return 1;
    }
    envlight_visibility_cache_free(loaded);
    loaded = NULL;
    if (envlight_visibility_cache_load(path, product, "room v2", &loaded) != ENVLIGHT_ERROR_MISMATCH ||
        loaded != NULL) {
        fprintf(stderr, "visibility: loading under another key was not a mismatch\n");
        return 1;
    }
    envlight_last_error(message, sizeof message);
    if (!strstr(message, "\"room v1\"") || !strstr(message, "\"room v2\"")) {
        fprintf(stderr, "visibility: the mismatch does not name both keys: %s\n", message);
        return 1;
    }

    /* The cache keeps the product sampler alive. */
    envlight_product_free(product);
    rows(cache, points, normals, u, dirs, n, again);
    if (memcmp(words, again, sizeof *words * WORDS * n) != 0) {
        fprintf(stderr, "visibility: the rows changed when the product's handle was freed\n");
        return 1;
    }

    printf("Y %llu %llu %08x %016llx %llu\n", (unsigned long long)summary.entries,
           (unsigned long long)summary.bytes, bits(summary.radius),
           (unsigned long long)bits64(summary.mean_visibility), (unsigned long long)summary.rays);
    printf("T %llu\n", (unsigned long long)traced.rays);
    for (k = 0; k < n; k++) {
        const uint32_t *w = words + (size_t)WORDS * k;
        printf("V %u %u %08x %08x %08x %08x %08x %08x %08x\n", k, w[0], w[1], w[2], w[3], w[4], w[5],
               w[6], w[7]);
        printf("W %u %08x\n", k, w[8]);
    }

    free(words);
    free(again);
    free(samples);
    free(pdf);
    free(points);
    free(normals);
    free(inputs);
    envlight_visibility_cache_free(cache);
    return 0;
}
