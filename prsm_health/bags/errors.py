"""Typed errors of :mod:`prsm_health.bags`.

Every message names the file and what is missing or wrong, so the CLI, the replay and the
node can report it verbatim.
"""

from __future__ import annotations

from pathlib import Path


class BagError(ValueError):
    """A bag cannot be written or read as asked: damaged, incomplete, or not what was expected.

    ``path`` is the bag (directory or ``.mcap`` file) or the file inside it that is at fault;
    ``reason`` is the text after the path.
    """

    def __init__(self, path: str | Path, reason: str) -> None:
        super().__init__(f"{path}: {reason}")
        self.path = Path(path)
        self.reason = reason


class InterfaceNotFoundError(LookupError):
    """The ``prsm_health_msgs`` message definitions (``.msg`` files) are not installed."""


class BagDamagedError(BagError):
    """The bag's file is cut short or corrupt at a known place (the text says where).

    Readers deliver everything that was complete before the damage, then raise this.
    """


class TopicNotFoundError(BagError):
    """The bag has no such topic (the text lists the topics it has)."""
