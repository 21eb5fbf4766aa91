//! The whole chain from a fuzzed spec to G-code: parse, design, part, toolpath and program.
//! Any spec the parser accepts must give outputs or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(spec) = camspring::Spec::from_toml(text) else {
        return;
    };
    let Ok(design) = camspring::design::design(&spec) else {
        return;
    };
    if let Ok(part) = camspring::part::build(&design) {
        let _ = camspring::toolpath::passes(&design, &part);
    }
});
