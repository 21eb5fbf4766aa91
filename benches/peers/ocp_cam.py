"""What a user would do instead of `camspring design`: a CadQuery-style script on CadQuery's
kernel (OCP, PyPI `cadquery-ocp-novtk`) that builds the same cam from the same law.

It solves the law (eq. 5), integrates the loading-corrected pitch curve with SciPy (DOP853,
1e-12), samples it at N points, offsets each by the roller radius along the normal, runs an
interpolating B-spline through the surface points, closes a one-follower block, extrudes it
and writes STEP and STL. Both cams are then measured against the exact surface: profile.csv of
a `camspring design` at 0.1 um chords.

Usage (from the repository root, after `scripts/test` made .venv):
    .venv/bin/python -m pip install scipy
    cargo build --release
    .venv/bin/python benches/peers/ocp_cam.py [N ...]     (default N = 6 11 21 50 200)
"""
import json
import math
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "interop"))
from conftest import distance_to_polyline, surface_reference  # noqa: E402

BIN = ROOT / "target" / "release" / "camspring"

# The one-follower spec both build (the peer hard-codes the same numbers).
SPEC = """
name = "peer"
[law]
fmax = "200 N"
fmin = "5 N"
xmax = "20 mm"
l0 = "5 mm"
c0 = 0.2
delta0 = "1 mm"
[follower]
count = 1
spring_rate = "10 N/mm"
preload = "1.5 mm"
roller_radius = "3 mm"
friction = 0.01
[part]
thickness = "10 mm"
lead_in = "0 mm"
run_out = "0 mm"
"""
K_EFF, YP, MU_F, R, XMAX, THICK = 10.0, 1.5, 0.01, 3.0, 20.0, 10.0


def law():
    fr, lr, sr = 200 / 5, 20 / 5, 0.2 * 5 / 1
    alpha = brentq(lambda a: (fr - 1) - sr * math.expm1((lr - 1) * a) / a, 1e-9, 10, xtol=1e-15)
    mu = sr * 5 / (alpha * math.exp(alpha))
    return mu, 5 - mu * math.exp(alpha), alpha / 5


def peer(n):
    """The user's script: returns (surface points, STEP and STL written, seconds per stage)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.GeomAPI import GeomAPI_Interpolate
    from OCP.gp import gp_Pnt, gp_Vec
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer
    from OCP.StlAPI import StlAPI_Writer
    from OCP.collections import HArray1_gp_Pnt

    t0 = time.perf_counter()
    mu, f0, k2 = law()

    def slope(x, y):
        force = mu * math.exp(k2 * x) + f0
        q = K_EFF * (y[0] + YP)
        return [(force - MU_F * q) / (q + MU_F * force)]

    sol = solve_ivp(slope, [0, XMAX], [0.0], method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    x = np.linspace(0, XMAX, n)
    y = sol.sol(x)[0]
    dy = np.array([slope(xi, [yi])[0] for xi, yi in zip(x, y)])
    norm = np.sqrt(1 + dy * dy)
    sx, sy = x + R * dy / norm, y - R / norm  # offset below the pitch curve
    t1 = time.perf_counter()
    pts = HArray1_gp_Pnt(1, n)
    for i in range(n):
        pts.SetValue(i + 1, gp_Pnt(float(sx[i]), float(sy[i]), 0.0))
    interp = GeomAPI_Interpolate(pts, False, 1e-9)
    interp.Perform()
    curve = interp.Curve()
    base = float(sy.min()) - 8.0
    p0, p1 = gp_Pnt(sx[0], sy[0], 0), gp_Pnt(sx[-1], sy[-1], 0)
    b1, b0 = gp_Pnt(sx[-1], base, 0), gp_Pnt(sx[0], base, 0)
    wire = BRepBuilderAPI_MakeWire()
    for e in (
        BRepBuilderAPI_MakeEdge(curve).Edge(),
        BRepBuilderAPI_MakeEdge(p1, b1).Edge(),
        BRepBuilderAPI_MakeEdge(b1, b0).Edge(),
        BRepBuilderAPI_MakeEdge(b0, p0).Edge(),
    ):
        wire.Add(e)
    face = BRepBuilderAPI_MakeFace(wire.Wire()).Face()
    solid = BRepPrimAPI_MakePrism(face, gp_Vec(0, 0, THICK)).Shape()
    tmp = pathlib.Path(tempfile.mkdtemp())
    writer = STEPControl_Writer()
    writer.Transfer(solid, STEPControl_AsIs)
    writer.Write(str(tmp / "peer.step"))
    BRepMesh_IncrementalMesh(solid, 0.005, False, 0.5, True)
    StlAPI_Writer().Write(solid, str(tmp / "peer.stl"))
    t2 = time.perf_counter()
    dense = np.array([[curve.Value(u).X(), curve.Value(u).Y()] for u in np.linspace(curve.FirstParameter(), curve.LastParameter(), 4000)])
    return dense, t1 - t0, t2 - t1


def camspring_design(out):
    spec = out / "peer.toml"
    spec.write_text(SPEC)
    t = []
    for _ in range(5):
        t0 = time.perf_counter()
        subprocess.run([str(BIN), "design", str(spec), "-o", str(out / "cs")], check=True, capture_output=True)
        t.append(time.perf_counter() - t0)
    fine = out / "fine.toml"
    fine.write_text(SPEC + '[output]\nchord_tolerance = "0.0001 mm"\n')
    subprocess.run([str(BIN), "design", str(fine), "-o", str(out / "ref")], check=True, capture_output=True)
    return sorted(t)[2]


def camspring_step_deviation(out, ref_summary):
    """Max distance of camspring's STEP B-spline cam edge from the exact surface."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomAbs import GeomAbs_BSplineCurve
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(out / "cs" / "cam.step")) == IFSelect_RetDone
    reader.TransferRoots()
    shape = reader.OneShape()
    refs = surface_reference(out / "ref", ref_summary)
    worst = 0.0
    e = TopExp_Explorer(shape, TopAbs_EDGE)
    while e.More():
        edge = TopoDS.Edge(e.Current())
        c = BRepAdaptor_Curve(edge)
        if c.GetType() == GeomAbs_BSplineCurve:
            us = np.linspace(c.FirstParameter(), c.LastParameter(), 2000)
            pts = np.array([[c.Value(u).X(), c.Value(u).Y()] for u in us if abs(c.Value(u).Z()) < 1e-9])
            if len(pts):
                worst = max(worst, min(distance_to_polyline(pts, r).max() for r in refs))
        e.Next()
    return worst


def main():
    ns = [int(a) for a in sys.argv[1:]] or [6, 11, 21, 50, 200]
    out = pathlib.Path(tempfile.mkdtemp())
    t_cs = camspring_design(out)
    summary = json.loads((out / "ref" / "design.json").read_text())
    rows = np.genfromtxt(out / "ref" / "profile.csv", delimiter=",", names=True)
    exact = np.column_stack([rows["surface_x_mm"], rows["surface_y_mm"]])
    cs_dev = camspring_step_deviation(out, summary)
    print(f"camspring design (all outputs: STEP, STL, DXF, drawing, G-code, report): {1e3 * t_cs:.1f} ms; "
          f"STEP cam edge max deviation {1e3 * cs_dev:.4f} um")
    for n in ns:
        runs = [peer(n) for _ in range(3)]
        dense, t_curve, t_cad = runs[1]
        dev = distance_to_polyline(dense, exact).max()
        total = sorted(r[1] + r[2] for r in runs)[1]
        print(f"peer N = {n:4d}: curve {1e3 * t_curve:.1f} ms + CAD {1e3 * t_cad:.1f} ms = {1e3 * total:.1f} ms; "
              f"spline max deviation {1e3 * dev:.3f} um; time ratio peer/camspring {total / t_cs:.2f}")


if __name__ == "__main__":
    main()
