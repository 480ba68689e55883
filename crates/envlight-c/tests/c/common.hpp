// Helpers the C++ test programs share: reading a file whole, a float's bits
// for exact comparisons, and a light from a map path or a raw `raw:FILE` dump
// (width and height as two u32, then RGB floats).
#ifndef ENVLIGHT_TESTS_COMMON_HPP
#define ENVLIGHT_TESTS_COMMON_HPP

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "envlight.hpp"

namespace test_common {

inline std::vector<char> read_file(const char *path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw std::runtime_error(std::string("cannot open ") + path);
    return std::vector<char>(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

inline std::uint32_t bits(float x) {
    std::uint32_t b;
    std::memcpy(&b, &x, sizeof b);
    return b;
}

inline std::uint64_t bits64(double x) {
    std::uint64_t b;
    std::memcpy(&b, &x, sizeof b);
    return b;
}

inline envlight::light open(const char *map) {
    if (std::strncmp(map, "raw:", 4) != 0) return envlight::light::load(map);
    std::vector<char> raw = read_file(map + 4);
    std::uint32_t wh[2];
    std::memcpy(wh, raw.data(), sizeof wh);
    std::vector<float> rgb(static_cast<std::size_t>(wh[0]) * wh[1] * 3);
    std::memcpy(rgb.data(), raw.data() + 8, rgb.size() * sizeof(float));
    return envlight::light::from_rgb(rgb, wh[0], wh[1]);
}

}  // namespace test_common

#endif
