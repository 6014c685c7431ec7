"""A structural check of MATLAB v5/v7 files, before SciPy reads them.

SciPy's MAT v5 reader (``scipy.io.loadmat``, compiled code) trusts the type code of
each data element: a damaged file whose numeric data element carries a code that is
not a MATLAB data type (a zeroed block, a flipped byte) makes it read through a null
pointer, and the whole process dies (a segmentation fault: no message, no other
recording analysed). :func:`mat5_variables` walks the file's elements in pure Python
first, following the MAT-file format (MathWorks, "MAT-File Format", v5 data elements:
an 8-byte tag of type and byte count, or a 4-byte small data element; ``miMATRIX``
arrays of array flags, dimensions, name and data; ``miCOMPRESSED`` zlib streams), and
refuses what SciPy would crash on. The variables a recording needs are checked down to
their data; the others only by their header, and SciPy is then asked for the needed
ones only (``variable_names``), so it never parses the rest.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass

from ..errors import InputError

__all__ = ["MatVariable", "mat5_variables", "MAT_CLASS_NAMES"]

#: MATLAB data types (miINT8 ... miUTF32) that hold numbers, and their item size in bytes.
_MI_SIZE = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8, 16: 1, 17: 2, 18: 4}
_MI_MATRIX = 14
_MI_COMPRESSED = 15
_MI_INT8, _MI_INT32, _MI_UINT32, _MI_UTF8 = 1, 5, 6, 16

#: MATLAB array classes (the low byte of the array flags), for messages.
MAT_CLASS_NAMES = {
    1: "cell array",
    2: "struct",
    3: "object",
    4: "char array",
    5: "sparse matrix",
    6: "double",
    7: "single",
    8: "int8",
    9: "uint8",
    10: "int16",
    11: "uint16",
    12: "int32",
    13: "uint32",
    14: "int64",
    15: "uint64",
    16: "function handle",
    17: "opaque object (string, table, datetime...)",
}
_NUMERIC = frozenset(range(6, 16))
_CHAR, _CELL, _STRUCT, _OBJECT = 4, 1, 2, 3
#: Largest decompressed variable, bytes (a recording of 10^8 double samples is 800 MB).
MAX_VARIABLE_BYTES = 1 << 31


class _Damaged(Exception):
    """A structural problem; the message says where."""


@dataclass(frozen=True)
class MatVariable:
    """A top-level variable of a MAT v5 file: its name, class and dimensions."""

    name: str
    mclass: int
    dims: tuple[int, ...]

    @property
    def class_name(self) -> str:
        return MAT_CLASS_NAMES.get(self.mclass, f"class {self.mclass}")


class _Reader:
    def __init__(self, data: bytes, order: str) -> None:
        self.data = data
        self.order = order

    def u32(self, pos: int) -> int:
        return struct.unpack_from(self.order + "I", self.data, pos)[0]

    def tag(self, pos: int, end: int) -> tuple[int, int, int, int]:
        """(type, byte count, data start, next element) of the element at ``pos``."""
        if pos + 8 > end:
            raise _Damaged(f"an element tag at byte {pos} runs past the end of its array")
        word = self.u32(pos)
        if word >> 16:  # small data element: type and count in 4 bytes, data in the other 4
            mdtype, count = word & 0xFFFF, word >> 16
            if count > 4:
                raise _Damaged(f"a small data element at byte {pos} claims {count} bytes")
            return mdtype, count, pos + 4, pos + 8
        count = self.u32(pos + 4)
        start = pos + 8
        stop = start + count
        if stop > end:
            raise _Damaged(f"an element at byte {pos} claims {count} bytes, past the end of its array")
        return word, count, start, start + count + (-count % 8)

    def numbers(self, pos: int, end: int, what: str) -> tuple[int, int]:
        """Check a numeric data element; return (element count, next position)."""
        mdtype, count, _, nxt = self.tag(pos, end)
        size = _MI_SIZE.get(mdtype)
        if size is None:
            raise _Damaged(f"{what}: data of type code {mdtype}, which is no MATLAB number type")
        if count % size:
            raise _Damaged(f"{what}: {count} bytes of {size}-byte numbers")
        return count // size, nxt

    def ints(self, pos: int, end: int, what: str) -> tuple[list[int], int]:
        mdtype, count, start, nxt = self.tag(pos, end)
        if mdtype not in (_MI_INT32, _MI_UINT32) or count % 4:
            raise _Damaged(f"{what}: expected 32-bit integers (type code {mdtype}, {count} bytes)")
        return list(struct.unpack_from(f"{self.order}{count // 4}i", self.data, start)), nxt

    def text(self, pos: int, end: int, what: str) -> tuple[str, int]:
        mdtype, count, start, nxt = self.tag(pos, end)
        if mdtype not in (_MI_INT8, _MI_UTF8):
            raise _Damaged(f"{what}: expected text (type code {mdtype})")
        return self.data[start : start + count].decode("latin-1"), nxt

    def matrix(self, pos: int, end: int, what: str, deep: bool) -> tuple[MatVariable, int]:
        """Check the miMATRIX element at ``pos``; return its header and the next position.

        ``deep``: check its data too (recursively for structs, cells and objects).
        """
        mdtype, count, start, nxt = self.tag(pos, end)
        if mdtype != _MI_MATRIX:
            raise _Damaged(f"{what}: expected an array (type code 14), found type code {mdtype}")
        stop = start + count
        ftype, fcount, fstart, p = self.tag(start, stop)
        if ftype != _MI_UINT32 or fcount != 8:
            raise _Damaged(f"{what}: damaged array flags")
        flags = self.u32(fstart)
        mclass, cplx = flags & 0xFF, bool(flags >> 11 & 1)
        if mclass == 17:  # opaque objects (MATLAB strings, tables...) have no dimensions
            name, p = self.text(p, stop, what)
            if deep:
                raise _Damaged(f"variable {name!r} is a MATLAB {MAT_CLASS_NAMES[17]}, expected numbers")
            return MatVariable(name, mclass, ()), nxt
        dims, p = self.ints(p, stop, f"{what}: dimensions")
        if not 1 <= len(dims) <= 32 or any(d < 0 for d in dims):
            raise _Damaged(f"{what}: damaged dimensions {dims[:4]}")
        name, p = self.text(p, stop, f"{what}: name")
        var = MatVariable(name, mclass, tuple(dims))
        where = f"variable {name!r}" if name else what
        if not deep:
            return var, nxt
        n = math.prod(dims)
        if mclass in _NUMERIC or mclass == _CHAR:
            for part in ("real", "imaginary")[: 1 + (cplx and mclass != _CHAR)]:
                k, p = self.numbers(p, stop, f"{where} ({part} part)")
                if k != n and mclass != _CHAR:  # UTF-8 text has more bytes than characters
                    raise _Damaged(f"{where}: {k} numbers for dimensions {'x'.join(map(str, dims))}")
        elif mclass == _CELL:
            for i in range(n):
                _, p = self.matrix(p, stop, f"{where}{{{i + 1}}}", True)
        elif mclass in (_STRUCT, _OBJECT):
            if mclass == _OBJECT:
                _, p = self.text(p, stop, f"{where}: class name")
            (width,), p = self.ints(p, stop, f"{where}: field name length")
            mdt, cnt, _, p = self.tag(p, stop)
            if mdt != _MI_INT8 or width <= 0 or cnt % width:
                raise _Damaged(f"{where}: damaged field names")
            for i in range(n * (cnt // width)):
                _, p = self.matrix(p, stop, f"{where} field {i + 1}", True)
        else:
            raise _Damaged(f"{where} is a MATLAB {var.class_name}, which a recording does not hold")
        return var, nxt


def mat5_variables(data: bytes, needed, source: str) -> list[MatVariable]:
    """The top-level variables of a MAT v5/v7 file, the ``needed`` ones checked down to their data.

    Parameters
    ----------
    data : bytes
        The whole file (a MAT v5 header: 128 bytes, version 0x0100).
    needed : callable
        ``needed(name) -> bool``: the variables to check fully (those SciPy will read).
    source : str
        The file, named in messages.

    Raises
    ------
    InputError
        Naming the file and what is damaged (a truncated element, a data type code that is
        no MATLAB type, a count that does not match the dimensions...).
    """
    if len(data) < 128:
        raise InputError("not a readable MATLAB .mat file (shorter than its 128-byte header)", source=source)
    order = {b"IM": "<", b"MI": ">"}.get(data[126:128])
    if order is None:
        raise InputError("not a readable MATLAB .mat file (no endian mark in its header)", source=source)
    r = _Reader(data, order)
    out: list[MatVariable] = []
    pos = 128
    try:
        while pos < len(data):
            if len(data) - pos < 8:
                raise _Damaged(f"{len(data) - pos} stray bytes at the end (a truncated file?)")
            mdtype, count, start, _ = r.tag(pos, len(data))
            what = f"variable {len(out) + 1} (byte {pos})"
            if mdtype == _MI_COMPRESSED:
                try:
                    z = zlib.decompressobj()
                    inner = z.decompress(data[start : start + count], MAX_VARIABLE_BYTES)
                except zlib.error as e:
                    raise _Damaged(f"{what}: damaged compressed data ({e})") from None
                if z.unconsumed_tail:
                    raise _Damaged(f"{what}: more than {MAX_VARIABLE_BYTES} bytes once decompressed")
                ri = _Reader(inner, order)
                head, _ = ri.matrix(0, len(inner), what, deep=False)
                if needed(head.name):
                    ri.matrix(0, len(inner), what, deep=True)
            else:
                head, _ = r.matrix(pos, len(data), what, deep=False)
                if needed(head.name):
                    r.matrix(pos, len(data), what, deep=True)
            out.append(head)
            pos = start + count  # top-level elements are not padded (compressed ones are not aligned)
    except _Damaged as e:
        raise InputError(f"not a readable MATLAB .mat file (damaged: {e})", source=source) from None
    except struct.error:
        raise InputError("not a readable MATLAB .mat file (damaged: truncated)", source=source) from None
    return out
