#![no_main]
include!("distribution_check.rs");
libfuzzer_sys::fuzz_target!(|data: &[u8]| check_distribution(data));
