"""A small record rewritten in place and crash-safe: the format of the run's checkpoints.

The file holds a header (:data:`MAGIC`, the slot size) and two slots of that size. A slot holds
its own magic, a sequence number, the payload's length and CRC-32, then the payload. A write
fills the slot that does not hold the newest record and syncs it (``fdatasync``); a read takes
the whole slot with the higher sequence number. A process killed at any point, or a machine that
loses power in the middle of a write, leaves the other slot whole: readers get the old record or
the new, never half of one.

Why in place: every process writes its checkpoint at every episode's end, and the episode's
last tick waits for the slowest of them; a rewrite in place is one ``pwrite`` and one
``fdatasync``, where a new file renamed over the old costs the file system a create, a truncate
and a rename (docs/design.md, "Checkpoints").

The payload is msgpack: a map of names to plain values, a numpy array as ``[dtype, shape,
bytes]``. A file is created (or grown, if a record outgrows its slots) whole, under a temporary
name renamed over it. Until the next write, the slot written before holds the record before
(:func:`read_all`): a reader that needs the one before the newest, because a process was killed
between writing this file and recording that it did, finds it there.
"""

import os
import struct
import zlib
from pathlib import Path

import msgpack
import numpy as np

MAGIC = b"NNQLSLT1"
_HEADER = struct.Struct("<8sI")  # magic, slot size
_SLOT = struct.Struct("<8sQII")  # magic, sequence, payload length, payload CRC-32
_ARRAY = "__array__"


class SlotFileError(ValueError):
    """A file that holds no whole record: missing, not of this format, or both slots damaged."""


def _pack(fields: dict) -> bytes:
    def plain(value):
        if isinstance(value, np.ndarray) and not value.dtype.hasobject:
            value = np.ascontiguousarray(value)
            return {_ARRAY: [value.dtype.str, list(value.shape), value.tobytes()]}
        if isinstance(value, np.generic):
            return value.item()
        raise TypeError(f"{type(value).__name__} is not a record value")

    return msgpack.packb(fields, default=plain, use_bin_type=True)


def _unpack(payload: bytes) -> dict:
    def arrays(value: dict):
        if len(value) == 1 and _ARRAY in value:
            dtype, shape, data = value[_ARRAY]
            return np.frombuffer(data, dtype=np.dtype(dtype)).reshape(shape).copy()
        return value

    fields = msgpack.unpackb(payload, object_hook=arrays, raw=False, strict_map_key=True)
    if not isinstance(fields, dict):
        raise SlotFileError("the record is not a map")
    return fields


def _slot_size(payload: bytes) -> int:
    """Room for this payload and a quarter more, in whole 4 KiB pages."""
    need = _SLOT.size + len(payload) + len(payload) // 4
    return -(-need // 4096) * 4096


def _records(data: bytes) -> tuple[int, list[tuple[int, bytes] | None]]:
    """The slot size and each slot's ``(sequence, payload)``, None where no whole record is."""
    if len(data) < _HEADER.size:
        raise SlotFileError("not a slot file")
    magic, size = _HEADER.unpack_from(data)
    if magic != MAGIC or size < _SLOT.size:
        raise SlotFileError("not a slot file")
    records = []
    for k in (0, 1):
        start = _HEADER.size + k * size
        record = None
        if len(data) >= start + _SLOT.size:
            slot_magic, sequence, length, crc = _SLOT.unpack_from(data, start)
            payload = data[start + _SLOT.size:start + _SLOT.size + length]
            if (slot_magic == MAGIC and _SLOT.size + length <= size and len(payload) == length
                    and zlib.crc32(payload) == crc):
                record = (sequence, payload)
        records.append(record)
    return size, records


def _create(path: Path, payload: bytes, sequence: int) -> int:
    """Write a new file whose first slot holds ``payload``; its slot size."""
    size = _slot_size(payload)
    tmp = path.with_name(path.name + ".tmp")
    slot = _SLOT.pack(MAGIC, sequence, len(payload), zlib.crc32(payload)) + payload
    with open(tmp, "wb") as f:
        f.write(_HEADER.pack(MAGIC, size) + slot.ljust(size, b"\0") + bytes(size))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    return size


class SlotFile:
    """One file written again and again by one process: what its slots hold is read from the
    disk at the first write and remembered after, so a write is the payload's one ``pwrite``
    and ``fdatasync``, not a read and check of both slots as well. Nobody else may write the
    file meanwhile (a run's files are its own: ``transport.runfiles``)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._slots: tuple[int, list[int]] | None = None  # slot size, each slot's sequence

    def write(self, fields: dict) -> None:
        """Make ``fields`` the file's record (see the module docstring)."""
        path = self.path
        payload = _pack(fields)
        try:
            fd = os.open(path, os.O_RDWR)
        except FileNotFoundError:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._slots = (_create(path, payload, 0), [0, -1])
            return
        try:
            size, sequences = self._slots or self._read_slots(fd)
            newest = max(sequences)
            if _SLOT.size + len(payload) > size:  # outgrown, or not a slot file: a new file
                self._slots = (_create(path, payload, newest + 1), [newest + 1, -1])
                return
            target = 1 if sequences[0] == newest and newest >= 0 else 0  # never the newest whole
            slot = _SLOT.pack(MAGIC, newest + 1, len(payload), zlib.crc32(payload)) + payload
            self._slots = None  # unknown until the write is done
            os.pwrite(fd, slot, _HEADER.size + target * size)
            os.fdatasync(fd)
            sequences[target] = newest + 1
            self._slots = (size, sequences)
        finally:
            os.close(fd)

    @staticmethod
    def _read_slots(fd: int) -> tuple[int, list[int]]:
        """The slot size and each slot's sequence (-1: no whole record) as the disk has them."""
        try:
            size, records = _records(os.pread(fd, os.fstat(fd).st_size, 0))
        except SlotFileError:  # not one of ours: replaced whole
            return 0, [-1, -1]
        return size, [-1 if r is None else r[0] for r in records]


def write(target: "Path | SlotFile", fields: dict) -> None:
    """Make ``fields`` the record of ``target``: a path (its slots read from the disk first), or
    a :class:`SlotFile` that remembers them."""
    (target if isinstance(target, SlotFile) else SlotFile(target)).write(fields)


def _payloads(path: Path) -> list[bytes]:
    """The payloads of the file's whole records, the newest first; raises FileNotFoundError or
    SlotFileError (no whole record)."""
    with open(path, "rb") as f:
        _, records = _records(f.read())
    whole = sorted((r for r in records if r is not None), reverse=True)
    if not whole:
        raise SlotFileError("no whole record in either slot")
    return [payload for _, payload in whole]


def _record(payload: bytes) -> dict:
    try:
        return _unpack(payload)
    except (ValueError, TypeError, msgpack.UnpackException) as error:
        raise SlotFileError(f"a damaged record ({error})") from None


def read(path: Path) -> dict:
    """The file's newest whole record; raises FileNotFoundError or SlotFileError."""
    return _record(_payloads(path)[0])


def read_all(path: Path) -> list[dict]:
    """The file's whole records, the newest first: the last one written, and the one before it
    unless that slot is empty or damaged. Raises FileNotFoundError or SlotFileError."""
    return [_record(payload) for payload in _payloads(path)]
