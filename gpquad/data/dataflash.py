"""A small reader of ArduPilot DataFlash `.bin` logs (self-describing FMT records).

Every record is `0xA3 0x95 <type>` followed by a payload whose layout an earlier FMT record
(type 128) gave: `Type (B), Length (B, with the 3 header bytes), Name (4 chars), Format
(16 chars), Columns (64 chars, comma-separated)`. Format characters (ArduPilot
libraries/AP_Logger/LogStructure.h): b B h H i I q Q integers, f d floats, n N Z strings of
4, 16, 64 chars, c C (x 0.01), e E (x 0.01), L (lat/lon x 1e-7), M (mode, uint8), a
(int16[32]). Records of one type are decoded at once with a numpy structured dtype.

The reader needs nothing beyond numpy (pymavlink is not required); a record whose type has
no FMT, or a truncated tail, makes it resynchronise on the next header and count the skipped
bytes. Cross-checked against pymavlink in tests/test_data_ardupilot.py.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from gpquad.errors import GpquadError

HEAD = b"\xa3\x95"
FMT_TYPE = 128
FMT_LENGTH = 89
_FMT = struct.Struct("<BB4s16s64s")
#: Format character -> (numpy dtype, scale or None).
_TYPES = {
    "b": ("<i1", None),
    "B": ("<u1", None),
    "h": ("<i2", None),
    "H": ("<u2", None),
    "i": ("<i4", None),
    "I": ("<u4", None),
    "q": ("<i8", None),
    "Q": ("<u8", None),
    "f": ("<f4", None),
    "d": ("<f8", None),
    "n": ("S4", None),
    "N": ("S16", None),
    "Z": ("S64", None),
    "c": ("<i2", 0.01),
    "C": ("<u2", 0.01),
    "e": ("<i4", 0.01),
    "E": ("<u4", 0.01),
    "L": ("<i4", 1e-7),
    "M": ("<u1", None),
    "a": (("<i2", (32,)), None),
}


class DataFlashLog:
    """Messages of a .bin file: `names()`, `columns(name)`, `get(name) -> {column: array}`."""

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise GpquadError("file not found", source=str(self.path))
        self.buf = self.path.read_bytes()
        self.formats: dict[int, tuple[str, str, list[str], int]] = {}
        self.offsets: dict[int, list[int]] = {}
        self.skipped = 0
        self._scan()
        if not self.formats:
            raise GpquadError(
                "not an ArduPilot DataFlash log (no FMT records)", source=str(self.path)
            )

    def _scan(self) -> None:
        buf, n, pos = self.buf, len(self.buf), 0
        formats, offsets = self.formats, self.offsets
        while pos + 3 <= n:
            if buf[pos] != 0xA3 or buf[pos + 1] != 0x95:
                nxt = buf.find(HEAD, pos + 1)
                self.skipped += (nxt if nxt >= 0 else n) - pos
                if nxt < 0:
                    break
                pos = nxt
                continue
            kind = buf[pos + 2]
            if kind == FMT_TYPE:
                if pos + FMT_LENGTH > n:
                    break
                typ, length, name, fmt, cols = _FMT.unpack_from(buf, pos + 3)
                formats[typ] = (_text(name), _text(fmt), _text(cols).split(","), length)
                pos += FMT_LENGTH
                continue
            spec = formats.get(kind)
            if spec is None or pos + spec[3] > n:
                self.skipped += 1
                pos += 1
                continue
            offsets.setdefault(kind, []).append(pos + 3)
            pos += spec[3]

    def names(self) -> list[str]:
        return sorted(self.formats[k][0] for k in self.offsets)

    def _type(self, name: str) -> int | None:
        return next(
            (k for k, f in self.formats.items() if f[0] == name and k in self.offsets), None
        )

    def columns(self, name: str) -> list[str]:
        k = self._type(name)
        return [] if k is None else list(self.formats[k][2])

    def get(self, name: str) -> dict[str, np.ndarray]:
        """Every record of message `name` as arrays (scaled to the logged units)."""
        k = self._type(name)
        if k is None:
            return {}
        _, fmt, cols, length = self.formats[k]
        try:
            dtype = np.dtype([(c, _TYPES[ch][0]) for c, ch in zip(cols, fmt, strict=True)])
        except (KeyError, ValueError):
            raise GpquadError(
                f"cannot decode message {name} (format '{fmt}')", source=str(self.path), field=name
            ) from None
        if dtype.itemsize != length - 3:
            raise GpquadError(
                f"message {name}: format '{fmt}' is {dtype.itemsize} bytes, the "
                f"FMT record says {length - 3}",
                source=str(self.path),
                field=name,
            )
        starts = np.asarray(self.offsets[k], dtype=np.int64)
        raw = np.frombuffer(self.buf, dtype=np.uint8)[starts[:, None] + np.arange(length - 3)]
        rec = np.ascontiguousarray(raw).view(dtype).reshape(-1)
        out = {}
        for c, ch in zip(cols, fmt, strict=True):
            scale = _TYPES[ch][1]
            out[c] = rec[c] * scale if scale else rec[c]
        return out

    def params(self) -> dict[str, float]:
        """PARM records: name -> last value."""
        p = self.get("PARM")
        if not p:
            return {}
        return {_text(n): float(v) for n, v in zip(p["Name"], p["Value"], strict=True)}


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", errors="replace").strip()
