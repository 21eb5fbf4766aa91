"""Shared fixtures: run the real camspring binary on example specs into temporary folders."""
import json
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = pathlib.Path(os.environ.get("CAMSPRING_BIN", ROOT / "target" / "release" / "camspring"))

# A one-follower part with two mounting holes, and a fine chord tolerance so that
# profile.csv is a 0.1 um reference polyline of the exact surface.
ONE_FOLLOWER = """
name = "one-follower"
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
friction = 0.02
[part]
thickness = "8 mm"
holes = [{ x = "10 mm", y = "-5 mm", diameter = "4 mm" }, { x = "2 mm", y = "-5 mm", diameter = "3 mm" }]
[machining]
tool_diameter = "2 mm"
flute_length = "12 mm"
depth_per_pass = "1.5 mm"
[output]
chord_tolerance = "0.0001 mm"
"""


def run(args, cwd):
    proc = subprocess.run([str(BIN), *args], cwd=cwd, capture_output=True, text=True)
    print(proc.stdout)
    print(proc.stderr)
    return proc


def design_into(spec_text_or_path, out_dir, fine=True):
    """Runs `camspring design` and returns (out_dir, design.json as dict)."""
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if isinstance(spec_text_or_path, pathlib.Path):
        text = spec_text_or_path.read_text()
    else:
        text = spec_text_or_path
    if fine and "[output]" not in text:
        text += '\n[output]\nchord_tolerance = "0.0001 mm"\n'
    spec = out_dir / "spec.toml"
    spec.write_text(text)
    proc = run(["design", str(spec), "-o", str(out_dir / "out")], cwd=out_dir)
    assert proc.returncode in (0, 1), proc.stderr
    return out_dir / "out", json.loads((out_dir / "out" / "design.json").read_text())


def pytest_collection_modifyitems(config, items):
    """Keeps together the tests that share one value of a module- or session-scoped fixture
    (the `case` logs of test_calibration, the `design` runs): under pytest-xdist's
    `--dist loadgroup` they then run on one worker, and each log or design is made once."""
    for item in items:
        callspec = getattr(item, "callspec", None)
        if callspec is None:
            continue
        fixtures = item._fixtureinfo.name2fixturedefs
        for name, index in sorted(callspec.indices.items()):
            defs = fixtures.get(name)
            if defs and defs[-1].scope == "session":
                item.add_marker(pytest.mark.xdist_group(f"{name}[{index}]"))
                break
            if defs and defs[-1].scope == "module":
                item.add_marker(pytest.mark.xdist_group(f"{item.module.__name__}:{name}[{index}]"))
                break


@pytest.fixture(scope="session", params=["paper", "ankle", "one-follower", "knee"])
def design(request, tmp_path_factory):
    base = tmp_path_factory.mktemp(request.param)
    if request.param == "one-follower":
        return design_into(ONE_FOLLOWER, base)
    if request.param == "knee":
        # A tabulated law: the table travels with the spec.
        (base / "knee.csv").write_text((ROOT / "specs" / "knee.csv").read_text())
    return design_into(ROOT / "specs" / f"{request.param}.toml", base)


def surface_reference(out, summary):
    """The exact cam surface from profile.csv (0.1 um chords) in part coordinates, one
    polyline per cam edge (upper, then mirrored lower for two followers)."""
    import numpy as np

    rows = np.genfromtxt(out / "profile.csv", delimiter=",", names=True)
    dy = summary["part"]["frame_dy_mm"]
    upper = np.column_stack([rows["surface_x_mm"], rows["surface_y_mm"] + dy])
    edges = [upper]
    if summary["follower"]["count"] == 2:
        edges.append(upper * np.array([1.0, -1.0]))
    return edges


def distance_to_polyline(points, poly):
    """Distance from each point (n x 2) to the polyline (m x 2)."""
    import numpy as np

    a = poly[:-1][None, :, :]
    b = poly[1:][None, :, :]
    p = points[:, None, :]
    ab = b - a
    l2 = np.maximum((ab * ab).sum(-1), 1e-300)
    t = np.clip(((p - a) * ab).sum(-1) / l2, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.sqrt(((p - closest) ** 2).sum(-1)).min(axis=1)
