//! Vector widths: which SIMD instructions the CPU offers, and one way to run a
//! kernel compiled for them. The bottom layer of the crate's vector code (the
//! light's batch queries, the bilinear build, the efficiency moments), so none of
//! them imports another for it.

/// The vectors the kernels are compiled for, picked at run time. The library
/// is built for the x86-64 baseline, whose vectors (SSE2) hold two f64; AVX2's
/// (x86-64 CPUs since 2013-2015) hold four, AVX-512's eight. The kernels are
/// `#[inline(always)]` all the way down so that the wider instructions reach them.
/// The results are the same at every width: the kernels use no fused
/// multiply-add, only operations that round alike at any vector width.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum VectorWidth {
    Baseline,
    Avx2,
    Avx512,
}

impl VectorWidth {
    /// The widest vectors the CPU has, or narrower ones where the environment
    /// variable `ENVLIGHT_VECTOR_WIDTH` asks for them (`baseline` or `avx2`; for
    /// benchmarks and for checking a result on another path). Decided once per
    /// process.
    #[inline]
    pub(crate) fn detect() -> Self {
        static WIDTH: std::sync::OnceLock<VectorWidth> = std::sync::OnceLock::new();
        *WIDTH.get_or_init(|| {
            let widest = Self::widest();
            match std::env::var("ENVLIGHT_VECTOR_WIDTH").as_deref() {
                Ok("baseline") => Self::Baseline,
                Ok("avx2") => widest.min(Self::Avx2),
                _ => widest,
            }
        })
    }

    /// The widest vectors the CPU has.
    pub(crate) fn widest() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::arch::is_x86_feature_detected!("avx512dq")
                && std::arch::is_x86_feature_detected!("avx512bw")
            {
                return Self::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                return Self::Avx2;
            }
        }
        Self::Baseline
    }
}

/// Runs `fn(args) -> R { body }` (or `fn(args) { body }`) compiled for the vectors `$width` names: for AVX2
/// and AVX-512 a copy of the function with those target features (kernels called
/// from `body` should be `#[inline(always)]`, so the wider instructions reach
/// their loops), else the baseline's. The arguments are passed by the names the
/// signature gives them, which must be in scope at the call. Kernels use no fused
/// multiply-add, so every width gives the same bits.
macro_rules! at_width {
    ($width:expr, fn($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2")]
            fn avx2($($arg: $ty),*) $(-> $ret)? $body
            #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
            fn avx512($($arg: $ty),*) $(-> $ret)? $body
            match $width {
                // SAFETY: `VectorWidth::detect` names only widths this CPU has.
                $crate::width::VectorWidth::Avx512 => unsafe { avx512($($arg),*) },
                // SAFETY: as above.
                $crate::width::VectorWidth::Avx2 => unsafe { avx2($($arg),*) },
                $crate::width::VectorWidth::Baseline => $body,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = $width;
            $body
        }
    }};
}
pub(crate) use at_width;
