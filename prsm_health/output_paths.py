"""Output folders of the commands: made before a run, so that one that cannot be made fails
before the work, and removed again when the run fails while they are still empty, so that a
failed command leaves nothing behind."""

from __future__ import annotations

import os
from pathlib import Path


def make_folder(folder: Path, option: str) -> list[Path]:
    """Make ``folder`` (and its missing parents) for the output of ``option``; returns the
    folders made, outermost first, for :func:`remove_made_folders`.

    Raises:
        ValueError: it cannot be made, or it is not writable (names ``option``).
    """
    missing = [f for f in (folder, *folder.parents) if not f.exists()][::-1]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        remove_made_folders(missing)
        raise ValueError(f"{option}: cannot make the folder {folder}: {exc}") from exc
    if not os.access(folder, os.W_OK | os.X_OK):
        remove_made_folders(missing)
        raise ValueError(f"{option}: the folder {folder} is not writable")
    return missing


def remove_made_folders(made: list[Path]) -> None:
    """Remove the folders of :func:`make_folder` that are still empty, innermost first."""
    for folder in reversed(made):
        try:
            folder.rmdir()
        except OSError:  # not empty (written into), or gone
            continue
