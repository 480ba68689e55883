// Shared by the loader targets and crates/envlight/tests/fuzz_regressions.rs
// (included with `include!`): decode `bytes` under a
// small texel limit and check what a successful load promises.
#[allow(dead_code)]
fn check_load(prefix: &[u8], data: &[u8]) {
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
