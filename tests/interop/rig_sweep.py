"""A random sweep of the independent rig (docs/CALIBRATION.md, "An independent rig"): each
draw is a transmission over the issue's ranges (m 0.002 to 0.5 N s^2/mm and d1 0.05 to 3 N s/mm
log-uniform, d2 0 or down to Table II's -0.106 N s^3/mm^3, d0 0 or up to 4 N, a random spring
law), one of the rig's five profiles, a sampling rate of 100 Hz to 1 kHz and the sensors' noise
a quarter to four times the paper's; 300 s logs through the real binary's identify, estimate
and validate (the true law, and one with k2 5 % high, at --tolerance 3%). Prints one line per
draw; a draw the rig cannot run (no speed keeps the damper force rising) says so.

    .venv/bin/python tests/interop/rig_sweep.py [--encoder [--dither FRACTION]] FIRST LAST

With --encoder the same transmissions, profiles and rates are read by a digital encoder: no
analog position noise, steps of 1 to 20 um (log-uniform, seeded by the draw's number apart
from the rest), the force noise as drawn. With --dither the position carries analog noise of
FRACTION steps' standard deviation before it is read in steps (an ADC reading an LVDT or a
potentiometer: its steps with the sensor's noise across a few of them). FIRST and LAST are draw numbers (each draw is seeded by its number, so a line can be
reproduced alone). CAMSPRING_BIN names the binary (default target/release/camspring).
"""
import json
import math
import pathlib
import sys
import tempfile
from functools import partial
from multiprocessing import Pool

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from rig_matrix import KEYS, camspring, spec  # noqa: E402
from rig_sim import Rig, Transmission, run, write_rig_log  # noqa: E402

PROFILES = ["multisine", "trapezoid", "scurve", "force", "servo"]


def draw(i):
    """The transmission, profile, rig and noise scale of draw `i`."""
    r = np.random.default_rng(1000 + i)

    def log_uniform(a, b):
        return float(math.exp(r.uniform(math.log(a), math.log(b))))

    tr = Transmission(m=log_uniform(0.002, 0.5), d0=float(r.choice([0.0, r.uniform(0, 4)])),
                      d1=log_uniform(0.05, 3.0), d2=float(r.choice([0.0, -log_uniform(1e-4, 0.106)])),
                      mu=log_uniform(0.5, 3.0), k2=float(r.uniform(0.1, 0.3)), f0=float(r.uniform(0, 15)))
    rate = float(r.choice([100.0, 100.0, 200.0, 500.0, 1000.0]))
    scale = log_uniform(0.25, 4.0)
    rig = Rig(rate_hz=rate, force_variance=0.017 * scale, position_variance=0.01 * scale, seed=i)
    return tr, PROFILES[i % len(PROFILES)], rig, scale


def encoder_draw(i, dither=0.0):
    """Draw `i` read by a digital encoder: the transmission, profile, rate and force noise of
    [`draw`], the position quantised in steps of 1 to 20 um with analog noise of `dither`
    steps' standard deviation before it (none by default). The last element is the step in
    um."""
    tr, profile, rig, _ = draw(i)
    r = np.random.default_rng(5000 + i)
    step_mm = float(math.exp(r.uniform(math.log(0.001), math.log(0.02))))
    rig = Rig(rate_hz=rig.rate_hz, force_variance=rig.force_variance,
              position_variance=(dither * step_mm) ** 2, encoder_step_mm=step_mm, seed=i)
    return tr, profile, rig, step_mm * 1000.0


def case(i, seconds=300.0, encoder=False, dither=0.0):
    tr, profile, rig, scale = encoder_draw(i, dither) if encoder else draw(i)
    sensor = (f"encoder {scale:.1f} um{f' dither {dither:.2f}' if dither else ''}" if encoder
              else f"noise x{scale:.2f}")
    tag = (f"#{i:3d} {profile:9s} m {tr.m:.3f} d0 {tr.d0:.2f} d1 {tr.d1:.2f} d2 {tr.d2:.4f} "
           f"k2 {tr.k2:.3f} {rig.rate_hz:.0f} Hz {sensor}")
    with tempfile.TemporaryDirectory() as d:
        tmp = pathlib.Path(d)
        try:
            t, f, x, truth = run(tr, rig, profile, seconds)
        except ValueError:
            return f"{tag}: the rig cannot run it"
        log = tmp / "log.tsv"
        write_rig_log(log, t, f, x, style="tab")
        ident = camspring("identify", log, "--json")
        if ident.returncode not in (0, 1):
            return f"{tag}: identify exit {ident.returncode}: {ident.stderr.strip()[-200:]}"
        j = json.loads(ident.stdout)
        p = j["parameters"]
        z = {n: (p[k] - truth[n]) / p[k + "_std"] for k, n in KEYS if p[k] is not None and p[k + "_std"]}
        worst = max(z.items(), key=lambda kv: abs(kv[1]))
        est = camspring("estimate", log, "--json", "-o", tmp / "est.csv")
        if est.returncode in (0, 1):
            e = json.loads(est.stdout)
            final = e["final"]
            k2_z = (final["k2_per_mm"] - truth["k2"]) / final["k2_per_mm_std"]
            ekf = (f"EKF {'consistent' if e['consistency']['consistent'] else 'FLAGGED'} "
                   f"k2 {100 * (final['k2_per_mm'] / truth['k2'] - 1):+.2f} % z {k2_z:+.1f}")
        else:
            ekf = f"EKF exit {est.returncode}"
        verdicts = []
        for k in (1.0, 1.05):
            v = camspring("validate", spec(tmp / f"s{k}.toml", tr, k), log, "--tolerance", "3%", "--json")
            shown = v.returncode in (0, 1) and json.loads(v.stdout)["conclusive"]
            verdicts.append(f"{'pass' if v.returncode == 0 else 'fail' if v.returncode == 1 else v.returncode}"
                            f"{'' if shown else ' (not conclusive)'}")
        return (f"{tag}: {j['fit']['status']} chi2 {j['reduced_chi2']:.2f} worst z {worst[1]:+.1f} ({worst[0]}) "
                f"k2 {100 * (p['k2_per_mm'] / truth['k2'] - 1):+.2f} % | {ekf} | validate true {verdicts[0]}, "
                f"k2 5 % high {verdicts[1]}")


def main():
    args = sys.argv[1:]
    encoder = "--encoder" in args
    dither = 0.0
    if "--dither" in args:
        at = args.index("--dither")
        dither = float(args[at + 1])
        del args[at:at + 2]
    first, last = (int(a) for a in args if a != "--encoder")
    with Pool(2) as pool:
        for line in pool.imap(partial(case, encoder=encoder, dither=dither), range(first, last)):
            print(line, flush=True)


if __name__ == "__main__":
    main()
