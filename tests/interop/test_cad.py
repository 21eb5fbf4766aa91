"""The CAD outputs read back by independent readers: OpenCASCADE (STEP), trimesh (STL),
ezdxf (DXF), the XML parser and headless Chromium (SVG drawing)."""
import math
import pathlib
import shutil
import re
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


def drawing_scale(root):
    """The scale the drawing states under its front view ("FRONT VIEW  2:1")."""
    label = next(t for t in texts(root) if t[0].startswith("FRONT VIEW"))[0]
    a, b = label.split()[-1].split(":")
    return float(a) / float(b)


def texts(root):
    """(text, x, y, size, anchor, vertical, class) of every text element."""
    ns = "{http://www.w3.org/2000/svg}"
    out = []
    for el in root.iter(ns + "text"):
        content = " ".join((el.text or "").split())
        if not content:
            continue
        out.append((content, float(el.get("x")), float(el.get("y")), float(el.get("font-size")),
                    el.get("text-anchor", "start"), "rotate(-90" in el.get("transform", ""), el.get("class", "")))
    return out


def test_svg_drawing_is_to_scale_and_has_the_outline(design):
    out, summary = design
    root = ET.parse(out / "drawing.svg").getroot()
    assert root.get("width").endswith("mm") and root.get("height").endswith("mm")
    width_mm = float(root.get("width")[:-2])
    vb = [float(v) for v in root.get("viewBox").split()]
    assert abs(vb[2] - width_mm) < 1e-6, "1 user unit = 1 mm"
    # A standard landscape sheet: A4 by default.
    assert (width_mm, float(root.get("height")[:-2])) == (297.0, 210.0)
    scale = drawing_scale(root)
    assert scale in (10, 5, 2, 1, 0.5, 0.2, 0.1, 0.05, 0.02)
    ns = {"s": "http://www.w3.org/2000/svg"}
    path = root.find(".//s:path[@id='outline']", ns)
    anchors = path_anchor_points(path.get("d"))
    # Page coordinates are part coordinates scaled, shifted and flipped in y: compare shapes.
    part = np.array(summary["part"]["outline_vertices_mm"])
    page = np.column_stack([anchors[:, 0], -anchors[:, 1]]) / scale
    page -= page.min(axis=0)
    part_shifted = part - np.array(summary["part"]["bounding_box_min_mm"][:2])
    d = np.sqrt(((part_shifted[:, None, :] - page[None, :, :]) ** 2).sum(-1)).min(axis=1)
    assert d.max() < 1e-4, d.max()
    text = " ".join(t[0] for t in texts(root))
    assert summary["name"].upper() in text and "LAW (" in text and "F " in text
    assert "ISO 2768-m" in text and "THIRD ANGLE" in text
    assert len(root.findall(".//s:circle[@class='roller']", ns)) == 3 * summary["follower"]["count"]
    # The side view is the thickness at the same scale.
    side = root.find(".//s:rect[@id='side-view']", ns)
    assert abs(float(side.get("width")) - summary["part"]["thickness_mm"] * scale) < 1e-3


def text_box(t, font):
    """The box (x0, y0, x1, y1) a text covers on the page, measured with the font's own
    metrics (Pillow reading DejaVu Sans), independently of camspring's layout."""
    content, x, y, size, anchor, vertical = t[:6]
    k = 100.0  # measure at 100 px per mm of font size
    f = font.font_variant(size=int(size * k))
    left, top, right, bottom = f.getbbox(content, anchor="ls")
    w = f.getlength(content) / k
    start = {"start": 0.0, "middle": -w / 2, "end": -w}[anchor]
    top, bottom = top / k, bottom / k  # relative to the baseline, y down
    if not vertical:
        return (x + start, y + top, x + start + w, y + bottom)
    # Rotated by -90 degrees about (x, y): the text runs upwards from y - start.
    return (x + top, y - start - w, x + bottom, y - start)


def page_geometry(root):
    """The part's geometry on the page as segments: the outline (cubic spans sampled), the
    holes and the side view."""
    import re

    ns = {"s": "http://www.w3.org/2000/svg"}
    d = root.find(".//s:path[@id='outline']", ns).get("d")
    segs = []
    pos = None
    for cmd, args in re.findall(r"([MLCZ])([^MLCZ]*)", d):
        nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", args)]
        if cmd == "M":
            pos = start = np.array(nums[:2])
        elif cmd == "L":
            segs.append((pos, np.array(nums[:2])))
            pos = np.array(nums[:2])
        elif cmd == "C":
            c = [pos] + [np.array(nums[i : i + 2]) for i in (0, 2, 4)]
            t = np.linspace(0, 1, 17)[:, None]
            pts = (1 - t) ** 3 * c[0] + 3 * (1 - t) ** 2 * t * c[1] + 3 * (1 - t) * t**2 * c[2] + t**3 * c[3]
            segs.extend(zip(pts[:-1], pts[1:]))
            pos = c[3]
        elif cmd == "Z":
            segs.append((pos, start))
    for c in root.findall(".//s:circle[@class='hole']", ns):
        cx, cy, r = (float(c.get(k)) for k in ("cx", "cy", "r"))
        a = np.linspace(0, 2 * np.pi, 33)
        pts = np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)])
        segs.extend(zip(pts[:-1], pts[1:]))
    side = root.find(".//s:rect[@id='side-view']", ns)
    x, y, w, h = (float(side.get(k)) for k in ("x", "y", "width", "height"))
    corners = [np.array(p) for p in ((x, y), (x + w, y), (x + w, y + h), (x, y + h))]
    segs.extend(zip(corners, corners[1:] + corners[:1]))
    return segs


def segment_hits_box(a, b, box):
    """Whether the segment a-b passes through the box (Liang-Barsky)."""
    x0, y0, x1, y1 = box
    t0, t1 = 0.0, 1.0
    d = b - a
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if abs(p) < 1e-12:
            if q < 0:
                return False
        else:
            t = q / p
            if p < 0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
            if t0 > t1:
                return False
    return True


def check_drawing_layout(svg_path):
    from PIL import ImageFont

    font = ImageFont.truetype(str(ROOT / "assets" / "fonts" / "DejaVuSans.ttf"), 100)
    root = ET.parse(svg_path).getroot()
    items = texts(root)
    boxes = [text_box(t, font) for t in items]
    w, h = float(root.get("width")[:-2]), float(root.get("height")[:-2])
    for t, b in zip(items, boxes):
        assert b[0] >= 10 and b[1] >= 10 and b[2] <= w - 10 and b[3] <= h - 10, f"outside the border: {t[0]}"
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            a, b = boxes[i], boxes[j]
            overlap = a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]
            assert not overlap, f"texts overlap: {items[i][0]!r} and {items[j][0]!r}"
    for t, b in zip(items, boxes):
        for a, c in page_geometry(root):
            assert not segment_hits_box(a, c, b), f"text over the part: {t[0]!r}"
    return root, items


@pytest.fixture(scope="module")
def holes_design(tmp_path_factory):
    text = (ROOT / "specs" / "paper.toml").read_text().replace(
        'roller_material = "bearing-steel"',
        'roller_material = "bearing-steel"\nholes = [{ x = "12 mm", y = "0 mm", diameter = "8 mm" }, '
        '{ x = "3 mm", y = "0 mm", diameter = "5 mm" }, { x = "18 mm", y = "-5.5 mm", diameter = "3.3 mm" }]',
    ) + '\n[drawing]\nnumber = "CS-0042"\nrevision = "B"\ndate = "2026-11-23"\n'
    return design_into(text, tmp_path_factory.mktemp("holes"))


def test_drawing_text_overlaps_neither_text_nor_the_part(design, holes_design):
    for out, _ in (design, holes_design):
        check_drawing_layout(out / "drawing.svg")


def test_drawing_tabulates_holes_and_the_cam_face_from_the_datum(holes_design):
    out, summary = holes_design
    root, items = check_drawing_layout(out / "drawing.svg")
    cells = [t[0] for t in items if t[6] == "hole-table"]
    rows = [cells[i : i + 4] for i in range(0, len(cells), 4)]
    holes = summary["spec"]["part"]["holes"]
    assert len(rows) == len(holes)
    for k, (row, h) in enumerate(zip(rows, holes)):
        assert row[0] == f"H{k + 1}"
        assert abs(float(row[1]) - h["x_mm"]) < 5e-4 and abs(float(row[2]) - h["y_mm"]) < 5e-4
        assert abs(float(row[3].split()[0]) - h["diameter_mm"]) < 5e-4
        # ... and each tag in the front view, beside its hole (within 4 diameters).
        scale = drawing_scale(root)
        tags = [t for t in items if t[0] == f"H{k + 1}" and t[6] == "hole-tag"]
        assert len(tags) == 1
    # The coordinate table: X, Y pairs on the exact cam surface (profile.csv at 0.1 um).
    values = [float(t[0]) for t in items if t[6] == "coordinate"]
    pts = np.array(values).reshape(-1, 2)
    ref = surface_reference(out, summary)[0]
    d = distance_to_polyline(pts, ref)
    assert len(pts) >= 20 and d.max() < 6e-4, d.max()
    text = " ".join(t[0] for t in items)
    assert "STEP 1.000 IN X" in text and "PROFILE 0.040" in text
    for field in ("CS-0042", "2026-11-23", "ALUMINIUM-6061-T6", "2:1"):
        assert any(t[0] == field for t in items), field
    assert any(t[0] == "B" and t[6] == "title" for t in items)


def test_drawing_pdf_renders_with_poppler_like_the_svg(holes_design, tmp_path):
    """pdftoppm renders drawing.pdf: one page the size of the sheet, with the same ink as
    Chromium's rendering of drawing.svg (the same lines and text in the same places)."""
    from PIL import Image

    out, _ = holes_design
    pdftoppm = shutil.which("pdftoppm")
    assert pdftoppm, "scripts/test installs poppler-utils"
    info = subprocess.run(["pdfinfo", str(out / "drawing.pdf")], capture_output=True, text=True, check=True).stdout
    assert re.search(r"Pages:\s+1\n", info), info
    size = re.search(r"Page size:\s+([\d.]+) x ([\d.]+) pts", info)
    assert abs(float(size.group(1)) - 297 / 25.4 * 72) < 0.5 and abs(float(size.group(2)) - 210 / 25.4 * 72) < 0.5
    subprocess.run([pdftoppm, "-r", "96", "-png", "-singlefile", str(out / "drawing.pdf"), str(tmp_path / "pdf")],
                   check=True, timeout=120)
    pdf = np.asarray(Image.open(tmp_path / "pdf.png").convert("L"))
    browser = chromium()
    assert browser
    shot = tmp_path / "svg.png"
    subprocess.run([
        browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--hide-scrollbars", f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
        f"--window-size={pdf.shape[1]},{pdf.shape[0]}", (out / "drawing.svg").as_uri(),
    ], check=True, capture_output=True, timeout=120)
    svg = np.asarray(Image.open(shot).convert("L"))
    assert svg.shape == pdf.shape, (svg.shape, pdf.shape)
    # Ink on 8 x 8 pixel cells: the two renderings agree where the drawing has ink.
    def cells(img):
        h, w = (img.shape[0] // 8) * 8, (img.shape[1] // 8) * 8
        return (img[:h, :w] < 160).reshape(h // 8, 8, w // 8, 8).any(axis=(1, 3))
    a, b = cells(pdf), cells(svg)
    iou = (a & b).sum() / (a | b).sum()
    assert a.mean() > 0.03, a.mean()
    assert iou > 0.8, iou


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
flute_length = "20 mm"
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
