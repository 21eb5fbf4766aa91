"""What a user would do instead of `camspring estimate`: the same EKF (the model of
docs/THEORY.md section 3, RK4 prediction, Phi = I + A T + (A T)^2 / 2, Joseph update) written with
numpy, one sample at a time, run on the same log with the same initial state and tuning.

Usage (from the repository root, after `scripts/test` made .venv and `cargo build --release`):
    .venv/bin/python benches/peers/numpy_ekf.py
It simulates a 300 s log with `camspring simulate`, runs `camspring estimate --json` on it (for
the initial state, the tuning and the result), then this filter, and prints samples per second
and the largest difference between the two final estimates.
"""
import json
import pathlib
import subprocess
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = ROOT / "target" / "release" / "camspring"


def f(z, u):
    x, xd, xdd, s, d, m, k2, d2 = z
    return np.array([xd, xdd, (u - s * xd - d * xdd) / m, k2 * s * xd, 6 * d2 * xd * xdd, 0, 0, 0])


def jac(z, u):
    x, xd, xdd, s, d, m, k2, d2 = z
    a = np.zeros((8, 8))
    a[0, 1] = 1
    a[1, 2] = 1
    a[2, 1], a[2, 2], a[2, 3], a[2, 4] = -s / m, -d / m, -xd / m, -xdd / m
    a[2, 5] = -(u - s * xd - d * xdd) / m**2
    a[3, 1], a[3, 3], a[3, 6] = k2 * s, k2 * xd, s * xd
    a[4, 1], a[4, 2], a[4, 7] = 6 * d2 * xdd, 6 * d2 * xd, 6 * xd * xdd
    return a


def run(z, p, q, r, rate, pos, dt):
    for k in range(1, len(rate)):
        u0, u1 = rate[k - 1], rate[k]
        a = jac(z, u0) * dt
        um = 0.5 * (u0 + u1)
        k1 = f(z, u0)
        k2 = f(z + 0.5 * dt * k1, um)
        k3 = f(z + 0.5 * dt * k2, um)
        k4 = f(z + dt * k3, u1)
        z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        phi = np.eye(8) + a + a @ a / 2
        p = phi @ p @ phi.T + np.diag(q) * dt
        s = p[0, 0] + r
        kg = p[:, 0] / s
        z = z + kg * (pos[k] - z[0])
        ikh = np.eye(8)
        ikh[:, 0] -= kg
        p = ikh @ p @ ikh.T + r * np.outer(kg, kg)
        p = 0.5 * (p + p.T)
        z[5] = max(z[5], 1e-6)
        z[3] = max(z[3], 1e-6)
    return z


def main():
    tmp = pathlib.Path(tempfile.mkdtemp())
    subprocess.run([str(BIN), "simulate", "-o", str(tmp / "calib.csv"), "--duration", "300s"], check=True, capture_output=True)
    est = json.loads(subprocess.run([str(BIN), "estimate", str(tmp / "calib.csv"), "-o", str(tmp / "est.csv"), "--json"],
                                    check=True, capture_output=True, text=True).stdout)
    # The camspring series gives the input and the start: rebuild them from its CSV.
    series = np.genfromtxt(tmp / "est.csv", delimiter=",", names=True)
    log = np.genfromtxt(tmp / "calib.csv", delimiter=",", names=True)
    first = est["first_sample"]
    n = len(series)
    dt = float(log["t_s"][1] - log["t_s"][0])
    # Zero-phase force rate: the quintic Savitzky-Golay derivative over 41 samples, as camspring.
    half = 20
    offs = np.arange(-half, half + 1, dtype=float)
    vander = np.vander(offs, 6, increasing=True)
    weights = np.linalg.pinv(vander)[1]
    rate = np.convolve(log["force_n"], weights[::-1], mode="valid") / dt
    pos = log["position_mm"][first:first + n]
    settings = est["settings"]
    names = ["x_mm", "xd_mm_per_s", "xdd_mm_per_s2", "sigma_n_per_mm", "d_n_s_per_mm", "m_n_s2_per_mm", "k2_per_mm", "d2_n_s3_per_mm3"]
    # camspring's state after the first update, and a covariance from its first-row stds.
    z0 = np.array([series[k][0] for k in names])
    p0 = np.diag(np.array([series[k + "_std"][0] for k in names]) ** 2)
    t0 = time.perf_counter()
    z = run(z0.copy(), p0, np.array(settings["q"]), settings["r_position_mm2"], rate[:n], pos, dt)
    seconds = time.perf_counter() - t0
    final = est["final"]
    print(f"numpy EKF: {n} samples in {seconds:.2f} s = {n / seconds / 1e3:.1f} k samples/s")
    for key, i in [("k2_per_mm", 6), ("m_n_s2_per_mm", 5), ("d2_n_s3_per_mm3", 7)]:
        print(f"  {key}: numpy {z[i]:.6g}, camspring {final[key]:.6g} (relative difference {abs(z[i] / final[key] - 1):.2e})")


if __name__ == "__main__":
    main()
