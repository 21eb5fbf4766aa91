"""G-code read by LinuxCNC's own interpreter (rs274, Debian package linuxcnc-uspace): every
program runs without error, and the interpreted tool path is checked against the exact part:
the finishing pass lies within the tolerance of the ideal tool-centre path (the part boundary
offset by the cutter radius) in both directions, and no move anywhere gouges the part."""
import math
import re
import shutil
import subprocess

import numpy as np
import pytest

from conftest import ONE_FOLLOWER, ROOT, design_into, distance_to_polyline, surface_reference

RS274 = shutil.which("rs274")
NUM = r"(-?\d+(?:\.\d+)?)"


def interpret(ngc, tmp_path):
    assert RS274, "scripts/test installs linuxcnc-uspace"
    proc = subprocess.run([RS274, "-g", str(ngc)], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr
    assert "PROGRAM_END()" in proc.stdout
    return proc.stdout


def moves(canon):
    """Yields (kind, start, end, extra, state) from rs274's canonical output."""
    pos = None
    feed = 0.0
    spindle = False
    label = ""
    section = ""
    for line in canon.splitlines():
        if "COMMENT(" in line:
            text = line.split('COMMENT("', 1)[1].rsplit('")', 1)[0]
            if text in ("lead-in", "contour", "lead-out"):
                section = text
            elif text == "tab":
                pass
            elif not text.startswith("interpreter"):
                label, section = text, ""
        elif "SET_FEED_RATE(" in line:
            feed = float(re.search(NUM, line.split("SET_FEED_RATE(")[1]).group(1))
        elif "START_SPINDLE_CLOCKWISE" in line:
            spindle = True
        elif "STOP_SPINDLE_TURNING" in line:
            spindle = False
        else:
            m = re.search(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED)\(([^)]*)\)", line)
            if not m:
                continue
            args = [float(v) for v in m.group(2).split(",")]
            if m.group(1) == "ARC_FEED":
                end = (args[0], args[1], args[5])
                extra = {"center": (args[2], args[3]), "rotation": int(args[4])}
            else:
                end = tuple(args[:3])
                extra = {}
            state = {"feed": feed, "spindle": spindle, "label": label, "section": section}
            if pos is not None:
                yield m.group(1), pos, end, extra, state
            pos = end


def sample(kind, start, end, extra, max_step=0.02):
    """Points along a feed move in the plane."""
    s, e = np.array(start[:2]), np.array(end[:2])
    if kind != "ARC_FEED":
        n = max(2, int(np.linalg.norm(e - s) / max_step) + 2)
        return s + np.linspace(0, 1, n)[:, None] * (e - s)
    c = np.array(extra["center"])
    r = np.linalg.norm(s - c)
    a0 = math.atan2(*(s - c)[::-1])
    a1 = math.atan2(*(e - c)[::-1])
    sweep = a1 - a0
    if extra["rotation"] > 0:
        while sweep <= 0:
            sweep += 2 * math.pi
    else:
        while sweep >= 0:
            sweep -= 2 * math.pi
    n = max(2, int(abs(sweep) * r / max_step) + 2)
    a = a0 + np.linspace(0, sweep, n)
    return c + r * np.column_stack([np.cos(a), np.sin(a)])


def part_boundary(out, summary):
    """The exact part outline as a dense closed polyline, and the hole circles."""
    verts = [np.array(v) for v in summary["part"]["outline_vertices_mm"]]
    refs = surface_reference(out, summary)
    poly = []
    for i, a in enumerate(verts):
        b = verts[(i + 1) % len(verts)]
        poly.append(a)
        for ref in refs:
            for pts in (ref, ref[::-1]):
                if np.linalg.norm(pts[0] - a) < 1e-6 and np.linalg.norm(pts[-1] - b) < 1e-6:
                    poly.extend(pts[1:-1])
    poly.append(verts[0])
    holes = [(np.array([h["x_mm"], h["y_mm"]]), h["diameter_mm"] / 2) for h in summary["spec"]["part"]["holes"]]
    return np.array(poly), holes


def distance_to_part(points, poly, holes):
    d = distance_to_polyline(points, poly)
    for c, r in holes:
        d = np.minimum(d, np.abs(np.linalg.norm(points - c, axis=1) - r))
    return d


def check_program(out, summary, tmp_path, ngc="cam.ngc"):
    canon = interpret(out / ngc, tmp_path)
    spec = summary["spec"]["machining"]
    radius = spec["tool_diameter_mm"] / 2
    tol = spec["tolerance_mm"]
    top = spec["stock_top_z_mm"]
    poly, holes = part_boundary(out, summary)
    all_moves = list(moves(canon))
    finish_pts = []
    z_final = min(e[2] for _, _, e, _, _ in all_moves)
    tab_top = top - summary["spec"]["part"]["thickness_mm"] + spec["tab_height_mm"]
    worst_gouge = np.inf
    for kind, s, e, extra, st in all_moves:
        if kind == "STRAIGHT_TRAVERSE":
            moves_xy = abs(s[0] - e[0]) > 1e-9 or abs(s[1] - e[1]) > 1e-9
            assert e[2] >= top - 1e-9 or (not moves_xy and e[2] > s[2]), f"rapid below the stock top: {s} -> {e}"
            if moves_xy:
                assert s[2] >= top - 1e-9, f"rapid across below the stock top: {s} -> {e}"
            continue
        assert st["feed"] > 0, "cutting move without a feed rate"
        assert st["spindle"], "cutting with the spindle stopped"
        pts = sample(kind, s, e, extra)
        if min(s[2], e[2]) < top:
            worst_gouge = min(worst_gouge, distance_to_part(pts, poly, holes).min())
        if st["label"].startswith("outline finish") and st["section"] == "contour":
            if abs(s[0] - e[0]) < 1e-9 and abs(s[1] - e[1]) < 1e-9:
                continue  # vertical move onto or off a holding tab
            assert abs(e[2] - s[2]) < 1e-9 and (abs(e[2] - z_final) < 1e-9 or abs(e[2] - tab_top) < 1e-9)
            finish_pts.append(pts)
    # No gouge anywhere: the tool centre stays at least one radius (less the tolerance) away.
    assert worst_gouge >= radius - tol, (worst_gouge, radius)
    # The finishing contour (lead arcs dropped) lies on the ideal offset within the tolerance.
    contour = np.vstack(finish_pts)
    d = distance_to_part(contour, poly, [])
    assert np.abs(d - radius).max() <= tol, np.abs(d - radius).max()
    # ... and covers it: every point of the outline has the tool centre within r + tol.
    dense = np.vstack([poly[:-1] + t * (poly[1:] - poly[:-1]) for t in np.linspace(0, 1, 4)[:-1]])
    cover = np.concatenate([distance_to_polyline(dense[i : i + 200], contour) for i in range(0, len(dense), 200)])
    assert cover.max() <= radius + tol + 1e-4, cover.max()
    return canon


def test_linuxcnc_runs_the_program_and_the_path_is_exact(design, tmp_path):
    out, summary = design
    assert summary["gcode"]["dialect"] == "linuxcnc"
    canon = check_program(out, summary, tmp_path)
    assert "ARC_FEED" in canon


@pytest.mark.parametrize("dialect", ["grbl", "fanuc"])
def test_other_dialects_follow_their_rules(tmp_path, dialect):
    text = (ROOT / "specs" / "paper.toml").read_text().replace('[machining]', f'[machining]\ndialect = "{dialect}"')
    out, summary = design_into(text, tmp_path)
    lines = (out / "cam.ngc").read_text().splitlines()
    code = [l for l in lines if not l.startswith("(")]
    assert not any(re.search(r"\bG4[0-2]\b", l) for l in code), "no cutter compensation"
    if dialect == "grbl":
        assert max(len(l) for l in lines) <= 70
        assert not any(re.search(r"\bM0?6\b|\bG43\b|^%|\bO\d", l) for l in code), "GRBL: no tool change, G43, % or O"
        assert code[-1] == "M2"
    else:
        assert lines[0] == "%" and lines[1].startswith("O") and lines[-1] == "%" and code[-2] == "M30"
        assert any(l.startswith("G43 H1") for l in code)
        assert all(c == c.upper() for c in lines if c.startswith("("))
        for l in code:
            for word in re.findall(r"[XYZIJ](-?[\d.]+)", l):
                assert "." in word, f"Fanuc needs the decimal point: {l}"
    # Both still describe the same path: strip the dialect-only lines and let rs274 check it.
    plain = [
        l.lower() if l.startswith("(") else l
        for l in lines
        if l not in ("%",) and not re.match(r"^O\d+", l) and not l.startswith("G43")
    ]
    (out / "plain.ngc").write_text("\n".join(plain) + "\n")
    check_program(out, summary, tmp_path, ngc="plain.ngc")


def test_lines_only_program_matches_and_needs_more_blocks(tmp_path):
    base = (ROOT / "specs" / "paper.toml").read_text()
    out_arcs, arcs = design_into(base, tmp_path / "arcs")
    out_g1, g1 = design_into(base.replace("[machining]", "[machining]\narcs = false"), tmp_path / "g1")
    canon = check_program(out_g1, g1, tmp_path)
    assert "ARC_FEED" not in canon
    assert g1["gcode"]["blocks"] > 2 * arcs["gcode"]["blocks"]


def test_a_cutter_too_large_for_the_cam_is_refused(tmp_path):
    text = (ROOT / "specs" / "paper.toml").read_text().replace('tool_diameter = "6 mm"', 'tool_diameter = "50 mm"\ndepth_per_pass = "1 mm"')
    out, summary = design_into(text, tmp_path)
    assert summary["gcode"] is None
    assert "end mill of at most" in summary["gcode_refused"]
    assert not (out / "cam.ngc").exists()


@pytest.mark.parametrize("seed", range(6))
def test_random_machining_settings_pass_rs274_and_the_path_checks(tmp_path, seed):
    """Property-style sweep over machining ranges (seeded, so failures reproduce)."""
    rng = np.random.default_rng(seed)
    spec = (ROOT / "specs" / ("paper.toml" if seed % 2 == 0 else "ankle.toml")).read_text()
    tool = float(rng.uniform(1.0, 8.0))
    settings = {
        "tool_diameter": f'"{tool:.3f} mm"',
        "depth_per_pass": f'"{rng.uniform(0.3, tool):.3f} mm"',
        "stock_allowance": f'"{rng.uniform(0.0, 0.5):.3f} mm"',
        "lead_in_radius": f'"{rng.uniform(0.5, 4.0):.3f} mm"',
        "climb": "true" if rng.random() < 0.5 else "false",
        "arcs": "true" if rng.random() < 0.7 else "false",
        "tolerance": f'"{rng.choice([0.0005, 0.001, 0.005, 0.02])} mm"',
    }
    lines = [l for l in spec.splitlines() if not l.startswith("tool_diameter")]
    i = lines.index("[machining]")
    lines[i + 1 : i + 1] = [f"{k} = {v}" for k, v in settings.items()]
    out, summary = design_into("\n".join(lines) + "\n", tmp_path)
    assert summary["gcode"] is not None, summary["gcode_refused"]
    check_program(out, summary, tmp_path)


def test_holding_tabs_leave_bridges_of_the_asked_width(tmp_path):
    text = (ROOT / "specs" / "paper.toml").read_text().replace(
        "[machining]", '[machining]\ntabs = 3\ntab_width = "2.5 mm"\ntab_height = "1.2 mm"'
    )
    out, summary = design_into(text, tmp_path)
    canon = check_program(out, summary, tmp_path)
    m = summary["spec"]["machining"]
    top = m["stock_top_z_mm"]
    tab_top = top - summary["spec"]["part"]["thickness_mm"] + m["tab_height_mm"]
    # Below the tab tops, the finishing pass leaves 3 gaps; each gap's tool-centre length is the
    # tab width plus the cutter diameter, so the bridge left is the tab width.
    lifted = []
    for kind, s, e, extra, st in moves(canon):
        if st["label"].startswith("outline finish") and kind == "STRAIGHT_FEED" and abs(s[2] - tab_top) < 1e-9 and abs(e[2] - tab_top) < 1e-9:
            lifted.append(math.hypot(e[0] - s[0], e[1] - s[1]))
    assert len(lifted) == 3, lifted
    for length in lifted:
        assert abs(length - (m["tab_width_mm"] + m["tool_diameter_mm"])) < 1e-4
    # Roughing levels above the tab tops cut straight through; those below lift too.
    assert canon.count('COMMENT("tab")') == 3 * sum(
        1 for line in canon.splitlines() if 'COMMENT("outline' in line and float(line.rsplit("Z", 1)[1].rstrip('")')) < tab_top - 1e-9
    )
