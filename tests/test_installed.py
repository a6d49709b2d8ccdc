"""The installed package, as a new user gets it: build the wheel, install it (without the
repository on the path), and run the `pf-offboard` entry point from an empty directory.

This fails when the shipped configs are not package data: the wheel must contain them, and
`pf-offboard demo` / `pf-offboard configs` run from a directory with no `configs/` in sight and
with the installed copy (not this source tree) on the import path."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted(p.name for p in (ROOT / "pf_offboard" / "configs").glob("*.yaml"))


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel built from this tree and installed (--no-deps: the dependencies are this
    interpreter's) into a fresh target directory; returns that directory."""
    tmp = tmp_path_factory.mktemp("installed")
    # build from a clean copy of the sources: a stale *.egg-info / build/ in the tree (from an earlier
    # build) would otherwise carry files into the wheel that the package data no longer declares
    src = tmp / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build", "*.pyc")
    for name in ("pf_offboard", "sitl_mock"):
        shutil.copytree(ROOT / name, src / name, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    # PIP_RETRIES=0: without a network (a sandbox, `unshare -n`) pip's isolated build env otherwise
    # retries the unreachable index for ~22 s before using the local/find-links wheels; same wheel either way
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", str(src), "-w", str(tmp / "wheel")],
                           capture_output=True, text=True, timeout=170, env={**os.environ, "PIP_RETRIES": "0"})  # fmt: skip
    assert build.returncode == 0, f"building the wheel failed:\n{build.stdout}\n{build.stderr}"
    (wheel,) = (tmp / "wheel").glob("pf_offboard-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = [n for n in SHIPPED if f"pf_offboard/configs/{n}" not in names]
    assert not missing, f"configs missing from the wheel (not package data): {missing}"
    site = tmp / "site"
    inst = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet", "--target", str(site), str(wheel)],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert inst.returncode == 0, inst.stderr
    return site


def _run(site: Path, cwd: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PYTHONPATH"] = str(site)  # the installed copy only: not this source tree
    env["MPLBACKEND"] = "Agg"
    return subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=170)


def test_installed_copy_is_the_one_imported(installed: Path, tmp_path: Path) -> None:
    r = _run(installed, tmp_path, sys.executable, "-c", "import pf_offboard, sitl_mock; print(pf_offboard.__file__); print(sitl_mock.__file__)")
    assert r.returncode == 0, r.stderr
    for line in r.stdout.split():
        assert Path(line).resolve().is_relative_to(installed.resolve()), line


def test_entry_point_lists_the_configs_from_anywhere(installed: Path, tmp_path: Path) -> None:
    r = _run(installed, tmp_path, installed / "bin" / "pf-offboard", "configs")
    assert r.returncode == 0, r.stderr
    listed = {line.split()[0] for line in r.stdout.splitlines() if line and not line.startswith("use:")}
    assert listed == {n.removesuffix(".yaml") for n in SHIPPED}
    r = _run(installed, tmp_path, installed / "bin" / "pf-offboard", "init", "mine", "--from", "helix")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "mine.yaml").read_text().startswith("# mine: your config (written by `pf-offboard init` from \"helix\")")


def test_demo_flies_from_an_empty_directory_and_writes_its_logs_there(installed: Path, tmp_path: Path) -> None:
    empty = tmp_path / "somewhere"
    empty.mkdir()
    r = _run(installed, empty, installed / "bin" / "pf-offboard", "demo", "--laps", "1", "--quiet", "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    report = json.loads(r.stdout)
    # it followed the path: 5.6-6.3 cm whole-flight cross-track RMS (approach included) in three runs.
    # Not the convergence time: on the noisy px4-sih one lap may end on a sample outside the 5 cm /
    # speed tolerance, which leaves "converged for the rest of the flight" unmet (seen once in CI).
    assert report["exit_code"] == 0 and report["summary"]["whole_flight"]["cross_track_rms_m"] < 0.15
    (log_dir,) = (empty / "flights").glob("demo-*")
    assert Path(report["log_dir"]).resolve() == log_dir.resolve()
    for name in ("flight.tlog", "flight.csv", "flight.yaml", "summary.json", "path3d.png", "map.png"):
        assert (log_dir / name).is_file(), name
