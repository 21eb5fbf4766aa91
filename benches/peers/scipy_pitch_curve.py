"""What a user would do instead: integrate the same loading-corrected pitch-curve ODE of
docs/THEORY.md with SciPy's DOP853 at the same tolerance, for the default spec (two followers,
5 N/mm each, preload 1.5 mm, friction 0.01, loading correction), and time it.

Usage: python benches/peers/scipy_pitch_curve.py   (needs numpy and scipy)
Prints the lift at Xmax (compare with `camspring design --json`, profile.lift_mm) and the
time per solve. It only solves the curve: no law solver, no offset, checks or outputs.
"""
import math
import time

from scipy.integrate import solve_ivp
from scipy.optimize import brentq

fr, lr, sr = 200 / 5, 20 / 5, 0.2 * 5 / 1
alpha = brentq(lambda a: (fr - 1) - sr * math.expm1((lr - 1) * a) / a, 1e-9, 10, xtol=1e-15)
mu = sr * 5 / (alpha * math.exp(alpha))
f0 = 5 - mu * math.exp(alpha)
k2 = alpha / 5
k_eff, yp, mu_f = 10.0, 1.5, 0.01


def slope(x, y):
    force = mu * math.exp(k2 * x) + f0
    q = k_eff * (y[0] + yp)
    return [(force - mu_f * q) / (q + mu_f * force)]


def solve():
    return solve_ivp(slope, [0, 20], [0.0], method="DOP853", rtol=1e-12, atol=1e-12)


sol = solve()
runs = 50
t0 = time.perf_counter()
for _ in range(runs):
    solve()
dt = (time.perf_counter() - t0) / runs
print(f"lift_mm {sol.y[0, -1]:.10f}  steps {sol.t.size}  time_per_solve_ms {dt * 1e3:.3f}")
