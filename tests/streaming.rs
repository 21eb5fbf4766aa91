//! `camspring estimate` streams: its peak memory does not grow with the log's length, and the
//! time series it writes as it goes holds every filtered sample once.
//!
//! Two 1 kHz logs, one eight times longer than the other, go through the binary; the peak
//! resident memory of each run comes from the kernel. Holding the log and the
//! filter's states, as `estimate` did before it streamed, costs about 430 bytes per sample:
//! 360 MB more for the longer log.
#![cfg(target_os = "linux")]

use std::path::Path;
use std::process::{Command, Stdio};

/// Runs the binary in `dir`; returns its exit code, stdout and peak resident memory (KiB).
///
/// The peak is the kernel's high-water mark of the process's own memory after exec (`VmHWM`
/// in /proc/PID/status), read until the process has exited and before it is reaped. (The
/// rusage of `wait4` would not do: it counts the test process's own image, which the child
/// shares until its exec.)
fn run_measured(dir: &Path, args: &[&str]) -> (i32, String, u64) {
    let stdout = std::fs::File::create(dir.join("stdout.txt")).unwrap();
    let stderr = std::fs::File::create(dir.join("stderr.txt")).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_camspring"))
        .args(args)
        .current_dir(dir)
        .env("CI", "true")
        .stdout(Stdio::from(stdout))
        .stderr(Stdio::from(stderr))
        .spawn()
        .unwrap();
    let status_path = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0;
    // A zombie (exited, not yet reaped) has no memory lines left.
    while let Some(hwm) = std::fs::read_to_string(&status_path).ok().and_then(|s| {
        s.lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
    }) {
        peak_kib = peak_kib.max(hwm);
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let code = child.wait().unwrap().code().unwrap_or(-1);
    let out = std::fs::read_to_string(dir.join("stdout.txt")).unwrap();
    let err = std::fs::read_to_string(dir.join("stderr.txt")).unwrap();
    assert!(
        code == 0 || code == 1,
        "{args:?}: exit {code}\n{out}\n{err}"
    );
    assert!(peak_kib > 0, "{args:?}: no memory reading");
    (code, out, peak_kib)
}

#[test]
fn estimate_streams_with_memory_independent_of_the_log_length() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut peaks = Vec::new();
    for (name, seconds) in [("short", 120), ("long", 960)] {
        let duration = format!("{seconds}s");
        let log = format!("{name}.csv");
        let (code, ..) = run_measured(
            d,
            &[
                "simulate",
                "--rate",
                "1kHz",
                "--duration",
                &duration,
                "--seed",
                "3",
                "-o",
                &log,
            ],
        );
        assert_eq!(code, 0);
        // Identification (the filter's init) reads the first minute of either log.
        let (code, out, peak_kib) =
            run_measured(d, &["estimate", &log, "--identify-span", "60s", "--json"]);
        let json: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(
            code, 0,
            "the filter is consistent at 1 kHz: {}",
            json["consistency"]
        );
        // Every sample but the force-rate window's 400 is filtered, and each is one row of the
        // time series, after its header.
        let samples = seconds as u64 * 1000 - 400;
        assert_eq!(json["samples"].as_u64(), Some(samples));
        let series = std::fs::read_to_string(d.join(format!("{name}.est.csv"))).unwrap();
        let mut lines = series.lines();
        assert!(lines.next().unwrap().starts_with("t_s,x_mm,x_mm_std,"));
        let times: Vec<f64> = lines
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect();
        drop(series);
        assert_eq!(times.len() as u64, samples);
        assert!(times.windows(2).all(|w| w[1] > w[0]));
        assert!((times[0] - 0.2).abs() < 1e-9, "first row at {}", times[0]);
        if name == "short" {
            // Every 1000th row: one a second, the same rows as the full series.
            let full: Vec<String> = std::fs::read_to_string(d.join("short.est.csv"))
                .unwrap()
                .lines()
                .map(String::from)
                .collect();
            let (code, ..) = run_measured(
                d,
                &[
                    "estimate",
                    &log,
                    "--identify-span",
                    "60s",
                    "--every",
                    "1000",
                    "-o",
                    "sparse.csv",
                ],
            );
            assert_eq!(code, 0);
            let sparse = std::fs::read_to_string(d.join("sparse.csv")).unwrap();
            let sparse: Vec<&str> = sparse.lines().collect();
            assert_eq!(sparse.len() as u64, 1 + samples.div_ceil(1000));
            for (k, row) in sparse.iter().enumerate().skip(1) {
                assert_eq!(*row, full[1 + (k - 1) * 1000]);
            }
        }
        // A command that holds the log (the noise model reads it whole), for contrast: the
        // reading above must be able to see memory that grows with the log.
        let (_, _, held_kib) = run_measured(d, &["noise", &log, "--json"]);
        eprintln!("{name}: estimate peak {peak_kib} KiB, noise (log held) peak {held_kib} KiB");
        peaks.push((peak_kib, held_kib));
    }
    // 840 000 more samples: holding them would take over 300 MB; streaming takes none.
    let growth_kib = peaks[1].0 as i64 - peaks[0].0 as i64;
    assert!(
        growth_kib < 4096,
        "estimate: peak memory {} KiB for 120 s, {} KiB for 960 s",
        peaks[0].0,
        peaks[1].0
    );
    assert!(peaks[1].0 < 64 * 1024, "peak memory {} KiB", peaks[1].0);
    // 840 000 samples of time, force and position alone are 20 MB.
    let held_growth_kib = peaks[1].1 as i64 - peaks[0].1 as i64;
    assert!(
        held_growth_kib > 16 * 1024,
        "noise: peak memory {} KiB for 120 s, {} KiB for 960 s",
        peaks[0].1,
        peaks[1].1
    );
}
