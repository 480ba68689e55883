/*
 * envlight.h: the C API of envlight, importance-sampled environment lighting.
 * Generated from crates/envlight-c by cbindgen; do not edit by hand.
 * Reference: docs/c-api.md. Licence: MIT OR Apache-2.0.
 *
 * Conventions: right-handed, z up; an image point (u, v) with u left to right and
 * v top to bottom looks along theta = pi v from +z, phi = 2 pi u from +x towards +y.
 * Densities are per steradian; radiance is linear RGB.
 */

#ifndef ENVLIGHT_H
#define ENVLIGHT_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/**
 * The major version of the library this header belongs to.
 */
#define ENVLIGHT_VERSION_MAJOR 0

/**
 * The minor version of the library this header belongs to.
 */
#define ENVLIGHT_VERSION_MINOR 1

/**
 * The patch version of the library this header belongs to.
 */
#define ENVLIGHT_VERSION_PATCH 0

/**
 * What a call that can fail returns. Every failure also leaves a message for
 * `envlight_last_error` on the calling thread.
 */
typedef enum envlight_status {
  /**
   * Success.
   */
  ENVLIGHT_OK = 0,
  /**
   * A NULL or misaligned pointer, a size of 0 or one too large, an option out
   * of range, or inputs that do not go together. The message names the argument.
   */
  ENVLIGHT_ERROR_INVALID_ARGUMENT = 1,
  /**
   * The file does not exist.
   */
  ENVLIGHT_ERROR_NOT_FOUND = 2,
  /**
   * The file exists but could not be read.
   */
  ENVLIGHT_ERROR_IO = 3,
  /**
   * The file is in no format envlight reads, or cannot be decoded (truncated,
   * corrupt, an unsupported feature).
   */
  ENVLIGHT_ERROR_FORMAT = 4,
  /**
   * The image cannot be lit: a texel that is NaN, infinite or negative, or
   * dimensions beyond the library's limits. The message names the texel.
   */
  ENVLIGHT_ERROR_INVALID_IMAGE = 5,
  /**
   * A combination of options a feature does not implement (the hierarchical
   * sampler exported as GPU tables, a texel too large for 16-bit radiance).
   */
  ENVLIGHT_ERROR_UNSUPPORTED = 6,
  /**
   * A bug in envlight, caught at the boundary (a Rust panic). The message says
   * where; please report it.
   */
  ENVLIGHT_ERROR_INTERNAL = 7,
  /**
   * A callback of the caller's (the visibility cache's `envlight_visibility_trace`)
   * returned a status other than `ENVLIGHT_OK`. The message gives that status.
   */
  ENVLIGHT_ERROR_CALLBACK = 8,
  /**
   * A saved file was made for other inputs than the ones given (a visibility
   * cache for another light or scene key). The message names both.
   */
  ENVLIGHT_ERROR_MISMATCH = 9,
} envlight_status;

/**
 * How directions are drawn from the density (`envlight_light_options.sampler`).
 */
enum envlight_sampler
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : uint32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /**
   * CDF inversion (the default): stratification kept, invertible.
   */
  ENVLIGHT_SAMPLER_INVERSION = 0,
  /**
   * Vose's alias table: O(1) per sample, no stratification, no inverse.
   */
  ENVLIGHT_SAMPLER_ALIAS = 1,
  /**
   * Hierarchical warping down a pyramid of sums.
   */
  ENVLIGHT_SAMPLER_HIERARCHICAL = 2,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum envlight_sampler envlight_sampler;
#else
typedef uint32_t envlight_sampler;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/**
 * The shape of the sampling density (`envlight_light_options.density`).
 */
enum envlight_density
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : uint32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /**
   * Constant over each texel: the smallest and cheapest, and the only density
   * of the alias and hierarchical samplers and of a reduced table
   * (`table_width`).
   */
  ENVLIGHT_DENSITY_PIECEWISE_CONSTANT = 0,
  /**
   * Bilinear between texel centres (inversion sampler only; the default of
   * `envlight_light_options_default`): follows the bilinear lookup.
   */
  ENVLIGHT_DENSITY_PIECEWISE_BILINEAR = 1,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum envlight_density envlight_density;
#else
typedef uint32_t envlight_density;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/**
 * How image points map to directions (`envlight_light_options.mapping`,
 * `input_mapping`).
 */
enum envlight_mapping
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : uint32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /**
   * Latitude-longitude: `θ = π v` from +z, `φ = 2π u` from +x towards +y.
   */
  ENVLIGHT_MAPPING_EQUIRECTANGULAR = 0,
  /**
   * The equal-area octahedral square.
   */
  ENVLIGHT_MAPPING_EQUAL_AREA = 1,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum envlight_mapping envlight_mapping;
#else
typedef uint32_t envlight_mapping;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/**
 * How radiance between texel centres is reconstructed
 * (`envlight_light_options.lookup`).
 */
enum envlight_lookup
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : uint32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /**
   * Bilinear between the four nearest texel centres (the default).
   */
  ENVLIGHT_LOOKUP_BILINEAR = 0,
  /**
   * The texel that contains the point.
   */
  ENVLIGHT_LOOKUP_NEAREST = 1,
  /**
   * Bilinear with the rows as nodes from pole to pole (row j at v = j/(h-1)),
   * as Mitsuba 3's envmap reads a map (equirectangular; the piecewise-bilinear
   * density puts its nodes on those rows).
   */
  ENVLIGHT_LOOKUP_NODE = 2,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum envlight_lookup envlight_lookup;
#else
typedef uint32_t envlight_lookup;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/**
 * How `envlight_light_gpu_tables` stores the radiance image.
 */
enum envlight_radiance_format
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : uint32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /**
   * RGB `f32`, 12 bytes per texel: exactly the light's texels.
   */
  ENVLIGHT_RADIANCE_F32 = 0,
  /**
   * RGBA `f16` (alpha 0), 8 bytes per texel.
   */
  ENVLIGHT_RADIANCE_F16 = 1,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum envlight_radiance_format envlight_radiance_format;
#else
typedef uint32_t envlight_radiance_format;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/**
 * Which of the three buffers `envlight_gpu_tables_buffer` returns.
 */
enum envlight_gpu_buffer
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : uint32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /**
   * The parameter block: 64 words (section 1).
   */
  ENVLIGHT_GPU_PARAMS = 0,
  /**
   * The tables buffer a shader binds (sections 2-8, each padded to 16 bytes).
   */
  ENVLIGHT_GPU_TABLES = 1,
  /**
   * The radiance image (section 9).
   */
  ENVLIGHT_GPU_RADIANCE = 2,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum envlight_gpu_buffer envlight_gpu_buffer;
#else
typedef uint32_t envlight_gpu_buffer;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/**
 * A light's GPU tables (layout version 1). Opaque and immutable; free it with
 * `envlight_gpu_tables_free`.
 */
typedef struct envlight_gpu_tables envlight_gpu_tables;

/**
 * An environment light: an HDR image at infinity and its sampling tables.
 * Opaque; immutable once built, so a `const` pointer serves any number of
 * threads at once. Free it with `envlight_light_free`.
 */
typedef struct envlight_light envlight_light;

/**
 * A light seen through portals. Opaque; a `const` pointer serves any number of
 * threads (each portal's tables are built, once, the first time a point on its
 * side asks). It keeps the light alive; free it with `envlight_portal_light_free`.
 */
typedef struct envlight_portal_light envlight_portal_light;

/**
 * A product sampler over a light: its tables for every surface normal, built once
 * (tens of milliseconds and a few bytes per texel; `envlight_product_memory_bytes`).
 * Opaque and immutable: a `const` pointer serves any number of threads. It keeps
 * the light alive; free it with `envlight_product_free`.
 */
typedef struct envlight_product envlight_product;

/**
 * What `envlight_light_extract_sun` found. Opaque and immutable; free it with
 * `envlight_sun_extraction_free`.
 */
typedef struct envlight_sun_extraction envlight_sun_extraction;

/**
 * A visibility cache over a product sampler: for each entry (a cell of space
 * times a cell of normals) where the build's points fell, what share of each
 * patch of the light it sees, and the sampling distribution that follows.
 * Opaque and immutable once built: a `const` pointer serves any number of
 * threads. It keeps the product sampler (and its light) alive; free it with
 * `envlight_visibility_cache_free`.
 */
typedef struct envlight_visibility_cache envlight_visibility_cache;

/**
 * How a light is built. Start from `envlight_light_options_default()` and change
 * fields; the enumerated fields hold the values of `envlight_sampler`,
 * `envlight_density`, `envlight_mapping` and `envlight_lookup`.
 */
typedef struct envlight_light_options {
  /**
   * An `envlight_sampler`.
   */
  uint32_t sampler;
  /**
   * An `envlight_density`.
   */
  uint32_t density;
  /**
   * An `envlight_mapping`: the parameterization the light samples in. A
   * lat-long input lit with `ENVLIGHT_MAPPING_EQUAL_AREA` is resampled.
   */
  uint32_t mapping;
  /**
   * An `envlight_mapping`: what the input image is (a 2:1 lat-long map, or an
   * equal-area square as PBRT-v4 writes them).
   */
  uint32_t input_mapping;
  /**
   * An `envlight_lookup`.
   */
  uint32_t lookup;
  /**
   * Rotation of the map about +z, in degrees (finite).
   */
  float rotate_deg;
  /**
   * Light-to-world rotation as matrix rows, applied after `rotate_deg`; all
   * zeros (the default) means none. Must be orthonormal with determinant 1.
   */
  float rotation[3][3];
  /**
   * Multiplies every radiance value, not the density (finite, >= 0).
   */
  float scale;
  /**
   * Width of the sampling table in cells; 0 (the default) gives one cell per
   * texel. Must divide the image's width, and the reduction its height.
   */
  uint32_t table_width;
  /**
   * Side of the square a lat-long input is resampled to for the equal-area
   * mapping; 0 keeps about the input's texel count.
   */
  uint32_t equal_area_size;
  /**
   * Non-zero: MIS compensation (sample `max(0, Y - mean)`); the light alone then
   * no longer covers the sphere; use it only inside MIS.
   */
  uint32_t mis_compensation;
  /**
   * Must be zero: room for options added later without changing this struct's size.
   */
  uint32_t reserved[4];
} envlight_light_options;

/**
 * A direction drawn from a light, with its solid-angle density (per steradian)
 * and the radiance arriving from it (linear RGB, scale applied). A call that
 * draws no direction leaves every field 0.
 */
typedef struct envlight_sample {
  /**
   * Unit direction towards the light, world frame, z up.
   */
  float direction[3];
  /**
   * Solid-angle density of `direction`, per steradian: > 0 and finite, or 0
   * when no direction was drawn.
   */
  float pdf;
  /**
   * Radiance arriving from `direction`.
   */
  float radiance[3];
} envlight_sample;

/**
 * What a light is: sizes, integrals, the brightest direction, memory.
 */
typedef struct envlight_light_info {
  /**
   * Width of the light's image in texels (after resampling to the equal-area
   * square, when asked).
   */
  uint32_t width;
  /**
   * Height of the light's image in texels.
   */
  uint32_t height;
  /**
   * Width of the sampling table in cells.
   */
  uint32_t table_width;
  /**
   * Height of the sampling table in cells.
   */
  uint32_t table_height;
  /**
   * The options' `envlight_sampler`, `envlight_density`, `envlight_mapping` and
   * `envlight_lookup`, in that order.
   */
  uint32_t sampler;
  /**
   * See `sampler`.
   */
  uint32_t density;
  /**
   * See `sampler`.
   */
  uint32_t mapping;
  /**
   * See `sampler`.
   */
  uint32_t lookup;
  /**
   * `∫ R dω, ∫ G dω, ∫ B dω` over the sphere (scale applied).
   */
  double integral_rgb[3];
  /**
   * `∫ Y dω` over the sphere (scale applied).
   */
  double integral_luminance;
  /**
   * The brightest texel's luminance (scale applied).
   */
  float max_luminance;
  /**
   * The world direction of the brightest texel's centre.
   */
  float brightest_direction[3];
  /**
   * Bytes of sampling tables (the image not counted).
   */
  uint64_t sampling_bytes;
  /**
   * Non-zero when the map is black: no direction can be drawn.
   */
  uint32_t black;
} envlight_light_info;

/**
 * What multiplies the light's radiance at a shading point (world frame; vectors
 * need not be unit length).
 *
 * - `roughness == 0`: the clamped cosine `max(0, n·ω)` of a diffuse surface;
 *   `outgoing` is ignored.
 * - `0 < roughness <= 1`: the clamped cosine times a GGX lobe proxy of that
 *   roughness about the mirror direction of `outgoing` (towards the viewer).
 *
 * A zero or non-finite `normal` (or `outgoing`, when used), or a `roughness`
 * outside `[0, 1]`, samples nothing: `false` and pdf 0.
 */
typedef struct envlight_factor {
  /**
   * The surface normal `n`.
   */
  float normal[3];
  /**
   * The outgoing direction `ωo`, for a glossy factor.
   */
  float outgoing[3];
  /**
   * 0 for the cosine alone; the GGX roughness `α ∈ (0, 1]` for a glossy lobe.
   */
  float roughness;
} envlight_factor;

/**
 * How a visibility cache is built. Start from
 * `envlight_visibility_options_default()` and change fields.
 */
typedef struct envlight_visibility_options {
  /**
   * Side of the cubic cells that group points into entries, in world units;
   * 0 (the default) chooses it from the points, so that about
   * `target_entries` entries form. Otherwise positive and finite.
   */
  float radius;
  /**
   * Cells per side of the octahedral grid of normals that splits a cell's
   * points by orientation, 1 to 16 (4: groups about 50° across).
   */
  uint32_t normal_bins;
  /**
   * The number of entries the automatic radius aims at (at least 1).
   */
  size_t target_entries;
  /**
   * Bytes the entries' tables may take; the radius grows until they fit.
   */
  size_t memory_budget;
  /**
   * Rays per entry and lit patch it can face in the first pass, 1 to 4096.
   */
  uint32_t rays_per_patch;
  /**
   * Rays per entry and patch in the second pass, towards the patches on an
   * edge of what the first pass saw, 0 to 4096 (0: no second pass).
   */
  uint32_t refine_rays;
  /**
   * The learned distribution's largest share of the mixture, in [0, 1); an
   * entry's share shrinks with the share of its sky it sees.
   */
  float learned_share;
  /**
   * The prior count of unoccluded rays in each visibility estimate (positive
   * and finite), so that no estimate is 0.
   */
  float prior;
  /**
   * Seed of the rays' directions and origins.
   */
  uint64_t seed;
  /**
   * Must be zero: room for options added later without changing this struct's size.
   */
  uint32_t reserved[4];
} envlight_visibility_options;

/**
 * The renderer's tracer, called by `envlight_visibility_cache_build` with
 * batches of `count` rays: `origins` and `directions` hold `count · 3` floats
 * each (world frame, z up; unit directions; rays start exactly at the given
 * points, so offset them as your shadow rays need), and the callback writes the
 * transmittance in [0, 1] of each ray to `transmittance[0..count]` (1: the ray
 * escapes to the sky; 0: it is blocked). `user` is the pointer given to the
 * build. It returns `ENVLIGHT_OK` (0) on success; any other value stops the
 * build, which returns `ENVLIGHT_ERROR_CALLBACK` with a message giving the
 * value. The arrays are valid during the call only. It is called on the thread
 * that called the build, one batch at a time (never concurrently), and must not
 * unwind or `longjmp` out (catch C++ exceptions inside; `envlight.hpp` does).
 */
typedef int32_t (*envlight_visibility_trace)(void *user,
                                             const float *origins,
                                             const float *directions,
                                             size_t count,
                                             float *transmittance);

/**
 * What a visibility cache holds (`envlight_visibility_cache_summary`).
 */
typedef struct envlight_visibility_summary {
  /**
   * Entries.
   */
  uint64_t entries;
  /**
   * Bytes of the entries' tables and of the lookup.
   */
  uint64_t bytes;
  /**
   * The cells' side, world units.
   */
  float radius;
  /**
   * The light-weighted visibility of each entry over the patches it can
   * face, averaged over entries, in [0, 1].
   */
  double mean_visibility;
  /**
   * Rays traced to build it (those of the build that made it, for a loaded
   * cache).
   */
  uint64_t rays;
} envlight_visibility_summary;

/**
 * A compact bright source as a uniform disc. Radiometric values are linear RGB
 * with the light's scale applied; the direction is in the world frame (the
 * light's rotation applied), z up.
 */
typedef struct envlight_sun {
  /**
   * Unit direction towards the disc's centre.
   */
  float direction[3];
  /**
   * Angular radius of the disc, in degrees.
   */
  double angular_radius_deg;
  /**
   * Solid angle of the disc, `2π (1 − cos r)`, in steradians.
   */
  double solid_angle_sr;
  /**
   * The disc's uniform radiance.
   */
  double radiance[3];
  /**
   * Irradiance at normal incidence, `L π sin² r`.
   */
  double irradiance[3];
  /**
   * The source's share of the map's `∫ Y dω`, in [0, 1].
   */
  double power_fraction;
  /**
   * Elevation above the horizon (the xy plane), in degrees.
   */
  double elevation_deg;
  /**
   * Azimuth in [0, 360) degrees, from +x towards +y.
   */
  double azimuth_deg;
  /**
   * The disc's mean luminance over the surrounding sky's median (+∞ on a black sky).
   */
  double contrast;
} envlight_sun;

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/**
 * The library's version, `"MAJOR.MINOR.PATCH"` (static storage; never NULL).
 */
const char *envlight_version(void);

/**
 * Copies this thread's last error message into `buf` (at most `len - 1` bytes and
 * a terminating NUL; nothing when `buf` is NULL or `len` is 0) and returns the
 * message's length in bytes, without the NUL, like `snprintf`: a buffer of the
 * returned length + 1 holds it whole. The message is set by every failing call on
 * this thread and kept until the next failure; "" before any.
 */
size_t envlight_last_error(char *buf, size_t len);

/**
 * A short static name for a status (`"ENVLIGHT_OK"`, ...; `"unknown status"` for
 * a value that is none).
 */
const char *envlight_status_name(uint32_t status);

/**
 * The default options: inversion sampler, piecewise-bilinear density,
 * equirectangular mapping and input, bilinear lookup, no rotation, scale 1, one
 * table cell per texel. With the alias or hierarchical sampler or a
 * `table_width`, set the density to `ENVLIGHT_DENSITY_PIECEWISE_CONSTANT` too.
 */
struct envlight_light_options envlight_light_options_default(void);

/**
 * Reads the map at `path` (`.hdr`, `.exr`, `.pfm`, 8-bit `.png`/`.jpg`; the content
 * decides, not the name) and builds a light with `options` (NULL: the defaults).
 * On success `*out` holds a new light to free with `envlight_light_free`; on
 * failure `*out` is set to NULL (when `out` is not NULL) and the status says why:
 * `ENVLIGHT_ERROR_NOT_FOUND`, `_IO`, `_FORMAT`, `_INVALID_IMAGE` (a NaN or
 * infinite texel, named) or `_INVALID_ARGUMENT`.
 */
enum envlight_status envlight_light_load(const char *path,
                                         const struct envlight_light_options *options,
                                         struct envlight_light **out);

/**
 * Builds a light from `height` rows of `width` linear RGB texels at `rgb`
 * (`height · width · 3` floats, row 0 at the top (θ = 0), column 0 at φ = 0), with
 * `options` (NULL: the defaults). The texels are copied. Every channel must be
 * finite and >= 0 (`ENVLIGHT_ERROR_INVALID_IMAGE` names the first that is not);
 * a zero or too large size is `ENVLIGHT_ERROR_INVALID_ARGUMENT`. `*out` as for
 * `envlight_light_load`.
 */
enum envlight_status envlight_light_from_rgb(const float *rgb,
                                             uint32_t width,
                                             uint32_t height,
                                             const struct envlight_light_options *options,
                                             struct envlight_light **out);

/**
 * Frees a light (NULL: nothing). Handles built from it (product samplers,
 * portal lights, sun extractions, GPU tables) keep what they need and stay
 * valid.
 */
void envlight_light_free(struct envlight_light *light);

/**
 * Draws a direction for `u` in [0, 1)², with density proportional to the map's
 * luminance (times the mapping's area factor). Writes `*out` and returns true;
 * returns false and zeroes `*out` when there is no direction (a black map, a
 * point on a pole of a lat-long map, a non-finite `u`) or an argument is NULL.
 */
bool envlight_light_sample(const struct envlight_light *light,
                           const float *u,
                           struct envlight_sample *out);

/**
 * The solid-angle density (per steradian) with which `envlight_light_sample`
 * draws the unit world direction `direction`: 0 where the light is black, at a
 * pole of a lat-long map, for a non-finite or zero direction, and for NULL
 * arguments.
 */
float envlight_light_pdf(const struct envlight_light *light, const float *direction);

/**
 * The radiance arriving from the unit world direction `direction` (linear RGB,
 * scale applied), written to `rgb`; zeros for NULL `light` or `direction`.
 */
void envlight_light_radiance(const struct envlight_light *light,
                             const float *direction,
                             float *rgb);

/**
 * `envlight_light_sample` for each of the `n` points `u[2i], u[2i+1]`, written to
 * `out[i]` (a zeroed sample where there is no direction), in parallel on the
 * library's thread pool. The results do not depend on the thread count.
 * `u` and `out` may be NULL when `n` is 0.
 */
enum envlight_status envlight_light_sample_batch(const struct envlight_light *light,
                                                 const float *u,
                                                 size_t n,
                                                 struct envlight_sample *out);

/**
 * `envlight_light_pdf` of each of the `n` directions at `directions` (`3n`
 * floats), written to `pdf[i]`, in parallel.
 */
enum envlight_status envlight_light_pdf_batch(const struct envlight_light *light,
                                              const float *directions,
                                              size_t n,
                                              float *pdf);

/**
 * `envlight_light_radiance` of each of the `n` directions at `directions`,
 * written to `rgb[3i..3i+3]`, in parallel.
 */
enum envlight_status envlight_light_radiance_batch(const struct envlight_light *light,
                                                   const float *directions,
                                                   size_t n,
                                                   float *rgb);

/**
 * The point `u` that `envlight_light_sample` maps to the unit world direction
 * `direction` (the inverse of sampling, up to float rounding), written to `u`;
 * false (and `u` zeroed) for the alias sampler, which has no inverse, and for NULL
 * arguments.
 */
bool envlight_light_invert(const struct envlight_light *light, const float *direction, float *u);

/**
 * Fills `*info` with what `light` is (cheap: nothing is integrated here; see
 * `envlight_light_efficiency`).
 */
enum envlight_status envlight_light_get_info(const struct envlight_light *light,
                                             struct envlight_light_info *info);

/**
 * The light's sampling efficiency `(∫ Y dω)² / ∫ (Y² / p) dω`, integrated by
 * quadrature over the map (1 when the pdf is proportional to luminance; about
 * as costly as building the light). 0 for a black map or a NULL `light`.
 */
double envlight_light_efficiency(const struct envlight_light *light);

/**
 * Lays `light` out as GPU tables with the radiance stored as
 * `radiance_format` (an `envlight_radiance_format`). `ENVLIGHT_ERROR_UNSUPPORTED`
 * for the hierarchical sampler (not ported) and for f16 radiance of a map with a
 * texel above 65504 (named).
 */
enum envlight_status envlight_light_gpu_tables(const struct envlight_light *light,
                                               uint32_t radiance_format,
                                               struct envlight_gpu_tables **out);

/**
 * Frees GPU tables (NULL: nothing).
 */
void envlight_gpu_tables_free(struct envlight_gpu_tables *tables);

/**
 * A pointer to one of the buffers (an `envlight_gpu_buffer`) as 32-bit
 * little-endian words, valid while `tables` lives, with its length in words
 * written to `*words`. NULL (and `*words` 0) for NULL arguments or an unknown
 * buffer.
 */
const uint32_t *envlight_gpu_tables_buffer(const struct envlight_gpu_tables *tables,
                                           uint32_t buffer,
                                           size_t *words);

/**
 * The tables as the file `envlight export` writes (a header, a section table,
 * the sections on 16-byte boundaries), copied into `buf` when it holds `len >=`
 * the file's size; returns the file's size in bytes (0 for a NULL `tables`). Call
 * with `buf` NULL to learn the size. A `len` too small copies nothing.
 */
size_t envlight_gpu_tables_to_bytes(const struct envlight_gpu_tables *tables,
                                    uint8_t *buf,
                                    size_t len);

/**
 * Builds a portal light over `light` from `count` portals at `corners`
 * (`count · 12` floats: each portal's four corners `x, y, z`, in order around a
 * planar convex quad, either winding; world frame). `resolution` is the cells
 * along each side of a portal's table (0: the light image's height clamped to
 * [32, 1024]). At most 8 portals. A bad quad is `ENVLIGHT_ERROR_INVALID_ARGUMENT`
 * with a message naming the portal (from 0) and what is wrong.
 */
enum envlight_status envlight_portal_light_new(const struct envlight_light *light,
                                               const float *corners,
                                               size_t count,
                                               uint32_t resolution,
                                               struct envlight_portal_light **out);

/**
 * Frees a portal light (NULL: nothing).
 */
void envlight_portal_light_free(struct envlight_portal_light *light);

/**
 * Draws a direction from the point `point` through the portals, for `u` in
 * [0, 1)², in proportion to the radiance seen through them. False (and `*out`
 * zeroed) when nothing lit is seen through a portal from `point`, `u` or `point`
 * is not finite, or an argument is NULL.
 */
bool envlight_portal_light_sample(const struct envlight_portal_light *light,
                                  const float *point,
                                  const float *u,
                                  struct envlight_sample *out);

/**
 * The density (per steradian) with which `envlight_portal_light_sample` draws
 * `direction` from `point`: 0 for a direction through no portal and for NULL
 * arguments.
 */
float envlight_portal_light_pdf(const struct envlight_portal_light *light,
                                const float *point,
                                const float *direction);

/**
 * `envlight_portal_light_sample` for `n` points (`points[3i..3i+3]` with
 * `u[2i], u[2i+1]`), written to `out[i]`, in parallel.
 */
enum envlight_status envlight_portal_light_sample_batch(const struct envlight_portal_light *light,
                                                        const float *points,
                                                        const float *u,
                                                        size_t n,
                                                        struct envlight_sample *out);

/**
 * `envlight_portal_light_pdf` for `n` points and directions, written to `pdf[i]`,
 * in parallel.
 */
enum envlight_status envlight_portal_light_pdf_batch(const struct envlight_portal_light *light,
                                                     const float *points,
                                                     const float *directions,
                                                     size_t n,
                                                     float *pdf);

/**
 * Builds the product sampler of `light` (default options: the light's own density
 * within patches, tables over an octahedral grid of normals). `*out` holds it on
 * success (NULL on failure).
 */
enum envlight_status envlight_product_new(const struct envlight_light *light,
                                          struct envlight_product **out);

/**
 * Frees a product sampler (NULL: nothing).
 */
void envlight_product_free(struct envlight_product *product);

/**
 * Bytes of the product sampler's tables.
 */
uint64_t envlight_product_memory_bytes(const struct envlight_product *product);

/**
 * Draws a direction for `u` in [0, 1)² with density proportional to radiance ×
 * `factor` (up to the tables' resolution; the pdf is exact). Returns false and
 * zeroes `*out` when nothing lit is seen by the factor, the factor is invalid,
 * `u` is not finite, or an argument is NULL.
 */
bool envlight_product_sample(const struct envlight_product *product,
                             const struct envlight_factor *factor,
                             const float *u,
                             struct envlight_sample *out);

/**
 * The density (per steradian) with which `envlight_product_sample` draws the unit
 * world direction `direction` at `factor`; 0 for NULL arguments.
 */
float envlight_product_pdf(const struct envlight_product *product,
                           const struct envlight_factor *factor,
                           const float *direction);

/**
 * `envlight_product_sample` for each of `n` shading points: `factors[i]` and
 * `u[2i], u[2i+1]` give `out[i]`, in parallel; independent of the thread count.
 */
enum envlight_status envlight_product_sample_batch(const struct envlight_product *product,
                                                   const struct envlight_factor *factors,
                                                   const float *u,
                                                   size_t n,
                                                   struct envlight_sample *out);

/**
 * `envlight_product_pdf` for each of `n` shading points: `factors[i]` and the
 * direction `directions[3i..3i+3]` give `pdf[i]`, in parallel.
 */
enum envlight_status envlight_product_pdf_batch(const struct envlight_product *product,
                                                const struct envlight_factor *factors,
                                                const float *directions,
                                                size_t n,
                                                float *pdf);

/**
 * The default options: the automatic radius aiming at 512 entries, 4 × 4 bins
 * of normals, a 64 MiB budget, 4 rays per entry and patch, a learned share of
 * 0.9, a prior of 0.1 rays and the library's seed.
 */
struct envlight_visibility_options envlight_visibility_options_default(void);

/**
 * Builds a visibility cache over `product` from `count` shading points:
 * `points` and `normals` hold `count · 3` floats each (world frame; normals
 * need not be unit length, but must be finite and non-zero, and the points
 * finite), typically the first hits of the renderer's camera rays. The build
 * asks `trace(user, ...)` for the transmittance of batches of rays (see
 * `envlight_visibility_trace`); `options` NULL means the defaults. `*out` holds
 * the cache on success (NULL on failure).
 *
 * Statuses: `ENVLIGHT_ERROR_CALLBACK` when `trace` returns anything but
 * `ENVLIGHT_OK`; `ENVLIGHT_ERROR_INVALID_ARGUMENT` for a NULL argument, an
 * option out of range (`options.FIELD ...`), a point or normal that is not
 * finite or a zero normal (`point i: ...`), or a transmittance the callback
 * wrote that is NaN or outside [0, 1] (naming the ray and the value).
 */
enum envlight_status envlight_visibility_cache_build(const struct envlight_product *product,
                                                     const float *points,
                                                     const float *normals,
                                                     size_t count,
                                                     const struct envlight_visibility_options *options,
                                                     envlight_visibility_trace trace,
                                                     void *user,
                                                     struct envlight_visibility_cache **out);

/**
 * Frees a visibility cache (NULL: nothing).
 */
void envlight_visibility_cache_free(struct envlight_visibility_cache *cache);

/**
 * Draws a direction at the shading point `point` with normal `normal` (world
 * frame; any length) for `u` in [0, 1)², from the cache's mixture of its
 * learned distribution and the product sampler's cosine-weighted one (the
 * product sampler alone where the build put no entry). Returns false and zeroes
 * `*out` when nothing lit can be drawn there, `u` is not finite, or an argument
 * is NULL.
 */
bool envlight_visibility_cache_sample(const struct envlight_visibility_cache *cache,
                                      const float *point,
                                      const float *normal,
                                      const float *u,
                                      struct envlight_sample *out);

/**
 * The density (per steradian) with which `envlight_visibility_cache_sample`
 * draws the unit world direction `direction` at `(point, normal)`; 0 for NULL
 * arguments.
 */
float envlight_visibility_cache_pdf(const struct envlight_visibility_cache *cache,
                                    const float *point,
                                    const float *normal,
                                    const float *direction);

/**
 * `envlight_visibility_cache_sample` for each of `n` shading points:
 * `points[3i..3i+3]`, `normals[3i..3i+3]` and `u[2i], u[2i+1]` give `out[i]`, in
 * parallel; independent of the thread count.
 */
enum envlight_status envlight_visibility_cache_sample_batch(const struct envlight_visibility_cache *cache,
                                                            const float *points,
                                                            const float *normals,
                                                            const float *u,
                                                            size_t n,
                                                            struct envlight_sample *out);

/**
 * `envlight_visibility_cache_pdf` for each of `n` shading points: `points[3i..]`,
 * `normals[3i..]` and the direction `directions[3i..3i+3]` give `pdf[i]`, in
 * parallel (0 for the all-zero direction of a sample that drew none).
 */
enum envlight_status envlight_visibility_cache_pdf_batch(const struct envlight_visibility_cache *cache,
                                                         const float *points,
                                                         const float *normals,
                                                         const float *directions,
                                                         size_t n,
                                                         float *pdf);

/**
 * Writes the cache to the file `path` with `scene_key` (UTF-8, at most 65536
 * bytes: what says which scene it was learned in, such as a file name and a
 * version or a hash of the geometry). The file is written whole or not at all.
 * `ENVLIGHT_ERROR_IO` (or `_NOT_FOUND` for a missing folder) names the path.
 */
enum envlight_status envlight_visibility_cache_save(const struct envlight_visibility_cache *cache,
                                                    const char *path,
                                                    const char *scene_key);

/**
 * Reads a cache saved by `envlight_visibility_cache_save` for `product`'s light
 * in the scene `scene_key`. `*out` holds it on success (NULL on failure).
 * `ENVLIGHT_ERROR_MISMATCH` when the file was made for another light (image,
 * options or patch grid) or another scene key, with a message naming both;
 * `ENVLIGHT_ERROR_NOT_FOUND`, `_IO` or `_FORMAT` (a file that is not a
 * well-formed cache) naming the path.
 */
enum envlight_status envlight_visibility_cache_load(const char *path,
                                                    const struct envlight_product *product,
                                                    const char *scene_key,
                                                    struct envlight_visibility_cache **out);

/**
 * Fills `*summary` with what the cache holds: entries, bytes, radius, mean
 * visibility and rays.
 */
enum envlight_status envlight_visibility_cache_summary(const struct envlight_visibility_cache *cache,
                                                       struct envlight_visibility_summary *summary);

/**
 * Looks for the light's sun (radius <= 5°, contrast >= 20, >= 1% of the power) and
 * in-paints it out of a copy of the image. `*out` holds the result on success
 * (NULL on failure); whether a sun was found is `envlight_sun_extraction_sun`'s
 * answer.
 */
enum envlight_status envlight_light_extract_sun(const struct envlight_light *light,
                                                struct envlight_sun_extraction **out);

/**
 * Frees a sun extraction (NULL: nothing).
 */
void envlight_sun_extraction_free(struct envlight_sun_extraction *extraction);

/**
 * Writes the sun to `*sun` and returns true; false (and `*sun` zeroed) when the
 * map has none or an argument is NULL.
 */
bool envlight_sun_extraction_sun(const struct envlight_sun_extraction *extraction,
                                 struct envlight_sun *sun);

/**
 * The residual image's size (the light's image's), written to `*width` and
 * `*height`, and the number of texels in-painted as the return value (0 also for
 * NULL arguments).
 */
uint64_t envlight_sun_extraction_residual_size(const struct envlight_sun_extraction *extraction,
                                               uint32_t *width,
                                               uint32_t *height);

/**
 * Copies the residual image (the map without its sun, in the image's own units:
 * the scale not applied; the image itself when there is no sun) into `rgb`, which
 * holds `len` floats: at least `width · height · 3`, rows from the top. With the
 * disc it reproduces the map's irradiance at any normal that does not graze the
 * sun; build a light from it with `envlight_light_from_rgb` and the same options.
 */
enum envlight_status envlight_sun_extraction_residual(const struct envlight_sun_extraction *extraction,
                                                      float *rgb,
                                                      size_t len);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* ENVLIGHT_H */
