// Shared by the loader targets and crates/envlight/tests/fuzz_regressions.rs
// (included with `include!`): decode `bytes` under a
// small texel limit and check what a successful load promises.
/// What each loader target puts before the fuzzer's bytes (`ANY`: nothing, the
/// loader guesses): a format's magic number, or enough of it to pick the format.
#[allow(dead_code)]
mod prefix {
    pub const ANY: &[u8] = b"";
    pub const HDR: &[u8] = b"#?RADIANCE\n";
    pub const EXR: &[u8] = &[0x76, 0x2f, 0x31, 0x01];
    pub const PFM: &[u8] = b"P";
    pub const PNG: &[u8] = &[0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    pub const JPEG: &[u8] = &[0xff, 0xd8, 0xff];
    /// Every one of them (the regression replay tries each).
    pub const ALL: [&[u8]; 6] = [ANY, HDR, EXR, PFM, PNG, JPEG];
}

#[allow(dead_code)]
fn check_load(prefix: &[u8], data: &[u8]) {
    tolerate_caught_dependency_panics();
    let mut bytes = Vec::with_capacity(prefix.len() + data.len());
    bytes.extend_from_slice(prefix);
    bytes.extend_from_slice(data);
    let options = envlight::load::LoadOptions {
        // Keep allocations small: a header may claim anything.
        max_texels: 1 << 20,
        replace_non_finite: data.first().is_some_and(|b| b & 1 == 1),
    };
    if let Ok(loaded) = envlight::load::load_from_memory("fuzz", &bytes, &options) {
        let image = &loaded.image;
        assert!(image.width() > 0 && image.height() > 0);
        assert!(image.width() * image.height() <= options.max_texels);
        for texel in image.texels() {
            for &c in texel {
                assert!(c.is_finite() && c >= 0.0, "loader let {c} through");
            }
        }
    }
}

// `load_from_memory` turns a decoder's panic into a Decode error (its last line of
// defence against third-party decoders), but libFuzzer's panic hook aborts before
// any unwinding, so a panic inside a dependency (zune-jpeg 0.5.15's AVX2 IDCT
// unwraps a slice past the block's end on some malformed JPEGs: zune-image issue
// 409, fixed upstream but not released) would fail the run
// although no caller ever sees it. Under the fuzzer, a panic located in a crate from
// the registry is therefore let unwind into that catch; every other panic (ours, or
// one escaping the catch) still aborts through libFuzzer's hook. In the regression
// replay (tests/fuzz_regressions.rs) the hook wraps the default one: an escaping
// panic still fails the test.
fn tolerate_caught_dependency_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let fuzzer_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let file = info.location().map_or("", |l| l.file());
            if file.contains("/registry/src/") {
                eprintln!("a dependency panicked (left to load_from_memory's catch): {info}");
            } else {
                fuzzer_hook(info);
            }
        }));
    });
}
