"""Typed errors of the physics core.

Every error names what was wrong, so a caller (CLI, estimator, node) can report it verbatim.
"""

from __future__ import annotations


class PhysicsError(Exception):
    """Base class of every error raised by :mod:`prsm_health.physics`."""


class ParameterError(PhysicsError, ValueError):
    """A geometry, material or model parameter is outside its allowed range.

    ``field`` is the dotted name of the offending parameter (e.g. ``"geometry.pitch_m"``).
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message

    @classmethod
    def combined(cls, problems: list[ParameterError]) -> ParameterError:
        """One error for several (at least one): the first's field, every message, so that one
        edit of a data file can fix them all."""
        first, *more = problems
        return cls(first.field, "; ".join([first.message, *map(str, more)]))

    def in_file(self, path: object) -> ParameterError:
        """The same error, naming the data file that holds the parameter."""
        return ParameterError(f"{path}: {self.field}", self.message)


class DomainError(PhysicsError, ValueError):
    """The requested operating point is outside the domain the model can solve.

    Example: a radial load so large that no set of loaded-flank contacts balances it.
    """


class ConvergenceError(PhysicsError, RuntimeError):
    """A solver stopped without meeting its residual tolerance (the residual is in the text)."""
