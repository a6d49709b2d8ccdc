"""The companion app: ``pf-offboard fly`` and ``pf-offboard demo`` (see docs/app.md, docs/ARCHITECTURE.md).

estimator (MAVLink state → core frames) → core → encoder (one per output mode), wired by the
pure :mod:`~pf_offboard.app.pipeline`. One flight's phase sequence is
:mod:`~pf_offboard.app.flight`; it wires :mod:`~pf_offboard.app.commands` (commands confirmed by
ACK / HEARTBEAT), :mod:`~pf_offboard.app.dialects` (PX4 / ArduPilot), :mod:`~pf_offboard.app.supervisor`
(envelope, watchdogs) and :mod:`~pf_offboard.app.status`; :mod:`~pf_offboard.app.link` owns the
MAVLink connection. Modules are imported where used (``pf-offboard --help`` stays fast).
"""
