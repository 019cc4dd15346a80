"""Atomic, self-checking checkpoints of a coevolution run (RunState).

File layout: an 8-byte magic ``GPQCKPT1``, the payload length (8 bytes,
little-endian), the payload's SHA-256 (32 bytes), then the payload: a pickle of
a plain dict ``{"state": {field: value, ...}, "meta": {...}}``. The state dict
holds every field of `RunState` (found with `dataclasses.fields`, so fields added
later still round-trip) except the unflushed history rows, which the caller must
have written to disk first. A short, damaged or foreign file raises
`CorruptCheckpoint`; the caller restarts that run.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pickle
import struct
from pathlib import Path

from gpquad.engine.evolve.coevolution import RunState
from gpquad.study.store import atomic_write_bytes

MAGIC = b"GPQCKPT1"
_HEADER = struct.Struct("<8sQ32s")


class CorruptCheckpoint(Exception):
    """A checkpoint that is truncated, damaged or not a checkpoint at all."""


def state_to_dict(state: RunState) -> dict:
    """Every RunState field but `history` (rows must be flushed before checkpointing)."""
    return {f.name: getattr(state, f.name) for f in dataclasses.fields(state)
            if f.name != "history"}


def state_from_dict(fields: dict) -> RunState:
    names = {f.name for f in dataclasses.fields(RunState)}
    return RunState(**{k: v for k, v in fields.items() if k in names})


def encode(state: RunState, meta: dict) -> bytes:
    """Header + pickle of the state's fields and `meta` (plain data)."""
    payload = pickle.dumps({"state": state_to_dict(state), "meta": dict(meta)},
                           protocol=pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(MAGIC, len(payload), hashlib.sha256(payload).digest()) + payload


def decode(blob: bytes) -> tuple[RunState, dict]:
    """Inverse of `encode`; raises CorruptCheckpoint on any damage."""
    if len(blob) < _HEADER.size:
        raise CorruptCheckpoint(f"{len(blob)} bytes, shorter than the {_HEADER.size}-byte header")
    magic, length, digest = _HEADER.unpack_from(blob)
    if magic != MAGIC:
        raise CorruptCheckpoint("not a gpquad checkpoint (bad magic)")
    payload = blob[_HEADER.size:]
    if len(payload) != length:
        raise CorruptCheckpoint(f"payload is {len(payload)} bytes, header says {length}")
    if hashlib.sha256(payload).digest() != digest:
        raise CorruptCheckpoint("checksum mismatch")
    try:
        obj = pickle.loads(payload)
        return state_from_dict(obj["state"]), obj["meta"]
    except Exception as exc:  # checksum passed but content unusable (e.g. older layout)
        raise CorruptCheckpoint(f"unreadable content ({exc})") from None


def save(path, state: RunState, meta: dict) -> Path:
    """Write atomically (temporary file, fsync, rename)."""
    return atomic_write_bytes(path, encode(state, meta))


def load(path) -> tuple[RunState, dict]:
    """Read and verify a checkpoint; CorruptCheckpoint if damaged, FileNotFoundError if absent."""
    return decode(Path(path).read_bytes())


def fsync_file(path) -> None:
    """Flush a file's data to disk (it may be open elsewhere)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
