"""Follows the README on a clean clone as a new user would: the two commands of "The two
commands" are the ones CI runs, the first one works in a fresh clone, and every path it prints
exists. (The second one, scripts/test, is what is running this test.)"""
import os
import pathlib
import re
import shutil
import subprocess

from conftest import ROOT


def readme_commands():
    text = (ROOT / "README.md").read_text()
    section = text.split("## The two commands", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```sh\n(.*?)```", section, re.S).group(1)
    return [line.split("#", 1)[0].strip() for line in block.splitlines() if line.strip()]


def test_the_readme_gives_exactly_two_commands_and_ci_runs_the_second():
    commands = readme_commands()
    assert commands == ["cargo run --release -- design", "scripts/test"], commands
    assert os.access(ROOT / "scripts" / "test", os.X_OK)
    ci = (ROOT / ".ci" / "run").read_text()
    assert re.search(r"^exec scripts/test$", ci, re.M), ci


def test_the_first_command_works_on_a_clean_clone(tmp_path):
    if not (ROOT / ".git").exists():
        import pytest

        pytest.skip("not a git checkout")
    clone = tmp_path / "camspring"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
    assert not (clone / "target").exists()
    assert [p.name for p in (clone / "out").iterdir()] in ([], [".keep"])
    command = readme_commands()[0].split()
    env = dict(os.environ)
    # Share the build cache only (the sources are the clone's), so that CI does not compile
    # everything twice; a new user's first run builds from scratch the same way.
    env["CARGO_TARGET_DIR"] = str(ROOT / "target")
    proc = subprocess.run(command, cwd=clone, env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    printed = [line.strip() for line in proc.stdout.splitlines() if line.strip().startswith("out/")]
    assert len(printed) >= 10, proc.stdout
    for p in printed:
        assert (clone / p).is_file(), p
    assert "out/paper/report.html" in printed and "out/paper/cam.step" in printed
    shutil.rmtree(clone / "out" / "paper")
