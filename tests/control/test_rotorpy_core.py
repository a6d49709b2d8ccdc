"""The bare core API in rotorpy (an independent multirotor simulator with rotor drag, induced
inflow, translational lift and parasitic drag): ``PathFollower(path, speed)`` with
``update(p, v, time_s=t)``, its outputs mapped onto rotorpy's control abstractions:

- ``acceleration``: ``cmd_acc`` (rotorpy's own SE(3) attitude loop; ``cmd_acc`` is the
  mass-normalised thrust vector in the world frame, so gravity is added back);
- ``rates``: the core's default rates output (``tracker``: :class:`~pf_offboard.control.AttitudeTracker`
  ``.from_vehicle(VehicleModel.typical())``, as the app runs it; else the attitude-rate law
  :class:`~pf_offboard.control.AttitudeRateLaw` alone) closed on rotorpy's attitude, sent as
  ``cmd_ctbr`` (collective thrust in newtons, body rates in rotorpy's body frame).

Frames: rotorpy's world frame is z up (x, y taken as east, north: ENU) and its body frame has z
along the thrust, x forward (FLU); its quaternions are scalar-last (x, y, z, w), the core's
(w, x, y, z). Vehicle: rotorpy's AscTec Hummingbird (0.5 kg, rotor drag 0.45 1/s horizontally).
Its stock body-rate gain ``k_w`` = 1 1/s is a one-second rate loop no attitude loop can fly on;
``rates`` runs with ``k_w`` = 30 1/s (a 33 ms rate loop, like an autopilot's).

Judged from rotorpy's true state: the distance to the path and the speed along it from the true
position's central difference (+-0.1 s), from WINDOW_S on (after the start from hover on the path,
the start ramp and the integrators' transient). 100 Hz control and 100 Hz physics steps (rotorpy's own
Environment default; solve_ivp integrates within each step: at 200 Hz the figures agree to 0.3 cm and 0.4 cm/s).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pf_offboard import Path, PathFollower
from pf_offboard.control import AttitudeRateLaw, AttitudeTracker, Compensation, VehicleModel
from pf_offboard.path import Projector

pytest.importorskip("rotorpy", reason="rotorpy is not installed (pip install rotorpy; it is in the test extra)")
from rotorpy.vehicles.hummingbird_params import quad_params as HUMMINGBIRD  # noqa: E402
from rotorpy.vehicles.multirotor import Multirotor  # noqa: E402

G = 9.81
DT_PHYS_S = 0.01
DT_CTRL_S = 0.01
SPEED_M_S = 1.5
RATE_GAIN_1_S = 30.0  # rotorpy's k_w for rates output (stock: 1 1/s)
FLIGHT_S = 12.0
WINDOW_S = 6.0


def figure_eight() -> Path:
    pts = []
    for i in range(12):
        u = 2 * math.pi * i / 12
        s = math.sin(u)
        pts.append([2.4 * math.cos(u) / (1 + s * s), 2.4 * math.sin(u) * math.cos(u) / (1 + s * s), 2.0 + 0.4 * math.sin(u)])
    return Path.from_waypoints(pts, closed=True)


def fly(path: Path, follower: PathFollower, mode: str, seconds: float, wind=(0.0, 0.0, 0.0), tracker: bool = False):
    """The core in rotorpy's loop: (times, true positions) at the control steps."""
    params = dict(HUMMINGBIRD)
    if mode == "rates":
        params["k_w"] = RATE_GAIN_1_S
    mass = params["mass"]
    hover = math.sqrt(mass * G / (params["num_rotors"] * params["k_eta"]))
    wind = np.asarray(wind, float)
    state = {"x": np.array(path.eval(0.0).sigma, float), "v": np.zeros(3), "q": np.array([0.0, 0.0, 0.0, 1.0]),
             "w": np.zeros(3), "wind": wind, "rotor_speeds": np.full(params["num_rotors"], hover)}  # fmt: skip
    vehicle = Multirotor(params, initial_state=state, control_abstraction="cmd_acc" if mode == "acceleration" else "cmd_ctbr")
    # rates: the default output (identifies the rate loop; the reference over a fast one), or the law alone
    law = AttitudeRateLaw.from_vehicle(VehicleModel.typical())
    track = AttitudeTracker.from_vehicle(VehicleModel.typical()) if tracker else AttitudeTracker(law, None)
    n = int(round(DT_CTRL_S / DT_PHYS_S))
    times, positions = [], []
    control: dict[str, np.ndarray | float] = {}
    for k in range(int(round(seconds / DT_PHYS_S))):
        t = k * DT_PHYS_S
        if k % n == 0:
            cmd = follower.update(state["x"], state["v"], time_s=t)
            if mode == "acceleration":
                control = {"cmd_acc": np.asarray(cmd.acceleration) + np.array([0.0, 0.0, G])}
            else:
                qx, qy, qz, qw = state["q"]
                rates = track.update(cmd.attitude, (qw, qx, qy, qz), cmd.body_rates, time_s=t)
                control = {"cmd_thrust": mass * cmd.thrust, "cmd_w": np.asarray(rates, float)}
            times.append(t)
            positions.append(np.array(state["x"], float))
        state["wind"] = wind  # rotorpy's wind is part of the state (simulate() sets it each step)
        state = vehicle.step(state, control, DT_PHYS_S)
    return np.array(times), np.array(positions)


def measure(path: Path, t: np.ndarray, p: np.ndarray, speed: float, window_s: float):
    """(cross-track RMS m, speed error RMS m/s, mean speed error m/s) from window_s on."""
    proj = Projector(path)
    lam = [proj.update(x) for x in p]
    sig = np.array([path.eval(float(x)).sigma for x in lam])
    d1 = np.array([path.eval(float(x)).d1 for x in lam])
    tan = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    k = int(round(0.1 / DT_CTRL_S))
    vel = (p[2 * k:] - p[:-2 * k]) / (t[2 * k:] - t[:-2 * k])[:, None]
    e = np.einsum("ij,ij->i", vel, tan[k:-k]) - speed
    ct = np.linalg.norm(p - sig, axis=1)[k:-k]
    win = t[k:-k] >= window_s
    return float(np.sqrt(np.mean(ct[win] ** 2))), float(np.sqrt(np.mean(e[win] ** 2))), float(np.mean(e[win]))


def _run(follower_for, mode: str, wind_m_s: float, label: str, seconds: float = FLIGHT_S, window_s: float = WINDOW_S,
         tracker: bool = False):  # fmt: skip
    path = figure_eight()
    t, p = fly(path, follower_for(path), mode, seconds, wind=(wind_m_s, 0.0, 0.0), tracker=tracker)
    ct, rms, mean = measure(path, t, p, SPEED_M_S, window_s)
    print(f"rotorpy {label} {mode}, wind {wind_m_s:g} m/s, {window_s:g}-{seconds:g} s: cross-track RMS {100 * ct:.2f} cm, "
          f"speed error RMS {100 * rms:.2f} cm/s (mean {100 * mean:+.2f})")  # fmt: skip
    return ct, rms, mean


@pytest.mark.parametrize("wind_m_s,seconds,window_s", [(0.0, FLIGHT_S, WINDOW_S), (3.0, 22.0, 12.0)])
def test_defaults_meet_the_targets_with_acceleration_output(wind_m_s, seconds, window_s):
    """``PathFollower(path, speed)`` as is: it identifies the inner loop in flight (on by default,
    control/adaptive.py). rotorpy's dead time (about 0; the typical model says 0.1 s) and drag
    (0.44 against the 0.45 1/s rotorpy's rotor drag gives at hover) are adopted within 3-4 s in still
    air; in the wind (quadratic drag, translational lift) the candidates' scores part later (adopted
    after about 8 s), hence the later window. Measured: still 0.26 cm, 0.31 cm/s RMS; 3 m/s wind
    0.45 cm, mean -0.33 cm/s."""
    follower = None

    def make(path: Path) -> PathFollower:
        nonlocal follower
        follower = PathFollower(path, SPEED_M_S)
        return follower

    ct, rms, mean = _run(make, "acceleration", wind_m_s, "defaults", seconds, window_s)
    model = follower.compensator.identified  # type: ignore[union-attr]
    assert model is not None and model.delay_s <= 0.04  # it adopted a shorter dead time
    if wind_m_s == 0.0:
        assert ct <= 0.003 and rms <= 0.02
    else:
        assert ct <= 0.005 and abs(mean) <= 0.02


def test_without_the_identification_the_typical_model_misses_them():
    """The same flight with ``identify_online=False``: the typical model's 0.1 s dead time against
    rotorpy's ~0 leaves centimetres no gain removes (measured 2.2 cm, 2.8 cm/s): what the
    identification is for (the measure can fail)."""
    def follower(path: Path) -> PathFollower:
        return PathFollower(path, SPEED_M_S, compensation=Compensation(identify_online=False))

    ct, rms, mean = _run(follower, "acceleration", 0.0, "identify_online=False")
    assert ct > 0.01


@pytest.mark.parametrize("wind_m_s,seconds,window_s", [(0.0, FLIGHT_S, WINDOW_S), (3.0, 22.0, 12.0)])
def test_defaults_meet_the_targets_with_rates_output(wind_m_s, seconds, window_s):
    """``PathFollower(path, speed)`` and the default rates output,
    ``AttitudeTracker.from_vehicle(VehicleModel.typical())``: it identifies rotorpy's rate loop
    from the attitudes it sees (33 ms, no dead time: fast) within about a second and then answers
    through an attitude reference with the modelled lag; the follower's identification adopts the
    dead time as for acceleration output. Measured: still 0.27 cm, 0.40 cm/s RMS; 3 m/s wind
    0.44 cm, mean -0.32 cm/s."""
    follower = None

    def make(path: Path) -> PathFollower:
        nonlocal follower
        follower = PathFollower(path, SPEED_M_S)
        return follower

    ct, rms, mean = _run(make, "rates", wind_m_s, "defaults", seconds, window_s, tracker=True)
    assert follower.compensator.identified is not None  # type: ignore[union-attr]
    if wind_m_s == 0.0:
        assert ct <= 0.003 and rms <= 0.02
    else:
        assert ct <= 0.005 and abs(mean) <= 0.02


def test_the_law_alone_misses_them_with_rates_output():
    """Why the reference: the law alone (its tilt follows the demand as a 0.25 s first-order lag
    plus rotorpy's 33 ms rate loop, the compensator leads and inverts the modelled 0.1 s, and the
    identifier adopts no shorter dead time; the joint bank reads it late, 9-11 s, as a 0.13 s dead
    time with gain 0.93). Measured 1.36 cm, 2.3 cm/s (the measure can fail)."""
    follower = None

    def make(path: Path) -> PathFollower:
        nonlocal follower
        follower = PathFollower(path, SPEED_M_S)
        return follower

    ct, rms, mean = _run(make, "rates", 0.0, "the law alone")
    model = follower.compensator.identified  # type: ignore[union-attr]
    assert model is None or (model.delay_s > 0.1 and model.adopted_at_s >= 6.0)  # never a shorter dead time
    assert ct > 0.01


def test_the_papers_law_flies_slow_in_the_wind():
    """The paper's law as published (no disturbance rejection) in the same 3 m/s wind: the rotor
    drag leaves a speed bias the default removes (the measure can fail)."""
    import warnings

    def follower(path: Path) -> PathFollower:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return PathFollower.paper(path, SPEED_M_S)

    ct, rms, mean = _run(follower, "acceleration", 3.0, "paper's law")
    assert abs(mean) > 0.02 or ct > 0.01
