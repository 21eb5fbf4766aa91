//! Criterion benchmarks of the design pipeline on the default spec (`specs/paper.toml`).
//! Run with `cargo bench --bench design`; results go in docs/BENCHMARKS.md.

use std::hint::black_box;

use camspring::cam::pitch_curve::synthesize;
use camspring::design::{design, law_of, synthesis_options};
use camspring::export::{drawing, dxf, step, stl};
use camspring::law::solve;
use camspring::outputs::summarize;
use camspring::part::build;
use camspring::part::mesh;
use camspring::render::design::{force_svg, profile_csv, profile_svg};
use camspring::{
    model::{LawSpec, Spec},
    spec::DEFAULT_SPEC_TOML,
};
use criterion::{criterion_group, criterion_main, Criterion};

fn benches(c: &mut Criterion) {
    let spec = Spec::from_toml(DEFAULT_SPEC_TOML).unwrap();
    let LawSpec::Targets(targets) = spec.law.clone() else {
        unreachable!("the default spec has targets")
    };
    c.bench_function("spec_parse", |b| {
        b.iter(|| Spec::from_toml(black_box(DEFAULT_SPEC_TOML)).unwrap())
    });
    c.bench_function("law_solve", |b| {
        b.iter(|| solve(black_box(&targets)).unwrap())
    });
    let law = law_of(&spec).unwrap().law;
    let options = synthesis_options(&spec);
    c.bench_function("pitch_curve_synthesize", |b| {
        b.iter(|| synthesize(black_box(&law), &spec.follower, 20.0, &options).unwrap())
    });
    c.bench_function("design_pipeline", |b| {
        b.iter(|| design(black_box(&spec)).unwrap())
    });
    let d = design(&spec).unwrap();
    c.bench_function("design_outputs_in_memory", |b| {
        b.iter(|| {
            let s = serde_json::to_vec_pretty(&summarize(&d, &[])).unwrap();
            (
                s,
                profile_csv(&d).unwrap(),
                force_svg(&d, None),
                profile_svg(&d),
            )
        })
    });
    // The tolerance band: 10 000 builds through the forward model (issue: under 1 s on 2 cores).
    let tolerances = camspring::model::TolerancesSpec {
        samples: 10_000,
        ..Default::default()
    };
    let mut group = c.benchmark_group("tolerance_band");
    group.sample_size(10);
    group.bench_function("10000 builds, 41 stations", |b| {
        b.iter(|| {
            camspring::cam::tolerance::force_band(
                black_box(&d.pitch_curve),
                &spec.follower,
                &tolerances,
            )
        })
    });
    group.finish();
    c.bench_function("part_build (outline, B-spline fit, area)", |b| {
        b.iter(|| build(black_box(&d)).unwrap())
    });
    let part = build(&d).unwrap();
    c.bench_function("step_export (solid + STEP text)", |b| {
        b.iter(|| step::step_text(black_box(&part), "paper", "0").unwrap())
    });
    c.bench_function("stl_export (5 um, mesh + bytes)", |b| {
        b.iter(|| {
            let rings = mesh::rings(black_box(&part), 5e-3, 1e-3);
            stl::stl_bytes(&mesh::mesh(&rings, part.thickness_mm).unwrap(), "0")
        })
    });
    c.bench_function("dxf_and_drawing_export", |b| {
        b.iter(|| {
            (
                dxf::dxf_bytes(black_box(&part), "0").unwrap(),
                drawing::drawing_svg(&d, &part),
            )
        })
    });
    let svg = drawing::drawing_svg(&d, &part);
    c.bench_function("drawing_pdf (svg2pdf, embedded font)", |b| {
        b.iter(|| drawing::drawing_pdf(black_box(&svg)).unwrap())
    });
    c.bench_function("gcode (passes + program, 1 um, arcs)", |b| {
        b.iter(|| {
            let (jobs, summary) = camspring::toolpath::jobs(black_box(&d), &part).unwrap();
            camspring::toolpath::gcode::write(&d, &jobs, &summary)
        })
    });
    // A failing design: the advice searches re-synthesise the curve many times.
    let literal = Spec::from_toml(include_str!("../specs/paper-literal.toml")).unwrap();
    c.bench_function("design_pipeline_with_advice (paper-literal)", |b| {
        b.iter(|| design(black_box(&literal)).unwrap())
    });
}

criterion_group! {
    name = group;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(group);
