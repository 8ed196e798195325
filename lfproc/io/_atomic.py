"""Atomic outputs: write to a temporary sibling, then rename; several outputs published together.

* :func:`atomic_file` / :func:`atomic_dir`: one output, written to a hidden temporary sibling
  and renamed onto its path, so an interrupted run never leaves a half-written file.
* :func:`atomic_outputs`: several outputs of one command (a profile, its bias sidecar and a
  report folder...), staged in hidden sibling folders and published together: a journal
  ``.lfproc-txn-<pid>-*.json`` is written next to each output folder before the first rename
  and removed after the last, so a run killed while publishing is rolled back by the next
  run (the previous outputs, if any, come back) and the outputs are all new or all old.
* Stale entries: every hidden entry carries the writer's process id
  (``.lfproc-tmp-<pid>-*`` temporaries, ``.lfproc-old-<pid>-*`` outputs moved aside while
  being replaced, ``.lfproc-txn-<pid>-*`` journals). :func:`check_output`, which every
  writer calls, first recovers the entries of the output's folder whose process is no
  longer alive (:func:`clean_stale`): journals are rolled back, an output moved aside is put
  back when its replacement never arrived, temporaries are removed. Entries of a live
  process (including this one) are never touched. Whether a process is alive is checked on
  this machine: do not let several machines write into one folder at the same time.

Testing hook: with ``LFPROC_TEST_KILL_AT=<point>`` (or ``<point>#<n>`` for its n-th
occurrence) the process SIGKILLs itself at that point, so tests can check what a kill at
exactly that moment leaves. Points: ``file-written`` and ``dir-written`` (an output is complete
in its temporary, not yet renamed), ``dir-aside`` (an existing folder moved aside, the new one
not yet in place), ``staged`` (every output of :func:`atomic_outputs` staged, no journal yet),
``journal`` (journals written, nothing renamed), ``moved`` (after each output is renamed into
place), ``committed`` (journals removed, replaced outputs not yet deleted).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import shutil
import signal
import tempfile
from collections.abc import Sequence
from pathlib import Path

from ..errors import InputError, OutputExistsError, option_name



def _exists(path) -> str:
    """The message of an existing output, naming force in the words of the interface in use."""
    return f"{path}: output exists; pass {option_name('force=True', '--force')} to overwrite it"

__all__ = ["check_output", "atomic_file", "atomic_dir", "atomic_outputs", "clean_stale"]

_STALE = re.compile(r"^\.lfproc-(tmp|old|txn)-(\d+)-(.+)$")
_KILL_ENV = "LFPROC_TEST_KILL_AT"
_seen: dict[str, int] = {}


def _checkpoint(name: str) -> None:
    """Testing hook: SIGKILL this process at the named point when ``LFPROC_TEST_KILL_AT`` asks for it."""
    want = os.environ.get(_KILL_ENV)
    if not want:
        return
    point, _, nth = want.partition("#")
    if point != name:
        return
    _seen[name] = _seen.get(name, 0) + 1
    if _seen[name] == int(nth or 1):
        os.kill(os.getpid(), signal.SIGKILL)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _publish_mode(path: Path, base: int) -> None:
    """mkstemp/mkdtemp create private (0600/0700) entries; give outputs the usual mode."""
    os.chmod(path, base & ~_umask())


# -- stale entries of killed runs ------------------------------------------------------------------

def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` may still be running (unknown counts as alive: never clean then)."""
    if pid == os.getpid():
        return True
    if os.name != "posix" or pid <= 0:
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: another user's live process
        return True
    try:  # a zombie (killed, not yet reaped by its parent) is dead for our purposes
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rindex(")") + 2:][:1] != "Z"
    except (OSError, ValueError):
        return True


def _remove(path: Path) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    except FileNotFoundError:
        pass


def _read_journal(path: Path) -> dict | None:
    try:
        doc = json.loads(path.read_text())
        return doc if isinstance(doc, dict) else None
    except (OSError, ValueError):
        return None


def _recover(journal: Path, pid: int) -> None:
    """Finish or undo the publication a dead process recorded in ``journal`` (see :func:`atomic_outputs`).

    Committed (some journal of the transaction says so: every output was in place): remove what
    was moved aside and the staging folders. Else roll back: the new outputs go, the previous
    ones come back. Only paths in folders that hold a journal of this transaction (so writable
    by whoever wrote it) and hidden entries named after the dead process are touched.
    """
    doc = _read_journal(journal)
    try:
        moves = [(Path(m["final"]), Path(m["staged"]), Path(m["old"]) if m.get("old") else None)
                 for m in doc["moves"]]  # type: ignore[index]
        journals = [Path(j) for j in doc["journals"]]  # type: ignore[index]
        stage_dirs = [Path(d) for d in doc["stage_dirs"]]  # type: ignore[index]
    except (KeyError, TypeError, ValueError):
        _remove(journal)  # not a journal lfproc wrote (they are written whole, via a temporary)
        return
    journals = [j for j in journals if j.name == journal.name] + [journal]
    folders = {j.parent for j in journals if j.exists()}
    committed = any((_read_journal(j) or {}).get("committed") is True for j in journals if j.exists())

    def ours(p: Path | None, kind: str) -> bool:  # a hidden entry of the dead process, in a journal's folder
        return p is not None and p.parent in folders and p.name.startswith(f".lfproc-{kind}-{pid}-")

    if not committed:
        for final, staged, old in moves:
            if final.parent not in folders:
                continue
            if ours(old, "old"):  # an output existed at ``final`` before
                if old.exists() or old.is_symlink():  # ... and was moved aside: what is at final is new
                    _remove(final)
                    os.replace(old, final)  # the previous output comes back
                # else it was never moved aside: it is still at ``final``, keep it
            elif old is None and ours(staged.parent, "tmp") and not (staged.exists() or staged.is_symlink()):
                _remove(final)  # nothing was there before and the new output was moved in: it goes
    for final, _, old in moves:
        if ours(old, "old"):
            _remove(old)  # committed: the replaced output; rolled back: already put back
    for d in stage_dirs:
        if ours(d, "tmp"):
            _remove(d)
    for j in journals:
        if j.parent in folders:
            _remove(j)


def clean_stale(folder: str | os.PathLike) -> list[Path]:
    """Recover the hidden entries that dead lfproc processes left in ``folder`` (not recursive).

    Journals are rolled back first, then an output moved aside (``.lfproc-old-*``) goes back to
    its name when nothing took its place (else it is removed), then temporaries are removed.
    Returns the entries handled. Entries of live processes are left alone.
    """
    folder = Path(folder)
    try:
        entries = sorted(folder.iterdir())
    except OSError:
        return []
    stale = []
    for p in entries:
        m = _STALE.match(p.name)
        if m and not _pid_alive(int(m.group(2))):
            stale.append((m.group(1), p, m.group(3)))
    order = {"txn": 0, "old": 1, "tmp": 2}
    for kind, p, rest in sorted(stale, key=lambda e: order[e[0]]):
        if not (p.exists() or p.is_symlink()):
            continue  # handled with its journal
        if kind == "txn":
            _recover(p, int(_STALE.match(p.name).group(2)))
        elif kind == "old":
            name = rest.rsplit("-", 1)[0]
            target = p.with_name(name)
            if name and not (target.exists() or target.is_symlink()):
                os.replace(p, target)
            else:
                _remove(p)
        else:
            _remove(p)
    return [p for _, p, _ in stale]


def check_output(path: str | os.PathLike, *, force: bool = False) -> Path:
    """Fail early when ``path`` exists and ``force`` is false, or its folder is missing.

    Stale entries of killed runs in the folder are recovered first (:func:`clean_stale`).
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{path}: the output folder {parent} does not exist")
    clean_stale(parent)
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputExistsError(_exists(path))
    return path


def _tmp_prefix(name: str) -> str:
    return f".lfproc-tmp-{os.getpid()}-{name}-"


# -- one output ---------------------------------------------------------------------------------------

@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, *, force: bool = False):
    """Yield a temporary path next to ``path`` (same suffix); rename it onto ``path`` on success.

    The suffix is kept because writers such as OpenCV choose the format from it.
    """
    path = check_output(path, force=force)
    fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix(path.stem), suffix=path.suffix, dir=path.parent or ".")
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        if not tmp.exists() or tmp.stat().st_size == 0:
            raise OSError(f"{path}: the writer produced no data")
        if path.exists() and not force:  # appeared while we were working
            raise OutputExistsError(_exists(path))
        _publish_mode(tmp, 0o666)
        _checkpoint("file-written")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, *, force: bool = False):
    """Yield a temporary folder next to ``path``; move it to ``path`` on success.

    With ``force`` an existing folder is replaced as a whole (moved aside, then removed),
    so readers never see a mix of old and new files; a run killed in between leaves the
    old folder aside, and the next run puts it back.
    """
    path = check_output(path, force=force)
    tmp = Path(tempfile.mkdtemp(prefix=_tmp_prefix(path.name), dir=path.parent or "."))
    try:
        yield tmp
        _checkpoint("dir-written")
        old = None
        if path.exists():
            if not force:
                raise OutputExistsError(_exists(path))
            old = path.with_name(f".lfproc-old-{os.getpid()}-{path.name}-{secrets.token_hex(4)}")
            os.replace(path, old)
            _checkpoint("dir-aside")
        _publish_mode(tmp, 0o777)
        os.replace(tmp, path)
        if old is not None:
            _remove(old)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


# -- several outputs ----------------------------------------------------------------------------------

@contextlib.contextmanager
def atomic_outputs(paths: Sequence[str | os.PathLike], *, force: bool = False):
    """Write several outputs and publish them together: all of them, or none.

    Yields one staged path per output (same name, inside a hidden staging folder
    ``.lfproc-tmp-<pid>-txn-*`` next to it); the caller writes each output there, as a file
    or a folder, with any writer (which may write atomically itself). On success every
    output is renamed into place under a journal (see the module notes): a run killed at any
    moment leaves either all new outputs, or the previous state once the next run has
    recovered the folder. An existing output is only replaced with ``force``.
    """
    finals = [Path(p) for p in paths]
    if len({p.resolve() for p in finals}) != len(finals):
        raise InputError(f"outputs: the same path is given twice ({', '.join(map(str, finals))})")
    for p in finals:
        check_output(p, force=force)
    stage_dirs: dict[Path, Path] = {}
    staged = []
    try:
        for p in finals:
            parent = p.parent if str(p.parent) else Path(".")
            if parent not in stage_dirs:
                stage_dirs[parent] = Path(tempfile.mkdtemp(prefix=_tmp_prefix("txn"), dir=parent))
            staged.append(stage_dirs[parent] / p.name)
        yield list(staged)
        for p, s in zip(finals, staged):
            if not (s.exists() or s.is_symlink()):
                raise OSError(f"{p}: the writer produced no output")
            if p.exists() and not force:
                raise OutputExistsError(_exists(p))
        _checkpoint("staged")
        _publish(finals, staged, list(stage_dirs.values()))
    finally:
        for d in stage_dirs.values():
            if d.exists():
                shutil.rmtree(d)


def _write_journal(path: Path, doc: dict) -> None:
    fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix("txn"), suffix=".json", dir=path.parent)
    with os.fdopen(fd, "w") as fh:
        fh.write(json.dumps(doc, indent=1))
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _publish(finals: list[Path], staged: list[Path], stage_dirs: list[Path]) -> None:
    pid, txn = os.getpid(), secrets.token_hex(4)
    moves = []
    for final, s in zip(finals, staged):
        exists = final.exists() or final.is_symlink()
        old = final.with_name(f".lfproc-old-{pid}-{final.name}-{txn}") if exists else None
        moves.append((final, s, old))
    parents = list(dict.fromkeys(final.parent if str(final.parent) else Path(".") for final in finals))
    journals = [parent / f".lfproc-txn-{pid}-{txn}.json" for parent in parents]
    doc = {
        "pid": pid,
        "committed": False,
        "journals": [str(j.resolve()) for j in journals],
        "stage_dirs": [str(d.resolve()) for d in stage_dirs],
        "moves": [{"final": str(f.resolve()), "staged": str(s.resolve()), "old": str(o.resolve()) if o else None}
                  for f, s, o in moves],
    }
    for j in journals:  # one journal per output folder, each describing the whole transaction
        _write_journal(j, doc)
    _checkpoint("journal")
    for final, s, old in moves:
        if old is not None:
            os.replace(final, old)
        _publish_mode(s, 0o777 if s.is_dir() else 0o666)
        os.replace(s, final)
        _checkpoint("moved")
    doc["committed"] = True  # the commit point: from the first rewrite on, the new outputs stay
    for j in journals:
        _write_journal(j, doc)
    for j in journals:
        j.unlink()
    _checkpoint("committed")
    for _, _, old in moves:
        if old is not None:
            _remove(old)
