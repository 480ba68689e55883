#![no_main]
// GPU table files (docs/gpu-tables.md) from untrusted bytes: parsing never panics,
// and whatever parses writes back to bytes that parse to the same tables. The
// magic and version are given, so the fuzzer spends its time on the section table.
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let mut bytes = b"ENVLGPU\0\x01\0\0\0".to_vec();
    bytes.extend_from_slice(data);
    if let Ok(tables) = envlight::gpu::GpuTables::from_bytes(&bytes) {
        let again = envlight::gpu::GpuTables::from_bytes(&tables.to_bytes())
            .expect("written tables parse");
        assert!(again == tables, "a round trip changed the tables");
    }
});
