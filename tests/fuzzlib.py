"""Seeded fuzzing of lfproc's readers, shared by ``tests/test_fuzz_readers.py`` (a few hundred
cases per reader) and ``benchmarks/fuzz_readers.py`` (ten thousand and more).

A *reader* has seed inputs (real Lytro containers from ``../shared/data/lytro`` when present,
and files lfproc itself writes), mutators that turn a seed into a damaged or hostile variant
(bit flips, truncations, wrong JSON types, huge/negative sizes, NaN/Inf, deep nesting,
missing keys, paths leading out of the folder, links, compression bombs), and a target that
runs the reader the way its command does. :func:`run_case` runs one case and classifies it:

* ``ok``: the reader accepted the input;
* ``lfproc``: it raised an :class:`lfproc.LfprocError` (the expected refusal);
* ``crash``: any other exception (a bug: the CLI would show a traceback);
* ``hang``: the case ran longer than its time budget;
* ``memory``: ``MemoryError``, or more memory traced (tracemalloc) than the case's budget.

Everything is deterministic: case ``i`` of reader ``r`` with base seed ``s`` always builds
the same input.
"""

from __future__ import annotations

import copy
import gzip
import hashlib
import io
import json
import os
import random
import shutil
import signal
import struct
import tarfile
import time
import tracemalloc
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("LFPROC_SHARED_DATA", ROOT.parent / "shared" / "data"))

# -- generic mutations ------------------------------------------------------------------------
INTERESTING_INTS = [0, 1, -1, 2, 7, 255, 256, 65535, 65536, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**63 - 1, -2**31,
                    10**12, 10**18]
DEEP = "[" * 5000 + "]" * 5000
HUGE_DIGITS = "9" * 5000


def _bomb_value(rng: random.Random):
    return rng.choice(["../../../../etc/passwd", "/etc/passwd", "..", "../../somewhere/evil", "C:\\evil", "", " ",
                       "\x00", "a" * 100000, "sha1-" + "0" * 40, "NaN", "inf", "-1", "1e999"])


def interesting_value(rng: random.Random):
    """A JSON value that breaks naive readers (the markers become literal text later)."""
    choices = [None, True, False, 0, -1, 1, 2**31, 2**64, -(2**63), 0.5, -0.5, 1e-300, -1e300, 1e300,
               float("nan"), float("inf"), float("-inf"), "", "x", "12", "abc", [], {}, [1, 2, 3], {"a": 1},
               "@@DEEP@@", "@@HUGE@@", "@@E999@@", _bomb_value(rng), [[[[[[]]]]]], {"": {"": {"": None}}}]
    return copy.deepcopy(rng.choice(choices))


def _dump(obj) -> str:
    text = json.dumps(obj, allow_nan=True)
    return (text.replace('"@@DEEP@@"', DEEP).replace('"@@HUGE@@"', HUGE_DIGITS).replace('"@@E999@@"', "1e999"))


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:50]):
            yield from _paths(v, prefix + (i,))


def _get(obj, path):
    for k in path:
        obj = obj[k]
    return obj


def mutate_json_obj(obj, rng: random.Random, *, n: int | None = None):
    """A copy of ``obj`` with 1..3 structural mutations: a value replaced by an interesting one,
    a key deleted or added, a container emptied or swapped for the other kind."""
    obj = copy.deepcopy(obj)
    for _ in range(n or rng.choice([1, 1, 1, 2, 3])):
        paths = list(_paths(obj))
        path = rng.choice(paths)
        op = rng.random()
        if not path:
            if op < 0.2:
                return interesting_value(rng)
            continue
        parent = _get(obj, path[:-1])
        key = path[-1]
        if op < 0.55:
            parent[key] = interesting_value(rng)
        elif op < 0.7:
            if isinstance(parent, dict):
                del parent[key]
            else:
                parent.pop(key)
        elif op < 0.8:
            value = parent[key]
            if isinstance(value, dict):
                parent[key] = list(value.values())
            elif isinstance(value, list):
                parent[key] = {str(i): v for i, v in enumerate(value)}
            else:
                parent[key] = [value]
        elif op < 0.9:
            value = parent[key]
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                parent[key] = rng.choice([-value, value * 1e9, value + 1, 0, -1, value * 1e300])
            elif isinstance(value, str):
                parent[key] = rng.choice([value * 3, value[:1], value + "/../..", str(rng.randint(-9, 10**9))])
            else:
                parent[key] = interesting_value(rng)
        else:
            target = parent[key]
            if isinstance(target, dict):
                target[rng.choice(["x", "files", "frames", "", "isos", "arrays"])] = interesting_value(rng)
            elif isinstance(target, list):
                target.append(interesting_value(rng))
    return obj


def mutate_json_text(text: str, rng: random.Random) -> str:
    """Mutate a JSON document structurally (when it parses) and serialise it (NaN/Infinity,
    1e999, 5000-digit integers and 5000-deep nesting appear as literal text)."""
    try:
        obj = json.loads(text)
    except ValueError:
        return mutate_bytes(text.encode(), rng).decode("latin-1")
    return _dump(mutate_json_obj(obj, rng))


def mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    """Byte-level damage: bit flips, overwritten bytes or integers, truncation, cut/duplicated chunks."""
    data = bytearray(data)
    if not data:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))
    op = rng.random()
    n = len(data)
    if op < 0.35:
        for _ in range(rng.choice([1, 1, 2, 4, 8, 32])):
            i = rng.randrange(n)
            data[i] ^= 1 << rng.randrange(8)
    elif op < 0.5:
        for _ in range(rng.choice([1, 4, 16])):
            data[rng.randrange(n)] = rng.choice([0, 0xFF, 0x7F, 0x80, rng.randrange(256)])
    elif op < 0.65:
        i = rng.randrange(n)
        value = rng.choice(INTERESTING_INTS)
        fmt = rng.choice([">i", "<i", ">I", "<I", ">q", "<q", ">Q", "<Q"])
        try:
            packed = struct.pack(fmt, value)
        except struct.error:
            packed = struct.pack(fmt[0] + fmt[1].upper(), value % (2 ** (8 * struct.calcsize(fmt))))
        data[i:i + len(packed)] = packed
        data = data[:n] if len(data) > n else data
    elif op < 0.82:
        data = data[:rng.randrange(n)]
    elif op < 0.92:
        i, j = sorted(rng.randrange(n + 1) for _ in range(2))
        data = data[:i] + data[j:]
    else:
        i, j = sorted(rng.randrange(n + 1) for _ in range(2))
        data = data[:j] + data[i:j] + data[j:]
    return bytes(data)


# -- cases ------------------------------------------------------------------------------------
@dataclass
class Seed:
    """One seed input: files (relative path -> bytes), the one the reader opens, and extras
    (files linked from a shared folder instead of copied, parsed structures...)."""

    name: str
    files: dict[str, bytes]
    main: str
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class Reader:
    name: str
    command: str
    seeds: list[Seed]
    mutators: list[tuple[float, Callable[[Seed, random.Random], dict[str, bytes]]]]
    target: Callable[[Path, Seed], Any]
    budget_s: float = 10.0
    bombs: list[Callable[[], bytes]] = field(default_factory=list)  # builders of the bombs cases may use


def prebuild_bombs(reader: Reader) -> None:
    """Build (and cache) every compression bomb the reader's cases can use."""
    for build in reader.bombs:
        build()


class CaseTimeout(BaseException):
    """Raised by the per-case alarm (a BaseException so that no reader code can swallow it)."""


@dataclass
class Outcome:
    kind: str  # ok | lfproc | crash | hang | memory
    detail: str = ""
    seconds: float = 0.0
    peak_bytes: int = 0
    input_bytes: int = 0
    warnings: list[str] = field(default_factory=list)  # Python warnings other than lfproc's own


def build_case(reader: Reader, index: int, base_seed: int) -> tuple[Seed, dict[str, bytes], str]:
    """The seed, mutated files and mutator name of case ``index`` (deterministic)."""
    rng = random.Random(f"{reader.name}:{base_seed}:{index}")
    seed = reader.seeds[rng.randrange(len(reader.seeds))]
    weights = [w for w, _ in reader.mutators]
    _, mutator = rng.choices(reader.mutators, weights=weights)[0]
    files = mutator(seed, rng)
    return seed, files, mutator.__name__


def write_case(folder: Path, seed: Seed, files: dict[str, bytes]) -> Path:
    """Write a case into an empty ``folder``; files named in ``seed.extra["links"]`` that the
    mutator left alone are hard-linked (or copied) from the seed's folder."""
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    for rel, data in files.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(data, Path):
            try:
                os.link(data, p)
            except OSError:
                shutil.copyfile(data, p)
        elif isinstance(data, tuple) and data and data[0] == "symlink":
            os.symlink(data[1], p)
        else:
            p.write_bytes(data)
    return folder / seed.main


def _alarm(signum, frame):
    raise CaseTimeout()


def run_case(reader: Reader, folder: Path, seed: Seed, files: dict[str, bytes], *, budget_s: float | None = None,
             memory_budget: int | None = None, trace_memory: bool = True) -> Outcome:
    """Run the reader on one case; see the module documentation for the outcome kinds.

    The memory budget defaults to 256 MiB plus 50 times the input's size.
    """
    from lfproc.errors import LfprocError

    main = write_case(folder, seed, files)
    size = sum(len(v) if isinstance(v, (bytes, bytearray)) else (v.stat().st_size if isinstance(v, Path) else 0)
               for v in files.values())
    budget_s = reader.budget_s if budget_s is None else budget_s
    memory_budget = (256 << 20) + 50 * size if memory_budget is None else memory_budget
    use_alarm = hasattr(signal, "setitimer") and budget_s > 0
    old = signal.signal(signal.SIGALRM, _alarm) if use_alarm else None
    if trace_memory:
        tracemalloc.start()
        tracemalloc.reset_peak()
    import warnings

    from lfproc.errors import LfprocWarning

    t0 = time.perf_counter()
    kind, detail = "ok", ""
    caught: list = []
    try:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, budget_s)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                reader.target(main, seed)
        finally:
            if use_alarm:
                signal.setitimer(signal.ITIMER_REAL, 0)
    except CaseTimeout:
        kind, detail = "hang", f"over {budget_s:g} s"
    except MemoryError as exc:
        kind, detail = "memory", f"MemoryError {exc}"
    except LfprocError as exc:
        kind, detail = "lfproc", f"{type(exc).__name__}: {exc}"
    except RecursionError as exc:
        kind, detail = "crash", f"RecursionError: {str(exc)[:200]}"
    except Exception as exc:  # noqa: BLE001 - classifying every other exception is the point
        import traceback

        tb = traceback.extract_tb(exc.__traceback__)
        where = next((f"{Path(f.filename).name}:{f.lineno}" for f in reversed(tb) if "lfproc" in f.filename
                      or "/calib/" in f.filename or "/cli/" in f.filename), "")
        kind, detail = "crash", f"{type(exc).__name__}: {str(exc)[:200]} [{where}]"
    finally:
        elapsed = time.perf_counter() - t0
        peak = 0
        if trace_memory:
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        if use_alarm:
            signal.signal(signal.SIGALRM, old)
    if kind in ("ok", "lfproc") and peak > memory_budget:
        kind, detail = "memory", f"traced peak {peak / 2**20:.0f} MiB > budget {memory_budget / 2**20:.0f} MiB"
    other = [f"{w.category.__name__}: {w.message} [{Path(w.filename).name}:{w.lineno}]" for w in caught or []
             if not issubclass(w.category, LfprocWarning)]
    return Outcome(kind, detail, elapsed, peak, size, other)


# -- container helpers ------------------------------------------------------------------------
def parse_lfp(data: bytes) -> list[tuple[str, bytes]]:
    """Sections ``(kind, payload)`` of a well-formed LFP container (seeds only)."""
    out = []
    off = 16
    while off + 96 <= len(data):
        kind = {b"\x89LFM": "LFM", b"\x89LFC": "LFC"}.get(data[off:off + 4])
        if kind is None:
            break
        (length,) = struct.unpack(">i", data[off + 12:off + 16])
        start = off + 96
        out.append((kind, data[start:start + length]))
        off = (start + length + 15) // 16 * 16
    return out


def build_lfp_sections(sections: list[tuple[str, bytes]]) -> bytes:
    from lfproc.lytro.container import LFP_MAGIC, _section_bytes

    return LFP_MAGIC + b"\x00\x00\x00\x00" + b"".join(_section_bytes(k, p) for k, p in sections)


def _sha(data: bytes) -> str:
    return "sha1-" + hashlib.sha1(data).hexdigest()


def _is_json(data: bytes) -> bool:
    return data.lstrip()[:1] in (b"{", b"[")


def mutate_lfp_json(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """Mutate a JSON section (table of contents or metadata) and keep every SHA-1 valid, so the
    damage reaches the metadata readers; references to a changed section follow it."""
    if "sections" not in seed.extra:
        return mutate_file_bytes(seed, rng)
    sections = list(seed.extra["sections"])
    candidates = [i for i, (k, p) in enumerate(sections) if k == "LFM" or _is_json(p)]
    i = rng.choice(candidates)
    kind, payload = sections[i]
    text = payload.decode("utf-8", "replace").strip("\x00")
    new = mutate_json_text(text, rng).encode("utf-8", "replace")
    old_sha, new_sha = _sha(payload), _sha(new)
    sections[i] = (kind, new)
    sections = [(k, p.replace(old_sha.encode(), new_sha.encode()) if k == "LFM" else p) for k, p in sections]
    return {seed.main: build_lfp_sections(sections)}


def mutate_lfp_structure(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """Re-hashed structural damage: a section cut short, dropped, duplicated or swapped."""
    if "sections" not in seed.extra:
        return mutate_file_bytes(seed, rng)
    sections = list(seed.extra["sections"])
    i = rng.randrange(len(sections))
    op = rng.random()
    kind, payload = sections[i]
    if op < 0.4:
        sections[i] = (kind, payload[:rng.randrange(len(payload) + 1)])
    elif op < 0.6 and len(sections) > 1:
        sections.pop(i)
    elif op < 0.8:
        sections.insert(i, sections[i])
    else:
        j = rng.randrange(len(sections))
        sections[i], sections[j] = sections[j], sections[i]
    return {seed.main: build_lfp_sections(sections)}


def mutate_file_bytes(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """Byte-level damage to the main file."""
    files = dict(seed.files)
    files[seed.main] = mutate_bytes(_data(files[seed.main]), rng)
    return files


def _data(value) -> bytes:
    return value.read_bytes() if isinstance(value, Path) else value


def mutate_lfp_header(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """A section's length field set to a huge, negative or off-by-one value (no re-hash)."""
    if "sections" not in seed.extra:
        return mutate_file_bytes(seed, rng)
    data = bytearray(_data(seed.files[seed.main]))
    offsets = []
    off = 16
    for _, payload in seed.extra["sections"]:
        offsets.append(off)
        off = (off + 96 + len(payload) + 15) // 16 * 16
    at = rng.choice(offsets)
    (length,) = struct.unpack(">i", data[at + 12:at + 16])
    value = rng.choice([-1, -(2**31), 2**31 - 1, length + 1, length - 1, 0, len(data), length * 2])
    data[at + 12:at + 16] = struct.pack(">i", max(-(2**31), min(2**31 - 1, value)))
    return {seed.main: bytes(data)}


# -- tar helpers ------------------------------------------------------------------------------
def read_tar_members(data: bytes) -> list[tuple[str, bytes]]:
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        return [(m.name, tar.extractfile(m).read()) for m in tar.getmembers() if m.isfile()]


def build_tar(members: list[tuple], *, compress: bool = False) -> bytes:
    """A tar from ``(name, data)`` members; ``(name, None, "symlink"|"hardlink", target)`` is a link."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=tarfile.GNU_FORMAT) as tar:
        for m in members:
            name, data = m[0], m[1]
            info = tarfile.TarInfo(name)
            info.mtime = 1431492370
            if len(m) > 2 and m[2] == "symlink":
                info.type = tarfile.SYMTYPE
                info.linkname = m[3]
                tar.addfile(info)
                continue
            if len(m) > 2 and m[2] == "hardlink":
                info.type = tarfile.LNKTYPE
                info.linkname = m[3]
                tar.addfile(info)
                continue
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    out = buf.getvalue()
    return gzip.compress(out, mtime=0) if compress else out


def mutate_tar_json(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """A JSON member (MOD TXT, unit_info.json, cal_file_manifest.json) mutated structurally."""
    members = list(seed.extra["members"])
    idx = [i for i, (n, d) in enumerate(members) if n.upper().endswith((".TXT", ".JSON"))]
    i = rng.choice(idx)
    name, data = members[i]
    members[i] = (name, mutate_json_text(data.decode("utf-8", "replace"), rng).encode("utf-8", "replace"))
    return {seed.main: build_tar(members)}


def mutate_tar_serial(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """The serial number in unit_info.json replaced by a path, a huge string or a non-string."""
    members = list(seed.extra["members"])
    i = next(i for i, (n, _) in enumerate(members) if n.endswith("unit_info.json"))
    doc = json.loads(members[i][1])
    doc["camera"]["serialNumber"] = rng.choice(["../../../somewhere/evil", "/tmp/evil", "..", "a/b", "x" * 300,
                                                "B5/../../x", 12345, None, ["B5"], {"a": 1}, "", "ok_serial-1.2"])
    members[i] = (members[i][0], json.dumps(doc).encode())
    return {seed.main: build_tar(members)}


def mutate_tar_members(seed: Seed, rng: random.Random) -> dict[str, bytes]:
    """Hostile tar structure: '..'/absolute names, symlinks and hard links, truncated or
    duplicated members, wrong sizes, or the tar gzip-compressed."""
    members = list(seed.extra["members"])
    i = rng.randrange(len(members))
    name, data = members[i]
    op = rng.random()
    if op < 0.15:
        members[i] = (rng.choice(["../" + name, "../../../tmp/" + name.rsplit("/", 1)[-1], "/tmp/" + name,
                                  "a/../../" + name]), data)
    elif op < 0.3:
        members.append((name.rsplit("/", 1)[0] + "/MOD_9999.RAW", None, "symlink",
                        rng.choice(["/etc/passwd", "../../etc/passwd", name])))
        members.append((name.rsplit("/", 1)[0] + "/MOD_9999.TXT", members[[n for n, *_ in members].index(
            next(n for n, *_ in members if n.endswith(".TXT")))][1]))
    elif op < 0.4:
        members[i] = (name, None, "hardlink", rng.choice(["/etc/passwd", members[0][0]]))
    elif op < 0.6:
        members[i] = (name, data[:rng.randrange(len(data) + 1)])
    elif op < 0.7:
        members.append(members[i])
    elif op < 0.8:
        members.pop(i)
    else:
        return {seed.main: build_tar(members, compress=True)}
    return {seed.main: build_tar(members)}


# -- zip helpers ------------------------------------------------------------------------------
def read_zip_members(data: bytes) -> list[tuple[str, bytes]]:
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return [(i.filename, zf.read(i)) for i in zf.infolist()]


def build_zip(members: list[tuple[str, bytes]]) -> bytes:
    import warnings

    buf = io.BytesIO()
    with warnings.catch_warnings(), zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED,
                                                    compresslevel=1) as zf:
        warnings.simplefilter("ignore")  # duplicated members are one of the mutations
        for name, data in members:
            info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, data)
    return buf.getvalue()


def mutate_npy_header(data: bytes, rng: random.Random) -> bytes:
    """A ``.npy`` member whose header announces another shape or dtype (data unchanged)."""
    try:
        version = data[6:8]
        hlen_size = 2 if version[0] == 1 else 4
        hlen = int.from_bytes(data[8:8 + hlen_size], "little")
        header = data[8 + hlen_size:8 + hlen_size + hlen].decode("latin-1")
        body = data[8 + hlen_size + hlen:]
        d = eval(header, {"__builtins__": {}}, {})  # noqa: S307 - our own seed files
    except Exception:
        return mutate_bytes(data, rng)
    op = rng.random()
    if op < 0.45:
        shape = list(d["shape"])
        if shape:
            j = rng.randrange(len(shape))
            shape[j] = rng.choice([0, -1, 1, shape[j] + 1, shape[j] * 1000, 2**31, 2**40, 10**12])
        else:
            shape = [rng.choice([1, 10**9])]
        d["shape"] = tuple(shape)
    elif op < 0.6:
        d["shape"] = tuple(d["shape"]) + (rng.choice([1, 2, 10**6]),)
    elif op < 0.85:
        d["descr"] = rng.choice(["<f8", "<i8", "|u1", "<U10", "|O", "|V8", "<c16", "[('a', '<f4')]", "<f2", ">u2"])
    else:
        d["fortran_order"] = not d["fortran_order"]
    text = repr(d)
    pad = (-(8 + hlen_size + len(text) + 1)) % 64
    text = text + " " * pad + "\n"
    head = data[:6] + version + len(text).to_bytes(hlen_size, "little") + text.encode("latin-1")
    return head + body


def bomb_zip_member(name: str, expanded: int) -> tuple[str, bytes]:
    """A ``.npy`` member announcing ``expanded`` bytes of zeros (a compression bomb)."""
    n = expanded // 2
    header = {"descr": "<u2", "fortran_order": False, "shape": (n,)}
    text = repr(header)
    text += " " * ((-(10 + len(text) + 1)) % 64) + "\n"
    head = b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode()
    return name, head + bytes(n * 2)


_BOMB_CACHE: dict[tuple, bytes] = {}


def bomb_zip(members: list[tuple[str, bytes]], victim: str, expanded: int) -> bytes:
    """A copy of a ZIP whose member ``victim`` becomes a ``.npy`` of ``expanded`` bytes of zeros
    (streamed: the bomb is never held in memory while it is built)."""
    key = (tuple(n for n, _ in members), victim, expanded)
    if key not in _BOMB_CACHE:
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
            for n, d in members:
                info = zipfile.ZipInfo(n, date_time=(2020, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                if n != victim:
                    zf.writestr(info, d)
                    continue
                head = bomb_zip_member(n, 0)[1]
                head = head.replace(b"(0,)", f"({expanded // 2},)".encode())
                text_len = len(head) - 10
                pad = (-(10 + text_len)) % 64
                head = head[:-1] + b" " * pad + b"\n"
                head = head[:8] + (len(head) - 10).to_bytes(2, "little") + head[10:]
                with zf.open(info, "w", force_zip64=True) as fh:
                    fh.write(head)
                    block = bytes(1 << 22)
                    left = expanded // 2 * 2
                    while left > 0:
                        fh.write(block[:min(left, len(block))])
                        left -= len(block)
        _BOMB_CACHE[key] = buf.getvalue()
    return _BOMB_CACHE[key]


def bomb_gzip_tar(members: list[tuple[str, bytes]], victim_suffix: str, expanded: int) -> bytes:
    key = ("tar", tuple(n for n, _ in members), victim_suffix, expanded)
    if key not in _BOMB_CACHE:
        buf = io.BytesIO()
        with gzip.GzipFile(fileobj=buf, mode="wb", compresslevel=9, mtime=0) as gz:
            with tarfile.open(fileobj=gz, mode="w|", format=tarfile.GNU_FORMAT) as tar:
                for n, d in members:
                    info = tarfile.TarInfo(n)
                    if n.upper().endswith(victim_suffix):
                        info.size = expanded
                        tar.addfile(info, _Zeros(expanded))
                    else:
                        info.size = len(d)
                        tar.addfile(info, io.BytesIO(d))
        _BOMB_CACHE[key] = buf.getvalue()
    return _BOMB_CACHE[key]


class _Zeros(io.RawIOBase):
    def __init__(self, n):
        self.left = n

    def read(self, n=-1):
        n = self.left if n is None or n < 0 else min(n, self.left)
        self.left -= n
        return bytes(n)


# -- the readers ------------------------------------------------------------------------------
BOMB_BYTES = int(os.environ.get("LFPROC_FUZZ_BOMB_BYTES", 256 << 20))  # what the compression bombs expand to


def _lytro_real_seeds() -> list[Seed]:
    folder = SHARED_DATA / "lytro"
    seeds = []
    if folder.is_dir():
        for p in sorted(folder.iterdir()):
            if p.suffix.lower() in (".lfp", ".lfr"):
                data = p.read_bytes()
                seeds.append(Seed(p.name, {p.name: data}, p.name, {"sections": parse_lfp(data), "real": True}))
    return seeds


def _small_lfr(folder: Path, name: str = "IMG_0001.LFR", h: int = 24, w: int = 32, **meta) -> bytes:
    from lfproc.lytro.container import illum_metadata, write_lfr

    rng = np.random.default_rng(3)
    raw = rng.integers(64, 1000, (h, w)).astype(np.uint16)
    path = folder / name
    write_lfr(path, raw=raw, metadata=illum_metadata(height=h, width=w, **meta), serial="B5152102610", force=True)
    return path.read_bytes()


def make_lytro_container_reader(work: Path) -> Reader:
    from lfproc.lytro.capture import describe_lytro

    seeds = _lytro_real_seeds()
    data = _small_lfr(work)
    seeds.append(Seed("lfproc.LFR", {"IMG_0001.LFR": data}, "IMG_0001.LFR", {"sections": parse_lfp(data)}))
    return Reader("Lytro container", "info", seeds,
                  [(3, mutate_lfp_json), (2, mutate_file_bytes), (1, mutate_lfp_structure), (1, mutate_lfp_header)],
                  lambda path, seed: describe_lytro(path))


def make_lytro_capture_reader(work: Path) -> Reader:
    from lfproc.lytro.capture import read_capture

    seeds = []
    for name, kw in (("IMG_0001.LFR", {}), ("IMG_0002.LFR", {"zoom_step": 5, "exposure_s": 0.02})):
        data = _small_lfr(work, name, **kw)
        seeds.append(Seed(name, {name: data}, name, {"sections": parse_lfp(data)}))
    # an unpacked F01-style RAW + metadata pair
    f01 = SHARED_DATA / "lytro" / "f01_IMG_0001__frame.json"
    if f01.is_file():
        from lfproc.lytro.raw import pack_raw12

        doc = json.loads(f01.read_text())
        doc["image"]["width"], doc["image"]["height"] = 16, 12
        raw = pack_raw12(np.random.default_rng(1).integers(0, 4095, (12, 16)))
        seeds.append(Seed("f01_raw", {"IMG__frame.raw": raw, "IMG__frame.json": json.dumps(doc).encode()},
                          "IMG__frame.raw", {"json": "IMG__frame.json"}))

    def mutate_raw_pair(seed, rng):
        files = dict(seed.files)
        if "json" not in seed.extra:
            return mutate_lfp_json(seed, rng)
        key = seed.extra["json"] if rng.random() < 0.7 else seed.main
        files[key] = (mutate_json_text(files[key].decode(), rng).encode("utf-8", "replace") if key.endswith(".json")
                      else mutate_bytes(files[key], rng))
        return files

    def target(path, seed):
        cap = read_capture(path)
        cap.black_level_2x2()
        cap.white_level_2x2()
        return cap

    return Reader("Lytro raw capture", "decode", seeds,
                  [(3, mutate_lfp_json), (2, mutate_file_bytes), (1, mutate_lfp_structure), (1, mutate_lfp_header),
                   (2, mutate_raw_pair)],
                  target)


def make_exr_reader(work: Path) -> Reader:
    from lfproc.info import describe_lightfield
    from lfproc.io import read_lightfield, write_lightfield
    from lfproc.synth import synthesize

    lf = synthesize("layers", size=(16, 16), views=3, random_state=1)
    variance = np.full(lf.shape, 0.01, np.float32)
    lf = lf.replace(variance=variance)
    p = work / "lf.exr"
    write_lightfield(lf, p, force=True)
    half = work / "lf_half.exr"
    write_lightfield(lf.replace(variance=None, disparity=None), half, dtype="half", force=True)
    seeds = [Seed("lf.exr", {"lf.exr": p.read_bytes()}, "lf.exr"), Seed("lf_half.exr", {"lf.exr": half.read_bytes()},
                                                                         "lf.exr")]

    def mutate_attribute(seed, rng):
        """The 'lfproc' JSON attribute of one part mutated (file rewritten by OpenEXR)."""
        import OpenEXR

        src = work / f"src-{os.getpid()}.exr"
        src.write_bytes(seed.files[seed.main])
        f = OpenEXR.File(str(src), separate_channels=True)
        parts = []
        k = rng.randrange(len(f.parts))
        for i, part in enumerate(f.parts):
            header = {key: value for key, value in part.header.items()
                      if key in ("compression", "type", "lfproc", "lfproc_version")}
            if i == k or rng.random() < 0.2:
                header["lfproc"] = mutate_json_text(header["lfproc"], rng)
            channels = {name: ch.pixels for name, ch in part.channels.items()}
            if rng.random() < 0.1 and channels:
                channels.pop(rng.choice(list(channels)))
            parts.append(OpenEXR.Part(header, channels, part.name()))
        out = work / f"out-{os.getpid()}.exr"
        try:
            OpenEXR.File(parts).write(str(out))
        except Exception:
            return mutate_file_bytes(seed, rng)
        return {seed.main: out.read_bytes()}

    def mutate_window(seed, rng):
        """A part's dataWindow (or chunkCount) set to huge, negative or inverted values."""
        data = bytearray(seed.files[seed.main])
        key = rng.choice([b"dataWindow\x00box2i\x00", b"displayWindow\x00box2i\x00", b"chunkCount\x00int\x00"])
        hits = [i for i in range(len(data)) if data.startswith(key, i)][:9]
        if not hits:
            return mutate_file_bytes(seed, rng)
        at = rng.choice(hits) + len(key) + 4
        n = 4 if key.startswith(b"chunk") else 16
        vals = [rng.choice([0, -1, 15, 16, 2**30, -(2**30), 2**31 - 1, 100000]) for _ in range(n // 4)]
        data[at:at + n] = struct.pack(f"<{n // 4}i", *vals)
        return {seed.main: bytes(data)}

    def target(path, seed):
        return describe_lightfield(read_lightfield(path))

    return Reader("EXR light field", "info, convert, evaluate", seeds,
                  [(3, mutate_file_bytes), (3, mutate_attribute), (2, mutate_window)], target)


def make_profile_reader(work: Path) -> Reader:
    from lfproc.sensor import load_profile, save_profile
    from lfproc.camera.simulate import simulate_capture
    from lfproc.cli.profile import describe_profile
    from lfproc.synth import synthesize

    base = load_profile("paper-low")
    bias = {iso: np.full((8, 8), base.black_level_dn, np.float32) + np.float32(0.25) for iso in base.iso_values}
    import dataclasses

    prof = dataclasses.replace(base, bias_frames=bias, name="fuzz")
    folder = work / "profile"
    folder.mkdir(exist_ok=True)
    save_profile(prof, folder / "cam.json", force=True)
    seeds = [Seed("cam.json", {"cam.json": (folder / "cam.json").read_bytes(),
                               "cam.bias.npz": (folder / "cam.bias.npz").read_bytes()}, "cam.json"),
             Seed("illum.json", {"illum.json": (ROOT / "lfproc" / "sensor" / "profiles" / "illum.json").read_bytes()}, "illum.json")]
    lf = synthesize("layers", size=(16, 16), views=3, random_state=0)

    def mutate_profile_json(seed, rng):
        files = dict(seed.files)
        files[seed.main] = mutate_json_text(files[seed.main].decode(), rng).encode("utf-8", "replace")
        return files

    def mutate_sidecar_path(seed, rng):
        files = dict(seed.files)
        doc = json.loads(files[seed.main])
        doc["bias_frame_file"] = rng.choice(["../../../../etc/passwd", "/etc/passwd", "../cam.bias.npz", "sub/../cam.bias.npz",
                                             "link.npz", 5, [], "", "cam.bias.npz"])
        if doc["bias_frame_file"] == "link.npz":
            files["link.npz"] = ("symlink", "/etc/passwd")
        files[seed.main] = json.dumps(doc).encode()
        return files

    def mutate_sidecar(seed, rng):
        files = dict(seed.files)
        if "cam.bias.npz" not in files:
            return mutate_profile_json(seed, rng)
        members = read_zip_members(files["cam.bias.npz"])
        op = rng.random()
        i = rng.randrange(len(members))
        if op < 0.3:
            members[i] = (members[i][0], mutate_npy_header(members[i][1], rng))
        elif op < 0.45:
            members[i] = (rng.choice(["iso_abc.npy", "iso_99999999.npy", "x.npy", "iso_7.npy", "../x.npy"]), members[i][1])
        elif op < 0.55:
            arr = rng.choice([np.full((8, 8), np.nan, np.float32), np.zeros((4, 4), np.float32),
                              np.zeros((2, 2, 2), np.float32), np.array(["x"]), np.zeros((8, 8), np.complex64)])
            b = io.BytesIO()
            np.lib.format.write_array(b, arr)
            members[i] = (members[i][0], b.getvalue())
        elif op < 0.65:
            files["cam.bias.npz"] = bomb_zip(members, members[i][0], BOMB_BYTES)
            return files
        else:
            files["cam.bias.npz"] = mutate_bytes(build_zip(members), rng)
            return files
        files["cam.bias.npz"] = build_zip(members)
        return files

    def target(path, seed):
        profile = load_profile(path)
        describe_profile(profile)
        simulate_capture(lf, profile=profile, isos=profile.iso_values[:2], shots=1, random_state=0)

    members = read_zip_members(seeds[0].files["cam.bias.npz"])
    bombs = [lambda v=name: bomb_zip(members, v, BOMB_BYTES) for name, _ in members]
    return Reader("camera profile JSON + sidecar", "profile show, simulate", seeds,
                  [(4, mutate_profile_json), (1, mutate_file_bytes), (1, mutate_sidecar_path), (2, mutate_sidecar)],
                  target, bombs=bombs)


def make_manifest_reader(work: Path) -> Reader:
    from lfproc.calib.frames import read_frame, read_manifest
    from lfproc.calib.simulate_frames import simulate_frames

    out = work / "frames"
    if not out.exists():
        simulate_frames("paper-low", out, isos=[100], size=(8, 8), random_state=0)
    # seeds: the first rows of each kind (the frames they name are linked into each case)
    import csv as _csv

    rows = list(_csv.DictReader((out / "manifest.csv").read_text().splitlines()))
    keep = [r for kind in ("bias", "dark", "flat") for r in [x for x in rows if x["kind"] == kind][:3]]
    frames = {r["path"]: out / r["path"] for r in keep}
    buf = io.StringIO()
    writer = _csv.DictWriter(buf, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(keep)
    doc = {"frames": [{k: v for k, v in r.items() if v != ""} for r in keep], "cfa_pattern": "RGGB", "adc_bits": 12}
    seeds = [Seed("manifest.csv", {"manifest.csv": buf.getvalue().encode(), **frames}, "manifest.csv"),
             Seed("manifest.json", {"manifest.json": json.dumps(doc).encode(), **frames}, "manifest.json")]

    def mutate_text(seed, rng):
        files = dict(seed.files)
        text = files[seed.main].decode()
        if seed.main.endswith(".json"):
            files[seed.main] = mutate_json_text(text, rng).encode("utf-8", "replace")
            return files
        lines = text.splitlines()
        for _ in range(rng.choice([1, 1, 2, 3])):
            i = rng.randrange(len(lines))
            cells = lines[i].split(",")
            j = rng.randrange(len(cells))
            cells[j] = rng.choice(["", "nan", "inf", "-1", "1e999", HUGE_DIGITS, "x", "bias", "flat", "0",
                                   "../../../../etc/passwd", "/etc/passwd", "frames/../../x.png", '"a,b"', "\x00",
                                   "a" * 200000, cells[j] * 2])
            lines[i] = ",".join(cells)
        if rng.random() < 0.1:
            lines = lines[:rng.randrange(len(lines) + 1)]
        files[seed.main] = "\n".join(lines).encode("utf-8", "replace")
        return files

    def mutate_frame(seed, rng):
        files = dict(seed.files)
        key = rng.choice([k for k in files if k.endswith(".png")])
        files[key] = mutate_bytes(files[key].read_bytes(), rng)
        return files

    def target(path, seed):
        records, _ = read_manifest(path)
        for r in records[:9]:
            read_frame(r.path)

    return Reader("calibration manifest", "calibrate", seeds,
                  [(4, mutate_text), (1, mutate_file_bytes), (1, mutate_frame)], target, budget_s=10.0)


def make_capture_reader(work: Path) -> Reader:
    from lfproc.camera.capture import describe_capture
    from lfproc.camera.simulate import simulate_capture
    from lfproc.synth import synthesize

    lf = synthesize("layers", size=(16, 16), views=3, random_state=0)
    seeds = []
    for name, kw in (("a.capture.npz", {"shots": 2}), ("b.capture.npz", {"shots": 1, "mask": "shifted",
                                                                          "iso_pattern_kind": "row"})):
        cap = simulate_capture(lf, profile="paper-low", random_state=1, **kw)
        p = cap.save(work / name, force=True)
        data = p.read_bytes()
        seeds.append(Seed(name, {name: data}, name, {"members": read_zip_members(data)}))

    def mutate_header(seed, rng):
        members = list(seed.extra["members"])
        name, data = members[0]
        members[0] = (name, mutate_json_text(data.decode(), rng).encode("utf-8", "replace"))
        return {seed.main: build_zip(members)}

    def mutate_arrays(seed, rng):
        members = list(seed.extra["members"])
        i = rng.randrange(1, len(members))
        op = rng.random()
        if op < 0.45:
            members[i] = (members[i][0], mutate_npy_header(members[i][1], rng))
        elif op < 0.6:
            members.pop(i)
        elif op < 0.7:
            members.append(members[i])
        elif op < 0.85:
            return {seed.main: bomb_zip(members, members[i][0], BOMB_BYTES)}
        else:
            members[i] = (members[i][0], mutate_bytes(members[i][1], rng))
        return {seed.main: build_zip(members)}

    def target(path, seed):
        return describe_capture(path)

    bombs = [lambda m=seed.extra["members"], v=name: bomb_zip(m, v, BOMB_BYTES)
             for seed in seeds for name, _ in seed.extra["members"][1:]]
    return Reader("capture file", "info, preview", seeds,
                  [(3, mutate_header), (3, mutate_arrays), (2, mutate_file_bytes)], target, bombs=bombs)


def make_caldata_reader(work: Path) -> Reader:
    from lfproc.lytro.caldata import WhiteFrame, white_metadata, write_caldata_tar
    from lfproc.lytro.caldata import read_caldata

    rng = np.random.default_rng(7)
    frames = []
    for i, (zoom, dark) in enumerate([(0, False), (100, False), (0, True)]):
        level = (600, 900) if not dark else (60, 70)
        frames.append(WhiteFrame(raw=rng.integers(*level, (8, 16)).astype(np.uint16),
                                 metadata=white_metadata(height=8, width=16, zoom_step=zoom), name=f"MOD_{i:04d}",
                                 is_dark=dark))
    p = write_caldata_tar(work / "caldata-B5152102610.tar", frames, serial="B5152102610", force=True)
    data = p.read_bytes()
    seeds = [Seed(p.name, {p.name: data}, p.name, {"members": read_tar_members(data)})]

    def mutate_bomb(seed, rng):
        return {seed.main: bomb_gzip_tar(seed.extra["members"], rng.choice([".RAW", ".TXT", ".GCT"]), BOMB_BYTES)}

    def target(path, seed):
        return read_caldata(path)

    bombs = [lambda v=v: bomb_gzip_tar(seeds[0].extra["members"], v, BOMB_BYTES) for v in (".RAW", ".TXT", ".GCT")]
    return Reader("caldata tar", "whites", seeds,
                  [(3, mutate_tar_json), (1, mutate_tar_serial), (2, mutate_tar_members), (2, mutate_file_bytes),
                   (0.05, mutate_bomb)], target, bombs=bombs)


def make_white_db_reader(work: Path) -> Reader:
    from lfproc.lytro.virtual import illum_grid, vignetting
    from lfproc.lytro.whites import load_white_db, select_white

    db = work / "whitedb"
    if not db.exists():  # written directly (the grid estimate needs a larger sensor than a fuzz seed)
        from lfproc._version import __version__
        from lfproc.lytro.whites import INDEX_NAME, SCHEMA, WhiteEntry

        db.mkdir()
        shape = (60, 80)
        entries = []
        for i, zoom in enumerate((0, 200)):
            grid = illum_grid(shape, zoom_step=zoom, random_state=i)
            raw = (64 + 900 * vignetting(grid)).astype(np.uint16)
            name = f"MOD_{i:04d}"
            np.savez_compressed(db / f"B5000000001_{name}.npz", raw=raw, metadata=np.array("{}"))
            entries.append(WhiteEntry(name=name, file=f"B5000000001_{name}.npz", serial="B5000000001",
                                      camera_model="B01", zoom_step=zoom, focus_step=0, exposure_s=0.01,
                                      geometry_hash=None, black_level=64.0, white_level=1023.0, cfa_pattern="GRBG",
                                      responses=(0.75, 1.0, 0.75), grid=grid, mean_level=0.5).to_dict())
        (db / INDEX_NAME).write_text(json.dumps({"schema": SCHEMA, "schema_version": 1, "lfproc_version": __version__,
                                                 "source": "fuzz", "whites": entries, "skipped": []}))
    files = {p.name: p for p in db.iterdir()}
    index = (db / "whites.json").read_text()
    seeds = [Seed("whitedb", {**files, "whites.json": index.encode()}, "whites.json")]

    def mutate_index(seed, rng):
        files = dict(seed.files)
        files["whites.json"] = mutate_json_text(files["whites.json"].decode(), rng).encode("utf-8", "replace")
        return files

    def mutate_entry_file(seed, rng):
        files = dict(seed.files)
        doc = json.loads(files["whites.json"])
        entry = rng.choice(doc["whites"])
        entry["file"] = rng.choice(["../../../../etc/passwd", "/etc/passwd", "../whitedb/x.npz", "link.npz", "", 7])
        if entry["file"] == "link.npz":
            files["link.npz"] = ("symlink", str(next(p for p in seed.files.values() if isinstance(p, Path))))
        files["whites.json"] = json.dumps(doc).encode()
        return files

    def mutate_npz(seed, rng):
        files = dict(seed.files)
        key = rng.choice([k for k in files if k.endswith(".npz")])
        data = _data(files[key])
        members = read_zip_members(data)
        op = rng.random()
        if op < 0.4:
            members = [(n, mutate_npy_header(d, rng) if n == "raw.npy" else d) for n, d in members]
            files[key] = build_zip(members)
        elif op < 0.5:
            files[key] = bomb_zip(members, "raw.npy", BOMB_BYTES)
        else:
            files[key] = mutate_bytes(data, rng)
        return files

    def target(path, seed):
        db = load_white_db(path.parent)
        for e in db.entries:
            e.load_raw(db.path)
        if db.entries:
            e = db.entries[0]
            select_white(db, serial=e.serial, zoom_step=0, focus_step=0, raw_shape=tuple(e.grid.image_size))

    bombs = [lambda m=read_zip_members(_data(v)): bomb_zip(m, "raw.npy", BOMB_BYTES)
             for k, v in seeds[0].files.items() if k.endswith(".npz")]
    return Reader("white-image database", "decode --white-db", seeds,
                  [(4, mutate_index), (1, mutate_entry_file), (2, mutate_npz)], target, bombs=bombs)


def make_emva_reader(work: Path) -> Reader:
    from lfproc.calib.emva import read_descriptor

    text = ("v 3.1\nn 12 8 8\nb 1000000 1234.5\ni images/b000_a.png\ni images/b000_b.png\n"
            "d 1000000\ni images/d000_a.png\ni images/d000_b.png\n")
    seeds = [Seed("emva1288.txt", {"emva1288.txt": text.encode()}, "emva1288.txt")]

    def mutate_lines(seed, rng):
        lines = seed.files[seed.main].decode().splitlines()
        i = rng.randrange(len(lines))
        parts = lines[i].split(" ")
        j = rng.randrange(len(parts))
        parts[j] = rng.choice(["", "nan", "inf", "-1", "1e999", HUGE_DIGITS, "x", "b", "d", "i", "n", "0",
                               "../../../../etc/passwd", "/etc/passwd", "images/../../x.png", "\x00", "a" * 5000])
        lines[i] = " ".join(parts)
        return {seed.main: "\n".join(lines).encode("utf-8", "replace")}

    return Reader("EMVA 1288 descriptor", "calibrate", seeds, [(4, mutate_lines), (1, mutate_file_bytes)],
                  lambda path, seed: read_descriptor(path))


READERS: dict[str, Callable[[Path], Reader]] = {
    "lytro-container": make_lytro_container_reader,
    "lytro-capture": make_lytro_capture_reader,
    "exr": make_exr_reader,
    "profile": make_profile_reader,
    "manifest": make_manifest_reader,
    "capture": make_capture_reader,
    "caldata": make_caldata_reader,
    "white-db": make_white_db_reader,
    "emva": make_emva_reader,
}
