"""Shipped configs: package data found by name, listed, copied by `init`; `configs/` in the
repository is the same directory."""

from __future__ import annotations

from pathlib import Path

import pytest

from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.errors import InputError
from pf_offboard.shipped import resolve_config, shipped_configs

ROOT = Path(__file__).resolve().parents[1]


def test_repository_configs_dir_is_the_package_data() -> None:
    assert (ROOT / "configs").resolve() == (ROOT / "pf_offboard" / "configs").resolve()
    assert {c.name for c in shipped_configs()} == {p.stem for p in (ROOT / "pf_offboard" / "configs").glob("*.yaml")}
    assert all(c.description and len(c.description) <= 100 for c in shipped_configs())


def test_resolve_by_name_or_file(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)  # no configs/ here
    assert resolve_config("paper").name == "paper.yaml"
    assert resolve_config("paper.yaml") == resolve_config("paper")
    (tmp_path / "paper").write_text("path: {waypoints: [[0, 0, 1], [1, 0, 1]]}\n")
    assert resolve_config("paper") == Path("paper")  # an existing file wins over a shipped name
    with pytest.raises(InputError, match=r"--config: no such file: nosuch, and not a shipped config \(shipped: arducopter, figure8, helix, paper"):
        resolve_config("nosuch")
    with pytest.raises(InputError, match="no such file"):
        resolve_config("dir/paper.yaml")  # a path is never looked up by name


def test_configs_command_lists_names_and_descriptions(capsys) -> None:
    assert main(["configs"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines[:-1]] == sorted(c.name for c in shipped_configs())
    assert lines[0].startswith("arducopter") and "ArduCopter" in lines[0]
    assert "closed, planar figure-eight" in lines[1]


def test_init_writes_a_commented_copy_and_never_overwrites(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["init", "myfield"]) == 0
    text = (tmp_path / "myfield.yaml").read_text()
    assert text.startswith("# myfield: your config")
    mine = load_config(tmp_path / "myfield.yaml")
    assert mine.path.waypoints_enu_m == load_config(resolve_config("paper")).path.waypoints_enu_m
    assert mine.gains_auto and mine.compensation.enabled  # the default, not the paper's gains
    assert "note:" not in capsys.readouterr().err  # the default needs no caution
    assert main(["init", "myfield"]) == 2
    assert "exists (pass --force" in capsys.readouterr().err
    assert main(["init", "x", "--from", "helix", "--out", str(tmp_path / "sub" / "h.yaml")]) == 0
    assert load_config(tmp_path / "sub" / "h.yaml").path.closed is False
    assert main(["init", "y", "--from", "nosuch"]) == 2


def test_init_from_paper_says_what_the_papers_gains_need(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["init", "p", "--from", "paper"]) == 0
    err = capsys.readouterr().err
    assert "note:" in err and "phase margin" in err and "--vehicle fast" in err
    assert "# The paper's experiment" in (tmp_path / "p.yaml").read_text()  # the shipped comments are kept


def test_fly_accepts_a_shipped_name(capsys) -> None:
    # the name resolves and loads: the flight gets as far as waiting for a HEARTBEAT (exit 3)
    assert main(["fly", "--connect", "udpin:127.0.0.1:9", "--config", "paper", "--airborne", "--heartbeat-timeout", "0.01", "--quiet"]) == 3
    assert "no HEARTBEAT" in capsys.readouterr().err
    assert main(["fly", "--connect", "udpin:127.0.0.1:9", "--config", "nosuch", "--airborne"]) == 2
    assert "not a shipped config" in capsys.readouterr().err
