"""Which bound limits the speed profile's planned mean speed on a config's path.

    python scripts/profile_bounds.py tests/real_sitl/configs/figure8-tilted.yaml --max-speed 3

Prints the planned lap (or start-to-end) time and mean speed with the config's speed profile
(or ``{max_speed_m_s: --max-speed}``) and vehicle model, beside the point-mass time under the
same acceleration limits (no jerk, no body-rate bound), the same with the whole share of the
limits (accel_share 1, ideal inner loop), the vehicle's bound (:func:`vehicle_lap_time_bound`),
the profile with each bound relaxed in turn (the jerk: the spec's and the inner loop's
``response_jerk_m_s3`` together), and the share of the time each constraint is active on the grid
(within 1 %).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from pf_offboard import PathFollower
from pf_offboard.config import load_config
from pf_offboard.control.profile import (SpeedProfile, SpeedProfileSpec, _Feasible, _geometry, _passes, _tilt_rate,
                                         _upper_bound, point_mass_lap_time, response_share, vehicle_lap_time_bound)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("--max-speed", type=float, default=3.0, help="used when the config has no speed_profile (m/s)")
    args = ap.parse_args()
    cfg = load_config(args.config)
    spec = cfg.speed_profile or SpeedProfileSpec(max_speed_m_s=args.max_speed)
    f = PathFollower.from_config(dataclasses.replace(cfg, speed_profile=spec))
    path, lim, prof = f.path, f.limits, f.profile
    direction, r, jr, L = prof.direction, prof.response_s, prof.jerk_response_s, path.length_m
    share = response_share(spec.accel_share, r)

    def line(label: str, t: float) -> None:
        print(f"  {label:64s} {t:6.2f} s  {L / t:5.2f} m/s")

    print(f"{args.config}: {L:.2f} m, {'closed' if path.closed else 'open'}, max {spec.max_speed_m_s:g} m/s, "
          f"share {spec.accel_share:g} x inner loop ({r:.2f} s) = {share:.3f}, tilt {lim.max_tilt_deg:g} deg, "
          f"jerk {spec.max_tangential_jerk_m_s3:g} (planned with {prof.jerk_bound_m_s3:.1f}) m/s^3, "
          f"body rate {spec.max_body_rate_rad_s:g} rad/s, tangential accel {spec.max_tangential_accel_m_s2:g} m/s^2")  # fmt: skip
    line("planned (all bounds)", prof.stats.travel_time_s)
    line("point mass at the profile's share (no jerk / rate bound)", prof.stats.point_mass_time_s)
    line("point mass at accel_share 1, ideal inner loop", point_mass_lap_time(path, dataclasses.replace(spec, accel_share=1.0), lim, direction))
    line("vehicle bound (whole thrust set, no tangential-accel cap)", vehicle_lap_time_bound(path, lim, spec.max_speed_m_s, direction))
    for label, kw, jr2 in (("jerk x2", {"max_tangential_jerk_m_s3": 2 * spec.max_tangential_jerk_m_s3}, jr / 2),
                           ("body rate x2", {"max_body_rate_rad_s": 2 * spec.max_body_rate_rad_s}, jr),
                           ("jerk x2 and body rate x2", {"max_tangential_jerk_m_s3": 2 * spec.max_tangential_jerk_m_s3,
                                                         "max_body_rate_rad_s": 2 * spec.max_body_rate_rad_s}, jr / 2),
                           ("tangential accel x2", {"max_tangential_accel_m_s2": 2 * spec.max_tangential_accel_m_s2}, jr),
                           ("accel_share 1", {"accel_share": 1.0}, jr)):  # fmt: skip
        s2 = dataclasses.replace(spec, **kw)
        line(f"planned, {label}", SpeedProfile(path, s2, lim, direction, r, jerk_response_s=jr2).stats.travel_time_s)
    # each bound relaxed in turn to (about) no bound, then every bound but the share relaxed, then
    # the share at its whole (ideal inner loop) with each other bound relaxed in turn
    free = {"jerk": {"max_tangential_jerk_m_s3": 1000.0, "max_body_rate_rad_s": 20.0},
            "body rate": {"max_body_rate_rad_s": 20.0},
            "tangential accel": {"max_tangential_accel_m_s2": 50.0}}
    print("  each bound relaxed in turn (jerk: with the body rate too, which caps the jerk planned):")
    for share_label, share_kw, resp, jresp in (("at the profile's share", {}, r, jr),
                                               ("at the whole share (1, ideal loop)", {"accel_share": 1.0}, 0.0, 0.0)):  # fmt: skip
        line(f"{share_label}: all bounds", SpeedProfile(path, dataclasses.replace(spec, **share_kw), lim, direction, resp, jerk_response_s=jresp).stats.travel_time_s)
        for label, kw in free.items():
            s2 = dataclasses.replace(spec, **share_kw, **kw)
            jr2 = 0.0 if label == "jerk" else jresp
            line(f"{share_label}: no {label} bound", SpeedProfile(path, s2, lim, direction, resp, jerk_response_s=jr2).stats.travel_time_s)
        s2 = dataclasses.replace(spec, **share_kw, **free["jerk"], **free["tangential accel"])
        line(f"{share_label}: none but the share", SpeedProfile(path, s2, lim, direction, resp, jerk_response_s=0.0).stats.travel_time_s)
    # which constraint is active where (travel order, as the profile's grid)
    geo = _geometry(path, spec, direction)
    feas = _Feasible(geo, lim, spec, r)
    ub = _upper_bound(geo, feas, bool(path.closed))
    pm = _passes(ub, feas, geo.ds, bool(path.closed))
    b = prof._b_travel
    v = np.sqrt(np.maximum(b, 0.0))
    moving = v > 0.05
    dt = np.where(moving, geo.ds / np.maximum(v, 1e-9), 0.0)
    near = lambda x: b >= (1.0 - 0.01) * x  # noqa: E731
    rate = _tilt_rate(b, geo, bool(path.closed))
    classes = {"max speed / table": near(geo.cap_b), "thrust set (share of the limits)": near(ub),
               "point-mass passes (accel / braking)": near(pm), "body rate": rate >= 0.97 * spec.max_body_rate_rad_s}  # fmt: skip
    left = moving.copy()
    a_t = np.gradient(b, geo.ds) / 2.0
    f = geo.s_ss * b[:, None] + geo.t_dir * a_t[:, None]
    f[:, 2] += 9.80665
    tilt = np.degrees(np.arctan2(np.linalg.norm(f[:, :2], axis=1), f[:, 2]))
    print(f"  planned reference tilt: max {tilt.max():.1f} deg, time-weighted mean {np.sum(tilt * dt) / dt.sum():.1f} deg "
          f"(limit {lim.max_tilt_deg:g}); max tilt rate {prof.stats.max_tilt_rate_rad_s:.2f} rad/s")
    print("  time share, active constraint (first that holds):")
    for name, m in classes.items():
        m = m & left
        left &= ~m
        print(f"    {name:40s} {100 * dt[m].sum() / dt.sum():5.1f} %")
    print(f"    {'below them all (jerk smoothing)':40s} {100 * dt[left].sum() / dt.sum():5.1f} %")


if __name__ == "__main__":
    main()
