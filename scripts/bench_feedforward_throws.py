#!/usr/bin/env python3
"""Body-rate feed-forward variants on thrown starts (a benchmark, not a test).

``sim`` flights (in process, the mock autopilot) with the realistic presets ``px4-sih`` (PX4
profile) and ``arducopter`` (ArduPilot profile), the paper path at +1.5 m/s with the typical vehicle
model (no gains / vehicle sections: auto gains; configs/px4-sih.yaml is identified for acceleration
setpoints, not attitude), in attitude and rates output, thrown from three states, with:

- ``lead``: the inner-loop compensation on (the default), whose lag lead replaces the roll/pitch
  body-rate feed-forward (the command carries the yaw rate only);
- ``on_path`` / ``any_state``: compensation off, the paper's feed-forward or the any-state one
  (which needs compensation off).

For each run,
over the first CONVERGENCE_S after activation: RMS attitude (tilt) tracking error (angle between the
commanded and the vehicle's body z, i.e. thrust direction, the vehicle's from the .tlog's
ATTITUDE_QUATERNION; the heading is left out: it converges on its own, slower) and RMS cross-track
error, and the convergence time of the flight summary (< 5 cm, < 0.1 m/s).

    PYTHONPATH=. python scripts/bench_feedforward_throws.py
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from pf_offboard import frames  # noqa: E402
from pf_offboard.logs.tlog import read_tlog  # noqa: E402
from pf_offboard.sim.flight import SimSpec, simulate  # noqa: E402

CONVERGENCE_S = 3.0
THROWS = ((1.0, -2.0, 1.2, 0.5, 1.0, 5.0), (-1.0, -1.0, 1.0, 2.0, -1.0, 5.5), (0.5, 0.5, 1.2, -1.5, 1.5, 5.0))


def _config(dst: Path, base: str, variant: str, typical: bool) -> Path:
    raw = yaml.safe_load((ROOT / "configs" / base).read_text())
    if typical:  # no gains / vehicle / compensation sections: auto gains from the typical model
        for key in ("gains", "vehicle", "compensation"):
            raw.pop(key, None)
    if variant == "lead":
        raw["feedforward"] = "on_path"
    else:
        raw["feedforward"] = variant
        raw["compensation"] = {"enabled": False}
    raw["speed_m_s"] = 1.5
    dst.write_text(yaml.safe_dump(raw, sort_keys=False))
    return dst


def _body_z(q: np.ndarray) -> np.ndarray:
    """Body z axis (world ENU) of a (w, x, y, z) body FLU -> world ENU quaternion."""
    w, x, y, z = q
    return np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])


def _run(config: Path, vehicle: str, autopilot: str, output: str, throw: tuple[float, ...], out: Path) -> tuple[float, float, float | None]:
    spec = SimSpec(throw_enu=throw, throw_height_m=2.0, autopilot=autopilot, vehicle=vehicle, output_mode=output,
                   duration_s=8.0, seed=3, epoch_unix_s=1.78e9, name="t")  # fmt: skip
    res = simulate(str(config), spec, out)
    rec = [r for r in res.records if r.active]
    t0 = rec[0].time_s
    meas_t, meas_q = [], []
    for e in read_tlog(res.paths.tlog):
        m = e.message
        if e.direction == "in" and m.get_type() == "ATTITUDE_QUATERNION":
            meas_t.append(m.time_boot_ms / 1000.0)
            meas_q.append(frames.quat_ned_frd_to_enu_flu(np.array([m.q1, m.q2, m.q3, m.q4])))
    meas_t_a = np.array(meas_t)
    att, ct = [], []
    for r in rec:
        if r.time_s - t0 > CONVERGENCE_S:
            break
        k = int(np.searchsorted(meas_t_a, r.time_s + 1e-6)) - 1
        if k < 0:
            continue
        att.append(math.acos(max(-1.0, min(1.0, float(_body_z(meas_q[k]) @ _body_z(np.asarray(r.q_cmd_enu_flu)))))))
        ct.append(r.cross_track_m)
    conv = res.summary.convergence_time_s
    return math.degrees(math.sqrt(np.mean(np.square(att)))), math.sqrt(np.mean(np.square(ct))), conv


def main() -> None:
    cases = (("px4-sih", "px4", "paper.yaml", True), ("arducopter", "ardupilot", "paper.yaml", True))
    print(f"| vehicle | output | feed-forward | tilt error RMS, first {CONVERGENCE_S:g} s (deg) | cross-track RMS, first {CONVERGENCE_S:g} s (m) | converged after (s) |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for vehicle, autopilot, base, typical in cases:
            for output in ("attitude", "rates"):
                for ff in ("lead", "on_path", "any_state"):
                    cfg = _config(out / f"{vehicle}-{ff}.yaml", base, ff, typical)
                    runs = [_run(cfg, vehicle, autopilot, output, th, out) for th in THROWS]
                    att = [r[0] for r in runs]
                    ct = [r[1] for r in runs]
                    conv = [r[2] for r in runs]
                    conv_s = "/".join("–" if c is None else f"{c:.1f}" for c in conv)
                    print(f"| {vehicle} | {output} | {ff} | {np.mean(att):.1f} ({'/'.join(f'{a:.1f}' for a in att)}) | "
                          f"{np.mean(ct):.3f} ({'/'.join(f'{c:.3f}' for c in ct)}) | {conv_s} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
