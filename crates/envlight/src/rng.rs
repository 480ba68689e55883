//! Counter-based random numbers: the `k`-th sample point of a stream is a pure
//! function of `(seed, k)`, so results never depend on how work is split between
//! threads.

/// The SplitMix64 finaliser: a bijective 64-bit mix with good avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Maps the top 24 bits of `bits` to a float in `[0, 1)` (every value exact).
#[inline]
pub fn unit_f32(bits: u64) -> f32 {
    (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// Maps the top 53 bits of `bits` to a double in `[0, 1)`.
#[inline]
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// The `index`-th 2D point in `[0, 1)²` of the stream `seed`.
#[inline]
pub fn xi_2d(seed: u64, index: u64) -> [f32; 2] {
    let base = mix64(seed ^ 0x9e37_79b9_7f4a_7c15).wrapping_add(index.wrapping_mul(2));
    [unit_f32(mix64(base)), unit_f32(mix64(base.wrapping_add(1)))]
}

/// A small sequential generator (SplitMix64) for code that draws many numbers in
/// one thread, e.g. one per pixel in a renderer seeded by [`mix64`] of its index.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator whose stream is fixed by `seed`.
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }

    /// A float in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        unit_f32(self.next_u64())
    }

    /// A double in `[0, 1)`.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }
}
