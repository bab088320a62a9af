"""Vectorised CDR: many messages of one fixed byte layout encoded or decoded as numpy rows.

A ROS 2 message serialised as little-endian CDR (``00 01 00 00`` encapsulation) has a byte
layout fixed by its length prefixes (string lengths, sequence counts). :class:`Cursor` walks one
payload and records that layout: the byte ranges that fix it (``structure``) and the offset of
every number to extract (``fields``). Messages of equal size whose structure bytes equal a
template's share its layout, so their numbers are read with one numpy view per field
(:func:`group_layouts`, :func:`column`), and written by filling a template payload serialised
once by rosbags (:func:`fill_rows`). Anything else (big-endian CDR, malformed payloads) is left
to the caller's per-message fallback.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

UInt8Array = NDArray[np.uint8]
Int64Array = NDArray[np.int64]

CDR_LE_HEADER = b"\x00\x01\x00\x00"
#: At most this many distinct layouts are tried per payload size before the rest of the
#: messages of that size go to the per-message fallback (keeps a pathological bag linear).
MAX_TEMPLATES_PER_SIZE = 16


class LayoutError(ValueError):
    """A payload is not little-endian CDR of the expected type (or is malformed)."""


@dataclass(frozen=True)
class Field:
    """``count`` numbers of ``dtype`` (little-endian numpy dtype) at byte ``offset``."""

    name: str
    offset: int
    dtype: str
    count: int = 1


@dataclass(frozen=True)
class Layout:
    """Byte layout of payloads of ``size`` bytes whose ``structure`` bytes match the template."""

    size: int
    structure: tuple[tuple[int, int], ...]
    fields: tuple[Field, ...]

    def field(self, name: str) -> Field | None:
        """The field called ``name``, or None when this layout has none (e.g. a short array)."""
        return next((f for f in self.fields if f.name == name), None)


class Cursor:
    """Walks one little-endian CDR payload and records its :class:`Layout`.

    Positions count from the start of the payload (the 4-byte encapsulation header included);
    alignment counts from the end of that header, as CDR does.
    """

    def __init__(self, payload: bytes | memoryview) -> None:
        self.data = bytes(payload)
        if self.data[:4] != CDR_LE_HEADER:
            raise LayoutError(f"not little-endian CDR (header {self.data[:4].hex()})")
        self.pos = 4
        self.structure: list[tuple[int, int]] = [(0, 4)]
        self.fields: list[Field] = []

    def align(self, size: int) -> None:
        """Advance to the next multiple of ``size`` (relative to the end of the header)."""
        self.pos += -(self.pos - 4) % size

    def _take(self, size: int) -> int:
        start, self.pos = self.pos, self.pos + size
        if self.pos > len(self.data):
            raise LayoutError(f"payload of {len(self.data)} bytes ends inside a field at {start}")
        return start

    def field(self, name: str, dtype: str, count: int = 1) -> None:
        """A number (``count`` = 1) or ``count`` consecutive numbers of ``dtype``."""
        size = np.dtype(dtype).itemsize
        if count:
            self.align(size)
        self.fields.append(Field(name, self._take(size * count), dtype, count))

    def skip(self, dtype: str, count: int = 1) -> None:
        """Numbers that are not extracted (their bytes are not part of the structure)."""
        size = np.dtype(dtype).itemsize
        if count:
            self.align(size)
        self._take(size * count)

    def length(self) -> int:
        """A uint32 length prefix (string length or sequence count): part of the structure."""
        self.align(4)
        start = self._take(4)
        self.structure.append((start, start + 4))
        return int.from_bytes(self.data[start : start + 4], "little")

    def string(self, *, structural: bool = False) -> bytes:
        """A string (length, characters, NUL); its characters are structure if ``structural``."""
        size = self.length()
        if size == 0 or len(self.data) < self.pos + size or self.data[self.pos + size - 1] != 0:
            raise LayoutError(f"string at {self.pos} of length {size} is not NUL-terminated")
        start = self._take(size)
        if structural:
            self.structure.append((start, start + size))
        return self.data[start : start + size - 1]

    def finish(self) -> Layout:
        """The layout; the payload must end here."""
        if self.pos != len(self.data):
            raise LayoutError(f"{len(self.data) - self.pos} bytes after the last field")
        return Layout(len(self.data), tuple(self.structure), tuple(self.fields))


def gather_rows(buffer: UInt8Array, starts: Int64Array, size: int) -> UInt8Array:
    """``(n, size)`` copy of the ``size`` bytes at each of ``starts`` in ``buffer``."""
    rows: UInt8Array = buffer[starts[:, None] + np.arange(size, dtype=np.int64)]
    return rows


def _matches(rows: UInt8Array, layout: Layout, template: UInt8Array) -> NDArray[np.bool_]:
    ok = np.ones(len(rows), dtype=np.bool_)
    for lo, hi in layout.structure:
        ok &= (rows[:, lo:hi] == template[lo:hi]).all(axis=1)
    return ok


def group_layouts(
    buffer: UInt8Array,
    starts: Int64Array,
    sizes: Int64Array,
    layout_of: Callable[[bytes], Layout],
) -> Iterator[tuple[Int64Array, Layout | None, UInt8Array]]:
    """Split messages into groups of one layout: ``(indices, layout, rows)`` per group.

    ``starts``/``sizes`` locate each payload in ``buffer``; ``layout_of`` parses one payload
    (raising :class:`LayoutError` when it cannot). Rows whose layout could not be found come in
    groups with ``layout = None``, for the caller's per-message fallback. Every index appears
    in exactly one group.
    """
    for size in np.unique(sizes):
        indices = np.flatnonzero(sizes == size).astype(np.int64)
        rows = gather_rows(buffer, starts[indices], int(size))
        for _ in range(MAX_TEMPLATES_PER_SIZE):
            if not len(indices):
                break
            template = rows[0]
            try:
                layout = layout_of(template.tobytes())
            except LayoutError:
                yield indices[:1], None, rows[:1]
                indices, rows = indices[1:], rows[1:]
                continue
            ok = _matches(rows, layout, template)
            yield indices[ok], layout, rows[ok]
            indices, rows = indices[~ok], rows[~ok]
        if len(indices):
            yield indices, None, rows


def column(rows: UInt8Array, field: Field) -> NDArray[np.generic]:
    """The values of ``field`` in every row: shape ``(n,)``, or ``(n, count)`` if count != 1."""
    size = np.dtype(field.dtype).itemsize * field.count
    raw = np.ascontiguousarray(rows[:, field.offset : field.offset + size])
    values = raw.view(field.dtype)
    return values[:, 0] if field.count == 1 else values


def fill_rows(
    template: bytes | memoryview,
    layout: Layout,
    values: Mapping[str, NDArray[np.generic]],
    count: int,
) -> UInt8Array:
    """``count`` copies of ``template`` with ``values[name]`` written into each named field."""
    rows = np.tile(np.frombuffer(template, dtype=np.uint8), (count, 1))
    for field in layout.fields:
        if field.name not in values:
            continue
        data = np.ascontiguousarray(values[field.name], dtype=field.dtype)
        size = np.dtype(field.dtype).itemsize * field.count
        rows[:, field.offset : field.offset + size] = data.reshape(count, field.count).view(
            np.uint8
        )
    return rows


def split_rows(rows: UInt8Array) -> list[memoryview]:
    """One read-only payload per row, without copying each row."""
    size = rows.shape[1] if rows.ndim == 2 else 0
    flat = memoryview(np.ascontiguousarray(rows).tobytes())
    return [flat[i : i + size] for i in range(0, len(flat), size)] if size else []
