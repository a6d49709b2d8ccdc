"""A :class:`~sitl_mock.config.MockConfig` as ``sitl-mock`` command-line flags (to run the mock in
a subprocess: :func:`sitl_mock.runner.spawn`). The inverse is :func:`sitl_mock.cli.config_from_args`."""

from __future__ import annotations

from sitl_mock.config import MockConfig


def config_to_args(config: MockConfig) -> list[str]:
    """The flags that reproduce ``config`` (used to run the mock in a subprocess)."""
    c, f = config, config.faults
    args = ["--profile", c.profile, "--vehicle", c.vehicle, "--seed", str(c.seed),
            "--ekf-delay", repr(c.ekf_ready_delay_s),
            "--home=" + ",".join(repr(v) for v in (c.home_lat_deg, c.home_lon_deg, c.home_alt_m))]  # "=": a south latitude starts with "-"
    if any(v != 0.0 for v in c.wind_ned_m_s):
        args += ["--wind", ",".join(repr(float(v)) for v in c.wind_ned_m_s)]
    for name, value in c.params:
        args += ["--param", f"{name}={float(value)!r}"]
    if c.wind_gust_std_m_s > 0.0:
        args += ["--wind-gusts", f"{c.wind_gust_std_m_s!r},{c.wind_gust_time_constant_s!r}"]
    if c.udp_local_port is None:
        args.append("--no-udp")
    else:
        args += ["--udp-local", str(c.udp_local_port)]
        args += ["--udp-remote", f"{c.udp_remote[0]}:{c.udp_remote[1]}" if c.udp_remote else "none"]
    if c.tcp_port is None:
        args.append("--no-tcp")
    else:
        args += ["--tcp", str(c.tcp_port)]
    if c.lockstep:
        args += ["--lockstep", "--lockstep-dt", repr(c.lockstep_dt_s)]
    else:
        args += ["--speed", repr(c.speed)]
    args += ["--spawn", c.spawn.args()]
    args += ["--loss", repr(f.loss * 100), "--duplicate", repr(f.duplicate * 100), "--corrupt", repr(f.corrupt * 100),
             "--latency", repr(f.latency_s * 1000), "--jitter", repr(f.jitter_s * 1000)]
    if f.blackout_s:
        args += ["--blackout", ",".join(repr(v) for v in f.blackout_s)]
    if f.windows_from_offboard:
        args.append("--windows-from-offboard")
    if f.loss_from_offboard:
        args.append("--loss-from-offboard")
    if f.estimator_reset_at_s is not None:
        args += ["--estimator-reset", ",".join(repr(v) for v in (f.estimator_reset_at_s, *f.estimator_reset_ned_m))]
    if f.takeover_at_s is not None:
        args += ["--takeover", repr(f.takeover_at_s) + (f",{f.takeover_mode}" if f.takeover_mode else "")]
    if f.gust_at_s is not None:
        args += ["--gust", ",".join(repr(v) for v in (f.gust_at_s, *f.gust_ned_m_s, f.gust_duration_s))]
    if c.duration_s is not None:
        args += ["--duration", repr(c.duration_s)]
    if c.truth_log:
        args += ["--truth-log", c.truth_log]
    if c.signing_key_file:
        args += ["--signing-key", c.signing_key_file]
    return args


