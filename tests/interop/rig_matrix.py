"""The independent rig's calibration matrix (docs/CALIBRATION.md, "An independent rig"):
every row x profile x seed is simulated by rig_sim.py, written as a rig writes it, and run
through the real binary's identify, estimate and validate (the true law, and one with k2 5 %
high, at --tolerance 3%). Prints one line per case, then the table of the docs.

    .venv/bin/python tests/interop/rig_matrix.py [ROWS] [PROFILES] [SECONDS] [SEEDS]

ROWS and PROFILES are comma-separated (default: all), SECONDS the log length (300), SEEDS
how many seeds (3). CAMSPRING_BIN names the binary (default target/release/camspring).
"""
import itertools
import json
import os
import pathlib
import subprocess
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from rig_sim import Rig, Transmission, run, write_rig_log  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = os.environ.get("CAMSPRING_BIN", str(ROOT / "target" / "release" / "camspring"))

ROWS = {
    "issue": Transmission(m=0.25, d0=0.0, d1=1.5, d2=-0.008),
    "table-I": Transmission(m=0.39, d0=3.82, d1=1.84, d2=-0.0108, mu=0.9251, k2=0.2586, f0=13.75),
    "light": Transmission(m=0.002, d0=0.0, d1=0.05, d2=0.0),
    "heavy": Transmission(m=0.25, d0=0.5, d1=1.5, d2=-0.008, f0=3.25),
    "default": Transmission(m=0.05, d0=0.0, d1=0.2, d2=-1e-4),
    "table-II-d2": Transmission(m=0.055, d0=0.2, d1=1.84, d2=-0.106, f0=2.5),
    "heaviest": Transmission(m=0.5, d0=4.0, d1=3.0, d2=0.0, f0=12.0),
}
PROFILES = ["multisine", "trapezoid", "scurve", "force", "servo"]
KEYS = [("m_n_s2_per_mm", "m"), ("d0_n", "d0"), ("d1_n_s_per_mm", "d1"), ("d2_n_s3_per_mm3", "d2"),
        ("mu_n", "mu"), ("k2_per_mm", "k2"), ("f0_n", "f0")]


def camspring(*args):
    return subprocess.run([BIN, *map(str, args)], capture_output=True, text=True)


def camspring_both(tmp, *args):
    """One run read both ways: the process (its text on stdout) and the JSON report it wrote
    with `--json-to`, parsed (None where none was written)."""
    path = tmp / "report.json"
    path.unlink(missing_ok=True)
    run = camspring(*args, "--json-to", path)
    return run, (json.loads(path.read_text()) if path.exists() else None)


def spec(path, tr, k2_scale):
    path.write_text(
        f'name = "rig"\n[law]\nmu = "{tr.mu} N"\nk2 = "{tr.k2 * k2_scale} /mm"\nf0 = "{tr.f0} N"\n'
        'xmax = "15 mm"\n[follower]\nspring_rate = "5 N/mm"\nroller_radius = "3 mm"\npreload = "1.5 mm"\n'
    )
    return path


def case(tmp, row, profile, seed, seconds):
    tr = ROWS[row]
    t, f, x, truth = run(tr, Rig(seed=seed), profile, seconds)
    log = tmp / f"{row}-{profile}-{seed}.tsv"
    write_rig_log(log, t, f, x, style="tab", drop=[1234])
    out = dict(row=row, profile=profile, seed=seed)
    ident = camspring("identify", log, "--json")
    j = json.loads(ident.stdout)
    p = j["parameters"]
    z = {}
    for key, name in KEYS:
        if p[key] is not None and p[key + "_std"]:
            z[name] = (p[key] - truth[name]) / p[key + "_std"]
    out["chi2"] = j["reduced_chi2"]
    out["fits"] = j["fit"]["status"] == "fits"
    out["worst"] = max(z.items(), key=lambda kv: abs(kv[1]))
    out["k2"] = 100 * (p["k2_per_mm"] / truth["k2"] - 1)
    out["mu"] = 100 * (p["mu_n"] / truth["mu"] - 1)
    m_resolved = p["m_n_s2_per_mm"] is not None and p["m_n_s2_per_mm_std"] < 0.1 * p["m_n_s2_per_mm"]
    est = camspring("estimate", log, "--json", "-o", tmp / "est.csv")
    out["ekf_rc"] = est.returncode
    if est.returncode in (0, 1):
        e = json.loads(est.stdout)
        fin = e["final"]
        out["consistent"] = e["consistency"]["consistent"]
        out["ekf_k2"] = 100 * (fin["k2_per_mm"] / truth["k2"] - 1)
        out["ekf_k2_z"] = (fin["k2_per_mm"] - truth["k2"]) / fin["k2_per_mm_std"]
        out["ekf_m_z"] = ((fin["m_n_s2_per_mm"] - truth["m"]) / fin["m_n_s2_per_mm_std"]
                          if m_resolved and fin["m_n_s2_per_mm_std"] else None)
    verdicts = [camspring("validate", spec(tmp / f"s{k}.toml", tr, k), log, "--tolerance", "3%", "--json")
                for k in (1.0, 1.05)]
    out["validate_right"] = [v.returncode for v in verdicts] == [0, 1]
    # Whether the true law's pass is shown by the log (a pass "not conclusive" is still exit 0).
    out["true_shown"] = verdicts[0].returncode == 0 and json.loads(verdicts[0].stdout)["conclusive"]
    return out


def main():
    rows = sys.argv[1].split(",") if len(sys.argv) > 1 else list(ROWS)
    profiles = sys.argv[2].split(",") if len(sys.argv) > 2 else PROFILES
    seconds = float(sys.argv[3]) if len(sys.argv) > 3 else 300.0
    seeds = int(sys.argv[4]) if len(sys.argv) > 4 else 3
    table = {}
    with tempfile.TemporaryDirectory() as d:
        for row, profile, seed in itertools.product(rows, profiles, range(seeds)):
            c = case(pathlib.Path(d), row, profile, seed, seconds)
            table.setdefault((row, profile), []).append(c)
            ekf = (f"EKF {'consistent' if c.get('consistent') else 'FLAGGED'} k2 {c['ekf_k2']:+.2f} % "
                   f"z {c['ekf_k2_z']:+.1f} M z {c['ekf_m_z'] if c['ekf_m_z'] is None else round(c['ekf_m_z'], 1)}"
                   if "ekf_k2" in c else f"EKF exit {c['ekf_rc']}")
            print(f"{row:12s} {profile:10s} seed {seed}: chi2 {c['chi2']:.2f} worst z {c['worst'][1]:+.1f} "
                  f"({c['worst'][0]}) k2 {c['k2']:+.2f} % mu {c['mu']:+.2f} % | {ekf} | validate "
                  f"{'right' if c['validate_right'] else 'WRONG'}{'' if c['true_shown'] else ' (true law not conclusive)'}",
                  flush=True)
    print()
    print("| row | profile | reduced chi2 | identify worst \\|z\\| | identify worst k2 / mu error | EKF "
          "consistent | EKF k2: worst error, worst \\|z\\| (consistent) | EKF M worst \\|z\\| | validate right | "
          "true law's pass shown |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for (row, profile), cs in table.items():
        worst = max((c["worst"] for c in cs), key=lambda kv: abs(kv[1]))
        ok = [c for c in cs if c.get("consistent")]
        k2 = (f"{max(abs(c['ekf_k2']) for c in ok):.2f} %, {max(abs(c['ekf_k2_z']) for c in ok):.1f}"
              if ok else "-")
        mz = [abs(c["ekf_m_z"]) for c in ok if c.get("ekf_m_z") is not None]
        print(f"| {row} | {profile} | {min(c['chi2'] for c in cs):.2f}-{max(c['chi2'] for c in cs):.2f} | "
              f"{abs(worst[1]):.1f} ({worst[0]}) | {max(abs(c['k2']) for c in cs):.2f} % / "
              f"{max(abs(c['mu']) for c in cs):.2f} % | {len(ok)} of {len(cs)} | {k2} | "
              f"{f'{max(mz):.1f}' if mz else '-'} | {sum(c['validate_right'] for c in cs)} of {len(cs)} | "
              f"{sum(c['true_shown'] for c in cs)} of {len(cs)} |")


if __name__ == "__main__":
    main()
