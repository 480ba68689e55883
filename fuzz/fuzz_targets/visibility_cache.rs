#![no_main]
// Visibility cache files (crates/envlight/src/visibility/file.rs) from untrusted
// bytes: reading never panics nor allocates beyond what the bytes can fill, and a
// cache that reads writes back to the same bytes and samples finite pdfs. The
// magic, version, light hash and an empty scene key are given, so the fuzzer
// spends its time past the keys. The light and patch grid are those the seeds
// were made with (crates/envlight/examples/fuzz_seeds.rs, `visibility_seeds`).
use envlight::visibility::{light_hash, FILE_VERSION};
use envlight::{
    EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3, VisibilityCache,
};
use std::sync::{Arc, OnceLock};

fn product() -> &'static Arc<ProductSampler> {
    static PRODUCT: OnceLock<Arc<ProductSampler>> = OnceLock::new();
    PRODUCT.get_or_init(|| {
        let light = EnvironmentLight::new(envlight::builtin::sky(32, 16), LightOptions::default())
            .expect("the built-in sky builds");
        let options = ProductOptions {
            patches: Some([8, 4]),
            ..Default::default()
        };
        Arc::new(ProductSampler::new(Arc::new(light), options))
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let product = product();
    let mut bytes = b"envlvis\0".to_vec();
    bytes.extend_from_slice(&FILE_VERSION.to_le_bytes());
    bytes.extend_from_slice(&light_hash(product).to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes.extend_from_slice(data);
    if let Ok(cache) = VisibilityCache::from_bytes(&bytes, "fuzz", product.clone(), "") {
        assert!(
            cache.to_bytes("").expect("an empty key") == bytes,
            "a round trip changed the file"
        );
        let up = Vec3::new(0.0, 0.0, 1.0);
        for (i, &key) in [0.0f32, 0.25, 0.5, 1.0].iter().enumerate() {
            let point = cache.at(Vec3::new(key, -key, 0.0), &Factor::cosine(up));
            if let Some(s) = point.sample([0.1 + 0.2 * i as f32, 0.6]) {
                assert!(s.pdf > 0.0 && s.pdf.is_finite(), "pdf {}", s.pdf);
            }
        }
    }
});
