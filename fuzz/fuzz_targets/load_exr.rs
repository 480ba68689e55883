#![no_main]
include!("common.rs");
libfuzzer_sys::fuzz_target!(|data: &[u8]| check_load(&[0x76, 0x2f, 0x31, 0x01], data));
