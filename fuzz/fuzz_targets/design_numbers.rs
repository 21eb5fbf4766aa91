//! Structure-aware: the fuzzer's bytes choose the numbers of a valid spec template (law
//! targets, follower, part and machining), so most inputs reach the design, the part and the
//! G-code instead of stopping in the TOML parser. Never a panic, whatever the numbers.
#![no_main]
use libfuzzer_sys::fuzz_target;

fn number(bytes: &[u8], i: usize, lo: f64, hi: f64) -> f64 {
    let b = [0, 1].map(|k| bytes.get(2 * i + k).copied().unwrap_or(0x80) as u16);
    let t = f64::from(b[0] << 8 | b[1]) / 65535.0;
    lo + (hi - lo) * t
}

fuzz_target!(|data: &[u8]| {
    let n = |i, lo, hi| number(data, i, lo, hi);
    let fmin = n(0, 0.5, 50.0);
    let xmax = n(2, 2.0, 60.0);
    let text = format!(
        r#"name = "fuzz"
[law]
fmax = "{fmax} N"
fmin = "{fmin} N"
xmax = "{xmax} mm"
l0 = "{l0} mm"
c0 = {c0}
delta0 = "{delta0} mm"
[follower]
count = {count}
spring_rate = "{ks} N/mm"
preload = "{preload} mm"
roller_radius = "{roller} mm"
friction = {friction}
[part]
thickness = "{thickness} mm"
web = "{web} mm"
[machining]
tool_diameter = "{tool} mm"
depth_per_pass = "{depth} mm"
tabs = {tabs}
"#,
        fmax = fmin * n(1, 1.01, 200.0),
        l0 = xmax * n(3, 0.02, 0.98),
        c0 = n(4, 0.01, 2.0),
        delta0 = n(5, 0.01, 5.0),
        count = if n(6, 0.0, 1.0) < 0.5 { 1 } else { 2 },
        ks = n(7, 0.1, 200.0),
        preload = n(8, 0.0, 20.0),
        roller = n(9, 0.0, 15.0),
        friction = n(10, 0.0, 0.3),
        thickness = n(11, 1.0, 30.0),
        web = n(12, 1.0, 30.0),
        tool = n(13, 0.5, 12.0),
        depth = n(14, 0.1, 1.0),
        tabs = (n(15, 0.0, 4.99)) as u32,
    );
    let Ok(spec) = camspring::Spec::from_toml(&text) else {
        return;
    };
    let Ok(design) = camspring::design::design(&spec) else {
        return;
    };
    // The plan (part, mesh, tool path, G-code) and every file's bytes (STEP included).
    if let Ok(outputs) = camspring::plan(&design) {
        let _ = camspring::export::design_files(&design, &outputs);
    }
});
