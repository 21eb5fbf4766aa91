"""The HTML pages in a real browser: Debian's headless Chromium renders report.html and
validation.html, with its console logged; the rendered DOM must hold the plots, the page must
have no console errors, and the screenshot must show a drawn page."""
import pathlib
import re
import shutil
import subprocess

import numpy as np
import pytest

from conftest import ROOT, run

FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--enable-logging=stderr", "--v=0",
]


def browser():
    for name in ("chromium", "chromium-browser"):
        if shutil.which(name):
            return shutil.which(name)
    pytest.fail("scripts/test installs Debian's chromium")


def render(page: pathlib.Path, tmp: pathlib.Path, size="1300,2600"):
    """Returns (rendered DOM, console lines, screenshot as a grey image array)."""
    from PIL import Image

    shot = tmp / (page.stem + ".png")
    common = [browser(), *FLAGS, f"--user-data-dir={tmp / 'profile'}", f"--window-size={size}"]
    dom = subprocess.run([*common, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0, dom.stderr
    shot_run = subprocess.run([*common, f"--screenshot={shot}", page.as_uri()], capture_output=True, text=True, timeout=120)
    assert shot_run.returncode == 0, shot_run.stderr
    console = [l for l in (dom.stderr + shot_run.stderr).splitlines() if "CONSOLE" in l]
    return dom.stdout, console, np.asarray(Image.open(shot).convert("L"))


def self_contained(html: str):
    assert "<script" not in html.lower()
    # No network: every src/href is a relative file or a fragment.
    for ref in re.findall(r'(?:src|href)="([^"]*)"', html):
        assert not re.match(r"^[a-z]+://", ref), ref


def test_design_report_renders_with_its_plots(tmp_path):
    proc = run(["design", "-o", str(tmp_path / "out")], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    page = tmp_path / "out" / "report.html"
    assert str(page.relative_to(tmp_path)) in proc.stdout or "report.html" in proc.stdout
    html = page.read_text()
    self_contained(html)
    dom, console, img = render(page, tmp_path)
    assert console == [], console
    # Force and stiffness (2 panels in one SVG), cam profile, pressure angle and stress.
    assert dom.count("<svg") >= 3, dom.count("<svg")
    assert dom.count("<polyline") >= 8
    for section in ("Force law", "Cam profile", "Pressure angle", "Checks", "Part", "Files", "Spec"):
        assert section in dom, section
    assert "alpha = k2 · L0 = 1.3201914760" in dom
    assert "1.3288" in dom  # the note on the paper's printed value
    # Every output file is linked and exists.
    for ref in re.findall(r'<li><a href="([^"]+)"', html):
        assert (page.parent / ref).exists(), ref
    dark = (img < 128).mean()
    assert 0.005 < dark < 0.5, dark


def test_validation_page_renders_with_the_verdict(tmp_path):
    spec = str(ROOT / "specs" / "paper.toml")
    assert run(["simulate", spec, "-o", "calib.csv", "--duration", "200s"], cwd=tmp_path).returncode == 0
    proc = run(["validate", spec, "calib.csv"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    page = tmp_path / "validation.html"
    html = page.read_text()
    self_contained(html)
    dom, console, img = render(page, tmp_path, size="1300,1200")
    assert console == [], console
    assert "PASS" in dom
    # By default the force curve is judged against the band of builds.
    for name in ("k2", "stiffness_force_line", "force_band"):
        assert name in dom, name
    assert dom.count("<svg") >= 1 and dom.count("<circle") > 100  # the stiffness scatter
    dark = (img < 128).mean()
    assert 0.002 < dark < 0.5, dark
