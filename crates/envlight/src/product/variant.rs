//! Altered product samplers, compiled only with the `variants` cargo feature: the
//! deliberately broken ones that show the verification harness
//! (`envlight-verify`) rejects what it should, and the on-the-fly product that
//! BENCHMARKS.md measures against the tables. None of them is for rendering.
//!
//! The sampler asks its [`Variant`] at the few places where an alteration
//! departs from it. Without the feature a `Variant` holds nothing and each answer
//! is a constant (the plain sampler's), so those checks vanish from the sampling
//! paths and the public API holds no trace of the alterations.

use super::bounds::PatchBound;

/// An altered [`ProductSampler`](super::ProductSampler), chosen with
/// [`ProductOptions::variant`](super::ProductOptions::variant) (only with the
/// `variants` feature). Each alteration exists for a test or a measurement, named
/// with it.
#[cfg(feature = "variants")]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ProductVariant {
    /// The sampler itself, as built without the feature: the tables and the
    /// bright patches.
    #[default]
    Tables,
    /// Every lit patch weighted at each shading point by the factor itself (as the
    /// bright patches are), none through the tables: an on-the-fly product over
    /// the patch grid in the manner of Clarberg and Akenine-Möller (2008), with
    /// the light's own density within a patch. Exact, but a shading point costs a
    /// bound of the factor per patch and a sample a scan of the patches: it is
    /// the yardstick of BENCHMARKS.md's comparison with the tables (`envlight
    /// render --product-on-the-fly`), and the unit test
    /// `on_the_fly_product_is_a_density` holds it to its pdf.
    OnTheFly,
    /// **Biased.** A patch's weight is the factor at its centre for the node's own
    /// direction, without the floor from the factor's bound over the patch and the
    /// node's neighbourhood: a patch beyond the node's horizon gets weight 0 while
    /// a neighbouring normal sees it lit, so lit directions get no density.
    /// `tests/product.rs`'s `broken_weight_at_the_node_only_is_rejected` shows the
    /// support and unbiasedness checks catch it.
    AxisOnlyBound,
    /// **Not a density of its samples.** Draws just below the horizon are still
    /// reflected above it, but the pdf within the band above the horizon leaves
    /// out the mirror image's density, so it integrates to less than 1.
    /// `tests/product.rs`'s `broken_fold_without_the_mirror_image_is_rejected`
    /// shows the normalisation and chi-square checks catch it.
    FoldWithoutMirror,
    /// **Inefficient, not wrong.** A glossy factor's lobe tables are looked up at
    /// the mirror direction itself rather than turned towards the normal
    /// (`tilted_mirror`), so they ignore the cosine under a grazing lobe.
    /// `tests/product.rs`'s `broken_glossy_tables_without_the_cosine_are_rejected`
    /// shows the efficiency check catches it (BENCHMARKS.md, "Glossy tables and
    /// the cosine under the lobe").
    GlossyWithoutTilt,
}

/// What the sampler's paths ask of its variant; see the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Variant {
    #[cfg(feature = "variants")]
    variant: ProductVariant,
}

#[cfg(feature = "variants")]
impl Variant {
    /// The variant of the options.
    pub fn new(options: &super::ProductOptions) -> Self {
        Self {
            variant: options.variant,
        }
    }

    /// Whether every lit patch is weighted at the shading point
    /// ([`ProductVariant::OnTheFly`]).
    #[inline(always)]
    pub fn on_the_fly(self) -> bool {
        self.variant == ProductVariant::OnTheFly
    }

    /// How a patch's weight is floored.
    #[inline(always)]
    pub fn bound(self) -> PatchBound {
        if self.variant == ProductVariant::AxisOnlyBound {
            PatchBound::AxisOnly
        } else {
            PatchBound::Cone
        }
    }

    /// Whether the pdf leaves out the mirror image's density
    /// ([`ProductVariant::FoldWithoutMirror`]).
    #[inline(always)]
    pub fn fold_without_mirror(self) -> bool {
        self.variant == ProductVariant::FoldWithoutMirror
    }

    /// Whether the lobe tables are looked up at the mirror direction itself
    /// ([`ProductVariant::GlossyWithoutTilt`]).
    #[inline(always)]
    pub fn glossy_without_tilt(self) -> bool {
        self.variant == ProductVariant::GlossyWithoutTilt
    }
}

/// Without the feature only the plain sampler exists: the same questions, each
/// answered by a constant.
#[cfg(not(feature = "variants"))]
impl Variant {
    /// The plain sampler, whatever the options.
    pub fn new(_options: &super::ProductOptions) -> Self {
        Self {}
    }

    /// Never.
    #[inline(always)]
    pub fn on_the_fly(self) -> bool {
        false
    }

    /// Always the floor by the bound.
    #[inline(always)]
    pub fn bound(self) -> PatchBound {
        PatchBound::Cone
    }

    /// Never.
    #[inline(always)]
    pub fn fold_without_mirror(self) -> bool {
        false
    }

    /// Never.
    #[inline(always)]
    pub fn glossy_without_tilt(self) -> bool {
        false
    }
}
