//! The whole chain from a fuzzed spec to every output's bytes: parse, design, plan (part,
//! mesh, toolpath, program) and serialisation.
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
    // The plan (part, mesh, tool path, G-code) and every file's bytes, in memory.
    if let Ok(outputs) = camspring::plan(&design) {
        let _ = camspring::export::design_files(&design, &outputs);
    }
});
