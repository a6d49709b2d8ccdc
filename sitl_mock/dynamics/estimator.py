"""EKF-like error of the *reported* position and velocity (world NED).

A real autopilot reports its estimator's output, not the truth. On PX4 SIH (GPS white noise
0.2 m horizontal / 0.5 m vertical, EKF2) the reported position wanders 0.4–0.9 m peak-to-peak
while the vehicle holds, the reported velocity carries ~2 cm/s of high-frequency noise, and the
position moves in small steps (mm) when a GPS sample is fused. This module models exactly that
error — what the truth would have to be corrected by to give the report — as:

- a **wander**: a slowly varying velocity error e_v (first-order Gauss–Markov, std
  ``wander_velocity_std_*``, time constant ``wander_velocity_time_constant_s``) integrated with a
  leak (``wander_position_time_constant_s``) into a position error e_p. The reported position
  and velocity stay consistent (e_v is what makes e_p move), as an EKF's are.
- **fusion steps**: the error is updated only at the GPS fusion rate ``fusion_rate_hz`` and held
  in between, plus white noise drawn at every fusion (``position_white_std_*``,
  ``velocity_white_std_*``).
- a **velocity bias** (``velocity_bias_std_*``, first-order Gauss–Markov with time constant
  ``velocity_bias_time_constant_s``) on the reported velocity only, *not* integrated into the
  position: the reported velocity then disagrees with the reported position's derivative, as
  EKF2's does on PX4 SIH (measured against ground truth: velocity 10–40 cm/s RMS off its own
  position's derivative, drifting over ~10 s, while that derivative follows the true velocity).
  Drawn from a generator spawned from the one given, so the other draws do not change with it.
- a **smoothing** (``smoothing_time_constant_s``, 0 = off): the wander velocity and the bias pass
  one more first-order low-pass before they are reported (and, for the wander, integrated), as
  EKF2's own filtering of the GPS noise does. On PX4 SIH the reported velocity's error falls off
  faster than first order above ~0.3 Hz (against ground truth: 12 cm/s at 0.1–0.3 Hz, 3.9 at
  0.3–0.7 Hz, 1.4 at 0.7–1.2 Hz per horizontal axis), which a single Gauss–Markov stage cannot
  give without too much error at 1–5 Hz.
- an **output predictor** (``output_time_constant_s``, 0 = off): the reported *position* error
  follows the fused one through a first-order lag instead of stepping at each fusion, as EKF2's
  output predictor applies its corrections over EKF2_TAU_POS rather than at once. Without it the
  reported position jumps every 0.1 s and its derivative is far off the reported velocity at high
  frequency: Δposition/Δt − velocity per horizontal axis was 3.8 / 8.8 / 13.9 cm/s RMS at 3–5 /
  5–10 / 10–25 Hz on the mock, against 1.0 / 2.6 / 1.5 on the real PX4 SIH (GT-free, in flight),
  and the app's loops turned those steps into a 1.2–2 Hz speed oscillation the real vehicle does
  not have. The velocity still steps (EKF2's reported velocity carries that much noise: 0.4–0.6
  cm/s per axis above 3 Hz, as here).

Units: metres, m/s, seconds, Hz. Deterministic for a numpy Generator (one draw per axis per
fusion, whatever the caller's step). Cost: a few µs per fusion (10 Hz); the output predictor adds
0.6 µs per :meth:`EstimatorError.advance_to` call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class EstimatorNoise:
    """Parameters of the reported-state error. ``fusion_rate_hz`` 0 switches it off (truth)."""

    fusion_rate_hz: float = 0.0
    wander_velocity_std_xy_m_s: float = 0.0
    wander_velocity_std_z_m_s: float = 0.0
    wander_velocity_time_constant_s: float = 2.0
    wander_position_time_constant_s: float = 10.0
    position_white_std_xy_m: float = 0.0
    position_white_std_z_m: float = 0.0
    velocity_white_std_xy_m_s: float = 0.0
    velocity_white_std_z_m_s: float = 0.0
    velocity_bias_std_xy_m_s: float = 0.0
    velocity_bias_std_z_m_s: float = 0.0
    velocity_bias_time_constant_s: float = 8.0
    smoothing_time_constant_s: float = 0.0
    output_time_constant_s: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, float | int) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"EstimatorNoise.{f.name}: must be finite and >= 0, got {value!r}")
        if self.fusion_rate_hz > 1000.0:
            raise ValueError(f"EstimatorNoise.fusion_rate_hz: must be <= 1000 (physics rate), got {self.fusion_rate_hz!r}")
        for name in ("wander_velocity_time_constant_s", "wander_position_time_constant_s", "velocity_bias_time_constant_s"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"EstimatorNoise.{name}: must be > 0, got {getattr(self, name)!r}")

    @property
    def enabled(self) -> bool:
        return self.fusion_rate_hz > 0.0

    def wander_position_std_m(self) -> tuple[float, float]:
        """Stationary std of the position wander (xy, z), metres, of the discrete process used.

        Continuous-time value for an OU velocity error (σ_v, τ_v) through a leaky integrator
        (τ_p): σ_p² = σ_v² τ_v τ_p² / (τ_v + τ_p); with the smoothing (τ_s) in between,
        σ_p² = σ_v² τ_v τ_p² (τ_v + τ_p + τ_s) / ((τ_v + τ_p)(τ_v + τ_s)(τ_p + τ_s)).
        """
        tv, tp, ts = self.wander_velocity_time_constant_s, self.wander_position_time_constant_s, self.smoothing_time_constant_s
        k = math.sqrt(tv * tp * tp * (tv + tp + ts) / ((tv + tp) * (tv + ts) * (tp + ts)))
        return (k * self.wander_velocity_std_xy_m_s, k * self.wander_velocity_std_z_m_s)


class EstimatorError:
    """The error process: ``position_error_ned_m`` / ``velocity_error_ned_m_s`` (reported − true).

    Call :meth:`advance_to` with the simulated time; the fused error changes only at fusion epochs
    ``k / fusion_rate_hz`` (k = 1, 2, ...), the reported position error then moves towards it
    continuously when ``output_time_constant_s`` > 0. Starts at zero error (a converged, just-reset
    EKF).
    """

    def __init__(self, noise: EstimatorNoise, rng: np.random.Generator) -> None:
        self.noise = noise
        self._rng = rng
        self._period_s = 1.0 / noise.fusion_rate_hz if noise.enabled else math.inf
        self._epoch = 0
        dt = self._period_s if noise.enabled else 0.0
        self._phi_v = math.exp(-dt / noise.wander_velocity_time_constant_s)
        self._leak = math.exp(-dt / noise.wander_position_time_constant_s)
        # Leaky integral of a velocity held over the epoch: ∫0^dt e^{-(dt-s)/τp} ds.
        self._gain_p = noise.wander_position_time_constant_s * (1.0 - self._leak)
        kv = math.sqrt(max(0.0, 1.0 - self._phi_v * self._phi_v))
        self._drive = (noise.wander_velocity_std_xy_m_s * kv,) * 2 + (noise.wander_velocity_std_z_m_s * kv,)
        self._white_p = (noise.position_white_std_xy_m,) * 2 + (noise.position_white_std_z_m,)
        self._white_v = (noise.velocity_white_std_xy_m_s,) * 2 + (noise.velocity_white_std_z_m_s,)
        self._phi_b = math.exp(-dt / noise.velocity_bias_time_constant_s)
        kb = math.sqrt(max(0.0, 1.0 - self._phi_b * self._phi_b))
        self._drive_b = (noise.velocity_bias_std_xy_m_s * kb,) * 2 + (noise.velocity_bias_std_z_m_s * kb,)
        # its own stream (spawned only when used): the wander and white draws stay as they were
        bias_on = noise.velocity_bias_std_xy_m_s > 0.0 or noise.velocity_bias_std_z_m_s > 0.0
        self._rng_b = rng.spawn(1)[0] if bias_on else None
        ts = noise.smoothing_time_constant_s
        self._smooth = math.exp(-dt / ts) if ts > 0.0 else 0.0
        self._vb = [0.0, 0.0, 0.0]  # velocity bias (reported velocity only)
        self._vbs = [0.0, 0.0, 0.0]  # the bias, smoothed
        self._wv = [0.0, 0.0, 0.0]  # wander velocity error
        self._wvs = [0.0, 0.0, 0.0]  # the wander velocity, smoothed (what moves the position)
        self._wp = [0.0, 0.0, 0.0]  # wander position error
        self.position_error_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.velocity_error_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._tau_out_s = noise.output_time_constant_s
        self._fused_p: tuple[float, float, float] = (0.0, 0.0, 0.0)  # what the output predictor tends to
        self._out_time_s = 0.0  # time of position_error_ned_m (output predictor on)

    def advance_to(self, time_s: float) -> bool:
        """Run the fusions due up to ``time_s``; True when the reported error changed."""
        if not self.noise.enabled:
            return False
        due = int(math.floor(time_s / self._period_s + 1e-9))
        if self._tau_out_s <= 0.0:
            if due <= self._epoch:
                return False
            self._fuse(due - self._epoch)
            self.position_error_ned_m = self._fused_p
            return True
        # output predictor: the reported position relaxes towards each fused value in turn (exact
        # first-order steps, so the result does not depend on how the caller steps time)
        changed = False
        while self._epoch < due:
            changed |= self._relax((self._epoch + 1) * self._period_s)
            self._fuse(1)
        return self._relax(time_s) or changed

    def _relax(self, time_s: float) -> bool:
        """Move the reported position error towards the fused one, up to ``time_s``."""
        dt = time_s - self._out_time_s
        if dt <= 0.0:
            return False
        k = math.exp(-dt / self._tau_out_s)
        p, f = self.position_error_ned_m, self._fused_p
        self.position_error_ned_m = (f[0] + (p[0] - f[0]) * k, f[1] + (p[1] - f[1]) * k, f[2] + (p[2] - f[2]) * k)
        self._out_time_s = time_s
        return True

    def _fuse(self, n: int) -> None:
        """Run ``n`` fusions: the fused position error and the reported velocity error."""
        self._epoch += n
        # 9 normals per fusion, drawn in one call (one numpy call per advance, or per epoch when
        # the output predictor needs each fused value).
        z = self._rng.standard_normal((n, 9)).tolist()
        wv, ws, wp = self._wv, self._wvs, self._wp
        phi, leak, gp, a = self._phi_v, self._leak, self._gain_p, self._smooth
        drive = self._drive
        row = z[-1]
        for row in z:
            for i in range(3):
                wp[i] = leak * wp[i] + gp * ws[i]
                wv[i] = phi * wv[i] + drive[i] * row[i]
                ws[i] = a * ws[i] + (1.0 - a) * wv[i]
        vb, bs = self._vb, self._vbs
        if self._rng_b is not None:
            phib, drive_b = self._phi_b, self._drive_b
            for zb in self._rng_b.standard_normal((n, 3)).tolist():
                for i in range(3):
                    vb[i] = phib * vb[i] + drive_b[i] * zb[i]
                    bs[i] = a * bs[i] + (1.0 - a) * vb[i]
        wpn, wvn = self._white_p, self._white_v
        self._fused_p = (wp[0] + wpn[0] * row[3], wp[1] + wpn[1] * row[4], wp[2] + wpn[2] * row[5])
        self.velocity_error_ned_m_s = (ws[0] + wvn[0] * row[6] + bs[0], ws[1] + wvn[1] * row[7] + bs[1],
                                       ws[2] + wvn[2] * row[8] + bs[2])  # fmt: skip


__all__ = ["EstimatorError", "EstimatorNoise"]
