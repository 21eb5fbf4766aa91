//! The real binary in a temporary folder: outputs, exit codes and error messages.

use std::process::Command;

mod common;
use common::camspring;

fn spec_path(name: &str) -> String {
    format!("{}/specs/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn default_design_writes_all_outputs_and_exits_zero() {
    let dir = tempfile::tempdir().unwrap();
    let out = camspring(dir.path(), &["design"]);
    assert_eq!(out.status.code(), Some(0));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("alpha = 1.3201914760"), "{stdout}");
    for f in [
        "design.json",
        "report.html",
        "profile.csv",
        "force.svg",
        "profile.svg",
        "cam.step",
        "cam.stl",
        "cam.dxf",
        "drawing.svg",
    ] {
        let p = dir.path().join("out/paper").join(f);
        assert!(p.metadata().unwrap().len() > 100, "{p:?}");
        assert!(
            stdout.contains(&format!("out/paper/{f}")),
            "the printed paths name {f}"
        );
    }
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("out/paper"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());

    // design.json carries the law, the follower and the checks with unit-bearing keys.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("out/paper/design.json")).unwrap())
            .unwrap();
    assert!((json["law"]["alpha"].as_f64().unwrap() - 1.320_191_476).abs() < 1e-9);
    assert!((json["law"]["mu_n"].as_f64().unwrap() - 1.011_535_7).abs() < 1e-7);
    assert_eq!(json["follower"]["k_eff_n_per_mm"].as_f64(), Some(10.0));
    assert_eq!(json["status"], "pass");
    let names: Vec<&str> = json["checks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "pressure_angle",
            "self_locking",
            "undercut",
            "cutter_fit",
            "contact_stress"
        ]
    );
    assert!(
        json["law"]["residuals"]["force_at_xmax"]
            .as_f64()
            .unwrap()
            .abs()
            < 1e-9
    );
}

#[test]
fn profile_csv_has_the_documented_header_and_consistent_rows() {
    let dir = tempfile::tempdir().unwrap();
    let out = camspring(dir.path(), &["design", "-o", "o"]);
    assert_eq!(out.status.code(), Some(0));
    let mut rdr = csv::Reader::from_path(dir.path().join("o/profile.csv")).unwrap();
    let header: Vec<String> = rdr.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(
        header,
        [
            "x_mm",
            "pitch_y_mm",
            "surface_x_mm",
            "surface_y_mm",
            "pressure_angle_deg",
            "force_design_n",
            "force_loading_n",
            "force_unloading_n",
            "stiffness_n_per_mm"
        ]
    );
    let rows: Vec<Vec<f64>> = rdr
        .records()
        .map(|r| r.unwrap().iter().map(|v| v.parse().unwrap()).collect())
        .collect();
    assert!(rows.len() > 200);
    assert_eq!(rows[0][0], 0.0);
    assert_eq!(rows.last().unwrap()[0], 20.0);
    for w in rows.windows(2) {
        assert!(
            w[1][0] > w[0][0] && w[1][1] >= w[0][1],
            "x and lift increase"
        );
    }
    for r in &rows {
        // The roller (3 mm) touches the surface point.
        assert!(((r[2] - r[0]).hypot(r[3] - r[1]) - 3.0).abs() < 1e-6);
        // Loading-corrected default: the loading force is the law (printed to 9 decimals).
        assert!((r[6] - r[5]).abs() <= 1e-6 * r[5]);
        // Stiffness is affine in force: k2 * (F - F0).
        assert!((r[8] - 0.264_038_295_2 * (r[5] - 1.212_670_593)).abs() < 1e-6);
        // Unloading is below loading with friction 0.01.
        assert!(r[7] < r[6]);
    }
}

#[test]
fn json_flag_prints_the_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = camspring(dir.path(), &["design", &spec_path("ankle.toml"), "--json"]);
    assert_eq!(out.status.code(), Some(0));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["name"], "ankle");
    // 100 lbf at 0.5 in, converted to N and mm.
    assert!((json["spec"]["law"]["fmax_n"].as_f64().unwrap() - 444.822_161_5).abs() < 1e-6);
    assert!((json["spec"]["law"]["xmax_mm"].as_f64().unwrap() - 12.7).abs() < 1e-12);
    assert!((json["law"]["force_at_xmax_n"].as_f64().unwrap() - 444.822_161_5).abs() < 1e-6);
    // Shared spring of 60 lbf/in between two followers: k_eff = 4 ks.
    assert!(
        (json["follower"]["k_eff_n_per_mm"].as_f64().unwrap()
            - 4.0 * 60.0 * 4.448_221_615_260_5 / 25.4)
            .abs()
            < 1e-9
    );
}

#[test]
fn json_to_writes_the_json_of_the_run_whose_text_is_printed() {
    let dir = tempfile::tempdir().unwrap();
    let spec = spec_path("ankle.toml");
    let out = camspring(dir.path(), &["design", &spec, "--json-to", "summary.json"]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(serde_json::from_str::<serde_json::Value>(&text).is_err());
    assert!(text.contains("ankle"), "{text}");
    let file = std::fs::read(dir.path().join("summary.json")).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&file).unwrap();
    // 100 lbf at 0.5 in, converted to N and mm.
    assert!((json["spec"]["law"]["fmax_n"].as_f64().unwrap() - 444.822_161_5).abs() < 1e-6);
    // What --json prints, byte for byte.
    let printed = camspring(dir.path(), &["design", &spec, "--json"]);
    assert_eq!(printed.stdout, file);

    // An error is written as --json prints it, with the error's exit code.
    std::fs::write(dir.path().join("bad.toml"), "[law]\nfmax = \"-3 N\"\n").unwrap();
    let bad = camspring(
        dir.path(),
        &["design", "bad.toml", "--json-to", "summary.json"],
    );
    assert_eq!(bad.status.code(), Some(2));
    let error: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("summary.json")).unwrap()).unwrap();
    assert_eq!(error["error"]["kind"], "spec", "{error}");

    // A file that cannot be written is exit code 3, and nothing is printed as if it were done.
    std::fs::create_dir(dir.path().join("folder")).unwrap();
    let unwritable = camspring(dir.path(), &["design", &spec, "--json-to", "folder"]);
    assert_eq!(unwritable.status.code(), Some(3));
    assert!(unwritable.stdout.is_empty());
    assert!(String::from_utf8_lossy(&unwritable.stderr).contains("--json-to"));
    let man = camspring(dir.path(), &["man", "--json-to", "x.json"]);
    assert_eq!(man.status.code(), Some(2));
}

#[test]
fn literal_paper_design_fails_its_checks_with_exit_one_and_still_writes() {
    let dir = tempfile::tempdir().unwrap();
    let out = camspring(
        dir.path(),
        &["design", &spec_path("paper-literal.toml"), "-o", "lit"],
    );
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.contains("FAIL  undercut"), "{stdout}");
    assert!(stdout.contains("follower.preload"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("lit/design.json")).unwrap())
            .unwrap();
    assert_eq!(json["status"], "fail");
}

#[test]
fn bad_specs_exit_two_naming_the_key_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(spec_path("paper.toml")).unwrap();
    let cases: [(&str, String, &[&str]); 6] = [
        (
            "unit.toml",
            base.replace("spring_rate = \"5 N/mm\"", "spring_rate = \"5 N\""),
            &["follower.spring_rate", "line 18", "\"5 N\"", "N/mm"],
        ),
        (
            "unknown.toml",
            base.replace("[checks]", "[checks]\nmax_presure_angle = 50"),
            &["max_presure_angle", "line 33"],
        ),
        (
            "missing.toml",
            base.replace("l0 = \"5 mm\"\n", ""),
            &["law.l0"],
        ),
        (
            "soft.toml",
            base.replace("c0 = 0.2 ", "c0 = 3.0 "),
            &["softening", "Fr - 1 = 39", "Sr*(Lr - 1) = 45"],
        ),
        ("syntax.toml", base.replace("[law]", "[law"), &["line 7"]),
        (
            "range.toml",
            base.replace("count = 2 ", "count = 3 "),
            &["follower.count", "= 3", "1 (one follower) or 2"],
        ),
    ];
    for (name, text, needles) in cases {
        std::fs::write(dir.path().join(name), text).unwrap();
        let out = camspring(dir.path(), &["design", name]);
        assert_eq!(out.status.code(), Some(2), "{name}");
        let stderr = String::from_utf8(out.stderr).unwrap();
        for n in needles {
            assert!(stderr.contains(n), "{name}: {n:?} not in {stderr}");
        }
        assert!(!stderr.contains("panicked"));
        assert!(
            !dir.path().join("out").exists(),
            "{name}: nothing is written for bad input"
        );
    }
    let out = camspring(dir.path(), &["design", "no-such-file.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8(out.stderr)
        .unwrap()
        .contains("no-such-file.toml"));
}

#[test]
fn a_hole_that_does_not_fit_exits_two_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(spec_path("paper.toml")).unwrap();
    let text = base.replace(
        "[machining]",
        "holes = [{ x = \"10 mm\", y = 0, diameter = \"4 mm\" }, { x = \"10 mm\", y = \"30 mm\", diameter = \"4 mm\" }]\n\n[machining]",
    );
    std::fs::write(dir.path().join("holes.toml"), text).unwrap();
    let out = camspring(dir.path(), &["design", "holes.toml"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains("part.holes[1]") && stderr.contains("outside"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("out").exists(),
        "nothing is written for bad input"
    );
}

#[test]
fn rerunning_replaces_outputs_atomically() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(
        camspring(dir.path(), &["design", "-o", "o"]).status.code(),
        Some(0)
    );
    let first = std::fs::read(dir.path().join("o/profile.csv")).unwrap();
    assert_eq!(
        camspring(dir.path(), &["design", "-o", "o"]).status.code(),
        Some(0)
    );
    assert_eq!(
        first,
        std::fs::read(dir.path().join("o/profile.csv")).unwrap(),
        "deterministic output"
    );
}

#[test]
fn simulate_noise_and_identify_work_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = camspring(
        d,
        &[
            "simulate",
            "-o",
            "calib.csv",
            "--truth",
            "truth.json",
            "--duration",
            "120s",
            "--seed",
            "7",
            "--profile",
            "steps",
        ],
    );
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stdout).contains("12000 samples"));
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["sigma_n_per_mm"].as_array().unwrap().len(), 12000);

    let out = camspring(d, &["identify", "calib.csv", "--json"]);
    assert_eq!(out.status.code(), Some(0));
    let id: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let p = &id["parameters"];
    for key in [
        "k2_per_mm",
        "mu_n",
        "f0_n",
        "m_n_s2_per_mm",
        "d0_n",
        "d1_n_s_per_mm",
        "d2_n_s3_per_mm3",
    ] {
        let v = p[key].as_f64().unwrap_or_else(|| panic!("{key}"));
        let s = p[format!("{key}_std")].as_f64().unwrap();
        let t = match key {
            "k2_per_mm" | "mu_n" | "f0_n" => truth["law"][key].as_f64().unwrap(),
            _ => truth["dynamics"][key].as_f64().unwrap(),
        };
        // The inertia on the steps profile can carry a filter-distortion bias of a few of its
        // (small) standard deviations: the window choice cannot see a bias below the noise
        // of the shorter windows (docs/CALIBRATION.md).
        let sigmas = if key == "m_n_s2_per_mm" { 4.0 } else { 3.0 };
        assert!((v - t).abs() < sigmas * s, "{key}: {v} +- {s} against {t}");
    }

    // Noise from a log at rest, then identification with that noise model.
    assert_eq!(
        camspring(
            d,
            &[
                "simulate",
                "--profile",
                "static",
                "--duration",
                "200s",
                "-o",
                "static.csv"
            ]
        )
        .status
        .code(),
        Some(0)
    );
    assert!(d.join("static.truth.json").exists());
    let out = camspring(d, &["noise", "static.csv", "--json"]);
    assert_eq!(out.status.code(), Some(0));
    std::fs::write(d.join("noise.json"), &out.stdout).unwrap();
    let noise: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let vf = noise["force"]["white_noise_variance_n2"].as_f64().unwrap();
    assert!((vf / 0.017 - 1.0).abs() < 0.1, "{vf}");
    let svg = std::fs::read_to_string(d.join("allan.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("averaging time tau (s)"));
    let out = camspring(d, &["identify", "calib.csv", "--noise", "noise.json"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stdout).contains("k2  ="));
}

#[test]
fn bad_logs_and_options_exit_two_with_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut text = String::from("t_s,force_n,position_mm\n");
    for i in 0..100 {
        text.push_str(&format!("{:.2},{},{}\n", i as f64 * 0.01, 10, 1));
    }
    std::fs::write(
        d.join("bad.csv"),
        text.replacen("0.50,10,1", "0.50,ten,1", 1),
    )
    .unwrap();
    for cmd in ["identify", "noise"] {
        let out = camspring(d, &[cmd, "bad.csv"]);
        assert_eq!(out.status.code(), Some(2));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("bad.csv") && err.contains("line 52") && err.contains("\"ten\""),
            "{err}"
        );
    }
    let out = camspring(d, &["identify", "missing.csv"]);
    assert_eq!(out.status.code(), Some(2));
    let out = camspring(d, &["identify", "bad.csv", "--force", "F:furlong"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("furlong"));
    let out = camspring(d, &["simulate", "--duration", "soon"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--duration"));
    let out = camspring(d, &["simulate", "--profile", "zigzag"]);
    assert_eq!(out.status.code(), Some(2));
    // A profile the wire cannot follow (pushing force) is refused, and nothing is written.
    let out = camspring(d, &["simulate", "--d1", "50", "-o", "push.csv"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("wire only pulls"));
    assert!(!d.join("push.csv").exists());
}

#[test]
fn progress_bar_only_on_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // One hour at 100 Hz: 11 MB, above the 8 MB threshold of the progress bar.
    let out = camspring(d, &["simulate", "--duration", "1h", "-o", "hour.csv"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(d.join("hour.csv").metadata().unwrap().len() > 8 << 20);
    // On a pipe: nothing but the result, even without CI set.
    let piped = Command::new(env!("CARGO_BIN_EXE_camspring"))
        .args(["noise", "hour.csv"])
        .env_remove("CI")
        .current_dir(d)
        .output()
        .unwrap();
    assert_eq!(piped.status.code(), Some(0));
    assert!(
        piped.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&piped.stderr)
    );
    // On a terminal (util-linux `script` gives the command a pseudo-terminal): a bar.
    let tty = Command::new("script")
        .args([
            "-qec",
            &format!("{} noise hour.csv", env!("CARGO_BIN_EXE_camspring")),
            "/dev/null",
        ])
        .env_remove("CI")
        .current_dir(d)
        .output()
        .expect("util-linux script");
    let text = String::from_utf8_lossy(&tty.stdout);
    assert!(
        text.contains("reading hour.csv") && text.contains("MiB"),
        "{text}"
    );
    // And with CI set, none even on a terminal.
    let ci = Command::new("script")
        .args([
            "-qec",
            &format!("{} noise hour.csv", env!("CARGO_BIN_EXE_camspring")),
            "/dev/null",
        ])
        .env("CI", "true")
        .current_dir(d)
        .output()
        .unwrap();
    assert!(!String::from_utf8_lossy(&ci.stdout).contains("reading hour.csv"));
}

#[test]
fn a_closed_pipe_is_not_a_crash() {
    // `camspring design | head -1`: stdout closes early; the command must not panic.
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_camspring"))
        .arg("design")
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("panicked"));
}

#[test]
fn estimate_and_validate_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = spec_path("paper.toml");
    let sim = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "simulate",
            spec.as_str(),
            "-o",
            out,
            "--duration",
            "300s",
            "--m",
            "0.05",
            "--d1",
            "0.2",
            "--d2",
            "-1e-4",
        ];
        args.extend_from_slice(extra);
        assert_eq!(camspring(d, &args).status.code(), Some(0));
    };
    sim("calib.csv", &[]);
    let out = camspring(d, &["estimate", "calib.csv", "-o", "est.csv", "--json"]);
    assert_eq!(out.status.code(), Some(0));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "k2_per_mm",
        "m_n_s2_per_mm",
        "d2_n_s3_per_mm3",
        "sigma_n_per_mm",
        "d_n_s_per_mm",
        "f0_n",
        "d0_n",
    ] {
        assert!(v["final"][key].is_f64(), "{key}");
        assert!(
            v["final"][format!("{key}_std")].as_f64().unwrap() > 0.0,
            "{key}_std"
        );
    }
    let k2 = v["final"]["k2_per_mm"].as_f64().unwrap();
    assert!((k2 / 0.2640383 - 1.0).abs() < 0.005, "{k2}");
    let csv = std::fs::read_to_string(d.join("est.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(
        header.starts_with("t_s,x_mm,x_mm_std,xd_mm_per_s,"),
        "{header}"
    );
    assert!(header.ends_with("f0_n,f0_n_std,d0_n,d0_n_std"), "{header}");
    assert!(csv.lines().count() > 29_000);

    // The designed spring passes (exit 0) and writes validation.svg.
    let out = camspring(d, &["validate", &spec, "calib.csv", "--tolerance", "3%"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("PASS"));
    let svg = std::fs::read_to_string(d.join("validation.svg")).unwrap();
    assert!(svg.contains("Stiffness against force") && svg.contains("<circle"));

    // The ankle spec's design is a different spring: the same log fails (exit 1), by name.
    let out = camspring(
        d,
        &["validate", &spec_path("ankle.toml"), "calib.csv", "--json"],
    );
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["pass"], false);
    let k2 = common::criterion(&v, "k2");
    assert_eq!(k2["pass"], false);

    // Q, P0 and R can be overridden, and the JSON says what was used.
    let out = camspring(
        d,
        &[
            "estimate",
            "calib.csv",
            "-o",
            "est2.csv",
            "--json",
            "--q",
            "xdd=0.25",
            "--q",
            "sigma_n_per_mm=0.002",
            "--p0",
            "m=0.02",
            "--r",
            "0.02",
        ],
    );
    // R is twice the position noise here, so the innovations are about half their predicted
    // variance: the run is reported as not consistent, exit 1, with the numbers.
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["consistency"]["consistent"], false);
    let nis = v["consistency"]["nis_mean"].as_f64().unwrap();
    assert!((0.35..0.65).contains(&nis), "{nis}");
    assert_eq!(v["settings"]["q"][2], 0.25);
    assert_eq!(v["settings"]["q"][3], 0.002);
    assert_eq!(v["settings"]["p0_std"][5], 0.02);
    assert_eq!(v["settings"]["r_position_mm2"], 0.02);

    // Bad options are bad input.
    for args in [
        vec!["estimate", "calib.csv", "--q", "jerk=1"],
        vec!["estimate", "calib.csv", "--p0", "m=-1"],
        vec!["estimate", "calib.csv", "--r", "0"],
        vec!["estimate", "calib.csv", "--discretization", "midpoint"],
        vec!["estimate", "calib.csv", "--force-rate", "psychic"],
        vec!["estimate", "calib.csv", "--force-rate", "zero-phase:6s"],
        vec!["estimate", "calib.csv", "--force-rate", "zero-phase:0s"],
        vec![
            "validate",
            spec.as_str(),
            "calib.csv",
            "--tolerance",
            "lots",
        ],
    ] {
        assert_eq!(camspring(d, &args).status.code(), Some(2), "{args:?}");
    }
}

#[test]
fn init_writes_a_starter_spec_whose_every_optional_key_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = camspring(d, &["init", "my.toml"]);
    assert_eq!(out.status.code(), Some(0));
    let out = camspring(d, &["design", "my.toml", "--json"]);
    assert_eq!(out.status.code(), Some(0));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((v["law"]["alpha"].as_f64().unwrap() - 1.3201914760).abs() < 1e-9);
    // Never overwrites without --force.
    assert_eq!(camspring(d, &["init", "my.toml"]).status.code(), Some(2));
    assert_eq!(
        camspring(d, &["init", "my.toml", "--force"]).status.code(),
        Some(0)
    );
    // Uncomment every optional key (except the given-law and pin-friction alternatives):
    // the spec is still valid, so the comments show real keys and values.
    let text = std::fs::read_to_string(d.join("my.toml")).unwrap();
    let mut full = String::new();
    for line in text.lines() {
        let body = line.strip_prefix("# ").unwrap_or(line);
        let is_key = body.starts_with('[')
            || body
                .split_once(" = ")
                .is_some_and(|(k, _)| k.chars().all(|c| c.is_ascii_lowercase() || c == '_'));
        let alternative = ["mu ", "k2 ", "f0 ", "pin_", "rolling_"]
            .iter()
            .any(|p| body.starts_with(p));
        if line.starts_with("# ") && is_key && !alternative {
            full.push_str(body);
        } else {
            full.push_str(line);
        }
        full.push('\n');
    }
    assert!(full.matches("\n[").count() >= 6, "{full}");
    std::fs::write(d.join("full.toml"), &full).unwrap();
    let out = camspring(d, &["design", "full.toml"]);
    assert_eq!(out.status.code(), Some(0), "{full}");
}

#[test]
fn completions_and_man_pages_come_from_the_clap_definitions() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = camspring(d, &["completions", "bash"]);
    assert_eq!(out.status.code(), Some(0));
    let script = String::from_utf8(out.stdout).unwrap();
    for sub in [
        "design", "simulate", "noise", "identify", "estimate", "validate", "init",
    ] {
        assert!(script.contains(sub), "{sub}");
    }
    assert!(script.contains("--discretization"));
    let out = camspring(d, &["man", "-o", "man"]);
    assert_eq!(out.status.code(), Some(0));
    let page = std::fs::read_to_string(d.join("man/camspring-validate.1")).unwrap();
    assert!(page.starts_with(".ie") || page.contains(".TH"), "{page}");
    assert!(page.contains("tolerance"));
    assert!(d.join("man/camspring.1").exists());
    assert_eq!(
        camspring(d, &["completions", "tcsh"]).status.code(),
        Some(2)
    );
}

#[test]
fn colour_only_on_a_terminal_and_never_with_no_color() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bin = env!("CARGO_BIN_EXE_camspring");
    let piped = camspring(d, &["design"]);
    assert!(!String::from_utf8_lossy(&piped.stdout).contains('\x1b'));
    let tty = |no_color: bool| {
        let mut cmd = Command::new("script");
        cmd.args(["-qec", &format!("{bin} design"), "/dev/null"])
            .current_dir(d);
        if no_color {
            cmd.env("NO_COLOR", "1");
        } else {
            cmd.env_remove("NO_COLOR");
        }
        String::from_utf8_lossy(&cmd.output().expect("util-linux script").stdout).into_owned()
    };
    assert!(tty(false).contains("\x1b[32mPASS\x1b[0m"));
    assert!(!tty(true).contains('\x1b'));
}

#[test]
fn sweep_writes_its_grid_and_refuses_bad_axes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = camspring(
        d,
        &[
            "sweep",
            "--vary",
            "spring_rate=2..20:4",
            "--vary",
            "roller_radius=2,3",
            "-o",
            "sw",
        ],
    );
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("8 designs:"));
    let csv = std::fs::read_to_string(d.join("sw/sweep.csv")).unwrap();
    assert_eq!(csv.lines().count(), 9);
    assert!(std::fs::read_to_string(d.join("sw/sweep.svg"))
        .unwrap()
        .contains("Largest pressure angle"));
    let out = camspring(d, &["sweep", "--vary", "preload=0..2:3", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v.as_array().unwrap().len(), 3);
    let out = camspring(d, &["sweep", "--vary", "colour=1..2"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown key"));
}

#[test]
fn help_has_examples_for_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let top = camspring(dir.path(), &["--help"]);
    assert_eq!(top.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&top.stdout).contains("Examples:"));
    for sub in [
        "design",
        "simulate",
        "noise",
        "identify",
        "estimate",
        "validate",
        "sweep",
        "init",
        "completions",
        "man",
    ] {
        let out = camspring(dir.path(), &[sub, "--help"]);
        assert_eq!(out.status.code(), Some(0), "{sub}");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("Examples:") && text.contains(&format!("camspring {sub}")),
            "{sub}: {text}"
        );
    }
}

/// A log of one design's part, diagnosed against another design: the forward model cannot
/// explain it whatever the build, and the diagnosis says so (exit 1) instead of reporting
/// findings, and `revise` builds nothing on it. Against its own design the same log fits.
#[test]
fn a_log_of_another_designs_part_does_not_fit_the_diagnosis_and_is_not_revised_on() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (knee, paper) = (spec_path("knee.toml"), spec_path("paper.toml"));
    let out = camspring(d, &["simulate", knee.as_str(), "-o", "knee.csv"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let diagnose = |spec: &str| {
        let out = camspring(d, &["diagnose", spec, "knee.csv", "--json"]);
        let g: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        (out.status.code(), g)
    };
    let (code, own) = diagnose(&knee);
    assert_eq!(code, Some(0), "{own}");
    assert_eq!(own["fit"]["status"], "fits", "{}", own["fit"]);
    let (code, other) = diagnose(&paper);
    assert_eq!(code, Some(1), "{other}");
    assert_eq!(other["fit"]["status"], "does-not-fit", "{}", other["fit"]);
    let reasons = other["fit"]["reasons"].to_string();
    assert!(reasons.contains("another design's part"), "{reasons}");
    let out = camspring(d, &["diagnose", paper.as_str(), "knee.csv"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.starts_with("diagnosis:") && text.contains("DOES NOT FIT THIS LOG"),
        "{text}"
    );
    // validate, which judges the strokes by the diagnosis's bins, says so too.
    let out = camspring(d, &["validate", paper.as_str(), "knee.csv"]);
    assert_eq!(out.status.code(), Some(1));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("warning: the design's forward model does not fit this log"),
        "{text}"
    );

    let out = camspring(
        d,
        &["revise", paper.as_str(), "knee.csv", "-o", "rev", "--json"],
    );
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let refusal = v["revision"]["refusal"].as_str().unwrap();
    assert!(refusal.contains("does not fit this log"), "{refusal}");
    assert!(
        v["revision"]["chosen"].is_null() && v["spec"].is_null(),
        "{v}"
    );
    assert!(!d.join("rev/paper-B.toml").exists());

    // A far softer part's log against a stiffer design: the weights take the position's noise
    // through the designed stiffness and expect far more scatter than the log has.
    let ankle = spec_path("ankle.toml");
    let out = camspring(d, &["simulate", paper.as_str(), "-o", "paper.csv"]);
    assert_eq!(out.status.code(), Some(0));
    let out = camspring(d, &["diagnose", ankle.as_str(), "paper.csv", "--json"]);
    let g: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", g["fit"]);
    assert_eq!(g["fit"]["status"], "does-not-fit", "{}", g["fit"]);
    let chi2 = g["fit"]["reduced_chi2"].as_f64().unwrap();
    assert!(chi2 < 0.5, "{chi2}");
    let reasons = g["fit"]["reasons"].to_string();
    assert!(
        reasons.contains("below 0.5") && reasons.contains("another design's part"),
        "{reasons}"
    );
}

#[test]
fn simulate_a_build_off_its_design_then_diagnose_and_revise_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = spec_path("paper.toml");
    // Springs 12 % stiff, 0.3 mm short of preload, three times the friction.
    let out = camspring(
        d,
        &[
            "simulate",
            spec.as_str(),
            "-o",
            "built.csv",
            "--built-rate-scale",
            "1.12",
            "--built-preload-offset",
            "-0.3mm",
            "--built-friction",
            "0.03",
        ],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("built.truth.json")).unwrap()).unwrap();
    assert_eq!(truth["as_built"]["spring_rate_scale"].as_f64(), Some(1.12));

    let out = camspring(d, &["diagnose", spec.as_str(), "built.csv", "--json"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let g: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let near = |key: &str, truth: f64, tol: f64| {
        let v = g[key]["value"].as_f64().unwrap();
        assert!((v - truth).abs() <= tol, "{key}: {v} against {truth}");
        assert_eq!(g[key]["resolved"], true, "{key}");
    };
    near("spring_rate_scale", 1.12, 0.01);
    near("preload_offset_mm", -0.3, 0.05);
    near("friction", 0.03, 0.005);
    assert!(d.join("diagnosis.svg").metadata().unwrap().len() > 1000);
    assert!(g["force_error_after_percent"].as_f64().unwrap() < 1.0);

    // The text names the deviations in words.
    let out = camspring(d, &["diagnose", spec.as_str(), "built.csv"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("stiffer than designed") && text.contains("short"),
        "{text}"
    );

    // A 12 % stiff spring cannot be shimmed to 2 %: the cam is re-cut, with the whole set.
    let out = camspring(
        d,
        &["revise", spec.as_str(), "built.csv", "-o", "revB", "--json"],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = &v["revision"];
    assert_eq!(r["revision"], "B");
    let chosen = r["chosen"].as_u64().unwrap() as usize;
    assert_eq!(r["options"][chosen]["kind"], "recut-cam");
    assert_eq!(r["options"][0]["kind"], "shim");
    assert_eq!(r["options"][0]["passes"], false);
    for f in [
        "paper-B.toml",
        "revision.json",
        "cam.step",
        "cam.ngc",
        "report.html",
        "drawing.pdf",
    ] {
        assert!(d.join("revB").join(f).exists(), "{f}");
    }
    let text = std::fs::read_to_string(d.join("revB/paper-B.toml")).unwrap();
    assert!(
        text.contains("revision = \"B\"") && text.contains("revision_note"),
        "{text}"
    );
    // The revised spec designs: it is a spec like any other.
    let out = camspring(d, &["design", "revB/paper-B.toml", "-o", "check"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Built from its parts (both strokes, the friction's hysteresis), the revision passes
    // against its band of builds, as the text suggests.
    let out = camspring(d, &["revise", spec.as_str(), "built.csv", "-o", "revB"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("--built -o built-B.csv"), "{text}");
    let out = camspring(
        d,
        &[
            "simulate",
            "revB/paper-B.toml",
            "--built",
            "-o",
            "built-B.csv",
            "--seed",
            "3",
        ],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = camspring(d, &["validate", "revB/paper-B.toml", "built-B.csv"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[test]
fn build_flags_and_assembly_keys_out_of_range_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = camspring(d, &["simulate", "-o", "x.csv", "--built-rate-scale", "0"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--built-rate-scale") && err.contains("expected"),
        "{err}"
    );
    let out = camspring(d, &["simulate", "-o", "x.csv", "--built-friction", "1.5"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--built-friction"));

    let spec = std::fs::read_to_string(spec_path("paper.toml")).unwrap();
    for (table, key, expected) in [
        (
            "[assembly]\nshim = \"-50 mm\"\n",
            "assembly.shim",
            "at least",
        ),
        (
            "[assembly]\nspring_rate = \"-2 N/mm\"\n",
            "assembly.spring_rate",
            "N/mm",
        ),
        (
            "[assembly]\nfriction = 2.0\n",
            "assembly.friction",
            "expected",
        ),
        ("[assembly]\nwasher = \"1 mm\"\n", "washer", "expected"),
    ] {
        std::fs::write(d.join("bad.toml"), format!("{spec}\n{table}")).unwrap();
        let out = camspring(d, &["design", "bad.toml"]);
        assert_eq!(out.status.code(), Some(2), "{table}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(key) && err.contains(expected),
            "{table}: {err}"
        );
    }
}

#[test]
fn springs_of_the_wrong_rate_are_swapped_for_a_catalogue_spring_and_the_revision_passes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = std::fs::read_to_string(spec_path("paper.toml")).unwrap();
    let spec = spec.replacen(
        "[follower]\n",
        "[follower]\nspring_catalogue = \"springs.csv\"\n",
        1,
    );
    std::fs::write(d.join("paper.toml"), spec).unwrap();
    std::fs::copy(spec_path("springs.csv"), d.join("springs.csv")).unwrap();
    // The vendor shipped 4.25 N/mm springs for the 5 N/mm design: no shim brings the force
    // back, the catalogue's 5.05 N/mm spring does.
    let out = camspring(
        d,
        &[
            "simulate",
            "paper.toml",
            "-o",
            "built.csv",
            "--built-rate-scale",
            "0.85",
            "--seed",
            "2",
        ],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = camspring(
        d,
        &["revise", "paper.toml", "built.csv", "-o", "rev/B", "--json"],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = &v["revision"];
    let o = &r["options"][r["chosen"].as_u64().unwrap() as usize];
    assert_eq!(o["kind"], "catalogue-spring", "{r}");
    assert_eq!(o["spring_part"], "CS-0505");
    assert!(o["predicted_error_max_percent"].as_f64().unwrap() <= 3.0);
    // Only the spec and the decision: the cam is kept.
    assert!(!d.join("rev/B/cam.step").exists());
    // The revised spec, two folders down, still finds the catalogue; built as it says (the
    // catalogue spring with the preload as assembled), it passes.
    let text = std::fs::read_to_string(d.join("rev/B/paper-B.toml")).unwrap();
    assert!(
        text.contains("spring_catalogue = \"../../springs.csv\""),
        "{text}"
    );
    assert!(text.contains("spring_part = \"CS-0505\""), "{text}");
    let out = camspring(
        d,
        &[
            "simulate",
            "rev/B/paper-B.toml",
            "-o",
            "after.csv",
            "--seed",
            "9",
        ],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = camspring(
        d,
        &[
            "validate",
            "rev/B/paper-B.toml",
            "after.csv",
            "--tolerance",
            "3%",
        ],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    // The unrevised spec fails the same kind of build.
    let out = camspring(
        d,
        &["validate", "paper.toml", "built.csv", "--tolerance", "3%"],
    );
    assert_eq!(out.status.code(), Some(1));
}

/// The heavy steps log of `estimate_warns_when_the_log_is_too_short_for_its_target_and_says_how_much_longer`
/// (148 s, seed 5): the filter's M is held to a quarter of identification's deviation of m,
/// nearly all of which is identification's allowance for its differentiating filter's bias
/// (`identify --json`, `filter_bias_std`). The text names that allowance and the JSON promises
/// no log length for M, where it had promised the target at 1.9 times a 30 s log.
#[test]
fn an_inertia_held_to_identifications_filter_bias_promises_no_log_length() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sim = [
        "simulate",
        "-o",
        "steps.csv",
        "--duration",
        "148.3s",
        "--seed",
        "5",
        "--profile",
        "steps",
    ];
    assert_eq!(camspring(d, &sim).status.code(), Some(0));
    let id = camspring(d, &["identify", "steps.csv", "--json"]);
    let id: serde_json::Value = serde_json::from_slice(&id.stdout).unwrap();
    let m_std = id["parameters"]["m_n_s2_per_mm_std"].as_f64().unwrap();
    let m_bias = id["filter_bias_std"][0].as_f64().unwrap();
    assert!(m_bias * m_bias > 0.5 * m_std * m_std, "{m_bias} of {m_std}");
    let text = camspring(d, &["estimate", "steps.csv", "-o", "est.csv"]);
    let text =
        String::from_utf8_lossy(&text.stderr).to_string() + &String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains("held to 1/4 of identification's")
            && text.contains("differentiating filter's bias"),
        "{text}"
    );
    let json = camspring(d, &["estimate", "steps.csv", "-o", "est2.csv", "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    let m = json["imprecise"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["state"] == "m_n_s2_per_mm")
        .unwrap_or_else(|| panic!("{}", json["imprecise"]));
    assert!(m["log_length_factor_for_target"].is_null(), "{m}");
    let bias = m["relative_identification_filter_bias"].as_f64().unwrap();
    let m_id = id["parameters"]["m_n_s2_per_mm"].as_f64().unwrap();
    assert!(
        (bias * m_id - m_bias).abs() < 0.2 * m_bias,
        "{bias} {m_bias}"
    );
}
