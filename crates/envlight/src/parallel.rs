//! How the library spreads its work over threads: at the bottom, so that every
//! layer that builds a table lazily asks the same question.

/// Whether a table built on first use (inside a `OnceLock`: portal sides, glossy
/// product tables) may be built in parallel here. Not on a rayon worker: a caller's
/// parallel loop asking for the table would let the waiting worker steal another
/// job that asks for the same table and block on the `OnceLock` it is itself
/// initialising (a deadlock). The result is the same either way.
pub(crate) fn lazy_build_in_parallel() -> bool {
    rayon::current_thread_index().is_none()
}
