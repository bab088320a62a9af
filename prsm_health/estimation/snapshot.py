"""The estimator's saved state: what identifies the actuator it belongs to, and the checks
that a saved state passes before :meth:`HealthEstimator.restore
<prsm_health.estimation.estimator.HealthEstimator.restore>` resumes from it (docs/ros.md,
persistence)."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from prsm_health.estimation.degradation import Degradation
from prsm_health.estimation.params import EstimatorParams

FloatArray = NDArray[np.float64]

#: Version of the :meth:`HealthEstimator.snapshot` layout.
SNAPSHOT_FORMAT = 2
#: A restored state's means and covariances must stay below this in magnitude. No state the
#: filter reaches comes near it (predictions are capped at one second); a larger one is a
#: damaged file, and it would overflow once symmetrised.
SNAPSHOT_LARGEST_VALUE = 1e100
#: The restored sample counters must sum to less than this: the messages carry the counts as
#: uint64 and the input stage adds them up in int64 (three counts of 2^62 - 1 each passed a
#: check of each alone and overflowed every block after). 2^62 samples at 1 kHz are 146 My.
SNAPSHOT_LARGEST_COUNT = 2**62
#: The snapshot's keys of the noises the input stage measures (inputs.SampleBlocker): the
#: motor speed's in motion [rad^2/s^2] and the motor current's [A^2].
NOISE_KEYS = ("speed_noise_var_rad2_s2", "current_noise_var_a2")


class SnapshotError(ValueError):
    """A saved estimator state cannot be resumed (malformed, or of another screw)."""


class ForeignStateError(SnapshotError):
    """A well-formed saved state of another screw (or actuator): not damaged, only not this
    one's, so it can resume once the parameters match again."""


def _digest(parts: tuple[object, ...]) -> str:
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:16]


def screw_fingerprint(params: EstimatorParams) -> str:
    """A stable digest of the screw itself (geometry, materials, friction, wear, fatigue):
    what the accumulated degradation and the jammed rollers belong to."""
    preset = params.actuator.preset
    return _digest((preset.geometry, preset.friction, preset.wear, preset.fatigue))


def actuator_fingerprint(params: EstimatorParams) -> str:
    """A stable digest of what the filters' states depend on: the screw, the drive train, the
    misalignment and whether there are ripple states (the same digest as in the state files
    saved before :func:`screw_fingerprint` existed, so that they still resume)."""
    actuator, preset = params.actuator, params.actuator.preset
    return _digest(
        (
            preset.geometry,
            preset.friction,
            preset.wear,
            preset.fatigue,
            actuator.drive_train,
            actuator.misalignment,
            params.radial_terms,
        )
    )


def actuator_parts(params: EstimatorParams) -> dict[str, str]:
    """A digest of each part of :func:`actuator_fingerprint` beyond the screw, by the name a
    message gives it: saved with a state, so that a restore can say which of them changed."""
    actuator = params.actuator
    return {
        "drive train": _digest((actuator.drive_train,)),
        "misalignment": _digest((actuator.misalignment,)),
        "ripple states": "on" if params.radial_terms else "off",
    }


#: What a partial restore names when the state file does not say which part changed (saved
#: before the parts were).
SOME_PART = "drive train, misalignment or ripple states"


def changed_parts(saved: object, params: EstimatorParams) -> tuple[str, ...]:
    """The parts of :func:`actuator_parts` whose digest differs from the ``saved`` ones (a
    snapshot's "parts"), or (SOME_PART,) when the snapshot does not say."""
    if not isinstance(saved, dict):
        return (SOME_PART,)
    parts = actuator_parts(params).items()
    return tuple(name for name, digest in parts if saved.get(name) != digest) or (SOME_PART,)


class SavedHypothesis(NamedTuple):
    """One saved hypothesis, as :meth:`JamHypotheses.restore
    <prsm_health.estimation.hypotheses.JamHypotheses.restore>` takes it."""

    jammed_rollers: int
    fresh: bool
    x: FloatArray
    p: FloatArray
    log_probability: float
    ripple_axis: FloatArray | None


@dataclass(frozen=True)
class SavedState:
    """A snapshot that passed :func:`read_snapshot`'s checks."""

    hypotheses: list[SavedHypothesis]
    degradation: Degradation
    samples_accepted: int
    samples_rejected: list[int]
    #: The parts of :func:`actuator_parts` that changed since the save: empty when the
    #: filters' states resume too, else only what belongs to the screw does.
    changed_parts: tuple[str, ...]
    #: The noises the input stage measured, by the snapshot's key (NOISE_KEYS; each
    #: :meth:`NoiseHistory.saved <prsm_health.estimation.noise_history.NoiseHistory.saved>`;
    #: empty in a state saved before it was measured).
    noise_variances: dict[str, list[float]]


def read_snapshot(
    snapshot: dict[str, Any],
    params: EstimatorParams,
    *,
    state_dim: int,
    n_rollers: int,
    rejection_reasons: int,
) -> SavedState:
    """Check a :meth:`HealthEstimator.snapshot
    <prsm_health.estimation.estimator.HealthEstimator.snapshot>` against the estimator it is
    to resume: ``params``, its filters' state dimension, the screw's rollers and the input
    stage's number of rejection reasons.

    Raises:
        ForeignStateError: a sound state of another screw (or, saved before the screw's own
            digest, of another actuator); said only once the rest is known sound, since a
            damaged file is no other actuator's.
        SnapshotError: anything else that is wrong, named.
    """
    try:
        if snapshot["format"] != SNAPSHOT_FORMAT:
            raise SnapshotError(f"format {snapshot['format']!r}, expected {SNAPSHOT_FORMAT}")
        whole = bool(snapshot["actuator"] == actuator_fingerprint(params))
        foreign = None if whole else _foreign(snapshot, params)
        hypotheses = [
            _saved_hypothesis(
                entry,
                state_dim=state_dim,
                largest_count=n_rollers if foreign is None else math.inf,  # another's rollers
                filter_state_used=whole,
            )
            for entry in snapshot["hypotheses"]
        ]
        degradation = Degradation(**{k: float(v) for k, v in snapshot["degradation"].items()})
        accepted = int(snapshot["samples_accepted"])
        rejected = [int(v) for v in snapshot["samples_rejected"]]
        noises = {key: [float(v) for v in snapshot.get(key, [])] for key in NOISE_KEYS}
    except SnapshotError:
        raise  # it says what is wrong
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise SnapshotError(f"malformed state: {exc!r}") from exc
    if not any(math.isfinite(h.log_probability) for h in hypotheses):
        raise SnapshotError("no hypothesis with a probability above zero")
    # Losses, damages, their error terms and the rate only ever grow from zero.
    if not all(0.0 <= v < SNAPSHOT_LARGEST_VALUE for v in degradation.to_dict().values()):
        raise SnapshotError(
            f"degradation values must be >= 0 and < {SNAPSHOT_LARGEST_VALUE:g}: {degradation}"
        )
    for key, variances in noises.items():
        if not all(0.0 <= v < SNAPSHOT_LARGEST_VALUE for v in variances):  # NaN fails too
            raise SnapshotError(
                f"{key}: variances must be >= 0 and < {SNAPSHOT_LARGEST_VALUE:g}: {variances}"
            )
    counts = [accepted, *rejected]
    if (
        len(rejected) != rejection_reasons
        or not all(n >= 0 for n in counts)
        or sum(counts) >= SNAPSHOT_LARGEST_COUNT
    ):
        raise SnapshotError(
            f"sample counters: {rejection_reasons} rejection reasons expected, each count "
            f">= 0 and their sum below 2^62, got {len(rejected)} reasons, counts {counts}"
        )
    if foreign is not None:
        raise ForeignStateError(foreign)
    return SavedState(
        hypotheses,
        degradation,
        accepted,
        rejected,
        () if whole else changed_parts(snapshot.get("parts"), params),
        noises,
    )


def _foreign(snapshot: dict[str, Any], params: EstimatorParams) -> str | None:
    """Why a snapshot whose actuator differs cannot resume at all (None: only the drive
    train, misalignment or ripple states differ, and its screw's part can)."""
    if "screw" not in snapshot:  # saved before the screw's own digest
        return (
            "the state belongs to another actuator (the preset or the drive train "
            "differ; the state does not say which): refusing to resume from it"
        )
    if snapshot["screw"] != screw_fingerprint(params):
        return (
            "the state belongs to another screw (the preset's geometry, materials, "
            "friction, wear or fatigue differ): refusing to resume from it"
        )
    return None


def _saved_hypothesis(
    entry: dict[str, Any], *, state_dim: int, largest_count: float, filter_state_used: bool
) -> SavedHypothesis:
    """One entry of a snapshot's "hypotheses", checked; its filter state (x, P) only when it
    will be used (``filter_state_used``: the drive train and model are unchanged). A load
    beyond the divergence bound passes: the resume forgets it
    (:meth:`~prsm_health.estimation.hypotheses.JamHypotheses.reinitialise_load`)."""
    k = int(entry["count"])
    x = np.asarray(entry["x"], dtype=np.float64)
    p = np.asarray(entry["P"], dtype=np.float64)
    saved = entry["log_probability"]
    log_probability = -math.inf if saved is None else float(saved)
    # Optional: a state saved before the ripple axis existed learns it again.
    axis = entry.get("ripple_axis")
    if axis is not None:
        axis = np.asarray(axis, dtype=np.float64)
        if axis.shape != (2,) or not abs(float(axis @ axis) - 1.0) < 1e-9:
            raise SnapshotError(f"hypothesis {k}: ripple_axis is not a unit 2-vector")
    filter_state_ok = (
        x.shape == (state_dim,)
        and p.shape == (state_dim, state_dim)
        and np.all(np.abs(x) < SNAPSHOT_LARGEST_VALUE)  # NaN fails too
        and np.all(np.abs(p) < SNAPSHOT_LARGEST_VALUE)
    )
    valid = (
        0 <= k <= largest_count
        and (filter_state_ok or not filter_state_used)
        and (saved is None or -math.inf < log_probability <= 0.0)
    )
    if not valid:
        raise SnapshotError(f"hypothesis {k} is malformed")
    return SavedHypothesis(k, bool(entry["fresh"]), x, p, log_probability, axis)
