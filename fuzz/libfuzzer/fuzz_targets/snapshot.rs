#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| meshless_fuzz::snapshot(data));
