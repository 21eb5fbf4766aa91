"""Are identification's standard deviations honest on one motion of the independent rig?

One row x profile x seed of the acceptance matrix (rig_matrix.py) fixes the motion; each redraw
adds fresh load-cell and encoder noise (the paper's, as the rig has it) and runs the binary's
identify on the log. Over the redraws, per parameter: the spread of the estimates, the mean
reported standard deviation (and its coefficient of variation), the bias, the rms and the
largest |z|, with z = (estimate - truth) / reported std. Honest deviations give an rms z
near 1; a covariance that ignored the residuals' correlation gives 2 to 5.

    .venv/bin/python tests/interop/rig_redraw.py ROW PROFILE SEED REDRAWS [identify args...]
    .venv/bin/python tests/interop/rig_redraw.py sweep DRAW REDRAWS [identify args...]

The second form redraws rig_sweep.py's draw DRAW (its rig's noise level).

CAMSPRING_BIN names the binary (default target/release/camspring).
"""
import json
import os
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from rig_matrix import BIN, KEYS, ROWS  # noqa: E402
from rig_sim import Rig, motion, run, write_rig_log  # noqa: E402


def redraws(row, profile, seed, count, args=(), seconds=300, folder=None):
    """Returns (truth, estimates, stds, windows): the truth as a dict of KEYS' short names, two
    (count, 7) arrays in KEYS order (NaN where identify reports a parameter as not
    identifiable) and the window each redraw's identification chose (s)."""
    return redraws_of(ROWS[row], Rig(seed=seed), profile, 10_000 + seed, count, args, seconds, folder)


def sweep_redraws(i, count, args=(), seconds=300, folder=None):
    """redraws() of rig_sweep.py's draw `i`: its transmission, rig, profile and noise level."""
    from rig_sweep import draw

    tr, profile, rig, _ = draw(i)
    return redraws_of(tr, rig, profile, 20_000 + i, count, args, seconds, folder)


def redraws_of(tr, rig, profile, noise_seed, count, args=(), seconds=300, folder=None):
    """redraws() of one transmission on one rig and profile, the noise seeded by `noise_seed`."""
    n = int(round(seconds * rig.rate_hz))
    t = np.arange(n) / rig.rate_hz
    # The speed (and truth) of the rig's run, then the same motion again.
    run_truth = run(tr, rig, profile, seconds)[3]
    truth = {name: run_truth[name] for _, name in KEYS}
    x, _, _, f = motion(tr, rig, profile, t, 15.0, run_truth["speed"], np.random.default_rng(rig.seed))
    noise = np.random.default_rng(noise_seed)
    values, stds, windows = [], [], []
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        log = pathlib.Path(tmp) / "redraw.tsv"
        for _ in range(count):
            fm = f + noise.normal(0.0, np.sqrt(rig.force_variance), n)
            xm = x + noise.normal(0.0, np.sqrt(rig.position_variance), n)
            write_rig_log(log, t, fm, xm, style="tab")
            out = subprocess.run([BIN, "identify", str(log), "--json", *map(str, args)],
                                 capture_output=True, text=True)
            j = json.loads(out.stdout)
            p = j["parameters"]
            windows.append(j["sg_window_s"])
            values.append([np.nan if p[k] is None else p[k] for k, _ in KEYS])
            stds.append([np.nan if p[k] is None else p[k + "_std"] for k, _ in KEYS])
    return truth, np.array(values), np.array(stds), np.array(windows)


def summary(truth, values, stds):
    """Per parameter (KEYS' short names): spread, mean reported std, its coefficient of
    variation, bias, mean z, rms z and max |z| over the redraws that identified it."""
    rows = {}
    for k, (_, name) in enumerate(KEYS):
        ok = np.isfinite(values[:, k])
        if not ok.any():
            continue
        v, s = values[ok, k], stds[ok, k]
        z = (v - truth[name]) / s
        rows[name] = dict(count=int(ok.sum()), spread=float(np.std(v)), reported=float(np.mean(s)),
                          cv=float(np.std(s) / np.mean(s)), bias=float(np.mean(v) - truth[name]),
                          mean_z=float(np.mean(z)), rms_z=float(np.sqrt(np.mean(z * z))),
                          max_z=float(np.max(np.abs(z))))
    return rows


if __name__ == "__main__":
    if sys.argv[1] == "sweep":
        i, count = int(sys.argv[2]), int(sys.argv[3])
        rest = sys.argv[4:]
        title = f"sweep draw {i}"
        truth, values, stds, windows = sweep_redraws(i, count, rest)
    else:
        row, profile, seed, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
        rest = sys.argv[5:]
        title = f"{row} {profile} seed {seed}"
        truth, values, stds, windows = redraws(row, profile, seed, count, rest)
    if os.environ.get("REDRAW_EACH"):
        for k in range(count):
            z = ["%s %+.1f" % (name, (values[k, i] - truth[name]) / stds[k, i]) for i, (_, name) in enumerate(KEYS)]
            print(f"redraw {k}: window {windows[k]:.2f} s,", ", ".join(z))
    print(f"{title}, {count} redraws, {os.path.basename(BIN)} {' '.join(rest)}")
    print("| parameter | identified | spread | mean reported std (cv) | bias | rms z | max abs z |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, r in summary(truth, values, stds).items():
        print(f"| {name} | {r['count']} | {r['spread']:.3g} | {r['reported']:.3g} ({r['cv']:.2f}) | "
              f"{r['bias']:+.3g} | {r['rms_z']:.2f} | {r['max_z']:.1f} |")
