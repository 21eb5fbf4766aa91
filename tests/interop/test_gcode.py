"""G-code read by LinuxCNC's own interpreter (rs274, Debian package linuxcnc-uspace): every
program runs without error, and the interpreted tool path is checked against the exact part:
the finishing pass lies within the tolerance of the ideal tool-centre path (the part boundary
offset by the cutter radius) in both directions, and no move anywhere gouges the part."""
import math
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from conftest import ONE_FOLLOWER, ROOT, design_into, distance_to_polyline, surface_reference

RS274 = shutil.which("rs274")
NUM = r"(-?\d+(?:\.\d+)?)"


def interpret(ngc, tmp_path):
    """rs274's canonical output for the program. Each run gets its own home folder: rs274 keeps
    its tool table in a memory-mapped file there (~/.tool.mmap), and two runs at once (the
    suite runs on two workers) shared it, so one program's tool changes emptied the other's
    pockets ("Requested tool 1 not found in the tool table", once in a CI run)."""
    assert RS274, "scripts/test installs linuxcnc-uspace"
    home = tmp_path / "rs274-home"
    home.mkdir(exist_ok=True)
    env = {**os.environ, "HOME": str(home)}
    proc = subprocess.run([RS274, "-g", str(ngc)], capture_output=True, text=True, cwd=tmp_path, timeout=120,
                          env=env)
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
    tool = None
    for line in canon.splitlines():
        if "COMMENT(" in line:
            text = line.split('COMMENT("', 1)[1].rsplit('")', 1)[0].lower()
            if text in ("ramp", "lead-in", "contour", "lead-out"):
                section = text
            elif text == "tab":
                pass
            elif re.match(r"^t(\d+) ", text):
                # The comment that starts a tool's work ("T2 3 mm end mill: mills hole 1"): GRBL
                # changes tools at a pause, which the interpreter does not see.
                tool = int(re.match(r"^t(\d+) ", text).group(1))
            elif not text.startswith("interpreter"):
                label, section = text, ""
        elif "SET_FEED_RATE(" in line:
            feed = float(re.search(NUM, line.split("SET_FEED_RATE(")[1]).group(1))
        elif "START_SPINDLE_CLOCKWISE" in line:
            spindle = True
        elif "STOP_SPINDLE_TURNING" in line:
            spindle = False
        elif "CHANGE_TOOL(" in line:
            tool = int(re.search(r"CHANGE_TOOL\((\d+)\)", line).group(1))
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
            state = {"feed": feed, "spindle": spindle, "label": label, "section": section, "tool": tool}
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


def tool_radii(summary):
    """T number -> radius, for the tools of the program (T1 when the program has no tool change)."""
    radii = {t["number"]: t["diameter_mm"] / 2 for t in summary["gcode"]["tools"]}
    return radii


def check_program(out, summary, tmp_path, ngc="cam.ngc"):
    canon = interpret(out / ngc, tmp_path)
    spec = summary["spec"]["machining"]
    radii = tool_radii(summary)
    outline_tool = next(t for t in summary["gcode"]["tools"] if "outline" in t["purpose"])
    radius = outline_tool["diameter_mm"] / 2
    tol = spec["tolerance_mm"]
    top = spec["stock_top_z_mm"]
    thickness = summary["spec"]["part"]["thickness_mm"]
    z_final = top - thickness - spec["breakthrough_mm"]
    poly, holes = part_boundary(out, summary)
    all_moves = list(moves(canon))
    finish_pts = []
    tab_top = top - thickness + spec["tab_height_mm"]
    worst_gouge = np.inf
    drilled = {}  # (x, y) -> deepest Z drilled there
    for kind, s, e, extra, st in all_moves:
        r_tool = radii[st["tool"]] if st["tool"] in radii else radius
        moves_xy = abs(s[0] - e[0]) > 1e-9 or abs(s[1] - e[1]) > 1e-9
        if kind == "STRAIGHT_TRAVERSE":
            if e[2] < top - 1e-9 and not moves_xy and e[2] < s[2]:
                # A rapid down below the stock top only inside its own drilled hole.
                deepest = drilled.get((round(e[0], 4), round(e[1], 4)))
                assert deepest is not None and e[2] >= deepest - 1e-9, f"rapid into material: {s} -> {e}"
                continue
            assert e[2] >= top - 1e-9 or (not moves_xy and e[2] > s[2]), f"rapid below the stock top: {s} -> {e}"
            if moves_xy:
                assert s[2] >= top - 1e-9, f"rapid across below the stock top: {s} -> {e}"
            continue
        assert st["feed"] > 0, "cutting move without a feed rate"
        assert st["spindle"], "cutting with the spindle stopped"
        if not moves_xy:
            key = (round(e[0], 4), round(e[1], 4))
            drilled[key] = min(drilled.get(key, top), e[2])
        pts = sample(kind, s, e, extra)
        if min(s[2], e[2]) < top:
            worst_gouge = min(worst_gouge, (distance_to_part(pts, poly, holes) - r_tool).min())
        if st["label"].startswith("outline finish") and st["section"] == "contour":
            if not moves_xy:
                continue  # vertical move onto a holding tab
            if abs(e[2] - s[2]) > 1e-9:
                # The ramp down off a holding tab, along the contour.
                assert z_final - 1e-9 <= min(s[2], e[2]) and max(s[2], e[2]) <= tab_top + 1e-9
                finish_pts.append(pts)
                continue
            assert abs(e[2] - s[2]) < 1e-9 and (abs(e[2] - z_final) < 1e-9 or abs(e[2] - tab_top) < 1e-9)
            finish_pts.append(pts)
        if st["label"].startswith("hole") and st["label"].split()[2] == "finish" and st["section"] == "contour":
            # A milled hole's finishing circle: on the hole's radius less the tool's.
            c, r_hole = holes[int(st["label"].split()[1])]
            d = np.linalg.norm(pts - c, axis=1)
            assert np.abs(d - (r_hole - r_tool)).max() <= tol, (st["label"], np.abs(d - (r_hole - r_tool)).max())
            assert abs(e[2] - z_final) < 1e-9
    # No gouge anywhere: every tool centre stays at least its radius (less the tolerance) away.
    assert worst_gouge >= -tol, worst_gouge
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


HOLES = 'holes = [{ x = "12 mm", y = "0 mm", diameter = "8 mm" }, { x = "3 mm", y = "0 mm", diameter = "5 mm" }, { x = "18 mm", y = "-5.5 mm", diameter = "3.3 mm" }]'
TOOLS = """
[[machining.tools]]
diameter = "6 mm"
flute_length = "16 mm"
flutes = 3
spindle_rpm = "10000 rpm"
feed = "900 mm/min"

[[machining.tools]]
number = 2
diameter = "3 mm"
flute_length = "12 mm"
flutes = 2
spindle_rpm = "16000 rpm"
feed = "500 mm/min"
plunge_feed = "100 mm/min"

[[machining.tools]]
number = 3
kind = "drill"
diameter = "3.3 mm"
spindle_rpm = "3000 rpm"
plunge_feed = "120 mm/min"
"""


def spec_text(dialect="linuxcnc", multi=False, extra=""):
    text = (ROOT / "specs" / "paper.toml").read_text()
    text = text.replace("[machining]", f'[machining]\ndialect = "{dialect}"\n{extra}')
    if multi:
        text = text.replace('tool_diameter = "6 mm"\n', "")
        text = text.replace('roller_material = "bearing-steel"', 'roller_material = "bearing-steel"\n' + HOLES)
        text += TOOLS
    return text


def plain(lines):
    """The program without dialect-only lines (Fanuc's % and O number), comments lower-cased."""
    return [l.lower() if l.startswith("(") else l for l in lines if l != "%" and not re.match(r"^O\d+", l)]


GRBL_G = {"0", "1", "2", "3", "4", "10", "17", "18", "19", "20", "21", "28", "28.1", "30", "30.1", "38.2", "38.3",
          "38.4", "38.5", "40", "43.1", "49", "53", "54", "55", "56", "57", "58", "59", "61", "80", "90", "91", "91.1",
          "92", "92.1", "93", "94"}
GRBL_M = {"0", "1", "2", "30", "3", "4", "5", "7", "8", "9", "56"}


def check_grbl_rules(lines):
    """GRBL 1.1: at most 80 characters a line, only the G and M words it supports, and every arc's
    end radius within its limit (error 33: off by more than 0.005 mm and 0.1 % of the radius)."""
    assert max(len(l) for l in lines) <= 80
    pos = {"X": None, "Y": None, "Z": None}
    motion = None
    arcs = 0
    for l in lines:
        code = re.sub(r"\(.*?\)", "", l).strip()
        if not code:
            continue
        words = re.findall(r"([A-Z])(-?\d*\.?\d*)", code)
        for letter, value in words:
            if letter == "G":
                assert value.rstrip("0").rstrip(".") in GRBL_G or value in GRBL_G, f"GRBL has no G{value}: {l}"
                if value in ("0", "1", "2", "3"):
                    motion = value
            if letter == "M":
                assert value.lstrip("0") in GRBL_M or value == "0", f"GRBL has no M{value}: {l}"
        w = dict(words)
        new = {k: float(w[k]) if k in w else pos[k] for k in pos}
        if motion in ("2", "3") and ("I" in w or "J" in w):
            cx, cy = pos["X"] + float(w.get("I", 0)), pos["Y"] + float(w.get("J", 0))
            r0 = math.hypot(pos["X"] - cx, pos["Y"] - cy)
            r1 = math.hypot(new["X"] - cx, new["Y"] - cy)
            dr = abs(r1 - r0)
            assert not (dr > 0.005 and (dr > 0.5 or dr > 0.001 * r0)), f"GRBL error 33: {l} (radius {r0} vs {r1})"
            arcs += 1
        pos = new
    return arcs


@pytest.mark.parametrize("dialect", ["grbl", "fanuc"])
@pytest.mark.parametrize("multi", [False, True])
def test_other_dialects_follow_their_rules(tmp_path, dialect, multi):
    out, summary = design_into(spec_text(dialect, multi), tmp_path)
    lines = (out / "cam.ngc").read_text().splitlines()
    code = [l for l in lines if not l.startswith("(")]
    assert not any(re.search(r"\bG4[12]\b", l) for l in code), "no cutter compensation"
    if dialect == "grbl":
        assert check_grbl_rules(lines) > 100
        assert not any(re.search(r"\bM0?6\b|\bG43\b|\bG8[1-9]\b|^%|\bO\d", l) for l in code), "GRBL: no tool change, G43, canned cycle, % or O"
        assert sum(l == "M0" for l in code) == (2 if multi else 0)
        assert code[-1] == "M2"
    else:
        assert lines[0] == "%" and lines[1].startswith("O") and lines[-1] == "%" and code[-2] == "M30"
        assert any(l.startswith("G0 G43 H1") for l in code)
        assert all(c == c.upper() for c in lines if c.startswith("("))
        for l in code:
            for word in re.findall(r"[XYZIJRQ](-?[\d.]+)", l):
                assert "." in word, f"Fanuc needs the decimal point: {l}"
        if multi:
            assert any(re.match(r"G98 G83 X18\. Y-5\.5 Z-11\.491 R1\. Q3\.3 F120\.", l) for l in code), code
    # Every variant still describes the same path: strip the dialect-only lines and let rs274 check it.
    (out / "plain.ngc").write_text("\n".join(plain(lines)) + "\n")
    check_program(out, summary, tmp_path, ngc="plain.ngc")


@pytest.mark.parametrize("dialect", ["linuxcnc", "grbl", "fanuc"])
def test_a_shallow_hole_is_drilled_in_one_feed(tmp_path, dialect):
    """A 6 mm hole through 10 mm (12.3 mm with breakthrough and the drill point) is within three
    diameters: one feed (G81), or for GRBL the same moves written out."""
    text = spec_text(dialect)
    text = text.replace('roller_material = "bearing-steel"', 'roller_material = "bearing-steel"\nholes = [{ x = "12 mm", y = "0 mm", diameter = "6 mm" }]')
    text += '\n[[machining.tools]]\ndiameter = "6 mm"\n\n[[machining.tools]]\nkind = "drill"\ndiameter = "6 mm"\nspindle_rpm = "2000 rpm"\nplunge_feed = "100 mm/min"\n'
    text = text.replace('tool_diameter = "6 mm"\n', "")
    out, summary = design_into(text, tmp_path)
    lines = (out / "cam.ngc").read_text().splitlines()
    code = [l for l in lines if not l.startswith("(")]
    if dialect == "grbl":
        check_grbl_rules(lines)
        assert not any("G81" in l or "G83" in l for l in code)
    else:
        assert sum(l.startswith("G98 G81 X12. Y0. Z-12.302") for l in code) == 1, code
    (out / "plain.ngc").write_text("\n".join(plain(lines)) + "\n")
    canon = check_program(out, summary, tmp_path, ngc="plain.ngc")
    # One feed down at the hole, to the drill point's depth.
    drills = [(s, e) for kind, s, e, _, st in moves(canon) if st["tool"] == 2 and kind == "STRAIGHT_FEED"]
    assert len(drills) == 1 and abs(drills[0][1][2] + 12.3024) < 1e-3, drills


def test_multi_tool_program_runs_and_each_tool_starts_safely(tmp_path):
    out, summary = design_into(spec_text(multi=True), tmp_path)
    assert [t["number"] for t in summary["gcode"]["tools"]] == [3, 2, 1]
    canon = check_program(out, summary, tmp_path)
    lines = canon.splitlines()
    changes = [i for i, l in enumerate(lines) if "CHANGE_TOOL(" in l]
    assert len(changes) == 3
    for i in changes:
        # The first motion after a tool change is a rapid of Z alone, up to the safe height.
        first = next(l for l in lines[i:] if "STRAIGHT_" in l or "ARC_FEED" in l)
        x, y, z = (float(v) for v in re.search(r"\(([^)]*)\)", first).group(1).split(",")[:3])
        prev = None
        for l in reversed(lines[:i]):
            m = re.search(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED)\(([^)]*)\)", l)
            if m:
                args = [float(v) for v in m.group(2).split(",")]
                prev = (args[0], args[1]) if m.group(1) != "ARC_FEED" else (args[0], args[1])
                break
        assert "STRAIGHT_TRAVERSE" in first and z == 5.0, first
        if prev is not None:
            assert (x, y) == prev, f"moved X or Y with the first rapid after a tool change: {first}"
    # Every spindle start is followed by a 3 s dwell before anything moves.
    starts = [i for i, l in enumerate(lines) if "START_SPINDLE_CLOCKWISE" in l]
    assert len(starts) == 3
    for i in starts:
        nxt = next(l for l in lines[i + 1 :] if "DWELL" in l or "STRAIGHT_" in l or "ARC_FEED" in l)
        assert "DWELL(3.0" in nxt, nxt
    # The drill pecks (G83) and returns into its own hole only; the 3 mm mill helixes.
    assert sum(1 for _, s, e, _, st in moves(canon) if st["tool"] == 3 and e[2] < s[2] and e[2] < -1) >= 4
    helix = [e for kind, s, e, x, st in moves(canon) if st["tool"] == 2 and kind == "ARC_FEED" and e[2] < s[2]]
    assert len(helix) > 10


def test_the_part_stays_attached_until_the_finishing_pass(tmp_path):
    """Nothing cuts through the plate's bottom face outside a hole before the outline's
    finishing pass, and that pass comes last."""
    for multi, extra in [(False, ""), (True, ""), (False, 'skin = "0.3 mm"\n')]:
        out, summary = design_into(spec_text(multi=multi, extra=extra), tmp_path / f"{multi}{len(extra)}")
        canon = interpret(out / "cam.ngc", tmp_path)
        m = summary["spec"]["machining"]
        bottom = m["stock_top_z_mm"] - summary["spec"]["part"]["thickness_mm"]
        _, holes = part_boundary(out, summary)
        through = []
        for kind, s, e, extra_, st in moves(canon):
            if kind == "STRAIGHT_TRAVERSE" or min(s[2], e[2]) >= bottom - 1e-9:
                continue
            pts = sample(kind, s, e, extra_)
            in_hole = any((np.linalg.norm(pts - c, axis=1) < r).all() for c, r in holes)
            if not in_hole:
                through.append(st["label"])
        assert through, "the finishing pass cuts through"
        assert all(l.startswith("outline finish") for l in through), set(through)
        # ... and the finishing pass is the last: no cut after it starts, other than its own.
        labels = [st["label"] for kind, *_, st in moves(canon) if kind != "STRAIGHT_TRAVERSE"]
        first = labels.index(through[0])
        assert all(l.startswith("outline finish") for l in labels[first:])
        # The roughing stops exactly the skin above the bottom face.
        rough = min(e[2] for kind, s, e, _, st in moves(canon) if st["label"].startswith("outline rough"))
        assert abs(rough - (bottom + m["skin_mm"])) < 1e-9


@pytest.mark.parametrize("extra", ['ramp_angle = "5 deg"\n', 'tabs = 3\ntab_width = "2.5 mm"\n'])
def test_entries_ramp_within_the_stated_angle(tmp_path, extra):
    """No end mill plunges into material: descents with no sideways motion stay in air (above
    the stock or above the floor already cut at that point); all others descend at most at
    the ramp angle, also coming off a holding tab."""
    out, summary = design_into(spec_text(multi=True, extra=extra), tmp_path)
    canon = interpret(out / "cam.ngc", tmp_path)
    m = summary["spec"]["machining"]
    kinds = {t["number"]: t["kind"] for t in summary["gcode"]["tools"]}
    tan = math.tan(math.radians(m["ramp_angle_deg"]))
    cut = []  # (points, z) of every cutting move so far, sampled
    ramps = 0
    for kind, s, e, extra, st in moves(canon):
        if kind == "STRAIGHT_TRAVERSE" or kinds[st["tool"]] == "drill":
            continue
        pts = sample(kind, s, e, extra, max_step=0.005)
        planar = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
        drop = s[2] - e[2]
        if drop > 1e-9:
            if planar < 1e-9:
                # Straight down: only where an earlier cut went at least as deep, within 0.01 mm.
                p = np.array(e[:2])
                ok = e[2] >= m["stock_top_z_mm"] or any(
                    np.any((np.linalg.norm(q - p, axis=1) < 0.01) & (z <= e[2] + 1e-9)) for q, z in cut
                )
                assert ok, f"plunge into material: {s} -> {e}"
            else:
                assert drop <= tan * planar * (1 + 1e-3) + 2e-5, f"steeper than the ramp angle: {s} -> {e}"
                ramps += 1
        cut.append((pts, np.linspace(s[2], e[2], len(pts)) if planar > 1e-9 else np.full(len(pts), e[2])))
    assert ramps > 20


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
        "flute_length": '"30 mm"',
        "depth_per_pass": f'"{rng.uniform(0.3, tool):.3f} mm"',
        "stock_allowance": f'"{rng.uniform(0.0, 0.5):.3f} mm"',
        "lead_in_radius": f'"{rng.uniform(0.5, 4.0):.3f} mm"',
        "climb": "true" if rng.random() < 0.5 else "false",
        "arcs": "true" if rng.random() < 0.7 else "false",
        "tolerance": f'"{rng.choice([0.0005, 0.001, 0.005, 0.02])} mm"',
    }
    lines = [l for l in spec.splitlines() if not l.startswith(("tool_diameter", "flute_length"))]
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
