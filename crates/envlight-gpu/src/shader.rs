//! The WGSL module and its translations.
//!
//! [`WGSL`] is the module [`GpuLight`](crate::GpuLight) compiles; [`translate`]
//! writes one of its compute entry points in another shading language through
//! naga, so the same shader can be read, compiled offline or embedded elsewhere:
//!
//! ```
//! use envlight_gpu::shader::{translate, Lang};
//!
//! let glsl = translate(Lang::Glsl, "sample_main").unwrap();
//! assert!(glsl.starts_with(b"#version 450"));
//! ```
//!
//! Every translation is one complete compute shader: the entry point's bindings
//! (all in group 0, at the binding numbers of the WGSL), and every function of
//! the module it reaches (`light_sample`, `light_pdf`, … and their helpers;
//! some backends keep functions it does not reach too).

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use naga::back::{glsl, hlsl, msl, spv};
use naga::proc::{BoundsCheckPolicies, BoundsCheckPolicy};
use naga::valid::{Capabilities, ModuleInfo, ValidationFlags, Validator};
use naga::{Module, ResourceBinding, ShaderStage};

/// The WGSL source of the light's functions and compute entry points.
pub const WGSL: &str = include_str!("envlight.wgsl");

/// The compute entry points of [`WGSL`], in the order the module declares them.
pub const ENTRY_POINTS: [&str; 4] = ["sample_main", "pdf_main", "radiance_main", "eval_main"];

/// The entry point `sample --device gpu` runs: directions drawn from the light.
pub const DEFAULT_ENTRY_POINT: &str = "sample_main";

/// The naga capabilities [`WGSL`] needs: none beyond naga's defaults. (Half-float
/// radiance is decoded with integer operations rather than `unpack2x16float`,
/// which would need `SHADER_FLOAT16_IN_FLOAT32`, a capability GL ES and some
/// Vulkan drivers do not grant.)
pub const CAPABILITIES: Capabilities = Capabilities::empty();

/// The file name errors attribute the WGSL to.
const SOURCE_NAME: &str = "envlight.wgsl";

/// A shading language [`translate`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Lang {
    /// WGSL: the module's source text as it is (all entry points).
    Wgsl,
    /// GLSL 4.50 core, compute stage (OpenGL 4.5, or Vulkan through glslang).
    Glsl,
    /// HLSL, shader model 5.1 (`cs_5_1`): registers `b`/`t`/`u` N in `space0`.
    Hlsl,
    /// Metal Shading Language 2.0: `[[buffer(N)]]` for binding N.
    Msl,
    /// SPIR-V 1.3 (Vulkan 1.1) binary, little-endian words.
    Spirv,
}

impl Lang {
    /// Every language, in the order of [`Lang::NAMES`].
    pub const ALL: [Lang; 5] = [Lang::Wgsl, Lang::Glsl, Lang::Hlsl, Lang::Msl, Lang::Spirv];

    /// The names [`Lang::from_str`] accepts, one per language of [`Lang::ALL`].
    pub const NAMES: [&'static str; 5] = ["wgsl", "glsl", "hlsl", "msl", "spirv"];

    /// The lower-case name (`"glsl"`, `"spirv"`, …), as parsed by [`Lang::from_str`].
    pub const fn name(self) -> &'static str {
        match self {
            Lang::Wgsl => "wgsl",
            Lang::Glsl => "glsl",
            Lang::Hlsl => "hlsl",
            Lang::Msl => "msl",
            Lang::Spirv => "spirv",
        }
    }

    /// True for SPIR-V, the one binary output; the others are UTF-8 text.
    pub const fn is_binary(self) -> bool {
        matches!(self, Lang::Spirv)
    }
}

impl fmt::Display for Lang {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Lang {
    type Err = ShaderError;

    /// Parses a name of [`Lang::NAMES`], ignoring ASCII case.
    ///
    /// # Errors
    /// [`ShaderError::UnknownLang`] for any other name.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Lang::ALL
            .into_iter()
            .find(|lang| lang.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| ShaderError::UnknownLang(s.to_string()))
    }
}

/// What can go wrong in [`translate`].
#[derive(Debug, thiserror::Error)]
pub enum ShaderError {
    /// A language name that is not one of [`Lang::NAMES`].
    #[error("unknown shader language `{0}` (expected wgsl, glsl, hlsl, msl or spirv)")]
    UnknownLang(String),
    /// An entry point the module does not have.
    #[error("envlight.wgsl has no compute entry point `{name}` (it has {})", .available.join(", "))]
    UnknownEntryPoint {
        /// The name asked for.
        name: String,
        /// The module's compute entry points.
        available: Vec<String>,
    },
    /// The WGSL does not parse (a bug in the module, not in the caller).
    #[error("{SOURCE_NAME}:{line}:{column}: the WGSL does not parse: {message}")]
    Parse {
        /// 1-based line of the error (0 when naga gave no position).
        line: u32,
        /// 1-based column, in bytes.
        column: u32,
        /// naga's message.
        message: String,
        /// naga's full report, with the source line and notes (several lines).
        report: String,
    },
    /// The WGSL parses but naga's validator rejects it.
    #[error("{SOURCE_NAME}:{line}:{column}: the WGSL does not validate: {message}")]
    Validation {
        /// 1-based line of the error (0 when naga gave no position).
        line: u32,
        /// 1-based column, in bytes.
        column: u32,
        /// naga's message and its causes, on one line.
        message: String,
        /// naga's full report, with the source line (several lines).
        report: String,
    },
    /// A naga backend could not write the language.
    #[error("naga could not write {lang} for `{entry_point}`")]
    Translate {
        /// The language asked for.
        lang: Lang,
        /// The entry point asked for.
        entry_point: String,
        /// The backend's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync + 'static>,
    },
}

/// Parses and validates [`WGSL`] with naga.
///
/// Validation uses every check (`ValidationFlags::all()`) and the capabilities
/// of [`CAPABILITIES`].
///
/// # Errors
/// [`ShaderError::Parse`] or [`ShaderError::Validation`], with naga's position
/// and report.
pub fn validate() -> Result<(Module, ModuleInfo), ShaderError> {
    let module = naga::front::wgsl::parse_str(WGSL).map_err(|e| {
        let (line, column) = line_column(e.location(WGSL));
        ShaderError::Parse {
            line,
            column,
            message: e.message().to_string(),
            report: e.emit_to_string_with_path(WGSL, SOURCE_NAME),
        }
    })?;
    let info = Validator::new(ValidationFlags::all(), CAPABILITIES)
        .validate(&module)
        .map_err(|e| {
            let (line, column) = line_column(e.location(WGSL));
            ShaderError::Validation {
                line,
                column,
                message: error_chain(e.as_inner()),
                report: e.emit_to_string_with_path(WGSL, SOURCE_NAME),
            }
        })?;
    Ok((module, info))
}

/// A naga error's `(line, column)` in [`WGSL`], `(0, 0)` where it has none.
fn line_column(location: Option<naga::SourceLocation>) -> (u32, u32) {
    location.map_or((0, 0), |l| (l.line_number, l.line_position))
}

/// The compute shader of `entry_point` (one of [`ENTRY_POINTS`]) in `lang`:
/// UTF-8 text, or for [`Lang::Spirv`] the binary module (its 32-bit words in
/// little-endian order, as `.spv` files hold them).
///
/// [`Lang::Wgsl`] gives [`WGSL`] itself, byte for byte (after checking that it
/// validates and has the entry point): WGSL has no single-entry-point form, and
/// the source keeps its comments. The other languages come from naga's backends:
///
/// - GLSL 4.50 core (`#version 450 core`); the entry point becomes `main`, and
///   each buffer has `layout(binding = N)` with N its WGSL binding (group 0).
/// - HLSL shader model 5.1: binding N of group 0 is register `bN` (uniform),
///   `tN` (read-only storage) or `uN` (read-write storage) in `space0`. HLSL has
///   no `num_workgroups`: the host passes the dispatch size in the constant
///   buffer `_NagaConstants` at `register(b0, space1)` (`first_vertex`,
///   `first_instance`, `other` = x, y, z), as wgpu does on Direct3D 12.
/// - MSL 2.0: binding N is `[[buffer(N)]]`; `[[buffer(6)]]` holds the byte
///   sizes of the storage buffers (bindings 1, 2, 4, 5, one `uint` each), which
///   the bounds checks need.
/// - SPIR-V 1.3 (the version Vulkan 1.1 accepts): descriptor set 0, binding N.
///
/// Out-of-bounds indices are clamped (naga's `Restrict` policy), as wgpu does
/// on a device without robust buffer access: the shader is safe to run
/// anywhere, whatever the buffer sizes.
///
/// # Errors
/// [`ShaderError::UnknownEntryPoint`] for a name that is not a compute entry
/// point of the module; [`ShaderError::Parse`], [`ShaderError::Validation`] or
/// [`ShaderError::Translate`] if naga rejects the module (a bug in the module
/// or in naga, not the caller's).
pub fn translate(lang: Lang, entry_point: &str) -> Result<Vec<u8>, ShaderError> {
    let (module, info) = validate()?;
    if !module
        .entry_points
        .iter()
        .any(|ep| ep.stage == ShaderStage::Compute && ep.name == entry_point)
    {
        return Err(ShaderError::UnknownEntryPoint {
            name: entry_point.to_string(),
            available: module
                .entry_points
                .iter()
                .filter(|ep| ep.stage == ShaderStage::Compute)
                .map(|ep| ep.name.clone())
                .collect(),
        });
    }
    let failed = |source: Box<dyn std::error::Error + Send + Sync>| ShaderError::Translate {
        lang,
        entry_point: entry_point.to_string(),
        source,
    };
    match lang {
        Lang::Wgsl => Ok(WGSL.as_bytes().to_vec()),
        Lang::Glsl => write_glsl(&module, &info, entry_point)
            .map(String::into_bytes)
            .map_err(|e| failed(e.into())),
        Lang::Hlsl => write_hlsl(&module, &info, entry_point)
            .map(String::into_bytes)
            .map_err(|e| failed(e.into())),
        Lang::Msl => write_msl(&module, &info, entry_point)
            .map(String::into_bytes)
            .map_err(failed),
        Lang::Spirv => write_spirv(&module, &info, entry_point)
            .map(|words| words.iter().flat_map(|w| w.to_le_bytes()).collect())
            .map_err(|e| failed(e.into())),
    }
}

/// The bounds-check policies of every backend: clamp indices into range, in
/// buffers and in local arrays alike (what wgpu does without robust access).
const BOUNDS_CHECKS: BoundsCheckPolicies = BoundsCheckPolicies {
    index: BoundsCheckPolicy::Restrict,
    buffer: BoundsCheckPolicy::Restrict,
    image_load: BoundsCheckPolicy::Restrict,
    binding_array: BoundsCheckPolicy::Unchecked,
};

/// The module's resource bindings (all in group 0).
fn bindings(module: &Module) -> impl Iterator<Item = ResourceBinding> + '_ {
    module
        .global_variables
        .iter()
        .filter_map(|(_, var)| var.binding)
}

/// `binding`'s number as a backend's 8-bit slot, for group 0, the only one the
/// slot-numbered backends (GLSL, MSL) are given.
fn slot(binding: ResourceBinding) -> Result<u8, String> {
    match u8::try_from(binding.binding) {
        Ok(slot) if binding.group == 0 => Ok(slot),
        _ => Err(format!(
            "group {} binding {} has no slot (only group 0, bindings 0 to 255)",
            binding.group, binding.binding
        )),
    }
}

fn write_glsl(
    module: &Module,
    info: &ModuleInfo,
    entry_point: &str,
) -> Result<String, glsl::Error> {
    let binding_map = bindings(module)
        .map(|binding| Ok((binding, slot(binding)?)))
        .collect::<Result<_, String>>()
        .map_err(glsl::Error::Custom)?;
    let options = glsl::Options {
        version: glsl::Version::Desktop(450),
        // Coordinate-space adjustment only concerns vertex outputs.
        writer_flags: glsl::WriterFlags::empty(),
        binding_map,
        zero_initialize_workgroup_memory: true,
    };
    let pipeline = glsl::PipelineOptions {
        shader_stage: ShaderStage::Compute,
        entry_point: entry_point.to_string(),
        multiview: None,
    };
    let mut text = String::new();
    glsl::Writer::new(&mut text, module, info, &options, &pipeline, BOUNDS_CHECKS)?.write()?;
    Ok(text)
}

/// Where HLSL reads `num_workgroups` from: `register(b0, space1)`, apart from
/// the module's own bindings (all in `space0`).
const NUM_WORKGROUPS_HLSL: hlsl::BindTarget = hlsl::BindTarget {
    space: 1,
    register: 0,
    binding_array_size: None,
    dynamic_storage_buffer_offsets_index: None,
    restrict_indexing: false,
};

fn write_hlsl(
    module: &Module,
    info: &ModuleInfo,
    entry_point: &str,
) -> Result<String, hlsl::Error> {
    let binding_map = bindings(module)
        .map(|binding| {
            let target = hlsl::BindTarget {
                space: u8::try_from(binding.group).map_err(|_| {
                    hlsl::Error::Custom(format!("group {} has no register space", binding.group))
                })?,
                register: binding.binding,
                binding_array_size: None,
                dynamic_storage_buffer_offsets_index: None,
                restrict_indexing: false,
            };
            Ok((binding, target))
        })
        .collect::<Result<_, hlsl::Error>>()?;
    let options = hlsl::Options {
        shader_model: hlsl::ShaderModel::V5_1,
        binding_map,
        fake_missing_bindings: false,
        // HLSL has no `num_workgroups`: naga reads it from a constant buffer the
        // host fills (its `first_vertex`, `first_instance`, `other` are x, y, z).
        special_constants_binding: Some(NUM_WORKGROUPS_HLSL),
        restrict_indexing: true,
        ..hlsl::Options::default()
    };
    let pipeline = hlsl::PipelineOptions {
        entry_point: Some((ShaderStage::Compute, entry_point.to_string())),
    };
    let mut text = String::new();
    hlsl::Writer::new(&mut text, &options, &pipeline).write(module, info, None)?;
    Ok(text)
}

fn write_msl(
    module: &Module,
    info: &ModuleInfo,
    entry_point: &str,
) -> Result<String, Box<dyn std::error::Error + Send + Sync>> {
    let mut resources = msl::BindingMap::default();
    let mut next_slot = 0;
    for binding in bindings(module) {
        let slot = slot(binding)?;
        next_slot = next_slot.max(slot.saturating_add(1));
        let target = msl::BindTarget {
            buffer: Some(slot),
            ..msl::BindTarget::default()
        };
        resources.insert(binding, target);
    }
    let resources = msl::EntryPointResources {
        resources,
        immediates_buffer: None,
        sizes_buffer: Some(next_slot),
    };
    let options = msl::Options {
        lang_version: (2, 0),
        per_entry_point_map: BTreeMap::from([(entry_point.to_string(), resources)]),
        fake_missing_bindings: false,
        bounds_check_policies: BOUNDS_CHECKS,
        ..msl::Options::default()
    };
    let pipeline = msl::PipelineOptions {
        entry_point: Some((ShaderStage::Compute, entry_point.to_string())),
        ..msl::PipelineOptions::default()
    };
    let (text, translation) = msl::write_string(module, info, &options, &pipeline)?;
    // A missing binding is reported here rather than as an error of the write.
    for name in translation.entry_point_names {
        name?;
    }
    Ok(text)
}

fn write_spirv(
    module: &Module,
    info: &ModuleInfo,
    entry_point: &str,
) -> Result<Vec<u32>, spv::Error> {
    let binding_map = bindings(module)
        .map(|binding| {
            let target = spv::BindingInfo {
                descriptor_set: binding.group,
                binding: binding.binding,
                binding_array_size: None,
            };
            (binding, target)
        })
        .collect();
    let options = spv::Options {
        lang_version: (1, 3),
        // Names for every id (readable under spirv-dis), whatever the build
        // profile; the vertex-output flags of the default do not apply.
        flags: spv::WriterFlags::DEBUG,
        fake_missing_bindings: false,
        binding_map,
        bounds_check_policies: BOUNDS_CHECKS,
        ..spv::Options::default()
    };
    let pipeline = spv::PipelineOptions {
        shader_stage: ShaderStage::Compute,
        entry_point: entry_point.to_string(),
    };
    spv::write_vec(module, info, &options, Some(&pipeline))
}

/// An error and its causes on one line, `outer: cause: root`.
fn error_chain(error: &dyn std::error::Error) -> String {
    let mut message = error.to_string();
    let mut cause = error.source();
    while let Some(e) = cause {
        message.push_str(": ");
        message.push_str(&e.to_string());
        cause = e.source();
    }
    message
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wgsl_validates_with_every_entry_point() {
        let (module, _) = validate().unwrap_or_else(|e| panic!("{e}\n{e:?}"));
        let names: Vec<&str> = module
            .entry_points
            .iter()
            .map(|ep| ep.name.as_str())
            .collect();
        assert_eq!(names, ENTRY_POINTS);
        assert!(module
            .entry_points
            .iter()
            .all(|ep| ep.stage == ShaderStage::Compute));
        assert!(ENTRY_POINTS.contains(&DEFAULT_ENTRY_POINT));
    }

    /// The WGSL `Params` struct is the parameter block of `envlight::gpu::param`:
    /// each member's byte offset, as naga lays the uniform out, is 4 × its word.
    #[test]
    fn params_struct_matches_the_rust_word_offsets() {
        use envlight::gpu::{param, PARAMS_WORDS};
        let (module, _) = validate().unwrap_or_else(|e| panic!("{e}\n{e:?}"));
        let (members, span) = module
            .types
            .iter()
            .find_map(|(_, ty)| match (&ty.name, &ty.inner) {
                (Some(name), naga::TypeInner::Struct { members, span }) if name == "Params" => {
                    Some((members, *span))
                }
                _ => None,
            })
            .expect("the WGSL declares struct Params");
        let words: &[(&str, usize)] = &[
            ("light_to_world", param::LIGHT_TO_WORLD),
            ("world_to_light", param::WORLD_TO_LIGHT),
            ("version", param::VERSION),
            ("sampler", param::SAMPLER),
            ("density", param::DENSITY),
            ("mapping", param::MAPPING),
            ("lookup", param::LOOKUP),
            ("radiance_format", param::RADIANCE_FORMAT),
            ("rotated", param::ROTATED),
            ("black", param::BLACK),
            ("image_width", param::IMAGE_WIDTH),
            ("image_height", param::IMAGE_HEIGHT),
            ("table_width", param::TABLE_WIDTH),
            ("table_height", param::TABLE_HEIGHT),
            ("scale", param::SCALE),
            ("integral_luminance", param::INTEGRAL_LUMINANCE),
            ("marginal_cdf", param::MARGINAL_CDF),
            ("marginal_guide", param::MARGINAL_GUIDE),
            ("marginal_guide_shift", param::MARGINAL_GUIDE_SHIFT),
            ("conditional_cdf", param::CONDITIONAL_CDF),
            ("conditional_guide", param::CONDITIONAL_GUIDE),
            ("conditional_guide_bits", param::CONDITIONAL_GUIDE_BITS),
            ("alias_slots", param::ALIAS_SLOTS),
            ("alias_func", param::ALIAS_FUNC),
            ("alias_offset_bits", param::ALIAS_OFFSET_BITS),
            ("alias_inv_integral", param::ALIAS_INV_INTEGRAL),
            ("bilinear_values", param::BILINEAR_VALUES),
            ("tables_words", param::TABLES_WORDS),
            ("bilinear_v_nodes", param::BILINEAR_V_NODES),
            // Words RESERVED.. (51–63): one u32, then three vec4<u32>.
            ("reserved1", param::RESERVED),
            ("reserved", param::RESERVED + 1),
        ];
        let got: Vec<(&str, u32)> = members
            .iter()
            .map(|m| (m.name.as_deref().unwrap_or(""), m.offset))
            .collect();
        let want: Vec<(&str, u32)> = words
            .iter()
            .map(|&(name, word)| (name, 4 * word as u32))
            .collect();
        assert_eq!(got, want);
        assert_eq!(span as usize, 4 * PARAMS_WORDS);
    }

    #[test]
    fn every_language_translates_every_entry_point() {
        for lang in Lang::ALL {
            for entry_point in ENTRY_POINTS {
                let out = translate(lang, entry_point)
                    .unwrap_or_else(|e| panic!("{lang} {entry_point}: {e}\n{e:?}"));
                assert!(!out.is_empty(), "{lang} {entry_point}: empty");
                if lang.is_binary() {
                    assert_eq!(out.len() % 4, 0);
                    // The SPIR-V magic number, little-endian.
                    assert_eq!(out[..4], 0x0723_0203u32.to_le_bytes());
                } else {
                    let text = String::from_utf8(out).unwrap();
                    match lang {
                        Lang::Wgsl => assert_eq!(text, WGSL),
                        // GLSL calls the entry point `main`.
                        Lang::Glsl => assert!(text.contains("void main()"), "{lang} {entry_point}"),
                        _ => assert!(text.contains(entry_point), "{lang} {entry_point}"),
                    }
                }
            }
        }
    }

    /// The library function each entry point calls.
    const REACHED: [(&str, &str); 4] = [
        ("sample_main", "light_sample"),
        ("pdf_main", "light_pdf"),
        ("radiance_main", "light_radiance"),
        ("eval_main", "light_eval"),
    ];

    #[test]
    fn translations_carry_the_library_functions_the_entry_point_reaches() {
        for lang in [Lang::Glsl, Lang::Hlsl, Lang::Msl] {
            for (entry_point, reached) in REACHED {
                let text = String::from_utf8(translate(lang, entry_point).unwrap()).unwrap();
                assert!(
                    text.contains(&format!("{reached}(")),
                    "{lang} {entry_point} lacks {reached}"
                );
            }
        }
        // The sampler's own pieces are inside the sampling shader.
        let glsl = String::from_utf8(translate(Lang::Glsl, "sample_main").unwrap()).unwrap();
        for helper in [
            "sample_alias(",
            "sample_bilinear(",
            "sample_inversion(",
            "xi_2d(",
        ] {
            assert!(glsl.contains(helper), "GLSL sample_main lacks {helper}");
        }
    }

    #[test]
    fn glsl_and_hlsl_bind_at_the_wgsl_binding_numbers() {
        let glsl = String::from_utf8(translate(Lang::Glsl, "sample_main").unwrap()).unwrap();
        for binding in 0..6 {
            assert!(
                glsl.contains(&format!("binding = {binding})")),
                "GLSL binding {binding}"
            );
        }
        let hlsl = String::from_utf8(translate(Lang::Hlsl, "sample_main").unwrap()).unwrap();
        for register in ["b0", "t1", "t2", "b3", "t4", "u5", "b0, space1"] {
            assert!(
                hlsl.contains(&format!("register({register}")),
                "HLSL register {register}"
            );
        }
        let msl = String::from_utf8(translate(Lang::Msl, "sample_main").unwrap()).unwrap();
        for slot in 0..7 {
            assert!(
                msl.contains(&format!("[[buffer({slot})]]")),
                "MSL buffer {slot}"
            );
        }
    }

    #[test]
    fn unknown_names_are_errors() {
        let e = translate(Lang::Glsl, "main").unwrap_err();
        assert!(matches!(e, ShaderError::UnknownEntryPoint { .. }));
        assert!(
            e.to_string()
                .contains("sample_main, pdf_main, radiance_main, eval_main"),
            "{e}"
        );
        assert!(matches!(
            "cuda".parse::<Lang>(),
            Err(ShaderError::UnknownLang(_))
        ));
    }

    #[test]
    fn language_names_round_trip() {
        for (lang, name) in Lang::ALL.into_iter().zip(Lang::NAMES) {
            assert_eq!(lang.name(), name);
            assert_eq!(name.parse::<Lang>().unwrap(), lang);
            assert_eq!(name.to_uppercase().parse::<Lang>().unwrap(), lang);
        }
    }
}
