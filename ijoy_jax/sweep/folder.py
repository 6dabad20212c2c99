"""A sweep's output folder: its layout, the lock a run holds on it, its records (manifest and process records)
and its parts, each written atomically and read back with a one-line refusal when damaged.

Layout of an output folder::

    DIR/sweep.toml              the sweep file's text, as run
    DIR/manifest.json           sweep text, plan, the robot (model, actions per density), package versions,
                                device, git commit, timings
    DIR/parts/part-00000.parquet  one file per completed chunk (written atomically), its plan record
                                (sweep name, chunk plan and the plan's hash) in the parquet metadata
    DIR/processes/process-00001.json  sessions of process 1 of several (process 0's are in the manifest)
    DIR/aggregates.parquet      per-cell means and 95% confidence intervals (when complete)
    DIR/.lock                   held (flock) while a run writes here: a second run refuses (see FolderLock)

Each finished chunk is written to a temporary file and renamed (atomic on POSIX), so after a kill a part file
is either complete or absent; a rerun on the same folder reads which scenarios each part holds
(:func:`held_ids`) and computes the rest. Every part records the hash of its plan
(:func:`ijoy_jax.sweep.plan.plan_hash`): a run refuses a folder holding parts of another plan (even with
``manifest.json`` deleted) before writing anything (:func:`check_plans`, :func:`check_same_plan`), and
:func:`ijoy_jax.sweep.load` refuses to mix them. A part or record damaged outside a run (truncated,
overwritten, hand-edited) is never skipped or read as results: the run and :func:`ijoy_jax.sweep.load` refuse
it in one line naming the file and the way out (delete that part, and the run recomputes its chunk; delete a
record, and the run writes it anew from the parts' plan records).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from ijoy_jax.sweep import models
from ijoy_jax.sweep.fits import file_values
from ijoy_jax.sweep.plan import PLAN_KEY, describe_plan, differences
from ijoy_jax.sweep.schema import SweepConfig, reach_of

__all__ = [
    "FolderLock",
    "IncompleteSweepError",
    "check_out_folder",
    "check_plans",
    "check_same_plan",
    "corrupt_part",
    "held_ids",
    "part_path",
    "part_plan",
    "parts_chunk_size",
    "read_part",
    "read_record",
    "read_records",
    "start_session",
    "write_part",
    "write_record",
    "write_rows",
]

_PART = "part-{:05d}.parquet"
_PROC = "process-{:05d}.json"


class IncompleteSweepError(ValueError):
    """A sweep folder lacks chunks (a process has not finished), holds duplicated scenarios, mixes in parts
    of another plan, or holds a part or record that cannot be read (truncated, overwritten or hand-edited)."""


def _reason(e: BaseException) -> str:
    """An exception's message as one short line (a parquet or JSON reader's may span lines)."""
    text = " ".join(str(e).split()) or type(e).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def corrupt_part(path, e: BaseException) -> IncompleteSweepError:
    """The error for a part that cannot be read (``e``): it names the file and says to delete it and rerun."""
    return IncompleteSweepError(
        f"{path}: corrupt or truncated result part ({_reason(e)}); delete it and rerun `ijoy sweep run` with the "
        f"same sweep file and --out: the run recomputes that chunk alone"
    )


def read_record(path, required: tuple[str, ...] = ()) -> dict:
    """A sweep folder's JSON record (``manifest.json``, ``processes/process-*.json``) as a dict.

    Args:
      path: the record's file.
      required: keys it must hold. Whatever it holds of ``plan`` (a dict with integer ``chunks`` and
        ``scenarios``), ``sweep_text`` (a string) and ``sessions`` (a list of dicts) must have that form.

    Raises:
      IncompleteSweepError: one line naming the file, what is wrong with it and the way out: every part
        records its plan (chunk size included), so a run with the same sweep file and ``--out`` writes the
        record anew once it is deleted, and resumes (only the record's session history is lost, and with it
        what slice the folder was asked for: give ``--scenarios-per-cell`` or ``--max-scenarios`` again).
    """
    path = Path(path)
    way_out = (
        "delete it and rerun `ijoy sweep run` with the same sweep file and --out (and --scenarios-per-cell "
        "or --max-scenarios as before): the parts record their plan, so the run writes it anew and resumes"
    )
    try:
        record = json.loads(path.read_bytes())
    except OSError as e:
        raise IncompleteSweepError(f"{path}: cannot read the sweep's record: {e.strerror or e}") from None
    except ValueError as e:  # JSONDecodeError, UnicodeDecodeError
        raise IncompleteSweepError(f"{path}: corrupt or truncated record, not JSON ({_reason(e)}); {way_out}") from None
    if not isinstance(record, dict):
        raise IncompleteSweepError(f"{path}: corrupt record: a JSON {type(record).__name__}, not an object; {way_out}")
    plan = record.get("plan", {})
    problems = [f"no {k!r}" for k in required if k not in record]
    if not isinstance(plan, dict) or any(
        isinstance(plan.get(k), bool) or not isinstance(plan.get(k), int)
        for k in ("chunks", "scenarios")
        if "plan" in record
    ):
        problems.append("'plan' is not an object with integer 'chunks' and 'scenarios'")
    if not isinstance(record.get("sweep_text", ""), str):
        problems.append("'sweep_text' is not a string")
    sel = record.get("selection", {})
    if not isinstance(sel, dict) or any(
        isinstance(sel.get(k), bool) or not isinstance(sel.get(k), int) or sel[k] < (1 if k == "replicates" else 0)
        for k in ("scenarios_per_cell", "max_scenarios", "replicates", "cells", "scenarios", "of")
        if "selection" in record
    ):
        problems.append(
            "'selection' is not an object with non-negative integer 'scenarios_per_cell', "
            "'max_scenarios', 'replicates' (>= 1), 'cells', 'scenarios' and 'of'"
        )
    sessions = record.get("sessions", [])
    if not isinstance(sessions, list) or not all(isinstance(x, dict) for x in sessions):
        problems.append("'sessions' is not a list of objects")
    if problems:
        raise IncompleteSweepError(f"{path}: corrupt record ({'; '.join(problems)}); {way_out}")
    return record


def part_plan(path) -> dict | None:
    """The plan record a part file was written with (:data:`PLAN_KEY`), or None for a part written before
    parts recorded their plan. Reads only the file's footer.

    Raises:
      IncompleteSweepError: the file is not a readable parquet file (truncated, overwritten) or its plan
        record is not a JSON object; the message names the file and says to delete it and rerun.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        meta = pq.read_schema(path).metadata or {}
    except (OSError, ValueError, pa.ArrowException) as e:  # ArrowInvalid: "Parquet magic bytes not found"
        raise corrupt_part(path, e) from None
    if PLAN_KEY not in meta:
        return None
    try:
        record = json.loads(meta[PLAN_KEY])
    except ValueError as e:
        raise corrupt_part(path, ValueError(f"its plan record is not JSON: {e}")) from None
    if not isinstance(record, dict):
        raise corrupt_part(path, ValueError("its plan record is not a JSON object"))
    return record


def read_part(path, columns=None):
    """A result part's rows (``columns`` of them, None: all) as a pandas.DataFrame.

    Raises:
      IncompleteSweepError: the file cannot be read (truncated, overwritten); the message names it and says to
        delete it and rerun (the run recomputes its chunk).
    """
    import pandas as pd
    import pyarrow as pa

    try:
        return pd.read_parquet(path, columns=columns)
    except (OSError, ValueError, pa.ArrowException) as e:
        raise corrupt_part(path, e) from None


def check_plans(path: Path, files, expected: dict | None, *, allow_unrecorded: bool) -> None:
    """Raise :class:`IncompleteSweepError` (naming the folder, the part, both plans and what differs between
    them) unless every part in ``files`` was written by the plan ``expected`` (a record as in :data:`PLAN_KEY`;
    None: the first recorded part's plan). Unrecorded (older) parts pass when ``allow_unrecorded``; a part that
    cannot be read raises too (:func:`part_plan`)."""

    def without_hash(record: dict | None) -> dict:
        return {k: v for k, v in (record or {}).items() if k != "hash"}

    for f in files:
        rec = part_plan(f)
        if rec is None and allow_unrecorded:
            continue
        if expected is None:
            expected = rec
            continue
        if rec is None or rec.get("hash") != expected.get("hash"):
            differing = ""
            if rec is not None:  # the hash also covers the sweep file's text, which the records do not hold
                what = differences(without_hash(rec), without_hash(expected)) or "the sweep file's text"
                differing = f" (differing: {what})"
            raise IncompleteSweepError(
                f"{path}: {Path(f).relative_to(path)} belongs to another plan: {describe_plan(rec)}, not "
                f"{describe_plan(expected)}{differing}; results of "
                f"different sweeps would be mixed: run into another folder, or delete the parts of the other plan"
            )


def _versions() -> dict:
    out = {"python": platform.python_version()}
    for pkg in ("ijoy_jax", "jax", "jaxlib", "numpy", "pandas", "pyarrow"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def _git_commit() -> str | None:
    try:
        here = Path(__file__).resolve().parent
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
        dirty = subprocess.run(["git", "status", "--porcelain"], cwd=here, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    if r.returncode != 0:
        return None
    return r.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


_WHO = f"{platform.node()}-{os.getpid()}"  # names this process's temporary files (host and pid)
_LOCK = ".lock"
_LOCK_PROC = ".lock-process-{:05d}"


def check_out_folder(out: Path) -> None:
    """Refuse an output folder that holds anything but a sweep's results (ValueError naming it and what it holds).

    A folder is a sweep's once it has ``manifest.json`` or ``parts/``; before that (a fresh or an empty folder,
    or one whose run stopped at once) it may hold only the run's locks and ``processes/``. So ``--out .`` in a
    project, or a folder of other files, is never written into (a sweep writes ``sweep.toml`` there)."""
    if not out.exists():
        return
    if not out.is_dir():
        raise ValueError(f"{out} is not a folder; choose another --out")
    if (out / "manifest.json").exists() or (out / "parts").is_dir():
        return
    foreign = sorted(
        p.name
        for p in out.iterdir()
        if not (p.name == _LOCK or p.name.startswith(".lock-process-") or p.name == "processes")
    )
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise ValueError(
            f"{out} holds files that are not a sweep's results ({shown}); a sweep writes only into a "
            f"new or empty folder or its own results: choose another --out"
        )


class FolderLock:
    """An advisory lock (``fcntl.flock``) on a sweep's output folder, taken before its manifest is read.

    One process of one (process 0 of 1) holds ``DIR/.lock`` exclusively; the processes of a
    multi-process layout (``num_processes > 1``: members of one ``jax.distributed`` run, which
    split the chunks between them) share it and each holds ``DIR/.lock-process-I`` exclusively.
    So a second run on the folder, or a second process I, is refused (ValueError naming the
    holder's pid and host, written into the lock file). The kernel drops a flock when its process
    dies, so a lock file left by a dead process is stale and simply taken over. (On NFS, Linux maps
    flock onto the server's byte-range locks.)
    """

    def __init__(self, out: Path, pid: int, nproc: int):
        import fcntl

        out.mkdir(parents=True, exist_ok=True)
        self.fds: list[int] = []
        me = {
            "pid": os.getpid(),
            "host": platform.node(),
            "process_id": pid,
            "num_processes": nproc,
            "since": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
        wanted = (
            [(out / _LOCK, fcntl.LOCK_EX)]
            if nproc == 1
            else [(out / _LOCK, fcntl.LOCK_SH), (out / _LOCK_PROC.format(pid), fcntl.LOCK_EX)]
        )
        try:
            for path, mode in wanted:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
                self.fds.append(fd)
                try:
                    fcntl.flock(fd, mode | fcntl.LOCK_NB)
                except BlockingIOError:
                    raise ValueError(self._refusal(out, path, nproc)) from None
                if mode == fcntl.LOCK_EX:  # the holder, for the next one's error message
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, json.dumps(me).encode(), 0)
        except BaseException:
            self.release()
            raise
        if nproc == 1:  # alone in the folder: temporary files left by killed runs are garbage
            for tmp in (out / "parts").glob("*.tmp"):
                tmp.unlink(missing_ok=True)

    @staticmethod
    def _refusal(out: Path, path: Path, nproc: int) -> str:
        holders = []
        for f in [out / _LOCK, *sorted(out.glob(".lock-process-*"))]:
            try:
                h = json.loads(f.read_text())
                if not _alive(h):
                    continue  # a stale record (its lock is not held)
                holders.append(
                    f"pid {h['pid']} on {h['host']}"
                    + (f" (process {h['process_id']} of {h['num_processes']})" if h.get("num_processes", 1) > 1 else "")
                )
            except (OSError, ValueError, KeyError, TypeError):
                continue
        who = "; ".join(dict.fromkeys(holders)) or "another process"
        what = "another run" if path.name == _LOCK else "another process with this --process-id"
        return f"{out} is in use by {what} ({who} holds {path.name}); wait for it to finish or choose another --out" + (
            "" if nproc > 1 else "; processes of one multi-process run share a folder (--num-processes/--process-id)"
        )

    def release(self) -> None:
        for fd in self.fds:
            os.close(fd)  # closing drops the flock
        self.fds = []


def _alive(holder: dict) -> bool:
    """Whether a lock file's holder may still run (a pid on another host cannot be checked: True)."""
    if holder.get("host") != platform.node():
        return True
    try:
        os.kill(int(holder["pid"]), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def parts_chunk_size(parts: Path) -> int | None:
    """The chunk size the first part in ``parts`` records in its plan, or None (no part, or none recorded)."""
    for f in sorted(parts.glob("part-*.parquet")) if parts.is_dir() else ():
        rec = part_plan(f)  # IncompleteSweepError for a part that cannot be read
        if rec is not None and isinstance(rec.get("chunk_size"), int) and rec["chunk_size"] >= 1:
            return rec["chunk_size"]
    return None


def _what_differs(prev: dict, text: str, plan_key: dict) -> str:
    """What differs between a folder's record (``prev``: its sweep text and plan) and this run's, compactly: the
    sweep file's keys (``sweep.seed 3 -> 4``, ``grid.robot.w [0.5, 2.0] -> [1.0, 4.0]``), then the plan's
    (``plan.chunk_size 2 -> 4``), each sorted, old -> new; the first differing line where the sweep files differ
    only in comments or layout (the plan's hash covers the text)."""
    import tomllib

    old_text = prev.get("sweep_text", "")
    sweep = ""
    if old_text != text:
        try:
            sweep = differences(tomllib.loads(old_text), tomllib.loads(text))
        except tomllib.TOMLDecodeError:
            sweep = "the sweep file's text (the folder's is not TOML)"
        if not sweep:  # the same keys and values
            old_lines, new_lines = old_text.splitlines(), text.splitlines()
            n = next(
                (i for i, (a, b) in enumerate(zip(old_lines, new_lines, strict=False)) if a != b),
                min(len(old_lines), len(new_lines)),
            )

            def line(lines: list[str]) -> str:
                return json.dumps(lines[n]) if n < len(lines) else "the end of the file"

            sweep = f"the sweep file's comments or layout, line {n + 1}: {line(old_lines)} -> {line(new_lines)}"
    plan = differences({"plan": prev.get("plan", {})}, {"plan": plan_key})
    return ", ".join(d for d in (sweep, plan) if d)


def write_record(path: Path, obj) -> None:
    """Write a record (``manifest.json`` or a process's record) as JSON, atomically (a temporary file renamed)."""
    tmp = path.with_name(f"{path.name}.{_WHO}.tmp")
    tmp.write_text(json.dumps(obj, indent=2, default=str))
    os.replace(tmp, path)


def write_part(df, path: Path, plan_record: dict) -> None:
    """Write one chunk's results as parquet, its plan record in the file's metadata (:data:`PLAN_KEY`).

    The writer :func:`read_part` and :func:`part_plan` read back. ``df``: the chunk's rows (a pandas.DataFrame,
    its index not written); ``plan_record``: a JSON-able dict (the sweep name, chunk plan and plan hash). It
    writes ``path`` in place: :func:`write_rows` writes to a temporary name and renames it, so that a part is
    either complete or absent.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = {**(table.schema.metadata or {}), PLAN_KEY: json.dumps(plan_record).encode()}
    pq.write_table(table.replace_schema_metadata(meta), path)


def held_ids(path: Path, ids: np.ndarray) -> np.ndarray:
    """The scenario ids whose results the part of a chunk (its scenario ids ``ids``) holds: none without a part,
    all of them when its footer counts them all, else its ``scenario`` column."""
    import pyarrow.parquet as pq

    if not path.exists():
        return ids[:0]
    try:
        if pq.read_metadata(path).num_rows == len(ids):
            return ids
    except Exception:  # noqa: BLE001 - read_part names the damaged file in one line
        pass
    return read_part(path, ["scenario"])["scenario"].to_numpy(np.int64)


def part_path(out: Path, chunk_id: int) -> Path:
    """The part file of chunk ``chunk_id`` in the folder ``out``."""
    return out / "parts" / _PART.format(chunk_id)


def read_records(out: Path, pid: int) -> tuple[dict | None, dict | None]:
    """The folder's manifest and, for process ``pid > 0``, its own record; None where absent.

    Raises:
      IncompleteSweepError: (a ValueError) a record that is not one, naming it and the way out.
    """
    manifest_path = out / "manifest.json"
    proc_path = out / "processes" / _PROC.format(pid)
    needed = ("sweep_text", "plan", "sessions")
    old = read_record(manifest_path, needed) if manifest_path.exists() else None
    mine = read_record(proc_path, needed) if pid > 0 and proc_path.exists() else None
    return old, mine


def check_same_plan(out: Path, records, text: str, plan_key: dict, ndev: int) -> None:
    """Refuse (ValueError listing what differs) a folder whose ``records`` (its manifest and this process's
    record, None where absent) hold another sweep text or chunk plan than this run's (``text``, ``plan_key``;
    ``ndev`` devices, to which the chunk size was rounded)."""
    for prev in records:
        if prev is not None and (prev.get("sweep_text") != text or prev.get("plan") != plan_key):
            what = _what_differs(prev, text, plan_key)
            if prev.get("plan", {}).get("chunk_size") != plan_key["chunk_size"]:
                what += f"; chunk_size is rounded up to a multiple of the {ndev} device(s)"
            raise ValueError(
                f"{out} holds results of a different sweep or chunk plan ({what}); choose another --out or delete it"
            )


def robot_record(cfg: SweepConfig) -> dict:
    """The sweep's robot as its manifest records it: ``{"model": "g1", "name": "the Unitree G1",
    "actions": {"1": 496}}``, the model (:data:`~ijoy_jax.sweep.schema.MODELS`), its name in words and its
    action set's size at each density the sweep walks (keys as ``format(density, "g")``)."""
    densities = file_values(cfg.robot, cfg.grid, cfg.random, "density", model=cfg.model)
    actions = {format(d, "g"): len(models.actions(cfg.model, d, reach_of(cfg))) for d in densities}
    return {"model": cfg.model, "name": models.MODEL_NAMES[cfg.model], "actions": actions}


def start_session(
    out: Path,
    cfg: SweepConfig,
    pid: int,
    nproc: int,
    old: dict | None,
    mine: dict | None,
    plan_key: dict,
    phash: str,
    union: dict,
    session: dict,
) -> tuple[dict, Path]:
    """Record the start of a run's ``session`` in the folder and return the record and its path.

    Process 0 writes the manifest (``old``, continued, or a new one with versions and git commit), with the
    process ``layout`` and the ``union`` of the slices asked, the ``robot`` (:func:`robot_record`) and
    ``sweep.toml``; process ``I > 0`` writes only its own record (``mine``, or a new one) under ``processes/``.
    Makes ``parts/``.
    """
    layout = {
        "num_processes": nproc,
        "rule": "chunk % num_processes == process_id",
        "process_files": "processes/process-NNNNN.json (sessions of processes 1..N-1)",
    }
    if pid == 0:  # the manifest and sweep.toml are written by process 0 only
        manifest = old or {
            "sweep_file": cfg.source,
            "sweep_text": cfg.text,
            "name": cfg.name,
            "plan": plan_key,
            "versions": _versions(),
            "git_commit": _git_commit(),
            "sessions": [],
        }
        manifest.setdefault("plan_hash", phash)  # a manifest from before plans were hashed: same text and plan
        manifest.setdefault("robot", robot_record(cfg))  # (one from before models: the same text, HRP-2's)
        manifest["layout"] = layout
        manifest["selection"] = union
        manifest.setdefault("complete", False)  # the whole sweep is in the folder (set when a session ends)
        record = out / "manifest.json"
    else:  # each other process writes only its own file
        manifest = mine or {"sweep_text": cfg.text, "plan": plan_key, "process_id": pid, "sessions": []}
        manifest.setdefault("plan_hash", phash)
        record = out / "processes" / _PROC.format(pid)
    (out / "parts").mkdir(parents=True, exist_ok=True)
    record.parent.mkdir(parents=True, exist_ok=True)
    if pid == 0:
        (out / "sweep.toml").write_text(cfg.text)
    manifest["sessions"].append(session)
    write_record(record, manifest)
    return manifest, record


def write_rows(out: Path, result, held: dict, plan_record: dict) -> None:
    """Write a call's rows (``result``, with its ``chunk`` column) into their chunks' parts, each merged with the
    rows its part already holds (``held``: per chunk, the scenario ids its part holds; updated)."""
    import pandas as pd

    for c in dict.fromkeys(result["chunk"].tolist()):
        rows = result[result["chunk"] == c]
        path = part_path(out, c)
        if len(held[c]):  # an earlier slice's rows of this chunk: kept, the new ones added
            rows = pd.concat([read_part(path), rows], ignore_index=True).sort_values("scenario", kind="stable")
        tmp = path.with_name(f"{path.name}.{_WHO}.tmp")  # per process: members never share a temp file
        write_part(rows.reset_index(drop=True), tmp, plan_record)
        os.replace(tmp, path)
        held[c] = rows["scenario"].to_numpy(np.int64)
