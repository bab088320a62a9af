"""Which MCAP files make up a bag: a rosbag2 directory (``metadata.yaml``) or a bare ``.mcap``.

A directory must hold ``metadata.yaml`` naming MCAP storage files (rosbag2 format version up
to 9); its topics and types are declared there. A bare ``.mcap`` file is read as it is.
Compressed storage files (``compression_mode: file`` or ``message``) are refused with a
:class:`BagError`: bags of this package compress the MCAP chunks instead, which every reader
understands. :func:`custom_data` reads the bag's rosbag2 ``custom_data`` (where
``prsm-health simulate`` records the scene a bag was simulated from).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader

from prsm_health.bags.errors import BagError

METADATA = "metadata.yaml"


@dataclass(frozen=True)
class BagFiles:
    """The storage files of a bag, and its topics (name -> type) if ``metadata.yaml`` has them,
    with its ``custom_data`` (string keys and values; empty without ``metadata.yaml``)."""

    path: Path
    files: tuple[Path, ...]
    topics: dict[str, str] | None
    custom_data: dict[str, str]


def _information(meta: Path) -> dict[str, Any]:
    try:
        loaded = yaml.safe_load(meta.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise BagError(meta, f"cannot read the bag's metadata: {exc}") from exc
    info = loaded.get("rosbag2_bagfile_information") if isinstance(loaded, dict) else None
    if not isinstance(info, dict):
        raise BagError(meta, "no rosbag2_bagfile_information mapping: not rosbag2 metadata")
    return info


def is_sqlite_bag(path: str | Path) -> bool:
    """Whether ``path`` is a rosbag2 directory whose metadata names SQLite3 storage (what
    rosbags reads and this package's MCAP reader does not); False for anything else, also
    what cannot be read."""
    meta = Path(path) / METADATA
    try:
        return meta.is_file() and _information(meta).get("storage_identifier") == "sqlite3"
    except BagError:
        return False


def _require(meta: Path, info: dict[str, Any], key: str, kind: type) -> Any:
    value = info.get(key)
    if not isinstance(value, kind):
        raise BagError(meta, f"{key} is missing or not a {kind.__name__}")
    return value


def bag_files(path: str | Path) -> BagFiles:
    """The storage files of the bag at ``path`` (directory or ``.mcap`` file), in order.

    Raises:
        BagError: the path does not exist or cannot be read, the directory has no (valid)
            metadata.yaml, a storage file is missing, or the storage is not plain MCAP.
    """
    bag = Path(path)
    try:
        return _bag_files(bag)
    except OSError as exc:  # e.g. a directory without read permission: stat inside it fails
        raise BagError(bag, f"cannot read: {exc.strerror or exc}") from exc


def _bag_files(bag: Path) -> BagFiles:
    if bag.is_file():
        if bag.suffix != ".mcap":
            raise BagError(bag, "not a .mcap file or a rosbag2 bag directory")
        return BagFiles(bag, (bag,), None, {})
    if not bag.is_dir():
        raise BagError(bag, "no such bag (neither a directory nor a .mcap file)")
    meta = bag / METADATA
    if not meta.is_file():
        raise BagError(
            meta,
            "missing: a rosbag2 bag directory needs its metadata.yaml "
            "(to read the MCAP file alone, pass the .mcap path itself)",
        )
    info = _information(meta)
    storage = info.get("storage_identifier")
    if storage != "mcap":
        raise BagError(meta, f"storage_identifier is {storage!r}; only 'mcap' bags are read")
    mode = str(info.get("compression_mode") or "").lower()
    if mode not in ("", "none"):
        raise BagError(
            meta,
            f"compression_mode {mode!r} is not supported (decompress the bag, or write it with "
            "MCAP chunk compression as prsm_health.bags.writer does)",
        )
    names = _require(meta, info, "relative_file_paths", list)
    files = tuple(bag / PurePath(str(name)).name for name in names)
    if missing := [f.name for f in files if not f.is_file()]:
        raise BagError(meta, f"storage file(s) listed but missing: {', '.join(missing)}")
    topics: dict[str, str] = {}
    for entry in _require(meta, info, "topics_with_message_count", list):
        topic = entry.get("topic_metadata") if isinstance(entry, dict) else None
        if not isinstance(topic, dict) or not all(
            isinstance(topic.get(key), str) for key in ("name", "type")
        ):
            raise BagError(meta, f"topic entry without name and type: {entry!r}")
        topics[topic["name"]] = topic["type"]
    return BagFiles(bag, files, topics, _strings(info.get("custom_data")))


def custom_data(path: str | Path) -> dict[str, str]:
    """The bag's rosbag2 ``custom_data`` (string keys and values; empty if it has none).

    From ``metadata.yaml`` for a bag directory; for a bare ``.mcap`` file from the ``rosbag2``
    metadata record that rosbag2 (and rosbags) write with the summary when they close the
    file: a file cut short has none.

    Raises:
        BagError: as :func:`bag_files`.
    """
    files = bag_files(path)
    if files.topics is None:  # a bare .mcap file
        return _strings(_mcap_information(files.path).get("custom_data"))
    return files.custom_data


def _strings(data: object) -> dict[str, str]:
    """The string keys and values of a ``custom_data`` mapping (empty if it is none)."""
    if not isinstance(data, dict):
        return {}
    return {k: v for k, v in data.items() if isinstance(k, str) and isinstance(v, str)}


def _mcap_information(mcap: Path) -> dict[str, Any]:
    """The rosbag2 metadata serialised into an MCAP file (empty if it cannot be read)."""
    try:
        with mcap.open("rb") as stream:
            for record in make_reader(stream).iter_metadata():
                if record.name == "rosbag2":
                    loaded = yaml.safe_load(record.metadata.get("serialized_metadata", ""))
                    return loaded if isinstance(loaded, dict) else {}
    except (OSError, McapError, struct.error, ValueError, yaml.YAMLError):
        return {}  # a damaged or foreign file: no metadata to read
    return {}
