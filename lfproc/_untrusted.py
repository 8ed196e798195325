"""Reading untrusted files: the one checked way every lfproc reader takes.

Files lfproc reads come from cameras, other tools and strangers. Everything a reader takes
from a file (a JSON field, a size in a header, a member of an archive, a path named inside
the file) goes through this module, which checks it *before* it is used or anything is
allocated, and raises an lfproc error naming the file, the field and what was wrong.
Hand-written rather than a schema library: the checks that matter here (sizes against
each other and against the file's size, expansion of compressed members, paths confined
to a folder) are not what JSON-schema validators do, and the typed accessor is short.

Errors
------
Every function takes ``source`` (the file, named first in messages) and ``error`` (the
class raised; default :class:`~lfproc.errors.FileFormatError`, readers pass their own
subclass such as ``LfpFormatError`` or ``ProfileError``). Paths that leave their folder,
links in archives and compression bombs raise :class:`~lfproc.errors.UnsafeFileError`.

API
---
Limits (module constants; every function also takes its limit as a keyword)

* ``MAX_JSON_BYTES`` (64 MiB), ``MAX_JSON_DEPTH`` (64): size and nesting of one JSON text.
* ``MAX_TEXT_BYTES`` (64 MiB): any text file read whole (manifests, descriptors).
* ``MAX_ARRAY_BYTES`` (4 GiB): one array allocated from a header.
* ``MAX_DIMENSION`` (2**20), ``MAX_PIXELS`` (2**28): one image axis, one image.
* ``EXPANSION_RATIO`` (100) and ``EXPANSION_FLOOR`` (64 MiB): a compressed input may expand
  to ``max(EXPANSION_FLOOR, EXPANSION_RATIO * compressed size)`` bytes, no more.

JSON

* ``parse_json(data, source=..., error=..., trailing="error"|"ignore")``: text/bytes -> value,
  with size and nesting checked before parsing; ``load_json(path, ...)`` reads a file.
* ``Node(value, source, error=...)``: typed access to a parsed value. ``node["a"]["b"]``
  (missing key -> error naming ``a.b``), ``node.get("a")`` (``None`` when missing or null),
  ``node.has("a")``, ``node.at("a.b.0.c", default)``, ``node.first("a.b", "c.d")`` (the first
  present), ``node.items()``; conversions ``as_dict()``, ``as_list(min_len=, max_len=)``,
  ``as_str(max_len=, choices=, pattern=, nonempty=)``, ``as_int(low=, high=)``,
  ``as_float(low=, high=, strict_low=, strict_high=, finite=, parse_str=)``, ``as_bool()``,
  ``as_floats(length=, **checks)``, ``as_ints(...)``; ``opt_int/opt_float/opt_str/opt_bool(key,
  default, **checks)`` give ``default`` for a missing or null field, ``opt_dict(key)`` an empty
  object. ``node.fail(message)`` builds the error for a rule of your own. ``node.value`` is the
  raw value, ``node.path`` its dotted name. Bools are never numbers; integral floats are
  accepted as ints.

Sizes and arrays

* ``check_dims(shape, source=..., what=..., max_dim=, max_pixels=)``: positive ints within limits.
* ``check_nbytes(shape, dtype, ...)``: bytes of an array from a header, against ``max_bytes``.
* ``expansion_limit(compressed)`` and ``check_expansion(expanded, compressed, ...)``: the
  compression-bomb rule above.
* ``read_npy(fileobj, size, ...)``: one ``.npy`` stream; its header (dtype, shape, order) is
  read and checked (no object dtypes, ``expect_shape``/``expect_dtype``, bytes = stream size)
  before the data are read.
* ``read_npz(path, ...)``: every (or the named) array of a ``.npz``/ZIP file, each member's
  declared size checked and their sum against the expansion rule first.
  ``npz_members(path)`` lists names and declared sizes without reading data.

Compressed data and archives

* ``read_capped(fileobj, limit, ...)``: read a stream, failing once it exceeds ``limit``.
* ``open_tar(path, ...)``: a context manager yielding a :class:`tarfile.TarFile` over a
  stream capped by the expansion rule (plain, gzip, bzip2 or xz); ``safe_members(tar, ...)``
  lists its regular files and refuses absolute names, ``..``, links and devices;
  ``read_member(tar, member, max_bytes=...)`` reads one member.

Paths

* ``resolve_inside(base, name, source=..., field=..., root=None)``: a path named inside a file,
  resolved against the folder ``base`` holding that file; refused (``UnsafeFileError``) when it
  is absolute or leads outside ``base`` (or outside ``root``, a folder the user named),
  symlinks included.
* ``safe_filename(text, what=..., source=...)``: a name taken from file content (serial
  number, id) checked to be a plain file-name component (letters, digits, ``._-``, no leading
  dot, at most 64 characters) before it is used to build a file name.
* ``inside(folder, path)``: whether ``path`` resolves inside ``folder``.

Example (the pattern every reader follows)::

    from lfproc import _untrusted as ut
    doc = ut.load_json(path, error=FileFormatError)             # Node
    n_atoms = doc["atoms"].as_int(low=1, high=1 << 20)
    size = doc["patch"]["size"].as_int(low=1, high=64)
    arrays = ut.read_npz(npz_path, expect={"D": ((size * size, n_atoms), "float32")})
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import tarfile
import zipfile
import zlib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from .errors import FileFormatError, LfprocError, UnsafeFileError

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_TEXT_BYTES",
    "MAX_ARRAY_BYTES",
    "MAX_DIMENSION",
    "MAX_PIXELS",
    "EXPANSION_RATIO",
    "EXPANSION_FLOOR",
    "Node",
    "parse_json",
    "load_json",
    "json_depth",
    "read_text",
    "read_bytes",
    "check_dims",
    "check_nbytes",
    "expansion_limit",
    "check_expansion",
    "read_capped",
    "read_npy",
    "read_npz",
    "npz_members",
    "open_tar",
    "safe_members",
    "read_member",
    "resolve_inside",
    "inside",
    "safe_filename",
    "show",
]

MAX_JSON_BYTES = 64 << 20
MAX_JSON_DEPTH = 64
MAX_TEXT_BYTES = 64 << 20
MAX_ARRAY_BYTES = 4 << 30
MAX_DIMENSION = 1 << 20
MAX_PIXELS = 1 << 28
EXPANSION_RATIO = 100
EXPANSION_FLOOR = 64 << 20

_ERRORS = (FileFormatError,)


def show(value: Any, limit: int = 60) -> str:
    """``repr`` of a value from a file, cut to ``limit`` characters for error messages."""
    try:
        text = repr(value)
    except Exception:  # pragma: no cover - reprs of JSON values do not fail
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, np.integer)):
        return "an integer"
    if isinstance(value, (float, np.floating)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, Mapping):
        return "an object"
    if isinstance(value, (list, tuple)):
        return "a list"
    return type(value).__name__


def _where(source) -> str:
    return f"{source}: " if source not in (None, "") else ""


# -- JSON -----------------------------------------------------------------------------------
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")


def json_depth(text: str) -> int:
    """Largest nesting depth of brackets outside strings (no recursion, linear time)."""
    brackets = _NOT_BRACKET.sub("", _JSON_STRING.sub("", text))
    if not brackets:
        return 0
    codes = np.frombuffer(brackets.encode("ascii"), dtype=np.uint8)
    steps = np.where((codes == ord("[")) | (codes == ord("{")), 1, -1).astype(np.int64)
    return int(np.cumsum(steps).max())


def parse_json(data: bytes | str, *, source=None, error: type[Exception] = FileFormatError, what: str = "",
               max_bytes: int | None = None, max_depth: int | None = None, trailing: str = "error",
               strip_nul: bool = False) -> Any:
    """Parse untrusted JSON with its size and nesting checked first.

    Parameters
    ----------
    data : bytes or str
        Bytes are decoded as UTF-8 (undecodable bytes are an error).
    source : file named in messages; ``what`` (e.g. ``"table of contents"``) follows it.
    trailing : ``"error"`` or ``"ignore"`` (Lytro TXT files may end in junk after the
        closing brace: the first complete value is returned).
    strip_nul : drop NUL padding around the text first.
    """
    max_bytes = MAX_JSON_BYTES if max_bytes is None else max_bytes
    max_depth = MAX_JSON_DEPTH if max_depth is None else max_depth
    label = _where(source) + (f"{what}: " if what else "")
    if len(data) > max_bytes:
        raise error(f"{label}JSON text of {len(data)} bytes exceeds the limit of {max_bytes} bytes")
    if isinstance(data, (bytes, bytearray, memoryview)):
        try:
            text = bytes(data).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise error(f"{label}not UTF-8 text (byte {exc.start}); expected JSON") from None
    else:
        text = data
    if strip_nul:
        text = text.strip("\x00")
    text = text.strip()
    depth = json_depth(text)
    if depth > max_depth:
        raise error(f"{label}JSON nested {depth} levels deep; the limit is {max_depth}")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        if trailing == "ignore":
            try:
                obj, _ = json.JSONDecoder().raw_decode(text)
                return obj
            except json.JSONDecodeError:
                pass
            except (ValueError, RecursionError) as exc2:
                raise error(f"{label}not valid JSON ({exc2})") from None
        raise error(f"{label}not valid JSON ({exc.msg} at character {exc.pos})") from None
    except (ValueError, RecursionError) as exc:  # e.g. integers longer than Python's 4300-digit limit
        why = "an integer with too many digits" if "digits" in str(exc) else str(exc)[:120]
        raise error(f"{label}not valid JSON ({why})") from None


def read_bytes(path: str | os.PathLike, *, max_bytes: int, source=None, error: type[Exception] = FileFormatError,
               what: str = "file") -> bytes:
    """The bytes of a file, refused (before reading) when it is larger than ``max_bytes``."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise error(f"{_where(source or path)}{what} of {size} bytes exceeds the limit of {max_bytes} bytes")
        with open(path, "rb") as fh:
            # read(n) allocates n bytes up front: ask for what the file holds, not the limit
            data = fh.read(size + 1)
            if len(data) > size:
                data += fh.read(max_bytes + 1 - len(data))
    except IsADirectoryError:
        raise error(f"{_where(source or path)}expected a {what}, found a folder") from None
    if len(data) > max_bytes:  # grew while we read it
        raise error(f"{_where(source or path)}{what} exceeds the limit of {max_bytes} bytes")
    return data


def read_text(path: str | os.PathLike, *, max_bytes: int | None = None, source=None,
              error: type[Exception] = FileFormatError, what: str = "text file", encoding: str = "utf-8") -> str:
    """A text file read whole, with a size limit and a clear error for non-text bytes."""
    data = read_bytes(path, max_bytes=MAX_TEXT_BYTES if max_bytes is None else max_bytes, source=source,
                      error=error, what=what)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error(f"{_where(source or path)}not a {what}: undecodable byte at offset {exc.start}") from None


def load_json(path: str | os.PathLike, *, source=None, error: type[Exception] = FileFormatError,
              max_bytes: int | None = None, max_depth: int | None = None, trailing: str = "error") -> "Node":
    """Read and parse a JSON file (limits as :func:`parse_json`); returns a :class:`Node`."""
    source = source or path
    max_bytes = MAX_JSON_BYTES if max_bytes is None else max_bytes
    data = read_bytes(path, max_bytes=max_bytes, source=source, error=error, what="JSON file")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    value = parse_json(data, source=source, error=error, max_bytes=max_bytes, max_depth=max_depth,
                       trailing=trailing)
    return Node(value, source=source, error=error)


_MISSING = object()


class Node:
    """A value from an untrusted document and where it came from (see the module docs).

    Parameters
    ----------
    value : the parsed value (dict, list, str, number, bool or None).
    source : file named in error messages.
    path : dotted field name of ``value`` in the document (``""`` for the root).
    error : exception class raised on a wrong value.
    """

    __slots__ = ("value", "source", "path", "error")

    def __init__(self, value: Any, source=None, path: str = "", error: type[Exception] = FileFormatError):
        self.value = value
        self.source = source
        self.path = path
        self.error = error

    def __repr__(self) -> str:
        return f"Node({self.path or '<root>'}={show(self.value)})"

    # -- navigation -----------------------------------------------------------------------
    def _child_path(self, key) -> str:
        key = str(key)
        return f"{self.path}.{key}" if self.path else key

    def fail(self, message: str) -> Exception:
        """The error to raise for this field: ``source: field 'path': message``."""
        field = f"field {self.path!r}: " if self.path else ""
        return self.error(f"{_where(self.source)}{field}{message}")

    def _expected(self, what: str) -> Exception:
        return self.fail(f"expected {what}, found {_kind(self.value)} {show(self.value)}"
                         if self.value is not None else f"expected {what}, found null")

    def __getitem__(self, key) -> "Node":
        node = self.get(key, _MISSING)
        if node is _MISSING:
            if isinstance(self.value, list):
                raise self.error(f"{_where(self.source)}field {self._child_path(key)!r}: missing "
                                 f"(the list has {len(self.value)} items)")
            raise self.error(f"{_where(self.source)}missing field {self._child_path(key)!r}")
        return node

    def get(self, key, default=None):
        """The child ``key`` as a Node; ``default`` when it is missing or null.

        On an object ``key`` is a string; on a list an int index. Raises when this value is
        neither (a scalar cannot have fields).
        """
        value = self.value
        if isinstance(value, Mapping):
            if key not in value:
                return default
            child = value[key]
        elif isinstance(value, list) and isinstance(key, int) and not isinstance(key, bool):
            if not -len(value) <= key < len(value):
                return default
            child = value[key]
        else:
            raise self._expected("an object" if isinstance(key, str) else "a list")
        if child is None and default is not _MISSING:
            return default
        return Node(child, self.source, self._child_path(key), self.error)

    def has(self, key) -> bool:
        """Whether ``key`` is present and not null (False for scalars)."""
        if isinstance(self.value, Mapping):
            return self.value.get(key) is not None
        if isinstance(self.value, list) and isinstance(key, int):
            return -len(self.value) <= key < len(self.value) and self.value[key] is not None
        return False

    def at(self, dotted: str, default=_MISSING):
        """Follow ``"a.b.0.c"`` (integers index lists); ``default`` (if given) when a step is
        missing or null, else an error naming the missing field."""
        node = self
        for part in dotted.split("."):
            key = int(part) if part.lstrip("-").isdigit() and isinstance(node.value, list) else part
            if default is _MISSING:
                node = node[key]
            else:
                if not isinstance(node.value, (Mapping, list)):
                    return default
                node = node.get(key)
                if node is None:
                    return default
        return node

    def first(self, *dotted: str, default=None):
        """The first of several dotted paths that is present (and not null), as a Node."""
        for d in dotted:
            node = self.at(d, None)
            if node is not None:
                return node
        return default

    # -- conversions ----------------------------------------------------------------------
    def as_dict(self) -> dict:
        if not isinstance(self.value, Mapping):
            raise self._expected("an object")
        return self.value

    def is_dict(self) -> bool:
        return isinstance(self.value, Mapping)

    def is_list(self) -> bool:
        return isinstance(self.value, list)

    def items(self) -> Iterator[tuple[str, "Node"]]:
        """``(key, Node)`` pairs of an object."""
        for key in list(self.as_dict()):
            yield key, Node(self.value[key], self.source, self._child_path(key), self.error)

    def as_list(self, *, min_len: int = 0, max_len: int | None = None) -> list["Node"]:
        value = self.value
        if not isinstance(value, list):
            raise self._expected("a list")
        if len(value) < min_len or (max_len is not None and len(value) > max_len):
            bounds = f"{min_len}..{max_len}" if max_len is not None else f"at least {min_len}"
            raise self.fail(f"expected a list of {bounds} items, found {len(value)}")
        return [Node(v, self.source, f"{self.path}[{i}]" if self.path else f"[{i}]", self.error)
                for i, v in enumerate(value)]

    def as_str(self, *, max_len: int = 4096, choices: Iterable[str] | None = None, pattern: str | None = None,
               nonempty: bool = False) -> str:
        value = self.value
        if not isinstance(value, str):
            raise self._expected("a string")
        if len(value) > max_len:
            raise self.fail(f"expected a string of at most {max_len} characters, found {len(value)}")
        if nonempty and not value.strip():
            raise self.fail("expected a non-empty string")
        if choices is not None:
            choices = tuple(choices)
            if value not in choices:
                raise self.fail(f"expected one of {', '.join(map(str, choices))}; found {show(value)}")
        if pattern is not None and not re.fullmatch(pattern, value):
            raise self.fail(f"expected a string matching {pattern}, found {show(value)}")
        return value

    def as_bool(self) -> bool:
        if not isinstance(self.value, (bool, np.bool_)):
            raise self._expected("true or false")
        return bool(self.value)

    def _number(self, *, parse_str: bool) -> float | int:
        value = self.value
        if isinstance(value, (bool, np.bool_)):
            raise self._expected("a number")
        if isinstance(value, (int, np.integer)):
            return int(value)
        if isinstance(value, (float, np.floating)):
            return float(value)
        if parse_str and isinstance(value, str) and len(value) <= 64:
            try:
                return float(value.strip())
            except ValueError:
                pass
        raise self._expected("a number")

    def _range(self, number, *, low, high, strict_low, strict_high, what):
        if low is not None and (number < low or (strict_low and number == low)):
            raise self.fail(f"expected {what} {'>' if strict_low else '>='} {low:g}, found {show(self.value)}")
        if high is not None and (number > high or (strict_high and number == high)):
            raise self.fail(f"expected {what} {'<' if strict_high else '<='} {high:g}, found {show(self.value)}")

    def as_float(self, *, low: float | None = None, high: float | None = None, strict_low: bool = False,
                 strict_high: bool = False, finite: bool = True, parse_str: bool = False) -> float:
        """A number (int or float; with ``parse_str`` also a numeric string) as a float,
        finite unless ``finite=False``, within ``[low, high]`` (``strict_*``: open bounds)."""
        number = self._number(parse_str=parse_str)
        try:
            number = float(number)
        except OverflowError:
            raise self.fail(f"expected a finite number, found an integer of {len(str(self.value))} digits") from None
        if finite and not math.isfinite(number):
            raise self.fail(f"expected a finite number, found {show(self.value)}")
        if math.isnan(number) and (low is not None or high is not None):
            raise self.fail(f"expected a number, found {show(self.value)}")
        self._range(number, low=low, high=high, strict_low=strict_low, strict_high=strict_high, what="a number")
        return number

    def as_int(self, *, low: int | None = None, high: int | None = None, parse_str: bool = False) -> int:
        """An integer (an integral float such as ``3.0`` is accepted) within ``[low, high]``."""
        number = self._number(parse_str=parse_str)
        if isinstance(number, float):
            if not math.isfinite(number) or number != int(number):
                raise self._expected("an integer")
            number = int(number)
        self._range(number, low=low, high=high, strict_low=False, strict_high=False, what="an integer")
        return number

    def as_floats(self, *, length: int | None = None, min_len: int = 0, max_len: int = 1 << 20, **checks) -> list[float]:
        """A list of numbers, each checked as :meth:`as_float`."""
        items = self.as_list(min_len=length if length is not None else min_len,
                             max_len=length if length is not None else max_len)
        return [item.as_float(**checks) for item in items]

    def as_ints(self, *, length: int | None = None, min_len: int = 0, max_len: int = 1 << 20, **checks) -> list[int]:
        """A list of integers, each checked as :meth:`as_int`."""
        items = self.as_list(min_len=length if length is not None else min_len,
                             max_len=length if length is not None else max_len)
        return [item.as_int(**checks) for item in items]

    # -- optional fields ------------------------------------------------------------------
    def opt_float(self, key, default=None, **checks):
        node = self.get(key)
        return default if node is None else node.as_float(**checks)

    def opt_int(self, key, default=None, **checks):
        node = self.get(key)
        return default if node is None else node.as_int(**checks)

    def opt_str(self, key, default=None, **checks):
        node = self.get(key)
        return default if node is None else node.as_str(**checks)

    def opt_bool(self, key, default=None):
        node = self.get(key)
        return default if node is None else node.as_bool()

    def opt_dict(self, key) -> "Node":
        """The child object ``key``, or an empty object Node when it is missing or null."""
        node = self.get(key)
        if node is None:
            return Node({}, self.source, self._child_path(key), self.error)
        node.as_dict()
        return node


# -- sizes ----------------------------------------------------------------------------------
def check_dims(shape: Iterable[Any], *, source=None, what: str = "image", error: type[Exception] = FileFormatError,
               max_dim: int | None = None, max_pixels: int | None = None, allow_zero: bool = False) -> tuple[int, ...]:
    """Sizes from a header as positive ints within ``max_dim`` each and ``max_pixels`` in all."""
    max_dim = MAX_DIMENSION if max_dim is None else max_dim
    max_pixels = MAX_PIXELS if max_pixels is None else max_pixels
    out = []
    for v in shape:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer, float, np.floating)) or (
                isinstance(v, (float, np.floating)) and not (math.isfinite(v) and v == int(v))):
            raise error(f"{_where(source)}{what} size: expected integers, found {show(list(shape))}")
        v = int(v)
        if v < (0 if allow_zero else 1) or v > max_dim:
            raise error(f"{_where(source)}{what} size {show(list(shape))}: each side must lie in "
                        f"{0 if allow_zero else 1}..{max_dim}")
        out.append(v)
    total = math.prod(out)
    if total > max_pixels:
        raise error(f"{_where(source)}{what} size {' x '.join(map(str, out))} = {total} elements exceeds the limit "
                    f"of {max_pixels}")
    return tuple(out)


def check_nbytes(shape: Iterable[int], dtype, *, source=None, what: str = "array",
                 error: type[Exception] = FileFormatError, max_bytes: int | None = None) -> int:
    """Bytes of an array of ``shape`` and ``dtype``; an error above ``max_bytes``."""
    max_bytes = MAX_ARRAY_BYTES if max_bytes is None else max_bytes
    nbytes = math.prod(int(s) for s in shape) * np.dtype(dtype).itemsize
    if nbytes > max_bytes:
        raise error(f"{_where(source)}{what} of shape {tuple(shape)} ({np.dtype(dtype)}) needs {nbytes} bytes, "
                    f"above the limit of {max_bytes}")
    return nbytes


def expansion_limit(compressed: int, *, ratio: float | None = None, floor: int | None = None) -> int:
    """Bytes a compressed input of ``compressed`` bytes may expand to."""
    ratio = EXPANSION_RATIO if ratio is None else ratio
    floor = EXPANSION_FLOOR if floor is None else floor
    return int(max(floor, ratio * max(int(compressed), 0)))


def check_expansion(expanded: int, compressed: int, *, source=None, what: str = "compressed data",
                    ratio: float | None = None, floor: int | None = None) -> None:
    """Refuse (``UnsafeFileError``) data that would expand beyond :func:`expansion_limit`."""
    limit = expansion_limit(compressed, ratio=ratio, floor=floor)
    if expanded > limit:
        raise UnsafeFileError(
            f"{_where(source)}{what} would expand from {compressed} to {expanded} bytes, above the limit of "
            f"{limit} bytes ({EXPANSION_RATIO if ratio is None else ratio:g} times its size); refused as a "
            "possible compression bomb")


def read_capped(fileobj, limit: int, *, source=None, what: str = "data", chunk: int = 1 << 20) -> bytes:
    """Read ``fileobj`` to its end, refusing (``UnsafeFileError``) more than ``limit`` bytes."""
    parts = []
    total = 0
    while True:
        block = fileobj.read(min(chunk, limit + 1 - total))
        if not block:
            break
        total += len(block)
        if total > limit:
            raise UnsafeFileError(f"{_where(source)}{what} expands beyond {limit} bytes; refused as a possible "
                                  "compression bomb")
        parts.append(block)
    return b"".join(parts)


# -- npy / npz ------------------------------------------------------------------------------
def _archive_errors() -> tuple[type[BaseException], ...]:
    import struct

    return (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, OSError, ValueError,
            NotImplementedError, RuntimeError, OverflowError, IndexError, struct.error, UnicodeDecodeError)


def read_npy(fileobj, size: int | None, *, source=None, what: str = "array", error: type[Exception] = FileFormatError,
             expect_shape: tuple | None = None, expect_dtype: str | np.dtype | None = None,
             max_bytes: int | None = None, check: Callable[[tuple, np.dtype], None] | None = None) -> np.ndarray:
    """Read one ``.npy`` stream: header first (no object dtype, shape/dtype as expected and
    within ``max_bytes``, data length = ``size`` minus the header when ``size`` is given),
    then exactly the data it announces. ``check(shape, dtype)`` may raise for other rules."""
    label = f"{_where(source)}{what}"
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fileobj)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fileobj, max_header_size=10000)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = fmt.read_array_header_2_0(fileobj, max_header_size=10000)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except LfprocError:
        raise
    except Exception as exc:  # numpy's header parser raises ValueError, SyntaxError, tokenize errors...
        raise error(f"{label}: not a valid .npy array ({type(exc).__name__}: {str(exc)[:120]})") from None
    dtype = np.dtype(dtype)
    if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None:
        raise error(f"{label}: dtype {dtype} is not a plain numeric type")
    shape = tuple(int(s) for s in shape)
    if any(s < 0 for s in shape):
        raise error(f"{label}: negative size in shape {shape}")
    if expect_dtype is not None and dtype != np.dtype(expect_dtype):
        raise error(f"{label}: expected dtype {np.dtype(expect_dtype)}, found {dtype}")
    if expect_shape is not None and tuple(expect_shape) != shape:
        raise error(f"{label}: expected shape {tuple(expect_shape)}, found {shape}")
    nbytes = check_nbytes(shape, dtype, source=source, what=what, error=error, max_bytes=max_bytes)
    if check is not None:
        check(shape, dtype)
    if size is not None:
        header_len = fileobj.tell() if hasattr(fileobj, "tell") else None
        if header_len is not None and size - header_len != nbytes:
            raise error(f"{label}: header announces {nbytes} bytes of data ({shape} {dtype}), the member holds "
                        f"{size - header_len}")
    data = bytearray(nbytes)
    view = memoryview(data)
    got = 0
    try:
        while got < nbytes:
            block = fileobj.read(min(1 << 22, nbytes - got))
            if not block:
                break
            view[got:got + len(block)] = block
            got += len(block)
    except _archive_errors() as exc:
        raise error(f"{label}: corrupt data ({type(exc).__name__}: {str(exc)[:120]})") from None
    if got != nbytes:
        raise error(f"{label}: truncated: {got} of {nbytes} bytes")
    array = np.frombuffer(data, dtype=dtype)
    if fortran:
        return array.reshape(shape[::-1]).transpose()
    return array.reshape(shape)


def npz_members(path: str | os.PathLike, *, source=None, error: type[Exception] = FileFormatError
                ) -> dict[str, tuple[int, int]]:
    """``{array name: (declared size, compressed size)}`` of a ``.npz``/ZIP (no data read)."""
    source = source or path
    try:
        with zipfile.ZipFile(path) as zf:
            return {(i.filename[:-4] if i.filename.endswith(".npy") else i.filename): (i.file_size, i.compress_size)
                    for i in zf.infolist()}
    except _archive_errors() as exc:
        raise error(f"{_where(source)}not a readable .npz/ZIP archive ({type(exc).__name__}: {str(exc)[:120]})") from None


def read_npz(path: str | os.PathLike, *, names: Iterable[str] | None = None, source=None,
             error: type[Exception] = FileFormatError, expect: Mapping[str, tuple] | None = None,
             max_bytes: int | None = None, max_members: int = 1024, ratio: float | None = None,
             floor: int | None = None, check: Callable[[str, tuple, np.dtype], None] | None = None
             ) -> dict[str, np.ndarray]:
    """Arrays of a ``.npz`` (ZIP of ``.npy``), read without trusting its sizes.

    Parameters
    ----------
    names : the arrays to read (default: all); a missing one is an error.
    expect : ``{name: (shape or None, dtype or None)}`` checked on each header.
    max_bytes : limit of one array (default ``MAX_ARRAY_BYTES``).
    ratio, floor : the expansion rule (:func:`check_expansion`) applied to the sum of the
        declared sizes of the members read against the file's size.
    check : ``check(name, shape, dtype)`` called on each header before its data are read.
    """
    path = Path(path)
    source = source or path
    try:
        compressed = path.stat().st_size
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            if len(infos) > max_members:
                raise error(f"{_where(source)}{len(infos)} archive members, more than the limit of {max_members}")
            by_name = {}
            for info in infos:
                if not info.filename.endswith(".npy"):
                    continue
                by_name[info.filename[:-4]] = info
            wanted = list(by_name) if names is None else list(names)
            missing = [n for n in wanted if n not in by_name]
            if missing:
                raise error(f"{_where(source)}no array {', '.join(map(repr, missing))} (the file holds "
                            f"{', '.join(sorted(by_name)) or 'no arrays'})")
            check_expansion(sum(by_name[n].file_size for n in wanted), compressed, source=source,
                            what="the arrays", ratio=ratio, floor=floor)
            out = {}
            for name in wanted:
                info = by_name[name]
                shape, dtype = (expect or {}).get(name, (None, None))
                with zf.open(info) as fh:
                    out[name] = read_npy(fh, info.file_size, source=source, what=f"array {name!r}", error=error,
                                         expect_shape=shape, expect_dtype=dtype, max_bytes=max_bytes,
                                         check=None if check is None else (lambda s, d, n=name: check(n, s, d)))
            return out
    except LfprocError:
        raise
    except _archive_errors() as exc:
        raise error(f"{_where(source)}not a readable .npz/ZIP archive ({type(exc).__name__}: {str(exc)[:120]})") from None


# -- tar ------------------------------------------------------------------------------------
class _CappedStream(io.RawIOBase):
    """A read/seek/tell view of a (decompressing) stream that refuses to go past ``limit``."""

    def __init__(self, inner, limit: int, source, what: str, compressed: bool = True):
        self.inner, self.limit, self.source, self.what = inner, limit, source, what
        self.compressed = compressed

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def _refuse(self, where: int):
        if not self.compressed:
            raise FileFormatError(f"{_where(self.source)}truncated or corrupt {self.what}: needs byte {where} of a "
                                  f"{self.limit}-byte file")
        raise UnsafeFileError(f"{_where(self.source)}{self.what} expands beyond {self.limit} bytes (needs byte "
                              f"{where}); refused as a possible compression bomb")

    def read(self, n: int = -1) -> bytes:
        pos = self.inner.tell()
        if n is None or n < 0:
            n = self.limit + 1 - pos
        data = self.inner.read(max(0, min(n, self.limit + 1 - pos)))
        if pos + len(data) > self.limit:
            self._refuse(pos + len(data))
        return data

    def readinto(self, b) -> int:
        data = self.read(len(b))
        b[: len(data)] = data
        return len(data)

    def seek(self, offset: int, whence: int = 0) -> int:
        if whence == 0:
            target = offset
        elif whence == 1:
            target = self.inner.tell() + offset
        else:
            return self.inner.seek(offset, whence)
        if target > self.limit:
            self._refuse(target)
        return self.inner.seek(target)

    def tell(self) -> int:
        return self.inner.tell()


@contextlib.contextmanager
def open_tar(path: str | os.PathLike, *, source=None, error: type[Exception] = FileFormatError,
             ratio: float | None = None, floor: int | None = None):
    """Open a tar (plain, ``.gz``, ``.bz2`` or ``.xz``) for reading with its expanded stream
    capped by the expansion rule; errors of the tar module become ``error``."""
    import bz2
    import gzip
    import lzma

    path = Path(path)
    source = source or path
    size = path.stat().st_size
    with open(path, "rb") as raw:
        magic = raw.read(6)
        raw.seek(0)
        if magic[:2] == b"\x1f\x8b":
            inner, kind = gzip.GzipFile(fileobj=raw), "gzip-compressed tar"
        elif magic[:3] == b"BZh":
            inner, kind = bz2.BZ2File(raw), "bzip2-compressed tar"
        elif magic[:6] == b"\xfd7zXZ\x00":
            inner, kind = lzma.LZMAFile(raw), "xz-compressed tar"
        else:
            inner, kind = raw, "tar"
        limit = size if inner is raw else expansion_limit(size, ratio=ratio, floor=floor)
        stream = _CappedStream(inner, limit, source, kind, compressed=inner is not raw)
        try:
            with tarfile.open(fileobj=stream, mode="r:") as tar:
                tar.lfproc_limit = limit  # read by safe_members
                tar.lfproc_kind = kind if inner is not raw else None
                yield tar
        except LfprocError:
            raise
        except (tarfile.TarError, EOFError, OSError, zlib.error, lzma.LZMAError, ValueError, OverflowError,
                UnicodeDecodeError) as exc:
            raise error(f"{_where(source)}corrupt {kind} ({type(exc).__name__}: {str(exc)[:120]})") from None


def safe_members(tar: tarfile.TarFile, *, source=None, max_members: int = 100000) -> list[tarfile.TarInfo]:
    """The regular-file members of ``tar``; ``UnsafeFileError`` for an absolute name, a ``..``
    component, a link or a device (lfproc never follows them)."""
    out = []
    for i, member in enumerate(tar):
        if i >= max_members:
            raise UnsafeFileError(f"{_where(source)}more than {max_members} archive members")
        name = member.name
        parts = re.split(r"[/\\]", name)
        if name.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", name) or ".." in parts:
            raise UnsafeFileError(f"{_where(source)}member {show(name)} leads outside the archive "
                                  "(absolute name or '..'); refused")
        if member.issym() or member.islnk():
            raise UnsafeFileError(f"{_where(source)}member {show(name)} is a link (to {show(member.linkname)}); "
                                  "links in archives are refused")
        if member.isdir():
            continue
        if not member.isfile():
            raise UnsafeFileError(f"{_where(source)}member {show(name)} is not a regular file; refused")
        limit = getattr(tar, "lfproc_limit", None)
        if limit is not None and member.offset_data + member.size > limit:
            if getattr(tar, "lfproc_kind", None):
                raise UnsafeFileError(f"{_where(source)}{tar.lfproc_kind} expands beyond {limit} bytes (member "
                                      f"{show(name)} announces {member.size}); refused as a possible compression bomb")
            raise FileFormatError(f"{_where(source)}member {show(name)} announces {member.size} bytes, past the end "
                                  "of the archive (truncated or corrupt)")
        out.append(member)
    return out


def read_member(tar: tarfile.TarFile, member: tarfile.TarInfo, *, max_bytes: int, source=None,
                error: type[Exception] = FileFormatError) -> bytes:
    """The bytes of one tar member whose size is at most ``max_bytes`` (checked first)."""
    if member.size > max_bytes:
        raise error(f"{_where(source)}member {show(member.name)} has {member.size} bytes, above the limit of "
                    f"{max_bytes} for it")
    fh = tar.extractfile(member)
    if fh is None:  # pragma: no cover - safe_members only lists regular files
        raise error(f"{_where(source)}member {show(member.name)} is not a regular file")
    data = fh.read(member.size)
    if len(data) != member.size:
        raise error(f"{_where(source)}member {show(member.name)} is truncated: {len(data)} of {member.size} bytes")
    return data


# -- paths ----------------------------------------------------------------------------------
def inside(folder: str | os.PathLike, path: str | os.PathLike) -> bool:
    """Whether ``path`` (symlinks resolved) lies inside ``folder`` (symlinks resolved)."""
    try:
        Path(path).resolve().relative_to(Path(folder).resolve())
        return True
    except (ValueError, OSError, RuntimeError):
        return False


def resolve_inside(base: str | os.PathLike, name: Any, *, source=None, field: str = "path",
                   root: str | os.PathLike | None = None, allow_absolute: bool = False) -> Path:
    """Resolve a path named inside a file against the folder ``base`` holding that file.

    The result must lie inside ``base`` (or inside ``root`` when the user named a folder;
    absolute names are then allowed when they lie inside it). ``..`` and symlinks are
    resolved before the check. Raises ``UnsafeFileError`` otherwise.
    """
    if not isinstance(name, (str, os.PathLike)) or not str(name).strip() or "\x00" in str(name):
        raise FileFormatError(f"{_where(source)}field {field!r}: expected a file name, found {show(name)}")
    text = str(name).strip().replace("\\", "/")
    candidate = Path(text)
    allowed = Path(root) if root is not None else Path(base)
    if candidate.is_absolute() or re.match(r"^[A-Za-z]:", text):
        if not (allow_absolute or root is not None):
            raise UnsafeFileError(f"{_where(source)}field {field!r}: {show(str(name))} is an absolute path; "
                                  f"referenced files must lie in {base} (the folder of the file naming them)")
        full = candidate
    else:
        full = Path(base) / candidate
    if not inside(allowed, full):
        raise UnsafeFileError(f"{_where(source)}field {field!r}: {show(str(name))} leads outside {allowed}; "
                              "referenced files must lie in the folder of the file naming them"
                              + ("" if root is None else " or in the folder given"))
    return full


_SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,63}")


def safe_filename(text: Any, *, what: str = "name", source=None, error: type[Exception] = UnsafeFileError) -> str:
    """``text`` when it can be used as one file-name component (letters, digits, ``._-``, no
    leading dot, 1..64 characters); ``error`` (default ``UnsafeFileError``) otherwise."""
    if not isinstance(text, str) or not _SAFE_NAME.fullmatch(text) or ".." in text:
        raise error(f"{_where(source)}{what} {show(text)} cannot be used in a file name (expected 1 to 64 letters, "
                    "digits, '.', '_' or '-', not starting with '.'); refused")
    return text
