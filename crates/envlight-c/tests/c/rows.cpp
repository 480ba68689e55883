// rows.cpp: the C++17 header's answers for given inputs, as rows that
// tests/c_programs.rs compares with the Rust library bit for bit (the "S", "P",
// "L" and "C" rows of rows.c, same format), through the batch calls over
// std::vector and the single calls, which must agree. Also checks that errors
// arrive as envlight::error with the status and the message.
//
//   rows_cpp MAP INPUTS     (MAP as for rows.c)
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <vector>

#include "envlight.hpp"
#include "common.hpp"

namespace {

using test_common::bits;
using test_common::open;
using test_common::read_file;

}  // namespace

int main(int argc, char **argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: rows_cpp MAP INPUTS\n");
        return 2;
    }
    try {
        // Errors are exceptions carrying the status and the message.
        try {
            envlight::light::load("/nonexistent/envlight.exr");
            std::fprintf(stderr, "rows_cpp: loading a missing file did not throw\n");
            return 1;
        } catch (const envlight::error &e) {
            if (e.status() != ENVLIGHT_ERROR_NOT_FOUND ||
                std::strstr(e.what(), "/nonexistent/envlight.exr") == nullptr) {
                std::fprintf(stderr, "rows_cpp: wrong error: %d %s\n", int(e.status()), e.what());
                return 1;
            }
        }

        const envlight::light light = open(argv[1]);
        envlight::light moved = open(argv[1]);
        envlight::light other = std::move(moved);  // move-only handles
        (void)other;
        const envlight::product product(light);

        std::vector<char> inputs = read_file(argv[2]);
        std::uint32_t n;
        std::memcpy(&n, inputs.data(), sizeof n);
        std::vector<float> u(2 * std::size_t(n)), dirs(3 * std::size_t(n));
        std::memcpy(u.data(), inputs.data() + 4, u.size() * sizeof(float));
        std::memcpy(dirs.data(), inputs.data() + 4 + u.size() * sizeof(float), dirs.size() * sizeof(float));

        std::vector<envlight_sample> samples(n);
        std::vector<float> pdf(n), rgb(3 * std::size_t(n));
        light.sample(u, samples);
        light.pdf(dirs, pdf);
        light.radiance(dirs, rgb);
        std::vector<envlight_factor> factors(n);
        for (std::uint32_t k = 0; k < n; k++) {
            factors[k] = envlight_factor{{dirs[3 * k], dirs[3 * k + 1], dirs[3 * k + 2]}, {0, 0, 0}, 0.0f};
        }
        std::vector<envlight_sample> cosine(n);
        product.sample(factors, u, cosine);

        for (std::uint32_t k = 0; k < n; k++) {
            const envlight_sample &s = samples[k];
            const auto single = light.sample({u[2 * k], u[2 * k + 1]});
            const envlight_sample zero{};
            const envlight_sample &t = single ? *single : zero;
            const std::array<float, 3> d{dirs[3 * k], dirs[3 * k + 1], dirs[3 * k + 2]};
            const auto l = light.radiance(d);
            if (std::memcmp(&s, &t, sizeof s) != 0 || bits(light.pdf(d)) != bits(pdf[k]) ||
                std::memcmp(l.data(), &rgb[3 * k], sizeof l) != 0) {
                std::fprintf(stderr, "rows_cpp: batch row %u differs from the single calls\n", k);
                return 1;
            }
            std::printf("S %u %u %08x %08x %08x %08x %08x %08x %08x\n", k, unsigned(s.pdf > 0.0f),
                        bits(s.direction[0]), bits(s.direction[1]), bits(s.direction[2]), bits(s.pdf),
                        bits(s.radiance[0]), bits(s.radiance[1]), bits(s.radiance[2]));
            std::printf("P %u %08x\n", k, bits(pdf[k]));
            std::printf("L %u %08x %08x %08x\n", k, bits(rgb[3 * k]), bits(rgb[3 * k + 1]),
                        bits(rgb[3 * k + 2]));
            const envlight_sample &c = cosine[k];
            std::printf("C %u %u %08x %08x %08x %08x\n", k, unsigned(c.pdf > 0.0f), bits(c.direction[0]),
                        bits(c.direction[1]), bits(c.direction[2]), bits(c.pdf));
        }

        // A range too short is an exception, not a read past its end.
        try {
            std::vector<float> short_pdf(n + 1);
            light.pdf(dirs, short_pdf);
            std::fprintf(stderr, "rows_cpp: a short range did not throw\n");
            return 1;
        } catch (const envlight::error &e) {
            if (e.status() != ENVLIGHT_ERROR_INVALID_ARGUMENT) return 1;
        }
    } catch (const std::exception &e) {
        std::fprintf(stderr, "rows_cpp: %s\n", e.what());
        return 1;
    }
    return 0;
}
