//! How a light is built: the C options, their defaults, and their conversion to
//! the library's `LightOptions`: the C encodings (enum codes, flags, the reserved
//! words, the rotation matrix) checked here, the options themselves by
//! `LightOptions::validate`.

use envlight::light::{Density, Mapping, NamedOption, OptionError, Sampler};
use envlight::{LightOptions, Lookup, Rotation};

use crate::boundary::{deref, Failure};

/// How directions are drawn from the density (`envlight_light_options.sampler`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_sampler {
    /// CDF inversion (the default): stratification kept, invertible.
    ENVLIGHT_SAMPLER_INVERSION = 0,
    /// Vose's alias table: O(1) per sample, no stratification, no inverse.
    ENVLIGHT_SAMPLER_ALIAS = 1,
    /// Hierarchical warping down a pyramid of sums.
    ENVLIGHT_SAMPLER_HIERARCHICAL = 2,
}

/// The shape of the sampling density (`envlight_light_options.density`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_density {
    /// Constant over each texel: the smallest and cheapest, and the only density
    /// of the alias and hierarchical samplers and of a reduced table
    /// (`table_width`).
    ENVLIGHT_DENSITY_PIECEWISE_CONSTANT = 0,
    /// Bilinear between texel centres (inversion sampler only; the default of
    /// `envlight_light_options_default`): follows the bilinear lookup.
    ENVLIGHT_DENSITY_PIECEWISE_BILINEAR = 1,
}

/// How image points map to directions (`envlight_light_options.mapping`,
/// `input_mapping`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_mapping {
    /// Latitude-longitude: `θ = π v` from +z, `φ = 2π u` from +x towards +y.
    ENVLIGHT_MAPPING_EQUIRECTANGULAR = 0,
    /// The equal-area octahedral square.
    ENVLIGHT_MAPPING_EQUAL_AREA = 1,
}

/// How radiance between texel centres is reconstructed
/// (`envlight_light_options.lookup`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_lookup {
    /// Bilinear between the four nearest texel centres (the default).
    ENVLIGHT_LOOKUP_BILINEAR = 0,
    /// The texel that contains the point.
    ENVLIGHT_LOOKUP_NEAREST = 1,
    /// Bilinear with the rows as nodes from pole to pole (row j at v = j/(h-1)),
    /// as Mitsuba 3's envmap reads a map (equirectangular; the piecewise-bilinear
    /// density puts its nodes on those rows).
    ENVLIGHT_LOOKUP_NODE = 2,
}

/// How a light is built. Start from `envlight_light_options_default()` and change
/// fields; the enumerated fields hold the values of `envlight_sampler`,
/// `envlight_density`, `envlight_mapping` and `envlight_lookup`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct envlight_light_options {
    /// An `envlight_sampler`.
    pub sampler: u32,
    /// An `envlight_density`.
    pub density: u32,
    /// An `envlight_mapping`: the parameterization the light samples in. A
    /// lat-long input lit with `ENVLIGHT_MAPPING_EQUAL_AREA` is resampled.
    pub mapping: u32,
    /// An `envlight_mapping`: what the input image is (a 2:1 lat-long map, or an
    /// equal-area square as PBRT-v4 writes them).
    pub input_mapping: u32,
    /// An `envlight_lookup`.
    pub lookup: u32,
    /// Rotation of the map about +z, in degrees (finite).
    pub rotate_deg: f32,
    /// Light-to-world rotation as matrix rows, applied after `rotate_deg`; all
    /// zeros (the default) means none. Must be orthonormal with determinant 1.
    pub rotation: [[f32; 3]; 3],
    /// Multiplies every radiance value, not the density (finite, >= 0).
    pub scale: f32,
    /// Width of the sampling table in cells; 0 (the default) gives one cell per
    /// texel. Must divide the image's width, and the reduction its height.
    pub table_width: u32,
    /// Side of the square a lat-long input is resampled to for the equal-area
    /// mapping; 0 keeps about the input's texel count.
    pub equal_area_size: u32,
    /// Non-zero: MIS compensation (sample `max(0, Y - mean)`); the light alone then
    /// no longer covers the sphere; use it only inside MIS.
    pub mis_compensation: u32,
    /// Must be zero: room for options added later without changing this struct's size.
    pub reserved: [u32; 4],
}

/// The default options: inversion sampler, piecewise-bilinear density,
/// equirectangular mapping and input, bilinear lookup, no rotation, scale 1, one
/// table cell per texel. With the alias or hierarchical sampler or a
/// `table_width`, set the density to `ENVLIGHT_DENSITY_PIECEWISE_CONSTANT` too.
#[no_mangle]
pub extern "C" fn envlight_light_options_default() -> envlight_light_options {
    envlight_light_options {
        sampler: envlight_sampler::ENVLIGHT_SAMPLER_INVERSION as u32,
        density: envlight_density::ENVLIGHT_DENSITY_PIECEWISE_BILINEAR as u32,
        mapping: envlight_mapping::ENVLIGHT_MAPPING_EQUIRECTANGULAR as u32,
        input_mapping: envlight_mapping::ENVLIGHT_MAPPING_EQUIRECTANGULAR as u32,
        lookup: envlight_lookup::ENVLIGHT_LOOKUP_BILINEAR as u32,
        rotate_deg: 0.0,
        rotation: [[0.0; 3]; 3],
        scale: 1.0,
        table_width: 0,
        equal_area_size: 0,
        mis_compensation: 0,
        reserved: [0; 4],
    }
}

/// The C name of the `LightOptions` field an [`OptionError`] names.
fn c_field(e: &OptionError) -> &'static str {
    match e.field() {
        // The matrix is checked as it is converted, so a rotation that is not
        // finite came from the angle.
        "rotation" => "rotate_deg",
        field => field,
    }
}

/// The library's options from C's, or an invalid-argument failure naming the field.
pub(crate) fn light_options(
    o: &envlight_light_options,
    function: &str,
) -> Result<LightOptions, Failure> {
    /// The value whose C code is `code`: its index in `order`.
    fn pick<T: NamedOption>(
        function: &str,
        field: &str,
        code: u32,
        order: &[T],
    ) -> Result<T, Failure> {
        order.get(code as usize).copied().ok_or_else(|| {
            let names: Vec<String> = order
                .iter()
                .enumerate()
                .map(|(k, &t)| format!("{k} {}", t.option_name()))
                .collect();
            Failure::argument(
                function,
                format_args!("options.{field} is {code}, not one of {}", names.join(", ")),
            )
        })
    }
    // The orders of the C enums: the library's own for the sampler, density and
    // mapping; the lookup's C codes put the default, bilinear, first.
    let sampler = pick(function, "sampler", o.sampler, &Sampler::ALL)?;
    let density = pick(function, "density", o.density, &Density::ALL)?;
    let mapping = pick(function, "mapping", o.mapping, &Mapping::ALL)?;
    let input_mapping = pick(function, "input_mapping", o.input_mapping, &Mapping::ALL)?;
    let lookup = pick(
        function,
        "lookup",
        o.lookup,
        &[Lookup::Bilinear, Lookup::Nearest, Lookup::Node],
    )?;
    let mut rotation = Rotation::about_z_degrees(o.rotate_deg);
    if o.rotation != [[0.0; 3]; 3] {
        let matrix = Rotation::from_rows(o.rotation).ok_or_else(|| {
            Failure::argument(
                function,
                format_args!(
                    "options.rotation {:?} is not a rotation (orthonormal rows, determinant 1)",
                    o.rotation
                ),
            )
        })?;
        rotation = rotation.then_after(matrix);
    }
    if o.mis_compensation > 1 {
        return Err(Failure::argument(
            function,
            format_args!(
                "options.mis_compensation must be 0 or 1, not {}",
                o.mis_compensation
            ),
        ));
    }
    if o.reserved != [0; 4] {
        return Err(Failure::argument(
            function,
            "options.reserved must be zero (start from envlight_light_options_default())",
        ));
    }
    let nonzero = |v: u32| (v != 0).then_some(v as usize);
    let options = LightOptions {
        scale: o.scale,
        rotation,
        lookup,
        sampler,
        density,
        mapping,
        input_mapping,
        equal_area_size: nonzero(o.equal_area_size),
        mis_compensation: o.mis_compensation == 1,
        table_width: nonzero(o.table_width),
    };
    options
        .validate()
        .map_err(|e| Failure::argument(function, format_args!("options.{}: {e}", c_field(&e))))?;
    Ok(options)
}

/// The options at `options` (the defaults for NULL).
///
/// # Safety
/// A non-NULL `options` must point to a valid `envlight_light_options`.
pub(crate) unsafe fn options_or_default(
    options: *const envlight_light_options,
    function: &str,
) -> Result<LightOptions, Failure> {
    if options.is_null() {
        return light_options(&envlight_light_options_default(), function);
    }
    // SAFETY: forwarded: the caller promises a valid `envlight_light_options` at a
    // non-NULL `options`; `deref` rejects a misaligned one.
    light_options(unsafe { deref(options, function, "options") }?, function)
}
