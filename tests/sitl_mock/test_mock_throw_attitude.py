"""A thrown spawn's attitude and body rates: validated, parsed, passed to the subprocess, flown."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl_mock.autopilot import Autopilot
from sitl_mock.cli import build_parser, config_from_args, config_to_args
from sitl_mock.config import MockConfig, MockConfigError, SpawnSpec

S = math.sqrt(0.5)
TILTED = (S, S, 0.0, 0.0)  # 90 deg roll


def test_a_throw_starts_with_its_attitude_and_spin() -> None:
    spawn = SpawnSpec("throw", (0.0, 0.0, -10.0), (1.0, 0.0, 0.0), TILTED, (0.5, -1.0, 2.0))
    ap = Autopilot(MockConfig(vehicle="fast", spawn=spawn, lockstep=True))
    np.testing.assert_allclose(ap.truth.q_ned_frd, TILTED, atol=1e-12)
    np.testing.assert_allclose(ap.truth.rates_frd_rad_s, (0.5, -1.0, 2.0), atol=1e-12)
    assert ap.motors_locked


def test_the_spawn_text_round_trips_with_and_without_attitude() -> None:
    spin = SpawnSpec("throw", (1.0, 2.0, -3.0), (0.0, 1.0, 0.0), TILTED, (0.0, 0.0, 1.5))
    plain = SpawnSpec("throw", (1.0, 2.0, -3.0), (0.0, 1.0, 0.0))
    assert plain.args() == "throw:1.0,2.0,-3.0,0.0,1.0,0.0"  # unchanged form for a plain throw
    for spawn in (spin, plain, SpawnSpec("hover", (0.0, 0.0, -2.0)), SpawnSpec("ground", (1.0, 2.0, 0.0))):
        assert SpawnSpec.parse(spawn.args()) == spawn
        config = MockConfig(vehicle="fast", spawn=spawn)
        assert config_from_args(build_parser().parse_args(config_to_args(config))).spawn == spawn


@pytest.mark.parametrize(("spawn", "field"), [
    (SpawnSpec("throw", (0.0, 0.0, -2.0), q_ned_frd=(1.0, 1.0, 0.0, 0.0)), "spawn.q_ned_frd"),
    (SpawnSpec("throw", (0.0, 0.0, -2.0), q_ned_frd=(1.0, 0.0, 0.0)), "spawn.q_ned_frd"),  # type: ignore[arg-type]
    (SpawnSpec("throw", (0.0, 0.0, -2.0), rates_frd_rad_s=(math.inf, 0.0, 0.0)), "spawn.rates_frd_rad_s"),
    (SpawnSpec("throw", (0.0, 0.0, -2.0), rates_frd_rad_s=(40.0, 0.0, 0.0)), "spawn.rates_frd_rad_s"),
    (SpawnSpec("hover", (0.0, 0.0, -2.0), q_ned_frd=TILTED), "spawn"),
    (SpawnSpec("ground", rates_frd_rad_s=(0.0, 0.0, 1.0)), "spawn"),
])
def test_bad_attitude_or_rates_name_the_field(spawn: SpawnSpec, field: str) -> None:
    with pytest.raises(MockConfigError) as exc:
        MockConfig(vehicle="fast", spawn=spawn).validate()
    assert exc.value.field == field


def test_a_throw_text_of_the_wrong_length_is_refused() -> None:
    with pytest.raises(MockConfigError, match=r"throw:x,y,z,vx,vy,vz\[,qw,qx,qy,qz,p,q,r\]"):
        SpawnSpec.parse("throw:0,0,-2,0,0,0,1,0,0")
