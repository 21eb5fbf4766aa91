//! The contract under faults and hostile input, driven through the real binary: an output
//! folder always holds exactly one complete run (after refusals, kills and concurrent runs),
//! special files are never written through, and write failures are exit code 3.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};

mod common;
use common::camspring;

const ALL_OUTPUTS: [&str; 12] = [
    "design.json",
    "report.html",
    "profile.csv",
    "force.svg",
    "profile.svg",
    "cam.step",
    "cam.stl",
    "cam.dxf",
    "drawing.svg",
    "drawing.pdf",
    "cam.ngc",
    "toolpath.svg",
];

/// Files whose header carries the run's identity.
const MARKED: [&str; 9] = [
    "report.html",
    "force.svg",
    "profile.svg",
    "cam.step",
    "cam.stl",
    "cam.dxf",
    "drawing.svg",
    "cam.ngc",
    "toolpath.svg",
];

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_camspring"))
}

fn spec(name: &str) -> String {
    format!("{}/specs/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// The output files present in `dir`.
fn outputs_in(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .map(|r| {
            r.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| ALL_OUTPUTS.contains(&n.as_str()))
                .collect()
        })
        .unwrap_or_default()
}

/// Checks that `dir` holds one complete run: design.json lists exactly the output files
/// present, and every file with a header carries design.json's run id. A folder without
/// design.json must hold no output at all. Returns the run id, if any.
fn assert_one_complete_run(dir: &Path) -> Option<String> {
    let present = outputs_in(dir);
    let Ok(text) = std::fs::read(dir.join("design.json")) else {
        assert!(present.is_empty(), "no design.json but {present:?}");
        return None;
    };
    let v: serde_json::Value = serde_json::from_slice(&text).expect("design.json is complete");
    let listed: BTreeSet<String> = v["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        listed, present,
        "design.json lists other files than present"
    );
    let id = v["run_id"].as_str().unwrap().to_string();
    for f in MARKED.iter().filter(|f| present.contains(**f)) {
        let bytes = std::fs::read(dir.join(f)).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(
            text.contains(&format!("camspring run {id}")) || text.contains(&format!("run {id}")),
            "{f} is not from run {id}"
        );
    }
    Some(id)
}

#[test]
fn a_refused_part_after_a_success_leaves_no_part_files() {
    let d = tempfile::tempdir().unwrap();
    assert_eq!(
        camspring(d.path(), &["design", &spec("paper.toml"), "-o", "x"])
            .status
            .code(),
        Some(0)
    );
    assert!(d.path().join("x/cam.ngc").exists());
    std::fs::write(d.path().join("x/calib.csv"), "t_s,force_n,position_mm\n").unwrap();
    let out = camspring(
        d.path(),
        &["design", &spec("paper-literal.toml"), "-o", "x"],
    );
    assert_eq!(out.status.code(), Some(1));
    let dir = d.path().join("x");
    assert_one_complete_run(&dir);
    for f in [
        "cam.ngc",
        "cam.step",
        "cam.stl",
        "cam.dxf",
        "drawing.svg",
        "toolpath.svg",
    ] {
        assert!(!dir.join(f).exists(), "{f} of the previous design survived");
    }
    // The user's own file stays.
    assert!(dir.join("calib.csv").exists());
}

#[test]
fn a_refused_program_after_a_success_leaves_no_program() {
    let d = tempfile::tempdir().unwrap();
    camspring(d.path(), &["design", &spec("paper.toml"), "-o", "x"]);
    let big_cutter = std::fs::read_to_string(spec("paper.toml"))
        .unwrap()
        .replace(
            "roller_material = \"bearing-steel\"",
            "roller_material = \"bearing-steel\"\nholes = [{ x = \"10 mm\", y = \"0 mm\", diameter = \"4 mm\" }]",
        );
    std::fs::write(d.path().join("big.toml"), big_cutter).unwrap();
    let out = camspring(d.path(), &["design", "big.toml", "-o", "x"]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "a refused program fails the design"
    );
    let dir = d.path().join("x");
    assert_one_complete_run(&dir);
    assert!(!dir.join("cam.ngc").exists());
    assert!(!dir.join("toolpath.svg").exists());
    assert!(dir.join("cam.step").exists());
}

#[test]
fn output_paths_that_are_not_regular_files_are_refused() {
    let d = tempfile::tempdir().unwrap();
    // A character device as the design folder and as a log file.
    let out = camspring(d.path(), &["design", "-o", "/dev/null"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/dev/null"));
    let out = camspring(
        d.path(),
        &["simulate", "--duration", "20s", "-o", "/dev/null"],
    );
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a regular file"));
    #[cfg(unix)]
    {
        // A FIFO is neither replaced nor written into.
        let fifo = d.path().join("fifo");
        let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
        assert!(made.success());
        let out = camspring(d.path(), &["init", "fifo", "--force"]);
        assert_eq!(out.status.code(), Some(3));
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    }
    // A regular file where the design folder should be.
    std::fs::write(d.path().join("plain"), "x").unwrap();
    let out = camspring(d.path(), &["design", "-o", "plain"]);
    assert_eq!(out.status.code(), Some(3));
    assert_eq!(
        std::fs::read_to_string(d.path().join("plain")).unwrap(),
        "x"
    );
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_stdout_is_exit_code_3() {
    let d = tempfile::tempdir().unwrap();
    for args in [
        vec!["design", "-o", "a", "--json"],
        vec!["design", "-o", "b"],
        vec!["init", "s.toml"],
    ] {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let status = bin()
            .args(&args)
            .current_dir(d.path())
            .stdout(full)
            .stderr(Stdio::null())
            .status()
            .unwrap();
        assert_eq!(status.code(), Some(3), "{args:?}");
    }
}

/// Runs `design` with `spec` into `dir`, killed (SIGKILL) after `after`.
fn killed_run(cwd: &Path, spec: &str, after: Duration) {
    let mut child = bin()
        .args(["design", spec, "-o", "x"])
        .current_dir(cwd)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while start.elapsed() < after {
        if child.try_wait().unwrap().is_some() {
            return;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn random_kills_never_leave_a_mixed_folder() {
    let d = tempfile::tempdir().unwrap();
    let specs = [
        spec("paper.toml"),
        spec("ankle.toml"),
        spec("paper-literal.toml"),
    ];
    // How long each design takes here, to kill anywhere inside a run.
    let durations: Vec<Duration> = specs
        .iter()
        .map(|s| {
            let t = Instant::now();
            camspring(d.path(), &["design", s, "-o", "timing"]);
            t.elapsed()
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(16);
    let dir = d.path().join("x");
    let mut kills = 0;
    let mut ids = BTreeSet::new();
    for i in 0..240 {
        let k = rng.random_range(0..specs.len());
        let after = durations[k].mul_f64(rng.random_range(0.0..1.2));
        killed_run(d.path(), &specs[k], after);
        kills += 1;
        if let Some(id) = assert_one_complete_run(&dir) {
            ids.insert(id);
        }
        if i % 40 == 39 {
            // A run that finishes cleans up whatever the killed ones left.
            camspring(d.path(), &["design", &specs[0], "-o", "x"]);
            assert_one_complete_run(&dir);
            let leftovers: Vec<String> = std::fs::read_dir(d.path())
                .unwrap()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains("stage") || n.ends_with(".tmp"))
                .collect();
            assert!(leftovers.is_empty(), "leftovers: {leftovers:?}");
        }
    }
    assert!(kills >= 200);
    // The kills landed in different places: several different runs were seen complete.
    assert!(ids.len() >= 2, "only {ids:?} seen");
}

#[test]
fn concurrent_runs_on_one_folder_never_mix() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().join("x");
    let (a, b) = (spec("paper.toml"), spec("ankle.toml"));
    let mut refused = 0;
    for _ in 0..30 {
        let spawn = |s: &str| {
            bin()
                .args(["design", s, "-o", "x"])
                .current_dir(d.path())
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (p, q) = (spawn(&a), spawn(&b));
        for child in [p, q] {
            let out = child.wait_with_output().unwrap();
            match out.status.code() {
                Some(0) => {}
                Some(3) => {
                    let e = String::from_utf8_lossy(&out.stderr);
                    assert!(e.contains("another camspring run"), "{e}");
                    refused += 1;
                }
                other => panic!("exit {other:?}: {}", String::from_utf8_lossy(&out.stderr)),
            }
        }
        assert!(assert_one_complete_run(&dir).is_some());
    }
    eprintln!("{refused} of 60 runs found the folder busy");
}

/// Writes `text` as `name` in `dir` and returns the name.
fn file(dir: &Path, name: &str, text: &str) -> String {
    std::fs::write(dir.join(name), text).unwrap();
    name.to_string()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn paper_with(replace: &str, by: &str) -> String {
    let text = std::fs::read_to_string(spec("paper.toml")).unwrap();
    assert!(text.contains(replace), "{replace}");
    text.replace(replace, by)
}

const GIVEN: &str = "[law]\nmu = 1\nk2 = 0.2\nf0 = 1\nxmax = \"20 mm\"\n[follower]\ncount = 2\nspring_rate = 5\nroller_radius = 3\npreload = 1.5\n";

#[test]
fn former_panics_are_clear_errors_or_designs() {
    let d = tempfile::tempdir().unwrap();
    // A small cutter with no depth_per_pass: half the cutter per pass, a program.
    let small = file(
        d.path(),
        "small.toml",
        &paper_with(
            "tool_diameter = \"6 mm\"",
            "tool_diameter = \"0.5 mm\"\nflute_length = \"12 mm\"",
        ),
    );
    let out = camspring(d.path(), &["design", &small, "-o", "s"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(std::fs::read_to_string(d.path().join("s/cam.ngc"))
        .unwrap()
        .contains("0.25"));
    let out = camspring(
        d.path(),
        &["sweep", &small, "--vary", "preload=1..2:2", "-o", "w"],
    );
    assert_eq!(out.status.code(), Some(0));
    // A stroke of 2e-8 mm.
    let tiny = file(d.path(), "tiny.toml", &GIVEN.replace("20 mm", "2e-8 mm"));
    let out = camspring(d.path(), &["design", &tiny]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("law.xmax") && stderr(&out).contains("line 5"));
    // A force spike of 1e160 N in a log.
    camspring(
        d.path(),
        &["simulate", "--duration", "120s", "-o", "calib.csv"],
    );
    let log = std::fs::read_to_string(d.path().join("calib.csv")).unwrap();
    let mut lines: Vec<String> = log.lines().map(str::to_string).collect();
    let mut cells: Vec<String> = lines[5000].split(',').map(str::to_string).collect();
    cells[1] = "1e160".into();
    lines[5000] = cells.join(",");
    file(d.path(), "spike.csv", &(lines.join("\n") + "\n"));
    for cmd in ["identify", "estimate"] {
        let out = camspring(d.path(), &[cmd, "spike.csv"]);
        assert_eq!(out.status.code(), Some(2), "{cmd}");
        assert!(stderr(&out).contains("line 5001"), "{cmd}");
    }
    let out = camspring(d.path(), &["validate", &spec("paper.toml"), "spike.csv"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn the_library_identifies_a_spiked_log_without_panicking() {
    use camspring::estimate::sim::{simulate, SimSettings};
    let law = camspring::ExpLaw {
        mu_n: 1.0115357,
        k2_per_mm: 0.2640383,
        f0_n: 1.2126706,
    };
    let settings = SimSettings {
        duration_s: 120.0,
        ..SimSettings::default()
    };
    let (mut log, _) = simulate(law, 20.0, 200.0, &settings).unwrap();
    for k in [10, 5000, 11_990] {
        let mut spiked = log.clone();
        spiked.force_n[k] = 1e160;
        // An error or a result, never a panic.
        let _ = camspring::identify(&spiked, &camspring::SensorNoise::default());
    }
    log.force_n[100] = f64::INFINITY;
    let _ = camspring::identify(&log, &camspring::SensorNoise::default());
}

#[test]
fn values_that_drive_work_are_bounded() {
    let d = tempfile::tempdir().unwrap();
    for (text, key) in [
        (
            paper_with("thickness = \"10 mm\"", "thickness = \"1e6 mm\""),
            "part.thickness",
        ),
        (
            paper_with(
                "tool_diameter = \"6 mm\"",
                "tool_diameter = \"6 mm\"\ndepth_per_pass = \"1e-6 mm\"",
            ),
            "machining.depth_per_pass",
        ),
        (GIVEN.replace("k2 = 0.2", "k2 = 50"), "law.k2"),
        (
            paper_with("fmax = \"200 N\"", "fmax = \"1e300 N\""),
            "law.fmax",
        ),
    ] {
        let spec = file(d.path(), "bounded.toml", &text);
        let out = camspring(d.path(), &["design", &spec]);
        assert_eq!(out.status.code(), Some(2), "{key}");
        assert!(stderr(&out).contains(key), "{key}: {}", stderr(&out));
    }
    // A tiny k2 finishes (it used to loop in the plot's grid).
    let spec = file(
        d.path(),
        "k2.toml",
        &GIVEN.replace("k2 = 0.2", "k2 = \"1e-20 /mm\""),
    );
    assert_eq!(
        camspring(d.path(), &["design", &spec, "-o", "k"])
            .status
            .code(),
        Some(0)
    );
    // Endless or huge inputs are refused before they are read whole.
    let out = camspring(d.path(), &["design", "/dev/zero"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("larger than"));
    let out = camspring(
        d.path(),
        &["simulate", "--rate", "166666Hz", "--duration", "300s"],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--rate"));
    let out = camspring(
        d.path(),
        &[
            "sweep",
            "--vary",
            "preload=0..1:200",
            "--vary",
            "spring_rate=1..9:200",
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("at most"));
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_stdout_is_exit_code_3_for_calibration_commands_too() {
    let d = tempfile::tempdir().unwrap();
    camspring(
        d.path(),
        &["simulate", "--duration", "60s", "-o", "calib.csv"],
    );
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let status = bin()
        .args(["identify", "calib.csv", "--json"])
        .current_dir(d.path())
        .stdout(full)
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(3));
}

#[test]
fn messages_name_the_key_and_never_echo_control_characters() {
    let d = tempfile::tempdir().unwrap();
    let cases: Vec<(String, &str)> = vec![
        // A terminal title escape in a value.
        (
            paper_with("name = \"paper\"", "name = \"a\\u001b]0;pwned\\u0007b\""),
            "name",
        ),
        (
            paper_with(
                "fmax = \"200 N\"",
                &format!("fmax = \"{} N\"", "9".repeat(200_000)),
            ),
            "at most 100 characters",
        ),
        (
            paper_with("fmax = \"200 N\"", "fmax = \"1e308 kN\""),
            "finite",
        ),
        (
            paper_with("fmax = \"200 N\"", "fmax = true"),
            "a quantity with its unit",
        ),
        (GIVEN.replace("f0 = 1", "f0 = -2"), "law.f0"),
        (
            paper_with(
                "name = \"paper\"",
                &format!("name = \"{}\"", "a".repeat(300)),
            ),
            "1 to 100",
        ),
    ];
    for (text, needle) in cases {
        let spec = file(d.path(), "m.toml", &text);
        let out = camspring(d.path(), &["design", &spec]);
        assert_eq!(out.status.code(), Some(2), "{needle}");
        let e = stderr(&out);
        assert!(e.contains(needle), "{needle}: {e}");
        assert!(
            !e.contains('\u{1b}') && !e.contains('\u{7}'),
            "raw control character: {e:?}"
        );
        assert!(
            e.len() < 2000,
            "the message echoes too much: {} bytes",
            e.len()
        );
    }
    // Negative numbers after flags reach the simulator, which names the flag.
    let out = camspring(d.path(), &["simulate", "--m", "-1", "--duration", "20s"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--m -1"));
    // A window too short is blamed on --window, not on the log.
    camspring(
        d.path(),
        &["simulate", "--duration", "60s", "-o", "calib.csv"],
    );
    let out = camspring(d.path(), &["identify", "calib.csv", "--window", "1ms"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--window"));
    // So is one of 11 samples (at the simulator's 100 Hz): a quintic needs 6 of the window's
    // even offsets, which 11 samples do not have (such a window once gave zero kernels, and a
    // message that the log did not move).
    let out = camspring(d.path(), &["identify", "calib.csv", "--window", "0.11s"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("needs at least 13 samples"),
        "{}",
        stderr(&out)
    );
    let out = camspring(d.path(), &["identify", "calib.csv", "--window", "0.13s"]);
    assert!(
        !stderr(&out).contains("does not excite"),
        "{}",
        stderr(&out)
    );
    // A duplicated column, and a value that overflows after conversion, name the line.
    let log = std::fs::read_to_string(d.path().join("calib.csv")).unwrap();
    let dup = log.replacen("t_s,force_n,position_mm", "t_s,force_n,force_n", 1);
    file(d.path(), "dup.csv", &dup);
    let out = camspring(d.path(), &["identify", "dup.csv", "--position", "force_n"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("2 columns named \"force_n\""));
    let mut lines: Vec<&str> = log.lines().collect();
    lines[7] = "0.06,1e306,5";
    file(d.path(), "kn.csv", &(lines.join("\n") + "\n"));
    let out = camspring(d.path(), &["identify", "kn.csv", "--force", "force_n:kN"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("line 8"), "{}", stderr(&out));
    // The same sweep axis twice.
    let out = camspring(
        d.path(),
        &["sweep", "--vary", "preload=0..1", "--vary", "preload=2..3"],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("twice"));
}

#[test]
fn json_errors_are_json_on_stdout() {
    let d = tempfile::tempdir().unwrap();
    let spec = file(
        d.path(),
        "bad.toml",
        &GIVEN.replace("spring_rate = 5", "spring_rate = -5"),
    );
    let out = camspring(d.path(), &["design", &spec, "--json"]);
    assert_eq!(out.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["error"]["kind"], "spec");
    assert_eq!(v["error"]["key"], "follower.spring_rate");
    assert_eq!(v["error"]["line"], 8);
    assert!(v["error"]["message"]
        .as_str()
        .unwrap()
        .contains("spring_rate"));
    // A log error names its line; a usage error is an argument error.
    file(
        d.path(),
        "short.csv",
        "t_s,force_n,position_mm\n0,1,2\n0.01,x,2\n",
    );
    let out = camspring(d.path(), &["identify", "short.csv", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["error"]["kind"].as_str(), v["error"]["line"].as_u64()),
        (Some("log"), Some(3))
    );
    let out = camspring(d.path(), &["design", "--nope", "--json"]);
    assert_eq!(out.status.code(), Some(2));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["error"]["kind"], "argument");
}

#[test]
fn the_current_folder_is_not_replaced() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("keep.txt"), "x").unwrap();
    let out = camspring(d.path(), &["design", "-o", "."]);
    assert_eq!(out.status.code(), Some(3));
    assert!(stderr(&out).contains("current folder"));
    assert!(d.path().join("keep.txt").exists());
}

#[test]
fn written_paths_are_printed_as_the_user_named_the_folder() {
    let d = tempfile::tempdir().unwrap();
    let out = camspring(d.path(), &["design", "-o", "out/p"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("\n    out/p/cam.step\n"), "{text}");
}
