"""The estimator's state on disk: atomic saves, and restore that never loses a bad file.

A state file is JSON::

    {"format": "prsm_health.state/1", "hardware_id": "...", "saved_unix_s": 1.7e9,
     "estimator": {...HealthEstimator.snapshot()...}}

Saving is atomic: the text goes to a temporary file in the same directory, which is flushed,
fsync'ed and renamed over the state file; then the directory is fsync'ed, so after a crash or
power loss the file is either the old or the new state, never a mix.

Restoring: a missing file means a fresh start. A file that cannot be used (not JSON, not this
format, another hardware_id, or refused by :meth:`HealthEstimator.restore`: malformed, or
another actuator's geometry) is moved aside to ``<name>.corrupt-<UTC time>`` and reported;
the estimator then starts fresh. A bad file is therefore never silently replaced by zeros.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from prsm_health.estimation.estimator import HealthEstimator, SnapshotError

FORMAT = "prsm_health.state/1"


def default_state_file(hardware_id: str) -> Path:
    """``$XDG_STATE_HOME/prsm_health/<hardware_id>.json`` (``~/.local/state`` by default)."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "prsm_health" / f"{hardware_id}.json"


@dataclass(frozen=True)
class RestoreOutcome:
    """What :meth:`StateStore.restore` did: resumed, started fresh, or kept a bad file aside."""

    restored: bool
    kept_corrupt: Path | None = None
    problem: str = ""


class StateStore:
    """Saves and restores one actuator's estimator state at ``path``."""

    def __init__(self, path: Path, hardware_id: str) -> None:
        self.path = path
        self.hardware_id = hardware_id

    def save(self, estimator: HealthEstimator) -> None:
        """Write the estimator's snapshot atomically (raises OSError on failure)."""
        document = {
            "format": FORMAT,
            "hardware_id": self.hardware_id,
            "saved_unix_s": time.time(),
            "estimator": estimator.snapshot(),
        }
        text = json.dumps(document, allow_nan=False)
        folder = self.path.parent
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
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return RestoreOutcome(restored=False)
        except (OSError, UnicodeDecodeError) as exc:
            return self._keep_aside(f"unreadable state file {self.path}: {exc}")
        try:
            document = json.loads(text)
            snapshot = self._snapshot(document)
            estimator.restore(snapshot)
        except ValueError as exc:  # JSONDecodeError and SnapshotError are ValueErrors
            return self._keep_aside(f"unusable state file {self.path}: {exc}")
        except RecursionError:  # json.loads of lists nested thousands deep
            return self._keep_aside(f"unusable state file {self.path}: nested too deeply")
        return RestoreOutcome(restored=True)

    def _snapshot(self, document: Any) -> dict[str, Any]:
        if not isinstance(document, dict) or document.get("format") != FORMAT:
            raise SnapshotError(f"not a {FORMAT} document")
        if document.get("hardware_id") != self.hardware_id:
            raise SnapshotError(
                f"it belongs to hardware_id {document.get('hardware_id')!r},"
                f" not {self.hardware_id!r}"
            )
        snapshot = document.get("estimator")
        if not isinstance(snapshot, dict):
            raise SnapshotError("no estimator state")
        return snapshot

    def _keep_aside(self, problem: str) -> RestoreOutcome:
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        target = self.path.with_name(f"{self.path.name}.corrupt-{stamp}")
        n = 1
        while target.exists():
            n += 1
            target = self.path.with_name(f"{self.path.name}.corrupt-{stamp}-{n}")
        os.replace(self.path, target)
        return RestoreOutcome(restored=False, kept_corrupt=target, problem=problem)
