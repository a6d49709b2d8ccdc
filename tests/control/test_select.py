"""The ``controller:`` config key: which controller sim / fly / replay build from a config."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pf_offboard.cli import main
from pf_offboard.config import load_config, parse_config
from pf_offboard.control import PathFollower, TrajectoryTracker, controller_from_config
from pf_offboard.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def config_path(name: str) -> Path:
    return CONFIGS / name


def _data(controller: object | None) -> dict:
    data = yaml.safe_load(config_path("paper.yaml").read_text())
    if controller is not None:
        data["controller"] = controller
    return data


def test_default_is_path_following_and_unchanged():
    cfg = load_config(config_path("paper.yaml"))
    assert cfg.controller == "path_following"
    c = controller_from_config(cfg)
    assert type(c) is PathFollower
    ref = PathFollower.from_config(cfg)
    y, v = (0.3, -1.2, 2.2), (0.5, 0.1, -0.2)
    a, b = c.update(y, v), ref.update(y, v)
    assert a.acceleration.tolist() == b.acceleration.tolist() and a.attitude.tolist() == b.attitude.tolist()


def test_trajectory_tracking_selects_the_baseline():
    cfg = parse_config(_data("trajectory_tracking"))
    assert cfg.controller == "trajectory_tracking"
    c = controller_from_config(cfg)
    assert type(c) is TrajectoryTracker
    assert (c.speed, c.gains, c.limits) == (cfg.speed_m_s, cfg.gains, cfg.limits)
    assert parse_config(_data("path_following")).controller == "path_following"


@pytest.mark.parametrize("bad", ["pid", "Path_Following", 1, True, None, ["path_following"]])
def test_bad_controller_names_the_field(bad):
    with pytest.raises(ConfigError) as exc:
        parse_config(_data(bad) if bad is not None else {**_data(None), "controller": None})
    assert exc.value.field == "controller"
    assert "path_following, trajectory_tracking" in exc.value.reason


def test_bad_controller_exits_2_in_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(yaml.safe_dump(_data("mpc")))
    assert main(["sim", "--config", str(cfg), "--out", str(tmp_path / "out"), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "controller: must be one of path_following, trajectory_tracking, got 'mpc'" in err
    assert "Traceback" not in err
