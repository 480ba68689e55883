#![no_main]
include!("common.rs");
// The first byte picks PNG or JPEG magic; the rest follows it.
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let (png, rest) = match data.split_first() {
        Some((b, rest)) => (b & 1 == 0, rest),
        None => return,
    };
    if png {
        check_load(&[0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a], rest)
    } else {
        check_load(&[0xff, 0xd8, 0xff], rest)
    }
});
