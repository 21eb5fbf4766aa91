"""Identification by two (or more) binaries side by side on the independent rig's random sweep
draws (rig_sweep.py): each draw's 300 s log is simulated once and identified by every binary
given; one line per draw with, per binary, the regression, the chosen window, the fit status,
the worst z (and which parameter), k2's error and how many parameters were given up. The last
line counts the draws whose lines are the same, and those beyond 3 standard deviations.

    .venv/bin/python tests/interop/rig_compare.py FIRST LAST BINARY [BINARY ...]

Used to measure a change of identification before and after (docs/CALIBRATION.md, "The cube's
noise through the parallel filter"): copy each binary out of target/ first.
"""
import json
import pathlib
import subprocess
import sys
import tempfile
from multiprocessing import Pool

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from rig_matrix import KEYS  # noqa: E402
from rig_sim import run, write_rig_log  # noqa: E402
from rig_sweep import draw  # noqa: E402


def summary(binary, log, truth):
    """One binary's identification of `log`: (text, worst |z|), or (text, None) if refused."""
    proc = subprocess.run([binary, "identify", str(log), "--json"], capture_output=True, text=True,
                          env={"CI": "true"})
    if proc.returncode not in (0, 1):
        return f"exit {proc.returncode}", None
    j = json.loads(proc.stdout)
    p = j["parameters"]
    z = {name: (p[key] - truth[name]) / p[key + "_std"]
         for key, name in KEYS if p[key] is not None and p[key + "_std"]}
    name, worst = max(z.items(), key=lambda kv: abs(kv[1]))
    return (f"{j['regression'][:3]} {j['sg_window_s']:.2f}s {j['fit']['status']} worst {worst:+.1f} ({name}) "
            f"k2 {100 * (p['k2_per_mm'] / truth['k2'] - 1):+.2f}% given up {len(j['not_identifiable'])}",
            abs(worst))


def case(args):
    i, binaries = args
    tr, profile, rig, scale = draw(i)
    try:
        t, f, x, truth = run(tr, rig, profile, 300.0)
    except ValueError:
        return i, f"#{i}: the rig cannot run it", None
    with tempfile.TemporaryDirectory() as d:
        log = pathlib.Path(d) / "log.tsv"
        write_rig_log(log, t, f, x, style="tab")
        results = [summary(b, log, truth) for b in binaries]
    line = f"#{i} {profile} {rig.rate_hz:.0f} Hz noise x{scale:.2f} | " + " | ".join(r[0] for r in results)
    return i, line, results


def main():
    first, last, binaries = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3:]
    same = compared = 0
    beyond = [0] * len(binaries)
    with Pool(2) as pool:
        for _, line, results in pool.imap(case, [(i, binaries) for i in range(first, last)]):
            print(line, flush=True)
            if results is None:
                continue
            compared += 1
            same += len({r[0] for r in results}) == 1
            for k, (_, worst) in enumerate(results):
                beyond[k] += worst is not None and worst > 3.0
    print(f"{compared} draws run, {same} the same for every binary; beyond 3 sigma: "
          + ", ".join(f"{pathlib.Path(b).name} {n}" for b, n in zip(binaries, beyond)))


if __name__ == "__main__":
    main()
