//! The committed header `include/envlight.h` is what cbindgen generates from this
//! crate today. `ENVLIGHT_BLESS=1 cargo test -p envlight-c --test header` writes
//! it anew after a change to the API.

use std::path::Path;

#[test]
fn committed_header_is_current() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml"))
        .expect("cbindgen.toml is readable");
    let bindings = cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header");
    let mut fresh = Vec::new();
    bindings.write(&mut fresh);
    let fresh = String::from_utf8(fresh).expect("the header is UTF-8");
    let path = crate_dir.join("include/envlight.h");
    if std::env::var_os("ENVLIGHT_BLESS").is_some() {
        std::fs::write(&path, &fresh).expect("include/envlight.h is writable");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    if committed != fresh {
        let line = committed
            .lines()
            .zip(fresh.lines())
            .position(|(a, b)| a != b)
            .map_or(committed.lines().count().min(fresh.lines().count()), |k| k);
        panic!(
            "include/envlight.h differs from a fresh generation from line {}: regenerate it \
             with `ENVLIGHT_BLESS=1 cargo test -p envlight-c --test header` and commit it",
            line + 1
        );
    }
}
