"""The estimator's state on disk: atomic saves, and restore that never loses a bad file.

A state file is JSON::

    {"format": "prsm_health.state/1", "hardware_id": "...", "saved_unix_s": 1.7e9,
     "estimator": {...HealthEstimator.snapshot()...},
     "last_estimate": {...the HealthState fields...} or null}

``last_estimate`` is the node's latest estimate at the save (null before the first, and in
files saved before it existed): the snapshot holds no estimate, and a restarted node shows
this one in its diagnostics until it makes a new one, so that a known jam does not turn into
"no estimate yet" by a restart.

Saving is atomic: the text goes to a temporary file in the same directory, which is flushed,
fsync'ed and renamed over the state file; then the directory is fsync'ed, so after a crash or
power loss the file is either the old or the new state, never a mix.

Restoring: a missing file means a fresh start. A file that cannot be used is moved aside and
reported, and the estimator starts fresh: to ``<name>.corrupt-<UTC time>`` if it is damaged
(not JSON, not this format, malformed), to ``<name>.foreign-<UTC time>`` if it is a sound
state of another actuator (another hardware_id, or another screw: a wrong preset given by
mistake), which resumes once moved back under parameters that match. A bad file is therefore
never silently replaced by zeros. A state of the same screw saved under another drive train,
misalignment or ripple setting resumes the screw's part (degradation, jam counts; the restore
says so in :attr:`RestoreOutcome.problem`).
A malformed ``last_estimate`` alone (or one of another version, with other fields) loses only
itself: the state is restored and the problem reported.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.inputs import LARGEST_STAMP_S
from prsm_health.estimation.snapshot import ForeignStateError, SnapshotError

FORMAT = "prsm_health.state/1"
#: Suffixes of a state file kept aside: damaged, or a sound state of another actuator (another
#: screw, or another hardware_id), which resumes once moved back under matching parameters.
CORRUPT_SUFFIX = "corrupt"
FOREIGN_SUFFIX = "foreign"


def parameters_changed(parts: tuple[str, ...]) -> str:
    """The problem of a state file restored for the same screw under other parameters: which
    ``parts`` differ (:meth:`HealthEstimator.restore`) and what was resumed."""
    return (
        f"the {' and the '.join(parts)} changed since the state was saved: the precision "
        "loss, fatigue damage and jam-count probabilities are resumed, the load is estimated "
        "afresh"
    )


def default_state_file(hardware_id: str) -> Path:
    """``$XDG_STATE_HOME/prsm_health/<hardware_id>.json`` (``~/.local/state`` by default)."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "prsm_health" / f"{hardware_id}.json"


@dataclass(frozen=True)
class RestoreOutcome:
    """What :meth:`StateStore.restore` did: resumed (with the last estimate saved, if any;
    ``problem`` says what of the file was not used: a malformed last estimate, or the filters'
    states saved under other parameters), started fresh, or kept a bad file aside
    (``problem`` says why)."""

    restored: bool
    kept_aside: Path | None = None
    problem: str = ""
    last_estimate: HealthState | None = None


class StateStore:
    """Saves and restores one actuator's estimator state at ``path``."""

    def __init__(self, path: Path, hardware_id: str) -> None:
        self.path = path
        self.hardware_id = hardware_id

    def save(self, estimator: HealthEstimator, last_estimate: HealthState | None = None) -> None:
        """Write the estimator's snapshot and the last estimate atomically (raises OSError on
        failure). A last estimate with a value JSON cannot hold (not finite) is saved as
        null: the diagnostics it is kept for are no reason to lose the state."""
        document = {
            "format": FORMAT,
            "hardware_id": self.hardware_id,
            "saved_unix_s": time.time(),
            "estimator": estimator.snapshot(),
            "last_estimate": _estimate_document(last_estimate),
        }
        text = json.dumps(document, allow_nan=False)
        folder = self.path.parent
        for above in (folder, *folder.parents):  # mkdir said only "File exists: '<folder>'"
            if above.exists():
                if not above.is_dir():
                    raise NotADirectoryError(
                        errno.ENOTDIR, "a file stands where the state's folder goes", str(above)
                    )
                break
        folder.mkdir(parents=True, exist_ok=True)
        fd, temporary = tempfile.mkstemp(prefix=f".{self.path.name}.", dir=folder)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as stream:
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(temporary, self.path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
        directory = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(directory)
        finally:
            os.close(directory)

    def restore(self, estimator: HealthEstimator) -> RestoreOutcome:
        """Resume ``estimator`` from the file, or keep an unusable file aside (module doc).

        Raises OSError only if the file exists but can neither be read nor moved aside.
        """
        if self.path.exists() and not self.path.is_file():  # a FIFO's read would block
            return self._keep_aside(f"state file {self.path} is not a regular file")
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return RestoreOutcome(restored=False)
        except (OSError, UnicodeDecodeError) as exc:
            return self._keep_aside(f"unreadable state file {self.path}: {exc}")
        try:
            document = json.loads(text)
            changed = estimator.restore(self._snapshot(document))
        except ForeignStateError as exc:
            problem = (
                f"state file {self.path} of another actuator ({exc}); to resume from it, move "
                "it back and start with parameters that match"
            )
            return self._keep_aside(problem, FOREIGN_SUFFIX)
        except ValueError as exc:  # JSONDecodeError and SnapshotError are ValueErrors
            return self._keep_aside(f"unusable state file {self.path}: {exc}")
        except RecursionError:  # json.loads of lists nested thousands deep
            return self._keep_aside(f"unusable state file {self.path}: nested too deeply")
        partly = parameters_changed(changed) if changed else ""
        try:
            rollers = estimator.params.actuator.preset.geometry.n_rollers
            last_estimate = _estimate(document.get("last_estimate"), rollers)
        except SnapshotError as exc:  # only the diagnostics' copy: the state is restored
            problem = f"the last estimate of {self.path} is not used: {exc}"
            return RestoreOutcome(restored=True, problem="; ".join(filter(None, (partly, problem))))
        return RestoreOutcome(restored=True, problem=partly, last_estimate=last_estimate)

    def _snapshot(self, document: Any) -> dict[str, Any]:
        if not isinstance(document, dict) or document.get("format") != FORMAT:
            raise SnapshotError(f"not a {FORMAT} document")
        if document.get("hardware_id") != self.hardware_id:
            raise ForeignStateError(
                f"it belongs to hardware_id {document.get('hardware_id')!r},"
                f" not {self.hardware_id!r}"
            )
        snapshot = document.get("estimator")
        if not isinstance(snapshot, dict):
            raise SnapshotError("no estimator state")
        return snapshot

    def _keep_aside(self, problem: str, suffix: str = CORRUPT_SUFFIX) -> RestoreOutcome:
        """Move the file to ``<name>.<suffix>-<UTC time>`` (a number added if that exists)."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        target = self.path.with_name(f"{self.path.name}.{suffix}-{stamp}")
        n = 1
        while target.exists():
            n += 1
            target = self.path.with_name(f"{self.path.name}.{suffix}-{stamp}-{n}")
        os.replace(self.path, target)
        return RestoreOutcome(restored=False, kept_aside=target, problem=problem)


def _estimate_document(state: HealthState | None) -> dict[str, Any] | None:
    """``state``'s fields as JSON (the event as its number), or None for no estimate or one
    with a value that is not finite."""
    if state is None:
        return None
    document = {
        **dataclasses.asdict(state),
        "jam_probabilities": list(state.jam_probabilities),
        "event": int(state.event),
    }
    return document if _finite_numbers(document) else None


def _estimate(document: Any, n_rollers: int) -> HealthState | None:
    """The estimate of :func:`_estimate_document` (None: none saved). Raises SnapshotError
    unless it has exactly the fields of an estimate, each a finite number, and an event of
    :class:`EstimateEvent`, and is one an estimator of ``n_rollers`` rollers can make
    (:func:`_impossible`)."""
    if document is None:
        return None
    try:
        state = HealthState(
            **{
                **document,
                "jam_probabilities": tuple(document["jam_probabilities"]),
                "event": EstimateEvent(document["event"]),
            }
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise SnapshotError(f"malformed last estimate: {exc!r}") from exc
    if not _finite_numbers(document):
        raise SnapshotError("malformed last estimate: a value is not a finite number")
    if problem := _impossible(state, n_rollers):
        raise SnapshotError(f"malformed last estimate: {problem}")
    return state


def _impossible(state: HealthState, n_rollers: int) -> str:
    """What no estimator of ``n_rollers`` rollers reports in ``state`` (empty if nothing): the
    diagnostics would show it (a stamp of 300 digits, a jam from probabilities [-1, 2, 0])."""
    probabilities = state.jam_probabilities
    if len(probabilities) != n_rollers + 1:
        return f"{len(probabilities)} jam probabilities for {n_rollers} rollers"
    if min(probabilities) < 0.0 or abs(sum(probabilities) - 1.0) > 1e-6:
        return f"jam probabilities {list(probabilities)} are not a distribution"
    if not abs(state.stamp_s) < LARGEST_STAMP_S:
        return f"stamp {state.stamp_s:g} s beyond +-2^31 s"
    negative = [
        name
        for name in (
            "axial_load_std_n",
            "precision_loss_m",
            "precision_loss_std_m",
            "fatigue_damage",
            "fatigue_damage_std",
            "samples_accepted",
            "samples_rejected",
            "nis",
        )
        if getattr(state, name) < 0
    ]
    if negative or not 0.0 <= state.efficiency <= 1.0:
        return f"{', '.join(negative) or 'efficiency'} out of range"
    return ""


def _finite_numbers(document: dict[str, Any]) -> bool:
    """Every value of an estimate's document, and each jam probability, is a finite number."""
    values = [*document["jam_probabilities"]]
    values += [v for k, v in document.items() if k != "jam_probabilities"]
    return all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values
    )
