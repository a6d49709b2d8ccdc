"""The companion app: ``pf-offboard fly`` and ``pf-offboard demo`` (see docs/app.md).

estimator (MAVLink state → core frames) → core → encoder (one per output mode), wired by the
pure :mod:`~pf_offboard.app.pipeline`; :mod:`~pf_offboard.app.bridge` owns activation, watchdog
and mode logic; :mod:`~pf_offboard.app.link` the MAVLink connection. Modules are imported where
used (``pf-offboard --help`` stays fast).
"""
