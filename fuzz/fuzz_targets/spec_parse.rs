//! The spec parser on arbitrary text: it returns a spec or an error, never panics.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = camspring::Spec::from_toml(text);
    }
});
