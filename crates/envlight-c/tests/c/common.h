/* Helpers the C test programs share: errors that end the program, reading a
 * file whole, and a float's bits for exact comparisons. Each program defines
 * PROGRAM (its name in messages) before including this file. */
#ifndef ENVLIGHT_TESTS_COMMON_H
#define ENVLIGHT_TESTS_COMMON_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "envlight.h"

static inline void fail(const char *what) {
    char message[512];
    envlight_last_error(message, sizeof message);
    fprintf(stderr, "%s: %s: %s\n", PROGRAM, what, message);
    exit(1);
}

static inline void *read_file(const char *path, size_t *size) {
    FILE *f = fopen(path, "rb");
    char *data;
    long n;
    if (!f) {
        fprintf(stderr, "%s: cannot open %s\n", PROGRAM, path);
        exit(1);
    }
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    data = malloc((size_t)n + 1);
    if (!data || fread(data, 1, (size_t)n, f) != (size_t)n) {
        fprintf(stderr, "%s: cannot read %s\n", PROGRAM, path);
        exit(1);
    }
    fclose(f);
    *size = (size_t)n;
    return data;
}

static inline uint32_t bits(float x) {
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

static inline uint64_t bits64(double x) {
    uint64_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

/* The light of MAP: a file the library loads, or `raw:FILE`, a dump of width
 * and height (two u32) and RGB floats. */
static inline envlight_light *open_light(const char *map) {
    envlight_light *light = NULL;
    if (strncmp(map, "raw:", 4) == 0) {
        size_t size;
        char *raw = read_file(map + 4, &size);
        uint32_t wh[2];
        memcpy(wh, raw, sizeof wh);
        if (envlight_light_from_rgb((const float *)(raw + 8), wh[0], wh[1], NULL, &light) != ENVLIGHT_OK)
            fail("envlight_light_from_rgb");
        free(raw);
    } else if (envlight_light_load(map, NULL, &light) != ENVLIGHT_OK) {
        fail("envlight_light_load");
    }
    return light;
}

#endif
