"""The shipped path configs: schema keys, and the geometry promised for each path."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from pathtools import CONFIGS, config_waypoints
from scipy.spatial import cKDTree

NAMES = ["paper.yaml", "figure8.yaml", "helix.yaml", "straight.yaml", "racetrack.yaml"]
TOP_KEYS = {"path", "speed_m_s", "gains", "yaw", "limits", "flight"}


def _samples(path, n: int = 6000) -> tuple[np.ndarray, np.ndarray]:
    lam = np.linspace(0.0, path.lam_max, n, endpoint=not path.closed)
    return lam, path._spline.eval_vectorised(lam, 0)


def _param_gap(path, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    g = np.abs(a - b)
    return np.minimum(g, path.lam_max - g) if path.closed else g


def _close_pairs(path, radius: float, min_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample pairs closer than ``radius`` in space but ``min_gap`` apart along the path."""
    lam, pts = _samples(path, 2000)
    pairs = cKDTree(pts).query_pairs(radius, output_type="ndarray")
    if len(pairs) == 0:
        return np.empty(0), np.empty(0)
    a, b = lam[pairs[:, 0]], lam[pairs[:, 1]]
    keep = _param_gap(path, a, b) > min_gap
    return a[keep], b[keep]


@pytest.mark.parametrize("name", NAMES)
def test_schema_keys(name):
    raw = yaml.safe_load((CONFIGS / name).read_text())
    # vehicle / compensation: the identified inner loop and its compensation (issue 8), optional
    # speed_profile / feedforward (issue 10), optional
    # gains: optional (absent = auto, the default: derived from the vehicle model)
    assert TOP_KEYS - {"gains"} <= set(raw) <= TOP_KEYS | {"vehicle", "compensation", "speed_profile", "feedforward"}
    if raw.get("gains", "auto") == "auto":
        raw["gains"] = {"transversal": {"bandwidth_hz": 0, "damping": 0}, "tangential": {"bandwidth_hz": 0, "damping": 0}}
    assert set(raw["path"]) == {"frame", "closed", "moving_frame", "waypoints"}
    assert raw["path"]["frame"] in ("enu", "ned")
    assert raw["path"]["moving_frame"] in ("auto", "frenet", "rmf")
    assert set(raw["gains"]) == {"transversal", "tangential"}
    for g in raw["gains"].values():
        assert set(g) == {"bandwidth_hz", "damping"}
    assert raw["yaw"]["mode"] in ("constant", "tangent", "table")
    # max_tangential_accel_m_s2: null where the speed loop's correction is left unbounded
    base = {"max_tilt_deg", "min_thrust_m_s2", "max_thrust_m_s2", "max_approach_speed_m_s"}
    assert base <= set(raw["limits"]) <= base | {"max_tangential_accel_m_s2"}
    # velocity_correction_s: paper.yaml pins it off (the paper's exact state)
    assert {"output_mode", "setpoint_rate_hz"} <= set(raw["flight"]) <= {"output_mode", "setpoint_rate_hz", "velocity_correction_s"}


def test_paper_config_values():
    raw = yaml.safe_load((CONFIGS / "paper.yaml").read_text())
    assert raw["speed_m_s"] == -1.5
    assert raw["gains"]["transversal"] == {"bandwidth_hz": 6.0, "damping": 0.7}
    assert raw["gains"]["tangential"] == {"bandwidth_hz": 4.0, "damping": 0.8}
    assert raw["yaw"]["mode"] == "constant" and raw["yaw"]["yaw_deg"] == 0.0
    assert raw["flight"]["velocity_correction_s"] is None
    assert raw["path"]["closed"] is True and raw["path"]["frame"] == "enu"


def test_paper_path_has_seven_waypoints_one_repeated(paper):
    w = paper.waypoints
    assert len(w) == 7
    same = [(i, j) for i in range(7) for j in range(i + 1, 7) if np.allclose(w[i], w[j])]
    assert len(same) == 1
    i, j = same[0]
    assert 1 < j - i < 6  # not neighbours, also not across the closing seam


def test_paper_path_fits_the_arena(paper):
    # The whole spline, not just the way-points: x, y in [-3, 3], z in [1, 4].
    _, pts = _samples(paper, 20000)
    assert np.all(np.abs(pts[:, :2]) <= 3.0)
    assert np.all((pts[:, 2] >= 1.0) & (pts[:, 2] <= 4.0))


def test_paper_path_is_gentle_and_passes_the_pf1_start(paper):
    lam = np.linspace(0, paper.lam_max, 3000, endpoint=False)
    kappa = np.array([paper.curvature(x) for x in lam])
    assert kappa.max() <= 1.5
    _, pts = _samples(paper, 20000)
    assert np.min(np.linalg.norm(pts - np.array([0.0, -1.5, 2.0]), axis=1)) < 0.01


@pytest.mark.parametrize("name", ["paper", "figure8"])
def test_exactly_one_self_intersection(name, request):
    path = request.getfixturevalue(name)
    knots = path._spline.knots
    w = path.waypoints
    rep = [(i, j) for i in range(len(w)) for j in range(i + 1, len(w)) if np.allclose(w[i], w[j])]
    assert len(rep) == 1
    ca, cb = knots[rep[0][0]], knots[rep[0][1]]
    # Parts of the path more than 1.5 m apart along it come within 30 cm of each other only
    # around the crossing (both within 0.5 m of the repeated way-point's two parameters).
    a, b = _close_pairs(path, 0.3, 1.5)
    assert len(a) > 0
    near_a = np.minimum(_param_gap(path, a, ca), _param_gap(path, a, cb))
    near_b = np.minimum(_param_gap(path, b, ca), _param_gap(path, b, cb))
    assert np.all(np.maximum(near_a, near_b) < 0.5)
    # Away from the crossing the path keeps >= 0.8 m clearance from itself (no second crossing,
    # no near-miss that could confuse the projection).
    lam, pts = _samples(path, 1500)
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    gap = _param_gap(path, lam[:, None], lam[None, :])
    near_c = np.minimum(_param_gap(path, lam, ca), _param_gap(path, lam, cb)) < 1.0
    mask = (gap > 1.5) & ~(near_c[:, None] & near_c[None, :])
    assert d[mask].min() > 0.8  # paper 0.85 m, figure8 0.94 m (docs/paths.md)


def test_helix_and_straight(helix, straight):
    assert not helix.closed and helix.frame_kind == "frenet"
    assert 0.4 < helix.kappa_min <= helix.kappa_max < 0.8
    assert not straight.closed and straight.frame_kind == "rmf"
    assert straight.kappa_max < 1e-9
    assert len(_close_pairs(helix, 0.3, 1.5)[0]) == 0  # turns are 1 m apart: no crossing


def test_racetrack_runs_are_nearly_straight(racetrack):
    pts, _, _ = config_waypoints("racetrack.yaml")
    _, s = _samples(racetrack, 20000)
    run = (np.abs(s[:, 0]) <= 1.275) & (s[:, 1] < 0)
    assert np.max(np.abs(s[run, 1] + 1.5)) < 0.03
    assert racetrack.kappa_min < 1e-2  # inflections: rmf territory


@pytest.mark.parametrize("name", NAMES)
def test_every_config_builds_and_stays_in_the_arena(name):
    from pf_offboard.path import Path

    pts, closed, frame = config_waypoints(name)
    path = Path.from_waypoints(pts, closed=closed, frame=frame)
    _, s = _samples(path, 5000)
    assert np.all(np.abs(s[:, :2]) <= 3.0) and np.all((s[:, 2] >= 1.0) & (s[:, 2] <= 4.0))
    assert path.kappa_max <= 1.5
