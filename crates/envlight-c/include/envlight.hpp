// envlight.hpp: a C++17 interface over envlight.h, header-only.
//
// Move-only owners of the C handles, errors as envlight::error (the status and the
// library's message), batch calls over contiguous ranges. Every number is the C
// API's, which is the Rust library's, bit for bit. Reference: docs/c-api.md.
// Licence: MIT OR Apache-2.0.
//
//   envlight::light light = envlight::light::load("sky.exr");
//   std::vector<envlight_sample> out(n);
//   light.sample(u, out);  // u: 2n floats
#ifndef ENVLIGHT_HPP
#define ENVLIGHT_HPP

#include <array>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include "envlight.h"

namespace envlight {

/// A failed call: the status and this thread's message from the library.
class error : public std::runtime_error {
public:
    error(envlight_status status, const std::string &message)
        : std::runtime_error(message), status_(status) {}
    /// What kind of failure (never ENVLIGHT_OK).
    envlight_status status() const noexcept { return status_; }

private:
    envlight_status status_;
};

namespace detail {

/// This thread's last error message.
inline std::string last_error() {
    std::string message(envlight_last_error(nullptr, 0), '\0');
    envlight_last_error(message.data(), message.size() + 1);
    return message;
}

/// Throws envlight::error unless `status` is ENVLIGHT_OK.
inline void check(envlight_status status) {
    if (status != ENVLIGHT_OK) {
        throw error(status, last_error());
    }
}

/// Throws when a range holds fewer than `need` values.
inline void check_size(std::size_t have, std::size_t need, const char *what) {
    if (have < need) {
        throw error(ENVLIGHT_ERROR_INVALID_ARGUMENT,
                    std::string("envlight: ") + what + " holds " + std::to_string(have) +
                        " values, " + std::to_string(need) + " needed");
    }
}

/// A move-only owner of a C handle freed by `Free`.
template <typename T, void (*Free)(T *)>
class handle {
public:
    handle() noexcept = default;
    explicit handle(T *p) noexcept : p_(p) {}
    handle(const handle &) = delete;
    handle &operator=(const handle &) = delete;
    handle(handle &&o) noexcept : p_(std::exchange(o.p_, nullptr)) {}
    handle &operator=(handle &&o) noexcept {
        if (this != &o) {
            Free(p_);
            p_ = std::exchange(o.p_, nullptr);
        }
        return *this;
    }
    ~handle() { Free(p_); }
    T *get() const noexcept { return p_; }
    explicit operator bool() const noexcept { return p_ != nullptr; }

    /// The owner of the handle that `make(args..., &p)` writes to `p`; throws
    /// envlight::error when `make` fails.
    template <typename Make, typename... Args>
    static handle made_by(Make make, Args... args) {
        T *p = nullptr;
        check(make(args..., &p));
        return handle(p);
    }

private:
    T *p_ = nullptr;
};

/// The base of each wrapper: the C handle it owns.
template <typename T, void (*Free)(T *)>
class owner {
public:
    /// The C handle, for calls this header does not wrap.
    const T *get() const noexcept { return h_.get(); }

protected:
    using handle = detail::handle<T, Free>;
    explicit owner(handle h) noexcept : h_(std::move(h)) {}
    handle h_;
};

/// What `get(args..., &value)` writes to `value` when it returns true, or nothing.
template <typename T, typename Get, typename... Args>
std::optional<T> optional_out(Get get, Args... args) noexcept {
    T value;
    if (get(args..., &value)) {
        return value;
    }
    return std::nullopt;
}

/// What the visibility callback's trampoline carries: the caller's callable, and
/// the exception it threw, if any.
template <typename Trace>
struct trace_call {
    Trace &trace;
    std::exception_ptr thrown;
};

/// The C callback (envlight_visibility_trace) over a C++ callable: an exception
/// it throws never crosses the C boundary; it is kept here, the build stops with
/// ENVLIGHT_ERROR_CALLBACK, and the wrapper rethrows it once the C call returns.
template <typename Trace>
std::int32_t trace_trampoline(void *user, const float *origins, const float *directions,
                              std::size_t count, float *transmittance) noexcept {
    auto *call = static_cast<trace_call<Trace> *>(user);
    try {
        call->trace(origins, directions, count, transmittance);
        return ENVLIGHT_OK;
    } catch (...) {
        call->thrown = std::current_exception();
        return ENVLIGHT_ERROR_CALLBACK;
    }
}

}  // namespace detail

/// The library's version, "MAJOR.MINOR.PATCH".
inline std::string version() { return envlight_version(); }

/// The default light options (see envlight_light_options).
inline envlight_light_options default_options() { return envlight_light_options_default(); }

/// The default visibility cache options (see envlight_visibility_options).
inline envlight_visibility_options default_visibility_options() {
    return envlight_visibility_options_default();
}

class product;
class portal_light;

/// An importance-sampled environment light (envlight_light). Queries are const
/// and thread-safe.
class light : public detail::owner<envlight_light, envlight_light_free> {
public:
    /// Reads a map file (.hdr, .exr, .pfm, 8-bit .png/.jpg) and builds the light.
    static light load(const std::string &path,
                      const envlight_light_options &options = default_options()) {
        return light(handle::made_by(envlight_light_load, path.c_str(), &options));
    }

    /// Builds a light from `height` rows of `width` RGB texels (row 0 at the top);
    /// `rgb` holds at least width * height * 3 floats.
    template <typename R>
    static light from_rgb(const R &rgb, std::uint32_t width, std::uint32_t height,
                          const envlight_light_options &options = default_options()) {
        detail::check_size(static_cast<std::size_t>(rgb.size()),
                           std::size_t(width) * height * 3, "rgb");
        return light(handle::made_by(envlight_light_from_rgb, rgb.data(), width, height, &options));
    }

    /// A direction for `u` in [0, 1)^2, or nothing (a black map).
    std::optional<envlight_sample> sample(const std::array<float, 2> &u) const noexcept {
        return detail::optional_out<envlight_sample>(envlight_light_sample, h_.get(), u.data());
    }

    /// The solid-angle pdf (per steradian) of a unit world direction.
    float pdf(const std::array<float, 3> &direction) const noexcept {
        return envlight_light_pdf(h_.get(), direction.data());
    }

    /// The radiance arriving from a unit world direction (linear RGB).
    std::array<float, 3> radiance(const std::array<float, 3> &direction) const noexcept {
        std::array<float, 3> rgb{};
        envlight_light_radiance(h_.get(), direction.data(), rgb.data());
        return rgb;
    }

    /// One sample per point of `u` (2 floats each) into `out` (as many samples);
    /// a sample with pdf 0 where there is no direction.
    template <typename U, typename S>
    void sample(const U &u, S &out) const {
        const std::size_t n = static_cast<std::size_t>(out.size());
        detail::check_size(static_cast<std::size_t>(u.size()), 2 * n, "u");
        detail::check(envlight_light_sample_batch(h_.get(), u.data(), n, out.data()));
    }

    /// The pdf of each direction of `directions` (3 floats each) into `pdf`.
    template <typename D, typename P>
    void pdf(const D &directions, P &pdf) const {
        const std::size_t n = static_cast<std::size_t>(pdf.size());
        detail::check_size(static_cast<std::size_t>(directions.size()), 3 * n, "directions");
        detail::check(envlight_light_pdf_batch(h_.get(), directions.data(), n, pdf.data()));
    }

    /// The radiance of each direction of `directions` into `rgb` (3 floats each).
    template <typename D, typename C>
    void radiance(const D &directions, C &rgb) const {
        const std::size_t n = static_cast<std::size_t>(rgb.size()) / 3;
        detail::check_size(static_cast<std::size_t>(directions.size()), 3 * n, "directions");
        detail::check(envlight_light_radiance_batch(h_.get(), directions.data(), n, rgb.data()));
    }

    /// The `u` that sampling maps to a direction; nothing for the alias sampler.
    std::optional<std::array<float, 2>> invert(const std::array<float, 3> &direction) const noexcept {
        std::array<float, 2> u{};
        if (envlight_light_invert(h_.get(), direction.data(), u.data())) {
            return u;
        }
        return std::nullopt;
    }

    /// Sizes, integrals, the brightest direction, memory.
    envlight_light_info info() const {
        envlight_light_info i;
        detail::check(envlight_light_get_info(h_.get(), &i));
        return i;
    }

    /// (∫Y dω)² / ∫(Y²/p) dω, by quadrature.
    double efficiency() const noexcept { return envlight_light_efficiency(h_.get()); }

    /// The light's GPU tables, as envlight_gpu_tables (free with envlight_gpu_tables_free),
    /// owned by the returned handle.
    using gpu_tables = detail::handle<envlight_gpu_tables, envlight_gpu_tables_free>;
    gpu_tables export_gpu_tables(std::uint32_t radiance_format = ENVLIGHT_RADIANCE_F32) const {
        return gpu_tables::made_by(envlight_light_gpu_tables, h_.get(), radiance_format);
    }

private:
    explicit light(handle h) noexcept : owner(std::move(h)) {}
};

/// Product sampling at shading points (envlight_product).
class product : public detail::owner<envlight_product, envlight_product_free> {
public:
    explicit product(const light &l) : owner(handle::made_by(envlight_product_new, l.get())) {}

    std::optional<envlight_sample> sample(const envlight_factor &factor,
                                          const std::array<float, 2> &u) const noexcept {
        return detail::optional_out<envlight_sample>(envlight_product_sample, h_.get(), &factor,
                                                     u.data());
    }

    float pdf(const envlight_factor &factor, const std::array<float, 3> &direction) const noexcept {
        return envlight_product_pdf(h_.get(), &factor, direction.data());
    }

    /// One sample per factor of `factors` and point of `u` (2 floats each) into `out`.
    template <typename F, typename U, typename S>
    void sample(const F &factors, const U &u, S &out) const {
        const std::size_t n = static_cast<std::size_t>(out.size());
        detail::check_size(static_cast<std::size_t>(factors.size()), n, "factors");
        detail::check_size(static_cast<std::size_t>(u.size()), 2 * n, "u");
        detail::check(envlight_product_sample_batch(h_.get(), factors.data(), u.data(), n, out.data()));
    }

    template <typename F, typename D, typename P>
    void pdf(const F &factors, const D &directions, P &pdf) const {
        const std::size_t n = static_cast<std::size_t>(pdf.size());
        detail::check_size(static_cast<std::size_t>(factors.size()), n, "factors");
        detail::check_size(static_cast<std::size_t>(directions.size()), 3 * n, "directions");
        detail::check(envlight_product_pdf_batch(h_.get(), factors.data(), directions.data(), n, pdf.data()));
    }
};

/// Sampling at shading points in proportion to the sky each region of the scene
/// sees, learned from rays the renderer traces (envlight_visibility_cache). Queries
/// are const and thread-safe; the cache keeps its product sampler alive.
class visibility_cache
    : public detail::owner<envlight_visibility_cache, envlight_visibility_cache_free> {
public:
    /// Builds the cache over `p` from shading points and their normals (3 floats
    /// each per point, world frame), calling `trace(origins, directions, count,
    /// transmittance)` (any callable taking `const float *, const float *,
    /// std::size_t, float *`) for batches of rays: it writes `count`
    /// transmittances in [0, 1]. An exception it throws stops the build and
    /// arrives here unchanged; every other failure is an envlight::error.
    template <typename P, typename N, typename Trace>
    static visibility_cache build(const product &p, const P &points, const N &normals,
                                  Trace &&trace,
                                  const envlight_visibility_options &options =
                                      default_visibility_options()) {
        const std::size_t n = static_cast<std::size_t>(points.size()) / 3;
        detail::check_size(static_cast<std::size_t>(normals.size()), 3 * n, "normals");
        using callable = std::remove_reference_t<Trace>;
        detail::trace_call<callable> call{trace, nullptr};
        envlight_visibility_cache *c = nullptr;
        const envlight_status status = envlight_visibility_cache_build(
            p.get(), points.data(), normals.data(), n, &options,
            detail::trace_trampoline<callable>, &call, &c);
        handle h(c);
        if (call.thrown) {
            std::rethrow_exception(call.thrown);
        }
        detail::check(status);
        return visibility_cache(std::move(h));
    }

    /// Reads a cache saved by `save` for the light of `p` in the scene
    /// `scene_key`; envlight::error with ENVLIGHT_ERROR_MISMATCH naming both when
    /// it was made for another light or scene.
    static visibility_cache load(const std::string &path, const product &p,
                                 const std::string &scene_key) {
        return visibility_cache(handle::made_by(envlight_visibility_cache_load, path.c_str(),
                                                p.get(), scene_key.c_str()));
    }

    /// Writes the cache to `path` with `scene_key`, which says which scene it was
    /// learned in.
    void save(const std::string &path, const std::string &scene_key) const {
        detail::check(envlight_visibility_cache_save(h_.get(), path.c_str(), scene_key.c_str()));
    }

    /// A direction at the shading point `point` with normal `normal` for `u` in
    /// [0, 1)^2, or nothing.
    std::optional<envlight_sample> sample(const std::array<float, 3> &point,
                                          const std::array<float, 3> &normal,
                                          const std::array<float, 2> &u) const noexcept {
        return detail::optional_out<envlight_sample>(envlight_visibility_cache_sample, h_.get(),
                                                     point.data(), normal.data(), u.data());
    }

    /// The pdf (per steradian) of a unit world direction at `(point, normal)`.
    float pdf(const std::array<float, 3> &point, const std::array<float, 3> &normal,
              const std::array<float, 3> &direction) const noexcept {
        return envlight_visibility_cache_pdf(h_.get(), point.data(), normal.data(),
                                             direction.data());
    }

    /// One sample per shading point of `points` and `normals` (3 floats each) and
    /// point of `u` (2 floats each) into `out` (as many samples).
    template <typename P, typename N, typename U, typename S>
    void sample(const P &points, const N &normals, const U &u, S &out) const {
        const std::size_t n = static_cast<std::size_t>(out.size());
        detail::check_size(static_cast<std::size_t>(points.size()), 3 * n, "points");
        detail::check_size(static_cast<std::size_t>(normals.size()), 3 * n, "normals");
        detail::check_size(static_cast<std::size_t>(u.size()), 2 * n, "u");
        detail::check(envlight_visibility_cache_sample_batch(h_.get(), points.data(),
                                                             normals.data(), u.data(), n,
                                                             out.data()));
    }

    /// The pdf of each direction of `directions` at its shading point into `pdf`.
    template <typename P, typename N, typename D, typename Q>
    void pdf(const P &points, const N &normals, const D &directions, Q &pdf) const {
        const std::size_t n = static_cast<std::size_t>(pdf.size());
        detail::check_size(static_cast<std::size_t>(points.size()), 3 * n, "points");
        detail::check_size(static_cast<std::size_t>(normals.size()), 3 * n, "normals");
        detail::check_size(static_cast<std::size_t>(directions.size()), 3 * n, "directions");
        detail::check(envlight_visibility_cache_pdf_batch(h_.get(), points.data(),
                                                          normals.data(), directions.data(), n,
                                                          pdf.data()));
    }

    /// Entries, bytes, radius, mean visibility, rays.
    envlight_visibility_summary summary() const {
        envlight_visibility_summary s;
        detail::check(envlight_visibility_cache_summary(h_.get(), &s));
        return s;
    }

private:
    explicit visibility_cache(handle h) noexcept : owner(std::move(h)) {}
};

/// The light seen through portals (envlight_portal_light).
class portal_light : public detail::owner<envlight_portal_light, envlight_portal_light_free> {
public:
    /// `corners`: 12 floats per portal (four corners x, y, z in order around it).
    template <typename C>
    portal_light(const light &l, const C &corners, std::uint32_t resolution = 0)
        : owner(handle::made_by(envlight_portal_light_new, l.get(), corners.data(),
                                static_cast<std::size_t>(corners.size()) / 12, resolution)) {}

    std::optional<envlight_sample> sample(const std::array<float, 3> &point,
                                          const std::array<float, 2> &u) const noexcept {
        return detail::optional_out<envlight_sample>(envlight_portal_light_sample, h_.get(),
                                                     point.data(), u.data());
    }

    float pdf(const std::array<float, 3> &point, const std::array<float, 3> &direction) const noexcept {
        return envlight_portal_light_pdf(h_.get(), point.data(), direction.data());
    }
};

/// The sun of a light and the map without it (envlight_sun_extraction).
class sun_extraction
    : public detail::owner<envlight_sun_extraction, envlight_sun_extraction_free> {
public:
    explicit sun_extraction(const light &l)
        : owner(handle::made_by(envlight_light_extract_sun, l.get())) {}

    /// The sun, or nothing when the map has none.
    std::optional<envlight_sun> sun() const noexcept {
        return detail::optional_out<envlight_sun>(envlight_sun_extraction_sun, h_.get());
    }

    /// The residual image's width and height.
    std::pair<std::uint32_t, std::uint32_t> residual_size() const noexcept {
        std::uint32_t w = 0, h = 0;
        envlight_sun_extraction_residual_size(h_.get(), &w, &h);
        return {w, h};
    }

    /// Copies the residual image (width * height * 3 floats) into `rgb`.
    template <typename C>
    void residual(C &rgb) const {
        detail::check(envlight_sun_extraction_residual(h_.get(), rgb.data(),
                                                       static_cast<std::size_t>(rgb.size())));
    }
};

}  // namespace envlight

#endif  // ENVLIGHT_HPP
