"""pf_offboard.logs.truth: estimate vs simulator ground truth from a flight's logs.

A short `sim` flight on the ideal preset gives a real .tlog / .csv pair; HIL_STATE_QUATERNION
records are added after each LOCAL_POSITION_NED with a known estimator error (a constant EKF
origin offset plus a sinusoid per axis). The report must recover that error, remove the offset
and measure the truth's cross-track error where the vehicle really was.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from pf_offboard import frames
from pf_offboard.errors import InputError
from pf_offboard.geo import GeoPoint, enu_to_geodetic
from pf_offboard.logs.tlog import TlogWriter, iter_tlog
from pf_offboard.logs.truth import judge
from pf_offboard.sim.flight import SimSpec, simulate

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "paper.yaml"
ORIGIN = GeoPoint(47.397742, 8.545594, 488.0)
OFFSET_NED_M = np.array([0.4, -0.3, 0.2])  # EKF origin vs truth: not an error
AMPLITUDE_NED_M = np.array([0.05, 0.02, 0.03])  # the estimator's error, sinusoid of 1 Hz


def _error_ned(t_s: float) -> np.ndarray:
    return AMPLITUDE_NED_M * math.sin(2.0 * math.pi * t_s)


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("truth")
    simulate(CONFIG, SimSpec(vehicle="fast", duration_s=6.0, epoch_unix_s=1.7e9), out)
    tlog = next(out.glob("*.tlog"))
    entries = list(iter_tlog(tlog))
    sender = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    with TlogWriter.open(tlog) as w:
        for e in entries:
            w.write(e.frame, e.time_unix_s)
            m = e.message
            if e.direction == "in" and m.get_type() == "LOCAL_POSITION_NED":
                # truth = estimate - offset - error (the estimate is truth + offset + error)
                truth_ned = np.array([m.x, m.y, m.z]) - OFFSET_NED_M - _error_ned(m.time_boot_ms * 1e-3)
                lat, lon, alt = enu_to_geodetic(frames.ned_to_enu(truth_ned)[None, :], ORIGIN)[0]
                hil = mavlink.MAVLink_hil_state_quaternion_message(
                    0, [1, 0, 0, 0], 0, 0, 0, round(lat * 1e7), round(lon * 1e7), round(alt * 1e3), 0, 0, 0, 0, 0, 0, 0, 0)
                w.write(hil.pack(sender), e.time_unix_s)
    return out


def test_recovers_the_estimator_error_and_removes_the_origin_offset(flight: Path) -> None:
    r = judge(flight, str(CONFIG), skip_s=2.0)
    assert r.samples > 300
    expected_rms = AMPLITUDE_NED_M / math.sqrt(2.0)
    # lat/lon quantised to 1e-7 deg (~1 cm): the RMS is recovered to a few mm
    np.testing.assert_allclose(r.estimate_error_rms_ned_m, expected_rms, atol=4e-3)
    np.testing.assert_allclose(r.estimate_error_p2p_ned_m, 2.0 * AMPLITUDE_NED_M, atol=1.5e-2)


def test_truth_cross_track_sees_the_error_the_estimate_hides(flight: Path) -> None:
    r = judge(flight, str(CONFIG), skip_s=2.0)
    # the ideal vehicle keeps its estimate on the path (< 1 mm); the truth is off by the error
    assert r.cross_track_rms_estimate_m < 1e-3
    assert 0.01 < r.cross_track_rms_truth_m < float(np.linalg.norm(AMPLITUDE_NED_M))


def test_a_log_without_truth_is_one_clear_error(tmp_path: Path) -> None:
    simulate(CONFIG, SimSpec(vehicle="fast", duration_s=1.5), tmp_path)
    with pytest.raises(InputError, match="no HIL_STATE_QUATERNION"):
        judge(tmp_path, str(CONFIG))
