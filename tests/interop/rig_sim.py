"""An independent calibration rig: logs of a transmission with known truth, written as rigs
write them, for judging camspring's identify / estimate / validate from outside.

Nothing here comes from camspring's own simulator. The motions are the kind a motion
controller or a force-controlled test machine produces:

- ``multisine``: a sum of sines at other frequencies than camspring's, with random phases;
- ``trapezoid``: point-to-point moves with a trapezoidal velocity profile (the acceleration
  steps, as a motion controller's does), with holds;
- ``scurve``: the same moves, jerk-limited: the acceleration ramps over 0.1 s (an S-curve
  motion controller's);
- ``servo``: ramp-hold at constant speeds (one per ramp) from a velocity command whose steps
  the servo follows with a first-order lag of 0.05 s: the acceleration is a spike a few
  samples wide at every start and stop, far shorter than any window that averages the
  encoder's noise;
- ``force``: a force-controlled rig: the motor's force follows a smooth command and the
  rod's motion is whatever the transmission makes of it (integrated here with RK4 at a fine
  step), with stick-slip friction: at rest the rod is held by static friction anywhere in
  +-d0, so a rest's force is the spring's plus whatever friction the last motion left.

The rod force is eq. (9): F = m xdd + d1 xd + d2 xd^3 + d0 sgn(xd) + mu exp(k2 x) + F0, in N,
mm and s. Sensor noise is white at the given variances; the encoder may also be quantised.

The two step-by-step integrations (the force-controlled rod, the servo's lag) are compiled by
numba: in pure Python a 300 s run at 1 kHz took 20 to 40 s, now about 1 s. They are the same
operations in the same order, so the logs are the same to the last bit.
"""
from dataclasses import dataclass

import math

import numba
import numpy as np


@dataclass
class Transmission:
    m: float = 0.25  # N s^2/mm
    d0: float = 0.0  # N
    d1: float = 1.5  # N s/mm
    d2: float = -0.008  # N s^3/mm^3
    mu: float = 1.1  # N
    k2: float = 0.24  # 1/mm
    f0: float = 2.0  # N

    def spring(self, x):
        return self.mu * np.exp(self.k2 * x) + self.f0

    def damper(self, xd):
        """The damper and Coulomb force. At rest (xd = 0) the friction keeps the sign of the
        last motion: a rod held still after loading stays held by the friction it slid
        against (no pre-sliding relaxation)."""
        sign = np.sign(xd)
        moving = np.flatnonzero(sign)
        if moving.size:
            # Carry the last nonzero sign forward over rests (the first rest takes the first).
            last = np.maximum.accumulate(np.where(sign != 0, np.arange(len(sign)), -1))
            sign = np.where(last >= 0, sign[np.maximum(last, 0)], sign[moving[0]])
        return self.d1 * xd + self.d2 * xd**3 + self.d0 * sign

    def force(self, x, xd, xdd):
        return self.m * xdd + self.damper(xd) + self.spring(x)

    def max_speed(self):
        """The speed above which the damper force would fall with speed (d2 < 0)."""
        if self.d2 >= 0.0:
            return np.inf
        return np.sqrt(self.d1 / (3.0 * abs(self.d2)))


@dataclass
class Rig:
    rate_hz: float = 100.0
    force_variance: float = 0.017  # N^2
    position_variance: float = 0.01  # mm^2
    encoder_step_mm: float = 0.0  # quantisation of the position (0: none)
    seed: int = 0


def multisine(t, lo, hi, freqs, rng):
    """Sum of sines with random phases, scaled into [lo, hi]; exact derivatives."""
    w = 2 * np.pi * np.asarray(freqs)
    amp = 1.0 / w**0.5  # more amplitude at low frequency, as a slow rig would
    ph = rng.uniform(0, 2 * np.pi, len(w))
    s = np.zeros_like(t)
    sd = np.zeros_like(t)
    sdd = np.zeros_like(t)
    for a, wi, p in zip(amp, w, ph):
        s += a * np.sin(wi * t + p)
        sd += a * wi * np.cos(wi * t + p)
        sdd -= a * wi * wi * np.sin(wi * t + p)
    peak = np.sum(amp)
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    k = half / peak
    return mid + k * s, k * sd, k * sdd


def trapezoid(t, levels, vmax, amax, hold):
    """Point-to-point moves between levels, trapezoidal velocity (acceleration steps)."""
    x = np.full_like(t, levels[0])
    xd = np.zeros_like(t)
    xdd = np.zeros_like(t)
    t0 = hold
    for a, b in zip(levels[:-1], levels[1:]):
        d = abs(b - a)
        s = np.sign(b - a)
        ta = vmax / amax
        if amax * ta * ta > d:  # triangular: never reaches vmax
            ta = np.sqrt(d / amax)
            tc = 0.0
            vp = amax * ta
        else:
            tc = (d - amax * ta * ta) / vmax
            vp = vmax
        T = 2 * ta + tc
        m = (t >= t0) & (t < t0 + T)
        u = t[m] - t0
        pos = np.where(
            u < ta,
            0.5 * amax * u * u,
            np.where(
                u < ta + tc,
                0.5 * amax * ta * ta + vp * (u - ta),
                d - 0.5 * amax * (T - u) ** 2,
            ),
        )
        vel = np.where(u < ta, amax * u, np.where(u < ta + tc, vp, amax * (T - u)))
        acc = np.where(u < ta, amax, np.where(u < ta + tc, 0.0, -amax))
        x[m] = a + s * pos
        xd[m] = s * vel
        xdd[m] = s * acc
        after = t >= t0 + T
        x[after] = b
        xd[after] = 0.0
        xdd[after] = 0.0
        t0 += T + hold
    return x, xd, xdd


def scurve(t, levels, vmax, amax, hold, jerk_time, fine=10):
    """The trapezoidal moves with the acceleration ramped over jerk_time (S-curve): the
    trapezoid on a grid `fine` times finer, each of x, xd and xdd averaged over a sliding
    jerk_time (an average commutes with the derivatives, so they stay one motion's), then
    sampled."""
    tf = t[0] + np.arange(len(t) * fine) * (t[1] - t[0]) / fine
    x, xd, xdd = trapezoid(tf, levels, vmax, amax, hold)
    width = max(1, int(round(jerk_time / (tf[1] - tf[0]))))
    kernel = np.ones(width) / width

    def average(v):
        padded = np.concatenate([np.full(width, v[0]), v, np.full(width, v[-1])])
        return np.convolve(padded, kernel, mode="same")[width:-width][::fine]

    return average(x), average(xd), average(xdd)


@numba.njit
def _first_order_lag(cmd, x0, dt, lag):
    """The exact motion of a servo that follows the velocity command `cmd` (held on each step
    of dt) with a first-order lag, from rest at x0: its positions and velocities."""
    decay = math.exp(-dt / lag)
    x = np.empty_like(cmd)
    v = np.empty_like(cmd)
    xi, vi = x0, 0.0
    for i in range(cmd.shape[0]):
        c = cmd[i]
        x[i], v[i] = xi, vi
        xi += c * dt + (vi - c) * lag * (1.0 - decay)
        vi = c + (vi - c) * decay
    return x, v


def servo_ramps(t, levels, speeds, hold, lag, fine=20):
    """Ramps between levels at the given speeds with holds between them: a velocity command
    that steps, followed by a servo with a first-order lag `lag` (its exact solution on a grid
    `fine` times finer, the command held on each fine step), sampled at t."""
    dt = (t[1] - t[0]) / fine
    starts, ends, vs = [], [], []
    t0, x0 = hold, levels[0]
    for b, v in zip(levels[1:], speeds):
        duration = abs(b - x0) / v
        starts.append(t0)
        ends.append(t0 + duration)
        vs.append(v * np.sign(b - x0))
        t0, x0 = t0 + duration + hold, b
    starts, ends, vs = np.array(starts), np.array(ends), np.array(vs)
    tf = t[0] + np.arange(len(t) * fine) * dt
    k = np.searchsorted(starts, tf, side="right") - 1
    cmd = np.where((k >= 0) & (tf < ends[np.maximum(k, 0)]), vs[np.maximum(k, 0)], 0.0)
    x, v = _first_order_lag(cmd, float(levels[0]), dt, lag)
    a = (cmd - v) / lag
    return x[::fine], v[::fine], a[::fine]


class Infeasible(Exception):
    """A run that leaves what the rig allows (see `feasible`), found before its end."""


# What `_force_block` ended on: every sample integrated, a sample at the rig's speed limit, or
# a rod that ran away (a speed beyond 1e3 mm/s, or a spring force beyond a float's range).
_DONE, _INFEASIBLE, _RUNAWAY = 0, 1, 2

# Below this speed (mm/s) a rod counts as at rest.
_V_STICK = 1e-4


@numba.njit
def _friction_state(c, x, v, d0, mu, k2, f0):
    """0 while static friction holds the rod, else the sign the friction opposes; NaN where
    the spring force overflows."""
    if abs(v) < _V_STICK:
        e = math.exp(k2 * x)
        if math.isinf(e):
            return math.nan
        drive = c - mu * e - f0
        return 0.0 if abs(drive) <= d0 else math.copysign(1.0, drive)
    return math.copysign(1.0, v)


@numba.njit
def _accel(c, x, v, sliding_sign, m, d0, d1, d2, mu, k2, f0):
    """The rod's acceleration under the command c, sliding against d0 sliding_sign; NaN where
    the rod runs away."""
    if abs(v) > 1e3:
        return math.nan
    e = math.exp(k2 * x)
    if math.isinf(e):
        return math.nan
    net = c - (d1 * v + d2 * v * v * v) - mu * e - f0
    return (net - d0 * sliding_sign) / m


@numba.njit
def _force_block(c0s, chs, lo, x, v, dt, v_limit, m, d0, d1, d2, mu, k2, f0, xs, vs, acc):
    """Integrates samples lo .. lo + len(c0s) of `force_driven` from the state (x, v): each
    sample's substeps by RK4 with Karnopp stick-slip friction, the command at each substep's
    start (c0s) and midpoint (chs). Fills xs, vs and acc, and returns (status, the sample
    reached, x, v)."""
    substeps = chs.shape[1]
    for r in range(c0s.shape[0]):
        i = lo + r
        if abs(v) >= v_limit:
            return _INFEASIBLE, i, x, v
        s_now = _friction_state(c0s[r, 0], x, v, d0, mu, k2, f0)
        if math.isnan(s_now):
            return _RUNAWAY, i, x, v
        xs[i], vs[i] = x, v
        if s_now == 0.0:
            acc[i] = 0.0
        else:
            acc[i] = _accel(c0s[r, 0], x, v, s_now, m, d0, d1, d2, mu, k2, f0)
            if math.isnan(acc[i]):
                return _RUNAWAY, i, x, v
        for j in range(substeps):
            s_now = _friction_state(c0s[r, j], x, v, d0, mu, k2, f0)
            if math.isnan(s_now):
                return _RUNAWAY, i, x, v
            if s_now == 0.0:
                v = 0.0
                continue
            k1x = v
            k1v = _accel(c0s[r, j], x, v, s_now, m, d0, d1, d2, mu, k2, f0)
            k2x = v + dt / 2 * k1v
            k2v = _accel(chs[r, j], x + dt / 2 * k1x, v + dt / 2 * k1v, s_now, m, d0, d1, d2, mu, k2, f0)
            k3x = v + dt / 2 * k2v
            k3v = _accel(chs[r, j], x + dt / 2 * k2x, v + dt / 2 * k2v, s_now, m, d0, d1, d2, mu, k2, f0)
            k4x = v + dt * k3v
            k4v = _accel(c0s[r, j + 1], x + dt * k3x, v + dt * k3v, s_now, m, d0, d1, d2, mu, k2, f0)
            if math.isnan(k1v) or math.isnan(k2v) or math.isnan(k3v) or math.isnan(k4v):
                return _RUNAWAY, i, x, v
            nv = v + dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            x += dt / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
            # Sliding stops where the velocity would change sign.
            v = 0.0 if nv * s_now < 0.0 else nv
    return _DONE, lo + c0s.shape[0], x, v


def force_driven(t, tr, f_lo, f_hi, freqs, rng, substeps=20, v_limit=math.inf):
    """A force-controlled rig: F(t) commanded, the transmission's motion integrated (RK4 on
    each substep) with Karnopp stick-slip friction: a rod at rest stays at rest while the net
    force is within +-d0 (static friction holds it), and slides against d0 sgn(v) otherwise.
    Raises Infeasible as soon as a sample's speed reaches `v_limit` (mm/s)."""
    w = 2 * np.pi * np.asarray(freqs)
    ph = rng.uniform(0, 2 * np.pi, len(w))
    amp = 1.0 / w**0.5
    peak = np.sum(amp)
    terms = list(zip(amp.tolist(), w.tolist(), ph.tolist()))
    mid, half = (f_lo + f_hi) / 2, (f_hi - f_lo) / 2

    def command(tt):
        # A smooth saturation, so that the run spends time near both ends of the range.
        # Evaluated on arrays of times, once for every time the integration asks for.
        s = np.zeros_like(tt)
        for a, wi, p in terms:
            s = s + a * np.sin(wi * tt + p)
        s = s / peak
        return mid + half * np.tanh(2.5 * s) / math.tanh(2.5)

    m, d0, d1, d2, mu, k2, f0 = tr.m, tr.d0, tr.d1, tr.d2, tr.mu, tr.k2, tr.f0
    dt = (t[1] - t[0]) / substeps
    f = command(np.asarray(t, dtype=float))

    def chunk(lo, hi):
        """The command at samples lo..hi's substeps, at the times the integration steps: at
        each substep's start (and the last one's end) and at its midpoint, accumulated as the
        integration accumulates them (computed a block at a time: a run too fast for the rig
        stops early)."""
        starts = np.empty((hi - lo, substeps + 1))
        mids = np.empty((hi - lo, substeps))
        tt = np.asarray(t[lo:hi], dtype=float).copy()
        for j in range(substeps):
            starts[:, j] = tt
            mids[:, j] = tt + dt / 2
            tt = tt + dt
        starts[:, substeps] = tt
        return command(starts), command(mids)

    # Start at the equilibrium of the first command (spring alone).
    x = math.log(max(float(f[0]) - tr.f0, 1e-9) / tr.mu) / tr.k2
    v = 0.0
    xs = np.empty_like(t)
    vs = np.empty_like(t)
    acc = np.empty_like(t)
    block = 2000
    for lo in range(0, len(t), block):
        at_start, at_mid = chunk(lo, min(lo + block, len(t)))
        status, i, x, v = _force_block(at_start, at_mid, lo, x, v, dt, v_limit,
                                       m, d0, d1, d2, mu, k2, f0, xs, vs, acc)
        if status == _INFEASIBLE:
            raise Infeasible(f"{abs(v)} mm/s at {t[i]} s")
        if status == _RUNAWAY:
            raise OverflowError("the rod runs away")
    return xs, vs, acc, f


SPEEDS = (1.0, 0.7, 0.5, 0.35, 0.25, 0.18, 0.12)


# The share of the transmission's largest speed (where the damper force stops rising) a run
# may reach.
SPEED_SHARE = 0.8


def feasible(tr, x, xd, xdd, f):
    """A wire only pulls, and the damper force must still rise with speed."""
    return f.min() > 0.3 and np.max(np.abs(xd)) < SPEED_SHARE * tr.max_speed()


def motion(tr, rig, profile, t, xmax, speed, rng):
    lo, hi = 0.12 * xmax, 0.88 * xmax
    if profile == "multisine":
        freqs = np.array([0.07, 0.19, 0.33, 0.57]) * speed
        x, xd, xdd = multisine(t, lo, hi, freqs, rng)
        return x, xd, xdd, tr.force(x, xd, xdd)
    if profile == "trapezoid":
        levels = list(rng.uniform(lo, hi, 400))
        x, xd, xdd = trapezoid(t, levels, vmax=6.0 * speed, amax=8.0 * speed, hold=1.0)
        return x, xd, xdd, tr.force(x, xd, xdd)
    if profile == "scurve":
        levels = list(rng.uniform(lo, hi, 400))
        x, xd, xdd = scurve(t, levels, vmax=6.0 * speed, amax=8.0 * speed, hold=1.0, jerk_time=0.1)
        return x, xd, xdd, tr.force(x, xd, xdd)
    if profile == "servo":
        levels = list(rng.uniform(lo, hi, 400))
        speeds = list(rng.uniform(1.0, 4.0, 400) * speed)
        x, xd, xdd = servo_ramps(t, levels, speeds, hold=2.0, lag=0.05)
        return x, xd, xdd, tr.force(x, xd, xdd)
    if profile == "force":
        f_lo, f_hi = tr.spring(0.02 * xmax), tr.spring(0.98 * xmax)
        freqs = np.array([0.05, 0.13, 0.29]) * speed
        return force_driven(t, tr, f_lo, f_hi, freqs, rng, v_limit=SPEED_SHARE * tr.max_speed())
    raise ValueError(profile)


def run(tr, rig, profile, duration_s, xmax=15.0):
    """Returns (t, force_measured, position_measured, truth dict), at the fastest speed of
    SPEEDS that the transmission allows (see `feasible`)."""
    n = int(round(duration_s * rig.rate_hz))
    t = np.arange(n) / rig.rate_hz
    for speed in SPEEDS:
        rng = np.random.default_rng(rig.seed)
        try:
            x, xd, xdd, f = motion(tr, rig, profile, t, xmax, speed, rng)
        except OverflowError:  # a force-driven run whose damper force falls with speed runs away
            continue
        except Infeasible:  # a force-driven run that is already too fast
            continue
        if np.all(np.isfinite(x)) and feasible(tr, x, xd, xdd, f):
            break
    else:
        raise ValueError(f"no feasible speed for {profile} on {tr}")
    fm = f + rng.normal(0, np.sqrt(rig.force_variance), n)
    xm = x + rng.normal(0, np.sqrt(rig.position_variance), n)
    if rig.encoder_step_mm > 0:
        xm = np.round(xm / rig.encoder_step_mm) * rig.encoder_step_mm
    truth = dict(
        m=tr.m, d0=tr.d0, d1=tr.d1, d2=tr.d2, mu=tr.mu, k2=tr.k2, f0=tr.f0, speed=speed,
        max_speed=float(np.max(np.abs(xd))), x_range=(float(x.min()), float(x.max())),
        force_range=(float(f.min()), float(f.max())), t=t, xd=xd,
    )
    return t, fm, xm, truth


def write_rig_log(path, t, f, x, style="comma", comment=True, drop=()):
    """Writes the log as a rig does: a comment header, the chosen separator, dropped rows."""
    sep = {"comma": ",", "tab": "\t", "semicolon": ";"}[style]
    drop = set(drop)
    with open(path, "w") as out:
        if comment:
            out.write("# rig: independent test bench, channel 3 load cell, channel 1 encoder\n")
            out.write("# started 2026-11-25T10:00:00Z\n")
        out.write(sep.join(["t_s", "force_n", "position_mm"]) + "\n")
        for i, (ti, fi, xi) in enumerate(zip(t, f, x)):
            if i in drop:
                continue
            out.write(f"{ti:.4f}{sep}{fi:.5f}{sep}{xi:.5f}\n")
