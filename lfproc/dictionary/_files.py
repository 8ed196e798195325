"""The dictionary type and its files.

A :class:`Dictionary` holds ``K`` unit-norm atoms of length ``n = V * U * P * P * C``: each
atom is a light-field patch of ``V x U`` views of ``P x P`` pixels and ``C`` colours,
vectorised in C order of ``(V, U, P, P, C)`` -- the order of the unknowns of
:meth:`lfproc.camera.projection.ProjectionOperator.patch_sparse`, so
``Phi_p @ atoms`` needs no reordering.

File format (``schema "lfproc.dictionary"``, ``schema_version 1``; suffix ``.npz``): a ZIP
archive readable by :func:`numpy.load` whose first member is ``lfproc-dictionary.json``, a
UTF-8 JSON header::

    {"schema": "lfproc.dictionary", "schema_version": 1, "lfproc_version": "...",
     "patch": [V, U, P, P, C], "n": n, "atoms": K, "sparsity": T, "preset": "default",
     "dtype": "float16", "normalisation": {...}, "provenance": {...}}

followed by ``atoms.npy`` (``(n, K)`` float16 or float32) and optionally ``usage.npy``
(``(K,)`` int64: how many training signals used each atom in the last iteration).
Loading checks the header's sizes before reading any array, then the array's shape, dtype,
finiteness and the unit norm of every atom.
"""

from __future__ import annotations

import io
import json
import math
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .. import _untrusted as ut
from .._shared.frozen import ReadOnlyState, frozen_array
from .._shared.jsonable import to_jsonable
from .._shared.zipfiles import zip_first_member
from .._version import __version__
from ..errors import FileFormatError, InputError, MissingFileError, ShapeError
from ..io._atomic import atomic_file

__all__ = ["is_dictionary_file", "Dictionary", "load_dictionary", "save_dictionary", "SCHEMA", "SCHEMA_VERSION", "SHIPPED",
           "shipped_path", "dictionary_patch"]

SCHEMA = "lfproc.dictionary"
SCHEMA_VERSION = 1
HEADER_NAME = "lfproc-dictionary.json"
#: Dictionaries shipped inside the package, by name.
SHIPPED = ("default",)
#: Largest dictionary a file may declare (atoms x signal length), checked before reading.
MAX_ELEMENTS = 400_000_000
_NORM_TOLERANCE = {np.dtype(np.float16): 5e-3, np.dtype(np.float32): 1e-4}
_FIXED_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


@dataclass(frozen=True, eq=False)
class Dictionary(ReadOnlyState):
    """A learned (or analytic) dictionary of light-field patches.

    Parameters
    ----------
    atoms : ndarray of shape (n, K)
        Unit-norm columns; stored as float32 (read-only).
    patch : (V, U, P, P, C)
        Patch shape; ``n == V * U * P * P * C``.
    sparsity : int
        Number of atoms per patch the dictionary was trained for.
    preset : str
        Name of the training preset (``"default"``, ``"tiny"``, ``"paper"``, ``"dct"``...).
    normalisation : dict
        How training patches were normalised (``{"kind": "l2"}``: each patch divided by its
        l2 norm before learning, so the dictionary is scale-free).
    provenance : dict
        Command, data, seed, iterations, final error... of the training run.
    usage : ndarray of shape (K,), optional
        Training signals that used each atom in the last iteration.
    name : str
        Where it came from (a file path, ``"default"``...).
    """

    atoms: np.ndarray
    patch: tuple[int, int, int, int, int]
    sparsity: int = 10
    preset: str = "custom"
    normalisation: dict = field(default_factory=lambda: {"kind": "l2"})
    provenance: dict = field(default_factory=dict)
    usage: np.ndarray | None = None
    name: str = ""

    def __post_init__(self):
        patch = tuple(self.patch) if isinstance(self.patch, (tuple, list)) else None
        if patch is None or len(patch) != 5 or not all(isinstance(p, (int, np.integer)) and p >= 1 for p in patch):
            raise ShapeError(f"dictionary patch: expected 5 positive integers (V, U, P, P, C), got {self.patch!r}")
        patch = tuple(int(p) for p in patch)
        if patch[2] != patch[3]:
            raise ShapeError(f"dictionary patch: expected square patches (P, P), got {patch[2]} x {patch[3]}")
        atoms = np.asarray(self.atoms)
        if atoms.ndim != 2:
            raise ShapeError(f"dictionary atoms: expected an array of shape (n, K), got {atoms.shape}")
        n = math.prod(patch)
        if atoms.shape[0] != n:
            raise ShapeError(f"dictionary atoms: patch {list(patch)} needs {n} rows, found {atoms.shape[0]}")
        if atoms.shape[1] < 1:
            raise ShapeError("dictionary atoms: expected at least one atom")
        if not np.issubdtype(atoms.dtype, np.floating):
            raise InputError(f"dictionary atoms: expected floating-point values, got {atoms.dtype}")
        tol = _NORM_TOLERANCE.get(atoms.dtype, 1e-4)
        atoms32 = atoms.astype(np.float32)
        if not np.isfinite(atoms32).all():
            raise InputError(f"dictionary atoms: {int((~np.isfinite(atoms32)).sum())} values are NaN or infinite")
        norms = np.sqrt(np.einsum("ij,ij->j", atoms32, atoms32, dtype=np.float64))
        bad = np.flatnonzero(np.abs(norms - 1) > tol)
        if bad.size:
            raise InputError(f"dictionary atoms: expected unit-norm columns; {bad.size} are not "
                             f"(atom {bad[0]} has norm {norms[bad[0]]:.6g})")
        if atoms.dtype != np.float32:
            atoms32 /= norms.astype(np.float32)  # exact unit norm after a float16 round trip
        sparsity = int(self.sparsity)
        if sparsity != self.sparsity or not 1 <= sparsity <= min(atoms.shape):
            raise InputError(f"dictionary sparsity: expected an integer in 1..{min(atoms.shape)}, got {self.sparsity!r}")
        usage = None
        if self.usage is not None:
            usage = np.asarray(self.usage)
            if usage.shape != (atoms.shape[1],) or not np.issubdtype(usage.dtype, np.integer) or (usage < 0).any():
                raise ShapeError(f"dictionary usage: expected {atoms.shape[1]} non-negative integers, got {usage.shape}")
            usage = frozen_array(usage, dtype=np.int64)
        object.__setattr__(self, "atoms", frozen_array(atoms32 if atoms32 is not atoms else atoms))
        object.__setattr__(self, "patch", patch)
        object.__setattr__(self, "sparsity", sparsity)
        object.__setattr__(self, "usage", usage)
        object.__setattr__(self, "normalisation", dict(self.normalisation))
        object.__setattr__(self, "provenance", dict(self.provenance))

    @property
    def n(self) -> int:
        """Signal length ``V * U * P * P * C``."""
        return int(self.atoms.shape[0])

    @property
    def n_atoms(self) -> int:
        """Number of atoms ``K``."""
        return int(self.atoms.shape[1])

    @property
    def views(self) -> tuple[int, int]:
        return self.patch[0], self.patch[1]

    @property
    def patch_px(self) -> int:
        return self.patch[2]

    @property
    def channels(self) -> int:
        return self.patch[4]

    def __repr__(self) -> str:
        return (f"Dictionary(name={self.name!r}, preset={self.preset!r}, patch={list(self.patch)}, n={self.n}, "
                f"atoms={self.n_atoms}, sparsity={self.sparsity})")

    def atom_patches(self) -> np.ndarray:
        """The atoms as patches: ``(K, V, U, P, P, C)`` float32 (a view)."""
        return self.atoms.T.reshape(self.n_atoms, *self.patch)

    def describe(self) -> dict[str, Any]:
        """Figures for ``lfproc dictionary info``."""
        prov = self.provenance
        out = {
            "kind": "dictionary",
            "name": self.name,
            "preset": self.preset,
            "atoms": self.n_atoms,
            "n": self.n,
            "patch": list(self.patch),
            "overcompleteness": round(self.n_atoms / self.n, 4),
            "sparsity": self.sparsity,
            "training_patches": prov.get("training_patches"),
            "iterations": prov.get("iterations"),
            "final_relative_error": prov.get("final_relative_error"),
            "seed": prov.get("seed"),
            "normalisation": self.normalisation,
            "command": prov.get("command"),
            "data": prov.get("data"),
            "lfproc_version": prov.get("lfproc_version"),
        }
        if self.usage is not None:
            out["unused_atoms"] = int((self.usage == 0).sum())
        return out


def is_dictionary_file(path: str | os.PathLike) -> bool:
    """True for a shipped name or a ZIP archive whose first member is the dictionary header.

    Parameters
    ----------
    path : str or path-like
        A shipped dictionary name or a file (only its first ZIP member name is read).

    Returns
    -------
    bool
    """
    if str(path) in SHIPPED and not Path(path).exists():
        return True
    return zip_first_member(path) == HEADER_NAME


def shipped_path(name: str) -> Path:
    """Path of a dictionary shipped in the package (``"default"``)."""
    if name not in SHIPPED:
        raise InputError(f"dictionary: expected a file or one of {', '.join(SHIPPED)}, got {name!r}")
    return Path(str(resources.files("lfproc.dictionary") / "data" / f"{name}.npz"))


def save_dictionary(dictionary: Dictionary, path: str | os.PathLike, *, dtype="float16", force: bool = False) -> Path:
    """Write a dictionary file atomically (see the module documentation).

    Parameters
    ----------
    dictionary : Dictionary
    path : str or path-like
        The ``.npz`` file to write.
    dtype : {"float16", "float32"}, default "float16"
        Storage precision of the atoms (float16 halves the file; atoms are renormalised on load).
    force : bool, default False
        Overwrite an existing file.

    The archive is byte-identical for equal dictionaries (fixed member timestamps).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        Not a Dictionary, or another dtype.
    OutputExistsError
        ``path`` exists and ``force`` is false.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.dictionary import dct_dictionary, load_dictionary, save_dictionary
    >>> d = dct_dictionary((3, 3, 4, 4, 3), 600)
    >>> save_dictionary(d, "dct.npz", dtype="float32").name
    'dct.npz'
    >>> back = load_dictionary("dct.npz")
    >>> back.patch, back.atoms.shape, bool(np.array_equal(back.atoms, d.atoms))
    ((3, 3, 4, 4, 3), (432, 600), True)
    """
    if not isinstance(dictionary, Dictionary):
        raise InputError(f"save_dictionary: expected a Dictionary, got {type(dictionary).__name__}")
    if str(dtype) not in ("float16", "float32"):
        raise InputError(f"dictionary dtype: expected float16 or float32, got {dtype!r}")
    atoms = dictionary.atoms.astype(dtype)
    arrays = {"atoms": atoms}
    if dictionary.usage is not None:
        arrays["usage"] = dictionary.usage
    header = {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "lfproc_version": __version__,
        "patch": list(dictionary.patch),
        "n": dictionary.n,
        "atoms": dictionary.n_atoms,
        "sparsity": dictionary.sparsity,
        "preset": dictionary.preset,
        "dtype": str(dtype),
        "normalisation": dictionary.normalisation,
        "provenance": dictionary.provenance,
        "arrays": {k: {"shape": list(a.shape), "dtype": str(a.dtype)} for k, a in arrays.items()},
    }
    path = Path(path)
    with atomic_file(path, force=force) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as zf:
            zf.writestr(zipfile.ZipInfo(HEADER_NAME, date_time=_FIXED_ZIP_TIME),
                        json.dumps(to_jsonable(header), indent=1).encode(), compress_type=zipfile.ZIP_DEFLATED)
            for name, array in arrays.items():
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.ascontiguousarray(array), allow_pickle=False)
                zf.writestr(zipfile.ZipInfo(f"{name}.npy", date_time=_FIXED_ZIP_TIME), buf.getvalue(),
                            compress_type=zipfile.ZIP_DEFLATED)
    return path


def _field(header: dict, key: str, kind, where: str):
    value = header.get(key)
    if value is None:
        raise FileFormatError(f"{where}: missing field {key!r}")
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise FileFormatError(f"{where}: field {key!r}: expected an integer, found {value!r:.60}")
    elif not isinstance(value, kind):
        raise FileFormatError(f"{where}: field {key!r}: expected {kind.__name__}, found {type(value).__name__}")
    return value


def _read_member(zf: zipfile.ZipFile, name: str, limit: int, where: str) -> bytes:
    try:
        info = zf.getinfo(name)
    except KeyError:
        raise FileFormatError(f"{where}: no {name!r} member") from None
    if info.file_size > limit:
        raise FileFormatError(f"{where}: member {name!r} expands to {info.file_size} bytes; expected at most {limit}")
    try:
        with zf.open(info) as fh:
            data = ut.read_capped(fh, limit, source=where, what=f"member {name!r}")
    except (zipfile.BadZipFile, OSError, EOFError, zlib.error) as exc:
        raise FileFormatError(f"{where}: member {name!r} is corrupt ({exc})") from None
    return data


def _read_header(zf: zipfile.ZipFile, where: str) -> dict:
    raw = _read_member(zf, HEADER_NAME, 1 << 20, where)
    header = ut.parse_json(raw, source=where, what="dictionary header", max_bytes=1 << 20)  # bounded size and depth
    if not isinstance(header, dict):
        raise FileFormatError(f"{where}: header: expected a JSON object")
    if header.get("schema") != SCHEMA:
        raise FileFormatError(f"{where}: field 'schema': expected {SCHEMA!r}, found {str(header.get('schema'))[:60]!r}")
    if header.get("schema_version") != SCHEMA_VERSION:
        raise FileFormatError(f"{where}: field 'schema_version': expected {SCHEMA_VERSION}, found "
                              f"{str(header.get('schema_version'))[:20]} (written by another lfproc version)")
    return header


def dictionary_patch(source: "str | os.PathLike | Dictionary" = "default") -> tuple[str, tuple[int, ...]]:
    """Name and patch shape ``(V, U, P, P, C)`` of a dictionary, reading only a file's header.

    Cheap (the atoms are not read); used to check a capture's views against the dictionary it is
    meant for before reconstructing.
    """
    if isinstance(source, Dictionary):
        return str(source.name or source.preset), tuple(source.patch)
    name = str(source)
    shipped = name in SHIPPED and not Path(name).exists()
    path = shipped_path(name) if shipped else Path(source)
    if not path.is_file() or not zipfile.is_zipfile(path):
        raise MissingFileError(f"{path}: no such dictionary file") if not path.exists() else \
            FileFormatError(f"{path}: not an lfproc dictionary (expected a .npz archive with {HEADER_NAME})")
    try:
        with zipfile.ZipFile(path) as zf:
            patch = _field(_read_header(zf, str(path)), "patch", list, str(path))
    except zipfile.BadZipFile as exc:
        raise FileFormatError(f"{path}: corrupt dictionary archive ({exc})") from None
    if len(patch) != 5 or not all(isinstance(p, int) and not isinstance(p, bool) and p >= 1 for p in patch):
        raise FileFormatError(f"{path}: field 'patch': expected 5 positive integers, found {str(patch)[:80]}")
    return (name if shipped else str(path)), tuple(patch)


def load_dictionary(source: str | os.PathLike | Dictionary = "default") -> Dictionary:
    """Read a dictionary: a :class:`Dictionary` (returned as is), a shipped name or a file path.

    Parameters
    ----------
    source : str, path-like or Dictionary, default "default"
        A shipped name (``"default"``, the one :func:`lfproc.reconstruct` uses; a file of that
        name in the current directory takes precedence), the path of a ``.npz`` file written by
        :func:`save_dictionary`, or a :class:`Dictionary`.

    Returns
    -------
    Dictionary
        Atoms ``(n, K)`` with unit-norm columns, ``n = V*U*P*P*C`` (the ``patch`` shape).

    Examples
    --------
    >>> from lfproc.dictionary import load_dictionary
    >>> d = load_dictionary("default")  # shipped with lfproc
    >>> d.patch, d.atoms.shape, d.atoms.dtype, d.sparsity
    ((5, 5, 8, 8, 3), (4800, 2560), dtype('float32'), 10)
    >>> load_dictionary(d) is d
    True

    Raises
    ------
    MissingFileError
        No such file.
    FileFormatError
        Not a dictionary file, another schema version, sizes that disagree, NaN atoms,
        atoms that are not unit-norm (each error names the file and the field).
    """
    if isinstance(source, Dictionary):
        return source
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"dictionary: expected a name, a path or a Dictionary, got {type(source).__name__}")
    name = str(source)
    if name in SHIPPED and not Path(name).exists():
        path = shipped_path(name)
        if not path.is_file():
            raise MissingFileError(f"dictionary {name!r}: the shipped file {path} is missing from this installation")
    else:
        path = Path(source)
    where = str(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such dictionary file")
    if not path.is_file() or not zipfile.is_zipfile(path):
        raise FileFormatError(f"{path}: not an lfproc dictionary (expected a .npz archive with {HEADER_NAME})")
    try:
        with zipfile.ZipFile(path) as zf:
            header = _read_header(zf, where)
            patch = _field(header, "patch", list, where)
            if len(patch) != 5 or not all(isinstance(p, int) and not isinstance(p, bool) and 1 <= p <= 4096
                                          for p in patch):
                raise FileFormatError(f"{where}: field 'patch': expected 5 positive integers, found {str(patch)[:80]}")
            n = _field(header, "n", int, where)
            k = _field(header, "atoms", int, where)
            if n != math.prod(patch):
                raise FileFormatError(f"{where}: field 'n' is {n}, but patch {patch} has {math.prod(patch)} samples")
            if not (1 <= k and n * k <= MAX_ELEMENTS):
                raise FileFormatError(f"{where}: field 'atoms': expected 1..{MAX_ELEMENTS // max(n, 1)} atoms of "
                                      f"length {n}, found {k}")
            sparsity = _field(header, "sparsity", int, where)
            arrays = {}
            for member, shape, dtypes in (("atoms", (n, k), ("<f2", "<f4")), ("usage", (k,), ("<i8",))):
                if member == "usage" and f"{member}.npy" not in zf.namelist():
                    continue
                data = _read_member(zf, f"{member}.npy", math.prod(shape) * 8 + 4096, where)
                try:
                    array = np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
                except (ValueError, OSError, EOFError) as exc:
                    raise FileFormatError(f"{where}: array {member!r} is corrupt ({str(exc)[:80]})") from None
                if array.shape != shape or array.dtype.str not in dtypes:
                    raise FileFormatError(f"{where}: array {member!r}: expected shape {list(shape)} of "
                                          f"{'/'.join(dtypes)}, found {list(array.shape)} {array.dtype}")
                arrays[member] = array
            normalisation = header.get("normalisation") or {}
            provenance = header.get("provenance") or {}
            preset = header.get("preset") or "custom"
            if not isinstance(normalisation, dict) or not isinstance(provenance, dict) or not isinstance(preset, str):
                raise FileFormatError(f"{where}: fields 'normalisation'/'provenance'/'preset' have wrong types")
    except zipfile.BadZipFile as exc:
        raise FileFormatError(f"{where}: corrupt dictionary archive ({exc})") from None
    try:
        return Dictionary(atoms=arrays["atoms"], patch=tuple(patch), sparsity=sparsity, preset=preset,
                          normalisation=normalisation, provenance=provenance, usage=arrays.get("usage"),
                          name=name if name in SHIPPED and not Path(name).exists() else where)
    except InputError as exc:
        raise FileFormatError(f"{where}: {exc}") from None
