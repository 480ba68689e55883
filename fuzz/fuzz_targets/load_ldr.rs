#![no_main]
include!("common.rs");
// The first byte picks PNG or JPEG magic; the rest follows it.
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let (png, rest) = match data.split_first() {
        Some((b, rest)) => (b & 1 == 0, rest),
        None => return,
    };
    if png {
        check_load(prefix::PNG, rest)
    } else {
        check_load(prefix::JPEG, rest)
    }
});
