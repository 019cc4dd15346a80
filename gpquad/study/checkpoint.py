"""Atomic, self-checking checkpoints of a coevolution run (RunState), in a data format.

File layout: an 8-byte magic ``GPQCKPT2``, the payload length (8 bytes, little-endian),
the payload's SHA-256 (32 bytes), then the payload: UTF-8 JSON of
``{"state": {field: value, ...}, "meta": {...}}``. Arrays are written as
``{"dtype": ..., "shape": [...], "data": [...]}`` and trees as ``{"codes", "values",
"delays"}`` lists; floats are written with repr, so a resumed run is bit-identical. The
state holds every field of `RunState` except the unflushed history rows, which the caller
must have written to disk first. Reading builds nothing but numbers, strings, lists and
numpy arrays of numeric dtypes, each checked: a checkpoint is data, never code. A short,
damaged or foreign file raises `CorruptCheckpoint`, and so does an older pickled checkpoint
(magic ``GPQCKPT1``), which is never unpickled; the caller restarts that run.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import struct
from pathlib import Path

import numpy as np

from gpquad.engine.evolve.state import RunState
from gpquad.engine.tree.encoding import Tree, is_valid
from gpquad.engine.tree.operators import VAR_BASE
from gpquad.study.store import atomic_write_bytes

MAGIC = b"GPQCKPT2"
#: The magic of the older pickled checkpoints: refused unread.
PICKLED_MAGIC = b"GPQCKPT1"
_HEADER = struct.Struct("<8sQ32s")
#: Largest checkpoint read (bytes).
MAX_BYTES = 1 << 30
_ARRAYS = {"model_errors": "float64", "tests": "int64", "suite": "int64", "suite_age": "int64"}


class CorruptCheckpoint(Exception):
    """A checkpoint that is truncated, damaged or not a checkpoint at all."""


def state_to_dict(state: RunState) -> dict:
    """Every RunState field but `history` (rows must be flushed before checkpointing), as
    plain JSON data."""
    out = {}
    for f in dataclasses.fields(state):
        value = getattr(state, f.name)
        if f.name == "history":
            continue
        if f.name == "models":
            value = [
                {
                    "codes": t.codes.tolist(),
                    "values": t.values.tolist(),
                    "delays": t.delays.tolist(),
                }
                for t in value
            ]
        elif isinstance(value, np.ndarray):
            value = {
                "dtype": str(value.dtype),
                "shape": list(value.shape),
                "data": value.ravel().tolist(),
            }
        out[f.name] = value
    return out


def _array(record, name: str) -> np.ndarray:
    dtype = _ARRAYS[name]
    if (
        not isinstance(record, dict)
        or record.get("dtype") != dtype
        or not isinstance(record.get("shape"), list)
        or not isinstance(record.get("data"), list)
    ):
        raise CorruptCheckpoint(f"{name} is not a {dtype} array record")
    shape = record["shape"]
    if (
        not all(isinstance(n, int) and n >= 0 for n in shape)
        or len(shape) > 2
        or math.prod(shape) != len(record["data"])
    ):
        raise CorruptCheckpoint(f"{name} has a bad shape {shape}")
    kind = float if dtype == "float64" else int
    if not all(type(v) is kind or (kind is float and type(v) is int) for v in record["data"]):
        raise CorruptCheckpoint(f"{name} holds values that are not {dtype}")
    return np.array(record["data"], dtype=dtype).reshape(shape)


def _tree(record, i: int) -> Tree:
    if not isinstance(record, dict):
        raise CorruptCheckpoint(f"model {i} is not a tree record")
    codes, values, delays = (record.get(k) for k in ("codes", "values", "delays"))
    ok = (
        isinstance(codes, list)
        and isinstance(values, list)
        and isinstance(delays, list)
        and len(codes) == len(values)
        and codes
        and all(type(c) is int and c >= 0 for c in codes)
        and all(type(v) in (float, int) for v in values)
        and all(type(d) is int and 0 <= d <= 1_000_000 for d in delays)
        and is_valid(codes)
    )
    if not ok:
        raise CorruptCheckpoint(f"model {i} is not a valid tree")
    return Tree.from_lists(codes, values, delays)


def _rng_state(record) -> dict:
    """A numpy bit generator state: a dict of strings, ints and such dicts only."""

    def plain(x, depth=0):
        if isinstance(x, dict) and depth < 3:
            return all(isinstance(k, str) and plain(v, depth + 1) for k, v in x.items())
        return type(x) in (int, str)

    if not (
        isinstance(record, dict) and plain(record) and isinstance(record.get("bit_generator"), str)
    ):
        raise CorruptCheckpoint("rng_state is not a bit generator state")
    try:
        bit_generator = getattr(np.random, record["bit_generator"])
        if not (
            isinstance(bit_generator, type) and issubclass(bit_generator, np.random.BitGenerator)
        ):
            raise TypeError(record["bit_generator"])
        bit_generator().state = record  # numpy checks every entry
    except (AttributeError, TypeError, ValueError, KeyError, OverflowError) as exc:
        raise CorruptCheckpoint(f"rng_state is not a usable generator state ({exc})") from None
    return record


def state_from_dict(fields: dict) -> RunState:
    """The RunState of checked plain data (CorruptCheckpoint when any field is off)."""
    names = {f.name for f in dataclasses.fields(RunState)} - {"history"}
    # a checkpoint of gpquad 0.2 has no best_errors: its run goes on without them
    if not isinstance(fields, dict) or set(fields) not in (names, names - {"best_errors"}):
        raise CorruptCheckpoint("the state's fields are not RunState's")
    best_errors = fields.get("best_errors", [])
    if not isinstance(best_errors, list) or not all(type(e) in (int, float) for e in best_errors):
        raise CorruptCheckpoint("best_errors is not a list of numbers")
    if (
        not isinstance(fields["target"], str)
        or type(fields["iteration"]) is not int
        or type(fields["inserted"]) is not int
        or fields["iteration"] < 0
    ):
        raise CorruptCheckpoint("target, iteration or inserted has a bad value")
    if not isinstance(fields["models"], list) or not fields["models"]:
        raise CorruptCheckpoint("models is not a list of trees")
    arrays = {name: _array(fields[name], name) for name in _ARRAYS}
    models = [_tree(t, i) for i, t in enumerate(fields["models"])]
    if (
        arrays["model_errors"].shape != (len(models),)
        or arrays["suite"].shape != arrays["suite_age"].shape
    ):
        raise CorruptCheckpoint("the arrays' lengths do not match the population")
    return RunState(
        target=fields["target"],
        iteration=fields["iteration"],
        models=models,
        inserted=fields["inserted"],
        rng_state=_rng_state(fields["rng_state"]),
        best_errors=[float(e) for e in best_errors],
        **arrays,  # type: ignore[arg-type]
    )


def encode(state: RunState, meta: dict) -> bytes:
    """Header + JSON of the state's fields and `meta` (plain data)."""
    payload = json.dumps({"state": state_to_dict(state), "meta": dict(meta)}).encode()
    return _HEADER.pack(MAGIC, len(payload), hashlib.sha256(payload).digest()) + payload


def decode(blob: bytes) -> tuple[RunState, dict]:
    """Inverse of `encode`; raises CorruptCheckpoint on any damage, and on an older pickled
    checkpoint (not read: a pickle can run code)."""
    if len(blob) < _HEADER.size:
        raise CorruptCheckpoint(f"{len(blob)} bytes, shorter than the {_HEADER.size}-byte header")
    magic, length, digest = _HEADER.unpack_from(blob)
    if magic == PICKLED_MAGIC:
        raise CorruptCheckpoint("an older pickled checkpoint, not read (a pickle can run code)")
    if magic != MAGIC:
        raise CorruptCheckpoint("not a gpquad checkpoint (bad magic)")
    payload = blob[_HEADER.size :]
    if len(payload) != length:
        raise CorruptCheckpoint(f"payload is {len(payload)} bytes, header says {length}")
    if hashlib.sha256(payload).digest() != digest:
        raise CorruptCheckpoint("checksum mismatch")
    try:
        obj = json.loads(payload.decode())
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise CorruptCheckpoint(f"unreadable content ({type(exc).__name__})") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("meta"), dict):
        raise CorruptCheckpoint("unreadable content (no state and meta)")
    state = obj.get("state")
    if not isinstance(state, dict):
        raise CorruptCheckpoint("unreadable content (no state and meta)")
    return state_from_dict(state), obj["meta"]


def save(path, state: RunState, meta: dict) -> Path:
    """Write atomically (temporary file, fsync, rename)."""
    return atomic_write_bytes(path, encode(state, meta))


def load(path) -> tuple[RunState, dict]:
    """Read and verify a checkpoint; CorruptCheckpoint if damaged (or not a regular file, or
    over MAX_BYTES), FileNotFoundError if absent."""
    path = Path(path)
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise CorruptCheckpoint("not a regular file")
    if path.stat().st_size > MAX_BYTES:
        raise CorruptCheckpoint(f"larger than {MAX_BYTES} bytes")
    return decode(path.read_bytes())


def fsync_file(path) -> None:
    """Flush a file's data to disk (it may be open elsewhere)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def check_fits(state: RunState, co) -> RunState:
    """`state` when it is a state of this coevolution `co` (target, population sizes, leaf
    codes, delays, window positions); CorruptCheckpoint otherwise, before any of it is used."""
    cfg, params = co.cfg, co.params
    n_rows = len(co.dataset.arrays.states)
    if state.target != co.target:
        raise CorruptCheckpoint(f"written for target {state.target!r}, not {co.target!r}")
    if (
        len(state.models) != cfg.n_models
        or len(state.tests) != cfg.n_tests
        or len(state.suite) != cfg.suite_size
    ):
        raise CorruptCheckpoint("its population sizes are not this config's")
    for i, tree in enumerate(state.models):
        if (
            int(tree.codes.max()) >= VAR_BASE + params.n_variables
            or len(tree.delays) != params.n_inputs
            or tree.delays.max(initial=0) > cfg.max_delay
        ):
            raise CorruptCheckpoint(f"model {i} uses leaves or delays this config has not")
    tests, suite = state.tests, state.suite
    if (len(tests) and (tests.min() < 0 or tests.max() >= co.space.size)) or (
        len(suite) and (suite.min() < 0 or suite.max() + co.window_steps >= n_rows)
    ):
        raise CorruptCheckpoint("its windows lie outside the training data")
    return state


def history_bytes(meta: dict, header: int, size: int) -> int:
    """The history length a checkpoint recorded, checked against the file: a whole number
    from the header's end to the file's current size (CorruptCheckpoint otherwise)."""
    value = meta.get("history_bytes")
    if type(value) is not int or not header <= value <= size:
        raise CorruptCheckpoint(
            f"it records a history of {value!r} bytes; history.csv has {size} (header {header})"
        )
    return value
