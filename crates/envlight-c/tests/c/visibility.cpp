// visibility.cpp: the C++17 header's visibility cache, built with a lambda that
// traces the room of visibility.c; prints that program's rows ("V", "W", "Y",
// "T", same query points and format) through the batch calls over std::vector,
// which must agree with the single calls, for tests/c_programs.rs to compare with
// the Rust library bit for bit. Also checks that a saved cache loads back the
// same, and that an exception thrown by the callable reaches the caller
// unchanged (its own type and value), never crossing the C boundary.
//
//   visibility_cpp MAP INPUTS DIR     (as for visibility.c)
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <vector>

#include "envlight.hpp"
#include "common.hpp"

namespace {

using test_common::bits;
using test_common::bits64;
using test_common::open;
using test_common::read_file;


float exit_time(float o, float d, float lo, float hi) {
    if (d > 0.0f) return (hi - o) / d;
    if (d < 0.0f) return (lo - o) / d;
    return std::numeric_limits<float>::infinity();
}

// 1 when the ray from o (inside the room) along d leaves through the window.
float room(const float *o, const float *d) {
    const float tx = exit_time(o[0], d[0], -1.0f, 1.0f);
    const float ty = exit_time(o[1], d[1], -1.0f, 1.0f);
    const float tz = exit_time(o[2], d[2], 0.0f, 2.0f);
    const float y = o[1] + d[1] * tx, z = o[2] + d[2] * tx;
    const bool window = d[0] > 0.0f && tx <= ty && tx <= tz;
    return window && std::fabs(y) < 0.4f && z > 0.6f && z < 1.4f ? 1.0f : 0.0f;
}

// An exception of the caller's own, not derived from std::exception.
struct out_of_rays {
    std::size_t count;
};

// An exception derived from std::runtime_error, not from envlight::error.
struct tracer_error : std::runtime_error {
    using std::runtime_error::runtime_error;
};

}  // namespace

int main(int argc, char **argv) {
    if (argc != 4) {
        std::fprintf(stderr, "usage: visibility_cpp MAP INPUTS DIR\n");
        return 2;
    }
    try {
        const envlight::light light = open(argv[1]);
        const envlight::product product(light);

        std::vector<float> build_points, build_normals;
        for (int i = 0; i < 20; i++) {
            for (int j = 0; j < 20; j++) {
                const float a = (float(i) + 0.5f) / 10.0f - 1.0f, b = (float(j) + 0.5f) / 10.0f - 1.0f;
                build_points.insert(build_points.end(), {a, b, 0.0f, -1.0f, a, b + 1.0f});
                build_normals.insert(build_normals.end(), {0.0f, 0.0f, 1.0f, 1.0f, 0.0f, 0.0f});
            }
        }
        envlight_visibility_options options = envlight::default_visibility_options();
        options.seed = 7;
        options.rays_per_patch = 2;
        std::uint64_t rays = 0;
        auto trace = [&rays](const float *origins, const float *directions, std::size_t count,
                             float *transmittance) {
            rays += count;
            for (std::size_t i = 0; i < count; i++)
                transmittance[i] = room(origins + 3 * i, directions + 3 * i);
        };
        const envlight::visibility_cache cache =
            envlight::visibility_cache::build(product, build_points, build_normals, trace, options);
        const envlight_visibility_summary summary = cache.summary();
        if (summary.rays != rays) {
            std::fprintf(stderr, "visibility_cpp: the summary's rays are not the callable's\n");
            return 1;
        }

        std::vector<char> inputs = read_file(argv[2]);
        std::uint32_t n;
        std::memcpy(&n, inputs.data(), sizeof n);
        std::vector<float> u(2 * std::size_t(n)), dirs(3 * std::size_t(n));
        std::memcpy(u.data(), inputs.data() + 4, u.size() * sizeof(float));
        std::memcpy(dirs.data(), inputs.data() + 4 + u.size() * sizeof(float), dirs.size() * sizeof(float));
        std::vector<float> points(3 * std::size_t(n)), normals(3 * std::size_t(n));
        for (std::uint32_t k = 0; k < n; k++) {
            const float a = float(k % 19) / 10.0f - 0.9f, b = float(k % 17) / 9.0f - 0.9f;
            float *p = &points[3 * k], *nrm = &normals[3 * k];
            const float floor_p[3] = {a, b, 0.0f}, wall_p[3] = {-1.0f, a, b + 1.0f},
                        out_p[3] = {5.0f + a, b, 3.0f};
            const float up[3] = {0.0f, 0.0f, 1.0f}, east[3] = {1.0f, 0.0f, 0.0f},
                        far_up[3] = {0.0f, 0.0f, k % 12 == 5 ? 3.0f : 0.0f};
            const float *pick_p = floor_p, *pick_n = up;
            switch (k % 6) {
            case 2:
            case 3:
                pick_p = wall_p;
                pick_n = east;
                break;
            case 4:
                pick_p = out_p;
                break;
            case 5:
                pick_n = far_up;
                break;
            default:
                break;
            }
            std::memcpy(p, pick_p, sizeof floor_p);
            std::memcpy(nrm, pick_n, sizeof up);
        }

        std::vector<envlight_sample> samples(n);
        std::vector<float> pdf(n);
        cache.sample(points, normals, u, samples);
        cache.pdf(points, normals, dirs, pdf);

        // Saved and loaded back: the same samples.
        const std::string path = std::string(argv[3]) + "/room-cpp.envlvis";
        cache.save(path, "room v1");
        const envlight::visibility_cache loaded = envlight::visibility_cache::load(path, product, "room v1");
        std::vector<envlight_sample> reloaded(n);
        loaded.sample(points, normals, u, reloaded);
        if (std::memcmp(samples.data(), reloaded.data(), n * sizeof(envlight_sample)) != 0) {
            std::fprintf(stderr, "visibility_cpp: the loaded cache samples differently\n");
            return 1;
        }
        try {
            envlight::visibility_cache::load(path, product, "room v2");
            std::fprintf(stderr, "visibility_cpp: loading under another key did not throw\n");
            return 1;
        } catch (const envlight::error &e) {
            if (e.status() != ENVLIGHT_ERROR_MISMATCH || !std::strstr(e.what(), "\"room v2\"")) {
                std::fprintf(stderr, "visibility_cpp: wrong error: %d %s\n", int(e.status()), e.what());
                return 1;
            }
        }

        // An exception thrown by the callable arrives unchanged, whatever its type.
        int calls = 0;
        try {
            envlight::visibility_cache::build(
                product, build_points, build_normals,
                [&calls](const float *, const float *, std::size_t count, float *) {
                    calls++;
                    throw out_of_rays{count};
                });
            std::fprintf(stderr, "visibility_cpp: a throwing callable did not throw\n");
            return 1;
        } catch (const out_of_rays &e) {
            if (calls != 1 || e.count == 0) {
                std::fprintf(stderr, "visibility_cpp: %d calls, count %zu\n", calls, e.count);
                return 1;
            }
        }
        try {
            envlight::visibility_cache::build(product, build_points, build_normals,
                                              [](const float *, const float *, std::size_t, float *) {
                                                  throw tracer_error("the scene is gone");
                                              });
            return 1;
        } catch (const envlight::error &e) {
            std::fprintf(stderr, "visibility_cpp: the callable's exception became %s\n", e.what());
            return 1;
        } catch (const tracer_error &e) {
            if (std::strcmp(e.what(), "the scene is gone") != 0) return 1;
        }
        // A transmittance out of range is the library's error.
        try {
            envlight::visibility_cache::build(product, build_points, build_normals,
                                              [](const float *, const float *, std::size_t count, float *t) {
                                                  for (std::size_t i = 0; i < count; i++) t[i] = 2.0f;
                                              });
            return 1;
        } catch (const envlight::error &e) {
            if (e.status() != ENVLIGHT_ERROR_INVALID_ARGUMENT || !std::strstr(e.what(), "transmittance 2")) {
                std::fprintf(stderr, "visibility_cpp: wrong error: %d %s\n", int(e.status()), e.what());
                return 1;
            }
        }

        std::printf("Y %llu %llu %08x %016llx %llu\n", (unsigned long long)summary.entries,
                    (unsigned long long)summary.bytes, bits(summary.radius),
                    (unsigned long long)bits64(summary.mean_visibility), (unsigned long long)summary.rays);
        std::printf("T %llu\n", (unsigned long long)rays);
        for (std::uint32_t k = 0; k < n; k++) {
            const envlight_sample &s = samples[k];
            const std::array<float, 3> p{points[3 * k], points[3 * k + 1], points[3 * k + 2]};
            const std::array<float, 3> nrm{normals[3 * k], normals[3 * k + 1], normals[3 * k + 2]};
            const auto single = cache.sample(p, nrm, {u[2 * k], u[2 * k + 1]});
            const envlight_sample zero{};
            const envlight_sample &t = single ? *single : zero;
            const std::array<float, 3> d{dirs[3 * k], dirs[3 * k + 1], dirs[3 * k + 2]};
            if (std::memcmp(&s, &t, sizeof s) != 0 || bits(cache.pdf(p, nrm, d)) != bits(pdf[k]) ||
                bits(cache.pdf(p, nrm, {s.direction[0], s.direction[1], s.direction[2]})) != bits(s.pdf)) {
                std::fprintf(stderr, "visibility_cpp: batch row %u differs from the single calls\n", k);
                return 1;
            }
            std::printf("V %u %u %08x %08x %08x %08x %08x %08x %08x\n", k, unsigned(s.pdf > 0.0f),
                        bits(s.direction[0]), bits(s.direction[1]), bits(s.direction[2]), bits(s.pdf),
                        bits(s.radiance[0]), bits(s.radiance[1]), bits(s.radiance[2]));
            std::printf("W %u %08x\n", k, bits(pdf[k]));
        }
    } catch (const std::exception &e) {
        std::fprintf(stderr, "visibility_cpp: %s\n", e.what());
        return 1;
    }
    return 0;
}
