"""Local polar coordinates of a jammed hypothesis' ripple phasor.

The filters carry the ripple as a phasor r = (c, s) (measurement.py). Once its phase is known,
a linear filter over (c, s) keeps the uncertainty across the phasor in absolute terms: when the
amplitude shrinks (the wall's radial load falls, or the load torque the ripple scales with
builds up from zero at a stroke start), the same absolute uncertainty is a growing uncertainty
of the phase, and a move across the phasor of one or two standard deviations turns the phase by
tens of degrees. The physics says the phase does not change (it is set by where the jammed
rollers sit on the carrier, docs/estimation.md): a hypothesis with one jammed roller too few
could then take up the turned ripple of a second one. In polar coordinates the phase keeps its
own uncertainty whatever the amplitude does.

Coordinates about the phasor's direction u at the linearisation point, v = u turned by 90°:

    r = rho (cos(delta) u + sin(delta) v),   rho signed (it may pass through zero), delta in rad;

at the linearisation point rho = |r| and delta = 0. The Jacobian d(c, s)/d(rho, delta) is
[e, rho n] with e = cos(delta) u + sin(delta) v and n = -sin(delta) u + cos(delta) v; the
other states map to themselves.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from prsm_health.estimation.measurement import RIPPLE, RIPPLE_COS, RIPPLE_SIN

FloatArray = NDArray[np.float64]

#: Smallest amplitude (relative ripple) taken into polar coordinates: below it the phase is
#: not defined by the phasor.
SMALLEST_AMPLITUDE = 1e-6


def polar_about(x: FloatArray) -> PolarPhasor | None:
    """Polar coordinates about the phasor at ``x``; None if it is shorter than
    SMALLEST_AMPLITUDE (no direction to turn about)."""
    c, s = float(x[RIPPLE_COS]), float(x[RIPPLE_SIN])
    amplitude = math.hypot(c, s)
    if not amplitude >= SMALLEST_AMPLITUDE:
        return None
    return PolarPhasor(amplitude, (c / amplitude, s / amplitude))


class PolarPhasor:
    """Polar coordinates (rho, delta) of the ripple phasor about the unit direction ``u``, at
    its linearisation point of length ``amplitude`` (> 0; :func:`polar_about`)."""

    def __init__(self, amplitude: float, u: tuple[float, float]) -> None:
        self.amplitude = amplitude
        self._u = u

    def _axes(self, delta: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """e and n at ``delta`` (module docstring)."""
        ux, uy = self._u
        cos, sin = math.cos(delta), math.sin(delta)
        return (cos * ux - sin * uy, cos * uy + sin * ux), (
            -sin * ux - cos * uy,
            -sin * uy + cos * ux,
        )

    def _jacobian(self, xp: FloatArray) -> FloatArray:
        """d(c, s)/d(rho, delta) at the polar state ``xp`` (2 x 2)."""
        rho = float(xp[RIPPLE_COS])
        e, n = self._axes(float(xp[RIPPLE_SIN]))
        return np.array([[e[0], rho * n[0]], [e[1], rho * n[1]]])

    def to_polar(self, x: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(x, P) with the phasor in polar coordinates at the linearisation point."""
        xp = x.copy()
        xp[RIPPLE_COS], xp[RIPPLE_SIN] = self.amplitude, 0.0
        # d(rho, delta)/d(c, s) at delta = 0: rows u and v / rho.
        ux, uy = self._u
        inverse = np.array([[ux, uy], [-uy / self.amplitude, ux / self.amplitude]])
        return xp, _transformed(p, inverse)

    def to_cartesian(self, xp: FloatArray, pp: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(x, P) back in (c, s), linearised at the polar state ``xp``."""
        return self.cartesian_state(xp), _transformed(pp, self._jacobian(xp))

    def cartesian_state(self, xp: FloatArray) -> FloatArray:
        """The state ``xp`` with its phasor in (c, s)."""
        x = xp.copy()
        rho = float(xp[RIPPLE_COS])
        e, _ = self._axes(float(xp[RIPPLE_SIN]))
        x[RIPPLE_COS], x[RIPPLE_SIN] = rho * e[0], rho * e[1]
        return x

    def polar_jacobian(self, xp: FloatArray, jacobian: FloatArray) -> FloatArray:
        """A measurement Jacobian over (c, s) as one over (rho, delta), at ``xp``."""
        mapped = jacobian.copy()
        mapped[RIPPLE] = jacobian[RIPPLE] @ self._jacobian(xp)
        return mapped


def _transformed(p: FloatArray, block: FloatArray) -> FloatArray:
    """T P T' for T the identity but ``block`` on the ripple states."""
    out = p.copy()
    out[RIPPLE, :] = block @ p[RIPPLE, :]
    out[:, RIPPLE] = out[:, RIPPLE] @ block.T
    return out
