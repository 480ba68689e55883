//! The light's option names and their validation, once for every front end.
//!
//! Each option enum a front end names ([`Sampler`], [`Density`], [`Mapping`],
//! [`Lookup`], and the GPU export's `RadianceFormat`) has `ALL` (every value, in declaration order),
//! `name()` (the spelling the command line, Python and Mitsuba use), [`FromStr`](std::str::FromStr)
//! back from that spelling with an [`UnknownName`] error listing the accepted
//! ones, and [`Display`](std::fmt::Display) printing the name. [`LightOptions::validate`] holds
//! every rule about the options alone; [`EnvironmentLight::new`] calls it, and the
//! front ends call it to refuse bad options before they read a map.
//!
//! [`EnvironmentLight::new`]: super::EnvironmentLight::new

use super::{Density, LightOptions, Mapping, Sampler};
use crate::image::Lookup;

/// An option enum whose values have names: what [`FromStr`](std::str::FromStr), [`Display`](std::fmt::Display)
/// and the front ends' lists of choices are built from.
pub trait NamedOption: Copy + Sized + 'static {
    /// What the option is called in messages: `"sampler"`, `"lookup"`, ...
    const OPTION: &'static str;
    /// Every value, in declaration order (the type's `ALL`).
    const VALUES: &'static [Self];
    /// The value's name (the type's `name()`).
    fn option_name(self) -> &'static str;

    /// Every value's name, in the order of [`Self::VALUES`].
    fn names() -> Vec<&'static str> {
        Self::VALUES.iter().map(|v| v.option_name()).collect()
    }

    /// The value named `name`, or an [`UnknownName`] listing the accepted names.
    ///
    /// # Errors
    /// [`UnknownName`] when no value has that name (names are case-sensitive).
    fn from_name(name: &str) -> Result<Self, UnknownName> {
        Self::VALUES
            .iter()
            .copied()
            .find(|v| v.option_name() == name)
            .ok_or_else(|| UnknownName {
                option: Self::OPTION,
                given: name.to_owned(),
                accepted: Self::names(),
            })
    }
}

/// A name that none of an option's values has.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{option} must be one of {}, not {given:?}", .accepted.join(", "))]
pub struct UnknownName {
    /// The option, as [`NamedOption::OPTION`] calls it; a front end may put its
    /// own name for the field here (`input_mapping` for a [`Mapping`]).
    pub option: &'static str,
    /// The name that was given.
    pub given: String,
    /// Every accepted name, in declaration order.
    pub accepted: Vec<&'static str>,
}

/// `FromStr` and `Display` through [`NamedOption`], for a type with inherent
/// `ALL` and `name()` (the GPU export's `RadianceFormat` takes it too, in
/// `crate::gpu`, which sits above the light).
macro_rules! named_option {
    ($ty:ty, $option:literal) => {
        impl $crate::light::NamedOption for $ty {
            const OPTION: &'static str = $option;
            const VALUES: &'static [Self] = &<$ty>::ALL;
            fn option_name(self) -> &'static str {
                <$ty>::name(self)
            }
        }

        impl ::std::str::FromStr for $ty {
            type Err = $crate::light::UnknownName;
            fn from_str(s: &str) -> Result<Self, $crate::light::UnknownName> {
                <$ty as $crate::light::NamedOption>::from_name(s)
            }
        }

        impl ::std::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                // `pad`, so that widths and alignment in format strings apply.
                f.pad(self.name())
            }
        }
    };
}

named_option!(Sampler, "sampler");
named_option!(Density, "density");
named_option!(Mapping, "mapping");
named_option!(Lookup, "lookup");
pub(crate) use named_option;

impl Lookup {
    /// Every lookup, in declaration order, for option parsers and tests.
    pub const ALL: [Lookup; 3] = [Lookup::Nearest, Lookup::Bilinear, Lookup::Node];
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Lookup::Nearest => "nearest",
            Lookup::Bilinear => "bilinear",
            Lookup::Node => "node",
        }
    }
}

/// Light options that no light can be built with, whatever the image: what
/// [`LightOptions::validate`] finds. [`OptionError::field`] names the field at
/// fault; the message states the rule. Rules that depend on the image (an
/// equal-area input must be square, a table width must divide it) are checked
/// when the light is built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum OptionError {
    /// `scale` is negative, NaN or infinite.
    #[error("radiance scale must be finite and >= 0, got {0}")]
    Scale(f32),
    /// `rotation` holds a NaN or an infinity (a rotation by a non-finite angle).
    #[error("the rotation must be finite, got rows {0:?}")]
    Rotation([[f32; 3]; 3]),
    /// `density` is piecewise-bilinear with a sampler other than inversion (the
    /// sampler given).
    #[error(
        "the piecewise-bilinear density (the default) is sampled by inversion only, \
         not by the {0} sampler: ask for the piecewise-constant density with it"
    )]
    BilinearDensitySampler(Sampler),
    /// `lookup` is [`Lookup::Node`] with the equal-area `mapping`.
    #[error("the node lookup reads equirectangular maps only, not the equal-area square")]
    NodeLookupMapping,
    /// `input_mapping` is equal-area and `mapping` equirectangular.
    #[error("an equal-area input can only be lit with the equal-area mapping")]
    EqualAreaInput,
    /// `equal_area_size` is `Some(0)` where a lat-long input is resampled to the
    /// equal-area mapping.
    #[error("the equal-area size must be at least 1")]
    EqualAreaSize,
    /// `table_width` is `Some(0)`.
    #[error("sampling table width 0: must be at least 1")]
    TableWidth,
}

// Here rather than in `crate::error`, which sits below the light and names no
// type of it; the message only, not the option error as the source, so that a
// front end printing the chain does not print it twice.
impl From<OptionError> for crate::error::Error {
    fn from(e: OptionError) -> Self {
        crate::error::Error::LightOption {
            field: e.field(),
            message: e.to_string(),
        }
    }
}

impl OptionError {
    /// The [`LightOptions`] field at fault: for a combination, the field a front
    /// end should name first (`density` for the density that the sampler does not
    /// take; `lookup` for the node lookup with the equal-area mapping;
    /// `input_mapping` for an equal-area input with the lat-long mapping).
    pub fn field(&self) -> &'static str {
        match self {
            OptionError::Scale(_) => "scale",
            OptionError::Rotation(_) => "rotation",
            OptionError::BilinearDensitySampler(_) => "density",
            OptionError::NodeLookupMapping => "lookup",
            OptionError::EqualAreaInput => "input_mapping",
            OptionError::EqualAreaSize => "equal_area_size",
            OptionError::TableWidth => "table_width",
        }
    }

    /// The other field of a combination that is at fault (`sampler` with
    /// `density`, `mapping` with `lookup` or `input_mapping`), `None` for a field
    /// that is wrong alone.
    pub fn other_field(&self) -> Option<&'static str> {
        match self {
            OptionError::BilinearDensitySampler(_) => Some("sampler"),
            OptionError::NodeLookupMapping | OptionError::EqualAreaInput => Some("mapping"),
            _ => None,
        }
    }
}

impl LightOptions {
    /// Checks every rule about the options alone, in the order
    /// [`EnvironmentLight::new`](super::EnvironmentLight::new) always checked
    /// them: `scale` finite and ≥ 0, `rotation` finite, the piecewise-bilinear
    /// `density` with the inversion `sampler` only, the node `lookup` with the
    /// equirectangular `mapping` only, an equal-area `input_mapping` with the
    /// equal-area `mapping` only, an `equal_area_size` of at least 1 where it is
    /// used, and a `table_width` of at least 1.
    ///
    /// # Errors
    /// The first [`OptionError`] found.
    pub fn validate(&self) -> Result<(), OptionError> {
        if !(self.scale >= 0.0 && self.scale.is_finite()) {
            return Err(OptionError::Scale(self.scale));
        }
        let rows = self.rotation.rows();
        if !rows.iter().flatten().all(|x| x.is_finite()) {
            return Err(OptionError::Rotation(rows));
        }
        if self.density == Density::PiecewiseBilinear && self.sampler != Sampler::Inversion {
            return Err(OptionError::BilinearDensitySampler(self.sampler));
        }
        // The node lookup is the equirectangular map's (Mitsuba's envmap).
        if self.lookup == Lookup::Node && self.mapping != Mapping::Equirectangular {
            return Err(OptionError::NodeLookupMapping);
        }
        match (self.input_mapping, self.mapping) {
            (Mapping::EqualArea, Mapping::Equirectangular) => {
                return Err(OptionError::EqualAreaInput)
            }
            // Only a lat-long input lit with the equal-area mapping is resampled;
            // elsewhere the size is not used, and not checked.
            (Mapping::Equirectangular, Mapping::EqualArea) if self.equal_area_size == Some(0) => {
                return Err(OptionError::EqualAreaSize)
            }
            _ => {}
        }
        self.validate_table_width()
    }

    /// The `table_width` rule alone, for [`super::table_reduction`], which front
    /// ends call on their own.
    pub(super) fn validate_table_width(&self) -> Result<(), OptionError> {
        if self.table_width == Some(0) {
            return Err(OptionError::TableWidth);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rotation;
    use std::fmt;
    use std::str::FromStr;

    fn round_trips<
        T: NamedOption + FromStr<Err = UnknownName> + fmt::Display + PartialEq + fmt::Debug,
    >() {
        for &v in T::VALUES {
            assert_eq!(v.option_name().parse::<T>().ok(), Some(v));
            assert_eq!(v.to_string(), v.option_name());
        }
        let e = "bogus".parse::<T>().err().unwrap();
        assert_eq!(e.option, T::OPTION);
        assert_eq!(e.accepted, T::names());
        let message = e.to_string();
        assert!(message.contains("\"bogus\""), "{message}");
        for name in T::names() {
            assert!(message.contains(name), "{message}");
        }
    }

    /// Every name parses back to its value, prints as itself, and an unknown one
    /// is refused with every accepted name.
    #[test]
    fn names_round_trip() {
        round_trips::<Sampler>();
        round_trips::<Density>();
        round_trips::<Mapping>();
        round_trips::<Lookup>();
        assert_eq!(
            "x".parse::<Lookup>().unwrap_err().to_string(),
            "lookup must be one of nearest, bilinear, node, not \"x\""
        );
        // Names are the front ends' spellings, and case-sensitive.
        assert_eq!(
            "piecewise-bilinear".parse::<Density>(),
            Ok(Density::PiecewiseBilinear)
        );
        assert!("Alias".parse::<Sampler>().is_err());
        assert_eq!(format!("{:>8}", Lookup::Node), "    node");
    }

    /// Each rule names its field, and the defaults pass.
    #[test]
    fn validate_names_the_field() {
        assert_eq!(LightOptions::default().validate(), Ok(()));
        let d = LightOptions::default;
        let cases = [
            (LightOptions { scale: -1.0, ..d() }, "scale"),
            (
                LightOptions {
                    scale: f32::NAN,
                    ..d()
                },
                "scale",
            ),
            (
                LightOptions {
                    rotation: Rotation::about_z_degrees(f32::INFINITY),
                    ..d()
                },
                "rotation",
            ),
            (
                LightOptions {
                    sampler: Sampler::Alias,
                    ..d()
                },
                "density",
            ),
            (
                LightOptions {
                    lookup: Lookup::Node,
                    mapping: Mapping::EqualArea,
                    ..d()
                },
                "lookup",
            ),
            (
                LightOptions {
                    input_mapping: Mapping::EqualArea,
                    ..d()
                },
                "input_mapping",
            ),
            (
                LightOptions {
                    mapping: Mapping::EqualArea,
                    equal_area_size: Some(0),
                    ..d()
                },
                "equal_area_size",
            ),
            (
                LightOptions {
                    table_width: Some(0),
                    density: Density::PiecewiseConstant,
                    ..d()
                },
                "table_width",
            ),
        ];
        for (options, field) in cases {
            let e = options.validate().unwrap_err();
            assert_eq!(e.field(), field, "{e}");
        }
        // An equal-area size where nothing is resampled is not used, and passes.
        let unused = LightOptions {
            equal_area_size: Some(0),
            ..d()
        };
        assert_eq!(unused.validate(), Ok(()));
        assert_eq!(
            LightOptions {
                sampler: Sampler::Hierarchical,
                ..d()
            }
            .validate()
            .unwrap_err()
            .other_field(),
            Some("sampler")
        );
    }
}
