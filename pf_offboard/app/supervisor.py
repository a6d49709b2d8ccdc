"""The safety supervisor: feeds the envelope monitor (:mod:`pf_offboard.safety`, pure) every state
sample and every setpoint before it leaves, and runs the watchdogs (HEARTBEAT silence, stale
state). It decides nothing itself and sends nothing: it returns verdicts and reasons, and the
flight (:mod:`pf_offboard.app.flight`) acts on them — safing (safe setpoint only, safe mode
requested until confirmed), exit 5 (envelope) / 6 (crash) / 3 (link)."""

from __future__ import annotations

from typing import Any

import numpy as np

from pf_offboard.app.estimator import StateEstimate, flight_clock_s
from pf_offboard.app.pipeline import Step
from pf_offboard.safety import EnvelopeMonitor, SafetyConfig, Verdict, VehicleSample


class SafetySupervisor:
    """``monitor`` None: no envelope (the watchdogs still run with ``SafetyConfig(enabled=False)``)."""

    def __init__(self, monitor: EnvelopeMonitor | None, output_mode: str) -> None:
        self.monitor = monitor
        self.config = monitor.config if monitor is not None else SafetyConfig(enabled=False)
        self.output_mode = output_mode
        self.landed_state: int | None = None  # EXTENDED_SYS_STATE
        self.breach: Verdict | None = None  # the first breach, and when (vehicle time)
        self.breach_time_s: float | None = None
        self._activation_checked = False

    def on_extended_sys_state(self, msg: Any) -> None:
        self.landed_state = int(msg.landed_state)

    def record(self, verdict: Verdict, est: StateEstimate | None) -> bool:
        """Keep the first breach; False if one was already recorded."""
        if self.breach is not None:
            return False
        self.breach, self.breach_time_s = verdict, (est.time_s if est is not None else None)
        return True

    def sample(self, est: StateEstimate, step: Step | None, armed: bool, following: bool) -> VehicleSample:
        cmd = step.command if step is not None else None
        rates = self.output_mode == "rates"
        return VehicleSample(
            # the monitor's durations (no-progress window, attitude-error time) on the estimator's
            # continuous clock: an autopilot clock jump is not 30 s without progress
            time_s=flight_clock_s(est),
            position_enu_m=est.position_enu_m,
            velocity_enu_m_s=est.velocity_enu_m_s,
            q_enu_flu=est.q_enu_flu,
            armed=armed,
            landed_state=self.landed_state,
            cross_track_m=float(cmd.cross_track_m) if cmd is not None else None,
            eta1_m=float(cmd.state.eta1) if cmd is not None else None,
            # our own attitude loop is judged only once the vehicle flies it (not while engaging)
            q_cmd_enu_flu=np.asarray(cmd.attitude, dtype=float) if (cmd is not None and rates and following) else None,
            rates_flu_rad_s=est.rates_flu_rad_s,
            q_demand_enu_flu=np.asarray(cmd.attitude, dtype=float) if cmd is not None else None,
        )

    def check_step(self, step: Step, armed: bool, following: bool) -> Verdict:
        """The envelope monitor on one controller step: the state it came from, then the setpoint
        itself, before it leaves. Activation (first active step) has its own distance limit."""
        monitor = self.monitor
        if monitor is None:
            return Verdict()
        sample = self.sample(step.estimate, step, armed, following)
        if step.estimator_reset_enu_m is not None:
            # the estimate jumped: following on would fly the vehicle by the jump (the path moved
            # under it; a 1.6 m vertical reset flew one to 3 cm above the ground)
            verdict = monitor.check_estimator(reset_enu_m=step.estimator_reset_enu_m)
            if verdict.breach:
                return verdict
        if not self._activation_checked:
            self._activation_checked = True
            verdict = monitor.check_activation(sample)
            if verdict.breach:
                return verdict
        verdict = monitor.check_state(sample, following=True)
        if verdict.breach or step.command is None or step.encoded.replaced:
            return verdict  # (a replaced step already carries the hold, not the command)
        mode, cmd = self.output_mode, step.command
        return monitor.check_setpoint(
            q_cmd_enu_flu=cmd.attitude if mode != "acceleration" else None,
            rates_frd_rad_s=step.encoded.rates_frd_rad_s if mode == "rates" else None,
            accel_cmd_enu_m_s2=cmd.acceleration if mode == "acceleration" else None,
        )

    def check_takeoff_state(self, est: StateEstimate, armed: bool) -> Verdict:
        """While climbing (armed): tilt, disarm."""
        if self.monitor is None:
            return Verdict()
        return self.monitor.check_state(self.sample(est, None, armed, False), following=False)

    def check_climb(self, target_enu_m: Any) -> Verdict:
        """A take-off position setpoint (above the vehicle), raised to the fence floor."""
        if self.monitor is None:
            return Verdict()
        floor = self.monitor.fence.floor_m
        target = np.array([target_enu_m[0], target_enu_m[1], max(float(target_enu_m[2]), floor)])
        return self.monitor.check_setpoint(position_target_enu_m=target)

    def heartbeat_silence(self, silent_s: float) -> str:
        """Why the autopilot's HEARTBEAT has been silent too long ("" if not)."""
        limit = self.config.heartbeat_timeout_s
        if silent_s > limit:
            return f"no HEARTBEAT from the autopilot for {silent_s:.2f} s (safety.heartbeat_timeout_s {limit:g}): mode unknown"
        return ""

    @staticmethod
    def stale_state(age_s: float, timeout_s: float) -> str:
        """Why the state is too old to fly on ("" if it is not)."""
        if age_s > timeout_s:
            return f"state went stale: no fresh state for {age_s:.2f} s (state_timeout_s {timeout_s:g})"
        return ""


__all__ = ["SafetySupervisor"]
