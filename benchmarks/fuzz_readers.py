"""Fuzz every reader of lfproc by the ten thousand and print the table of issue 13.

    python benchmarks/fuzz_readers.py                    # 10,000 cases per reader, 2 workers
    python benchmarks/fuzz_readers.py --cases 500 --readers exr,profile --json

The cases are those of ``tests/fuzzlib.py`` (seeded: case ``i`` of a reader is always the
same input): mutations of the real Lytro containers in ``../shared/data/lytro`` (when present)
and of files lfproc writes, compression bombs expanding to ``--bomb-bytes`` (default 1 GiB).

Each worker process runs with its address space limited (``RLIMIT_AS``: its size after
start-up plus ``--memory-gib``, default 3 GiB), traces allocations (tracemalloc) and stops a
case after ``--hang-seconds`` (SIGALRM); the parent kills a worker whose case runs 5 s past
that (a hang inside C code) and starts a new one. Outcomes:

* crash outside the tree: an exception that is not an ``LfprocError`` (or a worker that died);
* hang: a case longer than ``--hang-seconds`` (default 10 s);
* memory blow-up: ``MemoryError`` (the address-space limit), or a traced peak above
  256 MiB + 50 x the input's size.

Cases that end well but raise Python warnings (numpy's overflow or divide-by-zero on values
that went unchecked; the CLI would print them as extra lines) are counted apart.

Timings are upper bounds on a shared machine.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import signal
import sys
import tempfile
import time
from collections import Counter, defaultdict
from multiprocessing.connection import wait
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def _vm_size() -> int:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


_READER = None  # set by the parent before it forks the workers (seeds and bombs are inherited)


def _worker(conn, work: str, base_seed: int, hang_s: float, memory_gib: float):
    import fuzzlib

    reader = _READER
    work = Path(work)
    limit = _vm_size() + int(memory_gib * (1 << 30))
    try:
        resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))
    except (ValueError, OSError):
        pass
    conn.send(("ready", len(reader.seeds)))
    case_dir = work / f"case-{os.getpid()}"
    while True:
        msg = conn.recv()
        if msg is None:
            break
        index = msg
        try:
            seed, files, mutator = fuzzlib.build_case(reader, index, base_seed)
        except MemoryError:
            conn.send((index, "build-failed", "MemoryError while building the case", 0.0, 0, 0, "", []))
            continue
        conn.send(("started", index))  # the parent's hang timer starts now, not while the case was built
        outcome = fuzzlib.run_case(reader, case_dir, seed, files, budget_s=hang_s)
        conn.send((index, outcome.kind, outcome.detail[:300], outcome.seconds, outcome.peak_bytes,
                   outcome.input_bytes, f"{seed.name}/{mutator}", outcome.warnings[:1]))


class _Slot:
    def __init__(self, args, work):
        self.args, self.work = args, work
        self.start()

    def start(self):
        parent, child = mp.Pipe()
        self.conn = parent
        self.proc = mp.get_context("fork").Process(
            target=_worker, args=(child, self.work, self.args.seed, self.args.hang_seconds, self.args.memory_gib),
            daemon=True)
        self.proc.start()
        self.case = None
        self.started = 0.0
        ready = self.conn.recv()
        assert ready[0] == "ready"

    def send(self, index):
        self.case = index
        self.started = float("inf")  # until the worker says the case is built
        self.conn.send(index)

    def kill(self):
        if self.proc.is_alive():
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.join()


def run_reader(args, reader_name: str, work: Path) -> dict:
    global _READER
    import fuzzlib

    n = args.cases
    folder = work / reader_name
    folder.mkdir(parents=True, exist_ok=True)
    _READER = fuzzlib.READERS[reader_name](folder)
    tb = time.time()
    fuzzlib.prebuild_bombs(_READER)  # once, in the parent: the workers inherit them
    if args.progress:
        print(f"  {reader_name}: seeds and bombs ready in {time.time() - tb:.0f} s", file=sys.stderr, flush=True)
    slots = [_Slot(args, str(folder)) for _ in range(args.workers)]
    todo = list(range(n))
    results = Counter()
    examples: dict[str, list[str]] = defaultdict(list)
    peak = 0
    peak_ratio = 0.0
    slowest = 0.0
    t0 = time.time()
    done = shown = 0

    def record(kind, detail, index, label, seconds=0.0, peak_bytes=0, size=0):
        nonlocal peak, peak_ratio, slowest
        results[kind] += 1
        peak = max(peak, peak_bytes)
        if size:
            peak_ratio = max(peak_ratio, peak_bytes / size)
        slowest = max(slowest, seconds)
        if kind not in ("ok", "lfproc") and len(examples[kind]) < 8:
            examples[kind].append(f"case {index} ({label}): {detail}")

    for slot in slots:
        if todo:
            slot.send(todo.pop(0))
    while any(s.case is not None for s in slots):
        ready = wait([s.conn for s in slots if s.case is not None], timeout=1.0)
        for slot in slots:
            if slot.case is None:
                continue
            if slot.conn in ready:
                try:
                    message = slot.conn.recv()
                    if message[0] == "started":
                        slot.started = time.time()
                        continue
                    index, kind, detail, seconds, peak_bytes, size, label, warned = message
                    if warned:
                        results["warned"] += 1
                        if len(examples["warned"]) < 8:
                            examples["warned"].append(f"case {index} ({label}): {warned[0]}")
                except (EOFError, OSError):
                    code = slot.proc.exitcode
                    record("crash", f"worker died (exit code {code})", slot.case, "?")
                    slot.kill()
                    slot.start()
                else:
                    record("crash" if kind == "build-failed" else kind, detail, index, label, seconds, peak_bytes,
                           size)
                done += 1
                slot.case = None
            elif time.time() - slot.started > args.hang_seconds + 5:
                record("hang", f"killed after {args.hang_seconds + 5:g} s (stuck in C code)", slot.case, "?",
                       seconds=time.time() - slot.started)
                slot.kill()
                slot.start()
                done += 1
                slot.case = None
            if slot.case is None and todo:
                slot.send(todo.pop(0))
        if args.progress and done >= shown + 500:
            shown = done // 500 * 500
            print(f"  {reader_name}: {done}/{n} ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
    for slot in slots:
        try:
            slot.conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        slot.proc.join(5)
        slot.kill()
    return {"reader": reader_name, "cases": n, "outcomes": dict(results), "examples": dict(examples),
            "max_traced_peak_mib": round(peak / 2**20, 1), "max_peak_over_input": round(peak_ratio, 1),
            "slowest_case_s": round(slowest, 2), "seconds": round(time.time() - t0, 1)}


def main(argv=None) -> int:
    import fuzzlib

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=10000, help="cases per reader (default 10000)")
    p.add_argument("--readers", default=",".join(fuzzlib.READERS), help="comma-separated reader names")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=13, help="base seed of the cases (default 13)")
    p.add_argument("--hang-seconds", type=float, default=10.0, help="a case longer than this is a hang (default 10)")
    p.add_argument("--memory-gib", type=float, default=3.0, help="address space each worker may add (default 3)")
    p.add_argument("--bomb-bytes", type=int, default=1 << 30, help="what compression bombs expand to (1 GiB)")
    p.add_argument("--json", action="store_true", help="print the results as one JSON object")
    p.add_argument("--progress", action="store_true", help="report progress on stderr")
    args = p.parse_args(argv)
    os.environ["LFPROC_PROGRESS"] = "0"
    os.environ.setdefault("MPLBACKEND", "Agg")
    fuzzlib.BOMB_BYTES = args.bomb_bytes
    labels = {"lytro-container": "Lytro container (`info`)", "lytro-capture": "Lytro raw capture (`decode`)",
              "exr": "EXR light field (`info`, `convert`, `evaluate`)",
              "profile": "camera profile JSON + sidecar (`profile show`, `simulate`)",
              "manifest": "calibration manifest (`calibrate`)", "capture": "capture file (`info`, `preview`)",
              "caldata": "caldata tar (`whites`)", "white-db": "white-image database (`decode --white-db`)",
              "emva": "EMVA 1288 descriptor (`calibrate`)"}
    rows = []
    with tempfile.TemporaryDirectory(prefix="lfproc-fuzz-") as tmp:
        for name in args.readers.split(","):
            row = run_reader(args, name.strip(), Path(tmp))
            row["label"] = labels.get(name, name)
            rows.append(row)
            if args.progress:
                print(f"{name}: {row['outcomes']} in {row['seconds']} s", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps({"cases_per_reader": args.cases, "seed": args.seed, "hang_seconds": args.hang_seconds,
                          "bomb_bytes": args.bomb_bytes, "readers": rows}))
        return 0
    print(f"{args.cases} cases per reader, seed {args.seed}, hang > {args.hang_seconds:g} s, bombs of "
          f"{args.bomb_bytes / 2**30:g} GiB, {args.workers} workers\n")
    print("| reader (command) | inputs tried | crashes outside the tree | hangs > 10 s | memory blow-ups | "
          "refused (lfproc error) | accepted | with Python warnings | max traced peak | slowest case | time |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        o = r["outcomes"]
        print(f"| {r['label']} | {r['cases']} | {o.get('crash', 0)} | {o.get('hang', 0)} | {o.get('memory', 0)} | "
              f"{o.get('lfproc', 0)} | {o.get('ok', 0)} | {o.get('warned', 0)} | {r['max_traced_peak_mib']} MiB | "
              f"{r['slowest_case_s']} s | {r['seconds']:.0f} s |")
    for r in rows:
        for kind, items in r["examples"].items():
            print(f"\n{r['reader']} {kind}:")
            for item in items:
                print(f"  {item}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
