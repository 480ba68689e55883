/*
 * rows: prints what the C API answers for given inputs, one row per query, every
 * float as the hex of its bits, for tests/c_programs.rs to compare with the Rust
 * library bit for bit. Checks on its own that the batch calls equal the single
 * ones, and with --threads T that T threads querying one light at once get
 * exactly the single-threaded rows.
 *
 *   rows MAP INPUTS [--threads T]
 *   MAP: a map file, or raw:FILE (u32 width, u32 height, then width*height*3 floats)
 *   INPUTS: u32 n, then 2n floats u, then 3n floats directions (little-endian)
 *
 * Rows: "S k ok dx dy dz pdf r g b" light sample, "P k pdf", "L k r g b",
 * "C k ok ..." product sample with the cosine at directions[k],
 * "G k ok ..." product sample with a glossy lobe (normal directions[k],
 * outgoing directions[k+1], roughness 0.3), "Q k pdf" the product pdf of the
 * glossy sample's direction, "I ..." the light's info.
 */
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "envlight.h"

#define PROGRAM "rows"
#include "common.h"

/* Every row of one pass, as 32-bit words, to compare passes exactly. */
typedef struct {
    const envlight_light *light;
    const envlight_product *product;
    const float *u;
    const float *dirs;
    uint32_t n;
    uint32_t *words; /* WORDS per input */
} pass;

enum { WORDS = 26 };

static void put_sample(uint32_t *w, bool ok, const envlight_sample *s) {
    int i;
    w[0] = ok;
    for (i = 0; i < 3; i++) w[1 + i] = bits(s->direction[i]);
    w[4] = bits(s->pdf);
    for (i = 0; i < 3; i++) w[5 + i] = bits(s->radiance[i]);
}

static envlight_factor glossy(const float *dirs, uint32_t n, uint32_t k) {
    envlight_factor f;
    memcpy(f.normal, dirs + 3 * k, sizeof f.normal);
    memcpy(f.outgoing, dirs + 3 * ((k + 1) % n), sizeof f.outgoing);
    f.roughness = 0.3f;
    return f;
}

static envlight_factor cosine(const float *dirs, uint32_t k) {
    envlight_factor f;
    memset(&f, 0, sizeof f);
    memcpy(f.normal, dirs + 3 * k, sizeof f.normal);
    return f;
}

static void *run_pass(void *arg) {
    pass *p = arg;
    uint32_t k;
    for (k = 0; k < p->n; k++) {
        uint32_t *w = p->words + (size_t)WORDS * k;
        envlight_sample s;
        envlight_factor f;
        float rgb[3];
        bool ok = envlight_light_sample(p->light, p->u + 2 * k, &s);
        put_sample(w, ok, &s);
        w[8] = bits(envlight_light_pdf(p->light, p->dirs + 3 * k));
        envlight_light_radiance(p->light, p->dirs + 3 * k, rgb);
        w[9] = bits(rgb[0]);
        w[10] = bits(rgb[1]);
        w[11] = bits(rgb[2]);
        f = cosine(p->dirs, k);
        ok = envlight_product_sample(p->product, &f, p->u + 2 * k, &s);
        w[12] = ok;
        w[13] = bits(s.direction[0]);
        w[14] = bits(s.direction[1]);
        w[15] = bits(s.direction[2]);
        w[16] = bits(s.pdf);
        f = glossy(p->dirs, p->n, k);
        ok = envlight_product_sample(p->product, &f, p->u + 2 * k, &s);
        put_sample(w + 17, ok, &s);
        /* The glossy sample's pdf, recomputed from its direction. */
        w[25] = bits(envlight_product_pdf(p->product, &f, s.direction));
    }
    return NULL;
}

int main(int argc, char **argv) {
    envlight_light *light = NULL;
    envlight_product *product = NULL;
    envlight_light_info info;
    size_t size;
    char *inputs;
    uint32_t n, k, threads = 0;
    const float *u, *dirs;
    pass single;
    envlight_sample *samples;
    float *pdf, *rgb;

    if (argc != 3 && !(argc == 5 && strcmp(argv[3], "--threads") == 0)) {
        fprintf(stderr, "usage: rows MAP INPUTS [--threads T]\n");
        return 2;
    }
    if (argc == 5) threads = (uint32_t)atoi(argv[4]);

    light = open_light(argv[1]);
    if (envlight_product_new(light, &product) != ENVLIGHT_OK) fail("envlight_product_new");

    inputs = read_file(argv[2], &size);
    memcpy(&n, inputs, sizeof n);
    u = (const float *)(inputs + 4);
    dirs = u + 2 * (size_t)n;

    single.light = light;
    single.product = product;
    single.u = u;
    single.dirs = dirs;
    single.n = n;
    single.words = malloc(sizeof(uint32_t) * WORDS * n);
    run_pass(&single);

    /* The batch calls give the single calls' rows. */
    samples = malloc(sizeof *samples * n);
    pdf = malloc(sizeof *pdf * n);
    rgb = malloc(sizeof *rgb * 3 * n);
    if (envlight_light_sample_batch(light, u, n, samples) != ENVLIGHT_OK) fail("sample_batch");
    if (envlight_light_pdf_batch(light, dirs, n, pdf) != ENVLIGHT_OK) fail("pdf_batch");
    if (envlight_light_radiance_batch(light, dirs, n, rgb) != ENVLIGHT_OK) fail("radiance_batch");
    for (k = 0; k < n; k++) {
        uint32_t w[8];
        const uint32_t *r = single.words + (size_t)WORDS * k;
        put_sample(w, samples[k].pdf > 0.0f, &samples[k]);
        if (memcmp(w, r, sizeof w) != 0 || bits(pdf[k]) != r[8] || bits(rgb[3 * k]) != r[9] ||
            bits(rgb[3 * k + 1]) != r[10] || bits(rgb[3 * k + 2]) != r[11]) {
            fprintf(stderr, "rows: batch row %u differs from the single calls\n", k);
            return 1;
        }
    }
    {
        envlight_factor *factors = malloc(sizeof *factors * n);
        float *gpdf = malloc(sizeof *gpdf * n);
        float *gdirs = malloc(sizeof *gdirs * 3 * n);
        for (k = 0; k < n; k++) factors[k] = glossy(dirs, n, k);
        if (envlight_product_sample_batch(product, factors, u, n, samples) != ENVLIGHT_OK)
            fail("product_sample_batch");
        for (k = 0; k < n; k++) memcpy(gdirs + 3 * k, samples[k].direction, sizeof samples[k].direction);
        if (envlight_product_pdf_batch(product, factors, gdirs, n, gpdf) != ENVLIGHT_OK)
            fail("product_pdf_batch");
        for (k = 0; k < n; k++) {
            uint32_t w[8];
            const uint32_t *r = single.words + (size_t)WORDS * k;
            put_sample(w, samples[k].pdf > 0.0f, &samples[k]);
            if (memcmp(w, r + 17, sizeof w) != 0 || bits(gpdf[k]) != r[25]) {
                fprintf(stderr, "rows: product batch row %u differs from the single calls\n", k);
                return 1;
            }
        }
        free(factors);
        free(gpdf);
        free(gdirs);
    }

    if (threads > 0) {
        pthread_t *ids = malloc(sizeof *ids * threads);
        pass *passes = malloc(sizeof *passes * threads);
        uint32_t t;
        for (t = 0; t < threads; t++) {
            passes[t] = single;
            passes[t].words = malloc(sizeof(uint32_t) * WORDS * n);
            if (pthread_create(&ids[t], NULL, run_pass, &passes[t]) != 0) {
                fprintf(stderr, "rows: cannot start a thread\n");
                return 1;
            }
        }
        for (t = 0; t < threads; t++) {
            pthread_join(ids[t], NULL);
            if (memcmp(passes[t].words, single.words, sizeof(uint32_t) * WORDS * n) != 0) {
                fprintf(stderr, "rows: thread %u's rows differ from the single-threaded ones\n", t);
                return 1;
            }
            free(passes[t].words);
        }
        printf("threads %u identical\n", threads);
        free(ids);
        free(passes);
    }

    if (envlight_light_get_info(light, &info) != ENVLIGHT_OK) fail("get_info");
    printf("I %u %u %u %u %016llx %016llx %016llx %016llx %08x %08x %08x %08x\n", info.width,
           info.height, info.table_width, info.table_height,
           (unsigned long long)bits64(info.integral_rgb[0]),
           (unsigned long long)bits64(info.integral_rgb[1]),
           (unsigned long long)bits64(info.integral_rgb[2]),
           (unsigned long long)bits64(info.integral_luminance), bits(info.max_luminance),
           bits(info.brightest_direction[0]), bits(info.brightest_direction[1]),
           bits(info.brightest_direction[2]));
    for (k = 0; k < n; k++) {
        const uint32_t *w = single.words + (size_t)WORDS * k;
        printf("S %u %u %08x %08x %08x %08x %08x %08x %08x\n", k, w[0], w[1], w[2], w[3], w[4], w[5],
               w[6], w[7]);
        printf("P %u %08x\n", k, w[8]);
        printf("L %u %08x %08x %08x\n", k, w[9], w[10], w[11]);
        printf("C %u %u %08x %08x %08x %08x\n", k, w[12], w[13], w[14], w[15], w[16]);
        printf("G %u %u %08x %08x %08x %08x %08x %08x %08x\n", k, w[17], w[18], w[19], w[20], w[21],
               w[22], w[23], w[24]);
        printf("Q %u %08x\n", k, w[25]);
    }

    free(single.words);
    free(samples);
    free(pdf);
    free(rgb);
    free(inputs);
    envlight_product_free(product);
    envlight_light_free(light);
    return 0;
}
