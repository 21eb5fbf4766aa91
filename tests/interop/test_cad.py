"""The CAD outputs read back by independent readers: OpenCASCADE (STEP), trimesh (STL),
ezdxf (DXF), the XML parser and headless Chromium (SVG drawing)."""
import math
import pathlib
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import ROOT, design_into, distance_to_polyline, run, surface_reference


# ----------------------------------------------------------------------------- STEP (OCP)
def read_step(path):
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_RetDone
    assert reader.TransferRoots() >= 1
    return reader, reader.OneShape()


def count(shape, kind):
    from OCP.TopExp import TopExp_Explorer

    n, e = 0, TopExp_Explorer(shape, kind)
    while e.More():
        n += 1
        e.Next()
    return n


def test_step_is_one_valid_closed_solid_with_bspline_cam_faces(design):
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.GeomAbs import GeomAbs_BSplineSurface
    from OCP.ShapeAnalysis import ShapeAnalysis_FreeBounds
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out, summary = design
    reader, shape = read_step(out / "cam.step")
    assert count(shape, TopAbs_SOLID) == 1
    assert BRepCheck_Analyzer(shape).IsValid()
    free = ShapeAnalysis_FreeBounds(shape)
    assert count(free.GetClosedWires(), TopAbs_EDGE) == 0
    assert count(free.GetOpenWires(), TopAbs_EDGE) == 0
    bspline = 0
    faces = TopExp_Explorer(shape, TopAbs_FACE)
    while faces.More():
        surf = BRepAdaptor_Surface(TopoDS.Face(faces.Current()))
        if surf.GetType() == GeomAbs_BSplineSurface:
            b = surf.BSpline()
            if not (b.IsURational() or b.IsVRational()):
                bspline += 1
        faces.Next()
    # One polynomial B-spline face per cam surface.
    assert bspline >= summary["follower"]["count"]


def test_step_volume_and_bounding_box_match_the_analytic_part(design):
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    out, summary = design
    _, shape = read_step(out / "cam.step")
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props, 1e-10)
    volume = props.Mass()
    analytic = summary["part"]["area_mm2"] * summary["part"]["thickness_mm"]
    assert volume > 0, "the solid is inside-out"
    assert abs(volume - analytic) <= 1e-5 * analytic, (volume, analytic)
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)
    lo, hi = box.CornerMin(), box.CornerMax()
    gap = box.GetGap()
    want_lo, want_hi = summary["part"]["bounding_box_min_mm"], summary["part"]["bounding_box_max_mm"]
    for got, want in zip((lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z()), want_lo + want_hi):
        assert abs(got - want) <= gap + 1e-6, (got, want)


def test_step_header_is_clean_and_files_are_reproducible(design, tmp_path):
    out, summary = design
    text = (out / "cam.step").read_text()
    header = text.split("DATA;")[0]
    assert "(( '' ))" not in header and "(('')" not in header
    assert "FILE_NAME('cam.step', '2000-01-01T00:00:00', ('camspring'), ('camspring')" in header
    # A second run gives byte-identical STEP and STL.
    again = tmp_path / "again"
    spec = out.parent / "spec.toml"
    proc = run(["design", str(spec), "-o", str(again)], cwd=tmp_path)
    assert proc.returncode in (0, 1)
    for name in ("cam.step", "cam.stl", "cam.dxf", "drawing.svg"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name


# ----------------------------------------------------------------------------- STL (trimesh)
def test_stl_is_watertight_outward_and_matches_the_solid(design):
    import trimesh

    out, summary = design
    data = (out / "cam.stl").read_bytes()
    assert not data[:5].lower().startswith(b"solid"), "binary STL"
    mesh = trimesh.load(out / "cam.stl", process=True)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0, "normals point inwards"
    part = summary["part"]
    tol = part["stl_tolerance_mm"]
    analytic = part["volume_mm3"]
    # Chords cut at most `tol` off along the cam edges and the hole circles (which grow the
    # material), times the thickness.
    holes = summary["spec"]["part"]["holes"]
    bound = tol * part["thickness_mm"] * (part["cam_edge_length_mm"] + sum(math.pi * h["diameter_mm"] for h in holes))
    assert abs(mesh.volume - analytic) <= bound + 1e-6 * analytic, (mesh.volume, analytic, bound)
    # ... and so against the STEP solid's volume as OpenCASCADE computes it.
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(read_step(out / "cam.step")[1], props, 1e-10)
    assert abs(mesh.volume - props.Mass()) <= bound + 1e-5 * analytic, (mesh.volume, props.Mass(), bound)
    # Stored facet normals agree with the winding (outward).
    assert np.all((mesh.face_normals * trimesh.load(out / "cam.stl", process=False).face_normals).sum(1) > 0.99)


def test_stl_cam_face_is_within_the_chord_tolerance_of_the_exact_surface(design):
    import trimesh

    out, summary = design
    mesh = trimesh.load(out / "cam.stl", process=True)
    tol = summary["part"]["stl_tolerance_mm"]
    bottom = mesh.vertices[np.abs(mesh.vertices[:, 2]) < 1e-9][:, :2]
    for ref in surface_reference(out, summary):
        d = distance_to_polyline(bottom, ref)
        on_face = bottom[d < 1e-4]
        assert len(on_face) >= 5
        # Vertices lie on the exact surface (f32 storage: ~1e-6 mm).
        assert d[d < 1e-4].max() <= 1e-5
        # Chord midpoints between neighbouring cam vertices stay within the tolerance.
        order = np.argsort(on_face[:, 0])
        pts = on_face[order]
        mids = 0.5 * (pts[1:] + pts[:-1])
        worst = distance_to_polyline(mids, ref).max()
        assert worst <= tol + 1e-4, worst
        assert worst > 0.05 * tol, "the mesh should use its tolerance, not oversample"


# ----------------------------------------------------------------------------- DXF (ezdxf)
def test_dxf_outline_matches_the_part(design):
    import ezdxf

    out, summary = design
    doc = ezdxf.readfile(out / "cam.dxf")
    assert doc.header["$INSUNITS"] == 4, "millimetres"
    msp = doc.modelspace()
    vertices = np.array(summary["part"]["outline_vertices_mm"])
    ends = []
    for line in msp.query("LINE[layer=='OUTLINE']"):
        ends += [(line.dxf.start.x, line.dxf.start.y), (line.dxf.end.x, line.dxf.end.y)]
    splines = list(msp.query("SPLINE[layer=='OUTLINE']"))
    assert len(splines) == summary["follower"]["count"]
    refs = surface_reference(out, summary)
    fit = summary["part"]["fit_tolerance_mm"]
    for spline in splines:
        tool = spline.construction_tool()
        assert tool.degree == 3
        pts = np.array([(p.x, p.y) for p in tool.approximate(2000)])
        ends += [pts[0], pts[-1]]
        d = min((distance_to_polyline(pts, ref) for ref in refs), key=lambda x: x.max())
        assert d.max() <= fit + 1e-4, d.max()
    ends = np.array(ends)
    # Every segment end is an outline corner, and every corner is used twice.
    dist = np.sqrt(((ends[:, None, :] - vertices[None, :, :]) ** 2).sum(-1))
    assert dist.min(axis=1).max() < 1e-6
    assert sorted(np.argmin(dist, axis=1).tolist()) == sorted(list(range(len(vertices))) * 2)
    circles = list(msp.query("CIRCLE[layer=='HOLES']"))
    holes = summary["spec"]["part"]["holes"]
    assert len(circles) == len(holes)
    for c, h in zip(circles, holes):
        assert abs(c.dxf.radius - h["diameter_mm"] / 2) < 1e-12
        assert abs(c.dxf.center[0] - h["x_mm"]) < 1e-12 and abs(c.dxf.center[1] - h["y_mm"]) < 1e-12


# ----------------------------------------------------------------------------- SVG drawing
def path_anchor_points(d):
    """End points of M, L and C commands of an absolute SVG path."""
    import re

    points = []
    for cmd, args in re.findall(r"([MLCZ])([^MLCZ]*)", d):
        nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", args)]
        if cmd in "ML":
            points.append(nums[:2])
        elif cmd == "C":
            points.append(nums[4:6])
    return np.array(points)


def test_svg_drawing_is_to_scale_and_has_the_outline(design):
    out, summary = design
    root = ET.parse(out / "drawing.svg").getroot()
    assert root.get("width").endswith("mm") and root.get("height").endswith("mm")
    width_mm = float(root.get("width")[:-2])
    vb = [float(v) for v in root.get("viewBox").split()]
    assert abs(vb[2] - width_mm) < 1e-6, "1 user unit = 1 mm"
    ns = {"s": "http://www.w3.org/2000/svg"}
    path = root.find(".//s:path[@id='outline']", ns)
    anchors = path_anchor_points(path.get("d"))
    # Page coordinates are part coordinates shifted and flipped in y: compare shapes.
    part = np.array(summary["part"]["outline_vertices_mm"])
    page = np.column_stack([anchors[:, 0], -anchors[:, 1]])
    page -= page.min(axis=0)
    part_shifted = part - np.array(summary["part"]["bounding_box_min_mm"][:2])
    d = np.sqrt(((part_shifted[:, None, :] - page[None, :, :]) ** 2).sum(-1)).min(axis=1)
    assert d.max() < 1e-4, d.max()
    text = "".join(root.itertext())
    # "law: F = ..." for an exponential law, "law: F tabulated ..." for a table.
    assert summary["name"] in text and "law: F " in text and "scale 1:1" in text
    assert len(root.findall(".//s:circle[@class='roller']", ns)) == 3 * summary["follower"]["count"]


def chromium():
    for name in ("chromium", "chromium-browser"):
        if shutil.which(name):
            return shutil.which(name)
    return None


def test_drawing_renders_in_a_real_browser(design, tmp_path):
    from PIL import Image

    browser = chromium()
    assert browser, "scripts/test installs Debian's chromium"
    out, _ = design
    shot = tmp_path / "drawing.png"
    cmd = [
        browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}", "--window-size=1000,800",
        (out / "drawing.svg").as_uri(),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    img = np.asarray(Image.open(shot).convert("L"))
    dark = (img < 128).mean()
    tinted = ((img >= 128) & (img < 250)).mean()
    assert 0.002 < dark < 0.5, dark  # lines and text
    assert tinted > 0.005, tinted  # the filled part


# ----------------------------------------------------------------------------- refusal
def test_an_undercut_design_is_refused_with_advice(tmp_path):
    out, summary = design_into(ROOT / "specs" / "paper-literal.toml", tmp_path, fine=False)
    assert summary["part"] is None
    assert "follower.preload" in summary["part_refused"]
    for name in ("cam.step", "cam.stl", "cam.dxf", "drawing.svg"):
        assert not (out / name).exists()


@pytest.mark.parametrize("seed", range(8))
def test_random_specs_give_valid_solids_and_watertight_meshes(tmp_path, seed):
    """Property-style sweep (seeded): random laws, followers and parts, read by OpenCASCADE
    and trimesh. Every design either gives a valid solid and a watertight mesh of the right
    volume, or is refused for an undercut with advice."""
    import trimesh
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_SOLID

    rng = np.random.default_rng(100 + seed)
    fmin = rng.uniform(2, 30)
    l0 = rng.uniform(2, 8)
    delta0 = rng.uniform(0.2, 2)
    followers = int(rng.integers(1, 3))
    spec = f"""
name = "random-{seed}"
[law]
fmax = {fmin * rng.uniform(5, 60):.4f}
fmin = {fmin:.4f}
l0 = {l0:.4f}
xmax = {l0 * rng.uniform(2, 5):.4f}
delta0 = {delta0:.4f}
c0 = {rng.uniform(0.1, 0.9) * delta0 / l0:.5f}
[follower]
count = {followers}
spring = "{'shared' if followers == 2 and rng.random() < 0.5 else 'per-follower'}"
spring_rate = {rng.uniform(2, 30):.3f}
preload = {rng.uniform(0.5, 6):.3f}
roller_radius = {rng.uniform(1, 6):.3f}
friction = {rng.uniform(0, 0.05):.4f}
[part]
thickness = {rng.uniform(3, 15):.3f}
web = {rng.uniform(3, 12):.3f}
[machining]
tool_diameter = "1 mm"
depth_per_pass = "0.5 mm"
"""
    out, summary = design_into(spec, tmp_path, fine=False)
    print("part built:", summary["part"] is not None, "status:", summary["status"])
    if summary["part"] is None:
        assert "follower.preload" in summary["part_refused"] or "roller" in summary["part_refused"]
        return
    _, shape = read_step(out / "cam.step")
    assert count(shape, TopAbs_SOLID) == 1
    assert BRepCheck_Analyzer(shape).IsValid()
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props, 1e-10)
    analytic = summary["part"]["volume_mm3"]
    assert abs(props.Mass() - analytic) <= 1e-5 * analytic, (props.Mass(), analytic)
    mesh = trimesh.load(out / "cam.stl", process=True)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
