//! The contract under faults and hostile input, driven through the real binary: an output
//! folder always holds exactly one complete run (after refusals, kills and concurrent runs),
//! special files are never written through, and write failures are exit code 3.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};

const ALL_OUTPUTS: [&str; 11] = [
    "design.json",
    "report.html",
    "profile.csv",
    "force.svg",
    "profile.svg",
    "cam.step",
    "cam.stl",
    "cam.dxf",
    "drawing.svg",
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

fn camspring(dir: &Path, args: &[&str]) -> Output {
    let out = bin().args(args).current_dir(dir).output().unwrap();
    eprintln!(
        "camspring {args:?} -> {:?}\n--- stdout\n{}\n--- stderr\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
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
