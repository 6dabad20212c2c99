"""Messages that help: every refusal names the file, field or flag, says what is wrong and, where there is one,
the way out (one line from the ``ijoy`` command, status 2).

* A sweep folder's damaged part or record (truncated, overwritten, hand-edited): ``sweep.load`` and
  ``ijoy sweep run``/``summarize`` name the file, call it corrupt and say how to recover (delete it and rerun).
* A folder holding another sweep: the refusal lists what differs (old -> new), not two whole plans.
* A path a sweep file names (``command.file``, ``terrain.recording``) that is a directory, a device or a pipe
  says so, not "does not exist"; a binary file named as the sweep file is not a UTF-8 traceback.
* ``ijoy tune --set``/``--config`` values are checked against the config field's type (``distance=nan``:
  "distance takes a finite number"), and ``--set`` robot leaves must be finite.

Nothing here compiles: the sweep folders are written by hand as a run leaves them (a parquet part per chunk with
its plan record, a manifest), and every refusal comes before compute.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import os
from pathlib import Path

import jax
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from _sweep_util import tiny_sweep, write  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import sweep
from ijoy_jax.apps import cli
from ijoy_jax.apps.options import number_assignments
from ijoy_jax.apps.tune_cli import InverseConfig
from ijoy_jax.sweep import results as sweep_results
from ijoy_jax.tune.forward import ForwardConfig

TINY = tiny_sweep(margins=False)  # 2 cells x 3 replicates
OTHER = TINY.replace("[0.5, 2.0]", "[1.0, 4.0]")  # the same plan shape, other robot.w values
CHUNK = 2


def _plan(text: str, chunk: int) -> dict:
    """The chunk plan ``sweep.run`` makes for ``text`` at ``chunk`` scenarios per chunk on this machine's devices."""
    ndev = jax.local_device_count()
    chunk = -(-chunk // ndev) * ndev
    n = len(sweep.scenarios(sweep.parse_config(text)))
    return {"chunk_size": chunk, "max_scenarios": None, "scenarios": n, "chunks": -(-n // chunk)}


def _folder(root: Path, text: str = TINY, chunk: int = CHUNK) -> Path:
    """A finished sweep's folder as ``sweep.run`` leaves it (a manifest; per chunk a part with its plan record;
    the metrics are made up: nothing is computed)."""
    out = root / "results"
    (out / "parts").mkdir(parents=True)
    plan = _plan(text, chunk)
    record = {"hash": sweep.plan_hash(text, plan), "name": "tiny", **plan}
    for c in range(plan["chunks"]):
        ids = list(range(c * plan["chunk_size"], min((c + 1) * plan["chunk_size"], plan["scenarios"])))
        df = pd.DataFrame(
            {
                "scenario": ids,
                "chunk": c,
                "cell": [i // 3 for i in ids],
                "replicate": [i % 3 for i in ids],
                "robot.w": [0.5 if i < 3 else 2.0 for i in ids],
                "distance_along": [0.1 * i for i in ids],
            }
        )
        table = pa.Table.from_pandas(df, preserve_index=False)
        meta = {**(table.schema.metadata or {}), sweep_results.PLAN_KEY: json.dumps(record).encode()}
        pq.write_table(table.replace_schema_metadata(meta), out / "parts" / f"part-{c:05d}.parquet")
    manifest = {
        "sweep_file": "tiny.toml",
        "sweep_text": text,
        "name": "tiny",
        "plan": plan,
        "plan_hash": record["hash"],
        "sessions": [],
    }
    (out / "manifest.json").write_text(json.dumps(manifest))
    (out / "sweep.toml").write_text(text)
    return out


def _ijoy(*args) -> str:
    """``ijoy ARGS`` in this process: its one line on stderr (status 2 and nothing else printed, or fail)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main(["--no-compile-cache", *map(str, args)])
    lines = err.getvalue().strip().splitlines()
    assert status == 2 and len(lines) == 1 and lines[0].startswith("ijoy: error: "), err.getvalue()
    assert out.getvalue() == ""
    return lines[0]


# --------------------------------------------------------------------------- (a) damaged parts and records


def test_the_handmade_folder_loads(tmp_path):
    """The folder the tests below damage is one that loads (so each refusal is the damage's)."""
    df = sweep.load(_folder(tmp_path))
    assert df["scenario"].tolist() == list(range(6))


@given(cut=st.floats(0.0, 1.0, exclude_max=True), garbage=st.binary(max_size=64), overwrite=st.booleans())
@settings(max_examples=25, deadline=None)
def test_a_damaged_part_names_the_file_and_the_way_out(tmp_path_factory, cut, garbage, overwrite):
    out = _folder(tmp_path_factory.mktemp("cut"))
    part = out / "parts" / "part-00001.parquet"
    data = part.read_bytes()
    part.write_bytes(garbage if overwrite else data[: int(cut * len(data))] + garbage[:3])
    for partial in (False, True):
        with pytest.raises(sweep.IncompleteSweepError) as e:
            sweep.load(out, partial=partial)
        msg = str(e.value)
        assert str(part) in msg and "corrupt or truncated result part" in msg, msg
        assert "delete it and rerun `ijoy sweep run`" in msg and "\n" not in msg, msg


def test_a_damaged_part_refuses_the_run_and_the_summary_in_one_line(tmp_path):
    out = _folder(tmp_path)
    (out / "manifest.json").unlink()  # a run then checks every part's plan (none vouched for by a manifest)
    part = out / "parts" / "part-00000.parquet"
    part.write_bytes(part.read_bytes()[:-40])  # the footer cut: "Parquet magic bytes not found"
    sweep_file = write(tmp_path, TINY)
    for args in (("sweep", "run", sweep_file, "--out", out, "--chunk", CHUNK), ("sweep", "summarize", out)):
        line = _ijoy(*args)
        assert str(part) in line and "corrupt or truncated" in line and "delete it and rerun" in line, line
    assert sorted(p.name for p in (out / "parts").iterdir()) == [f"part-{c:05d}.parquet" for c in range(3)]


def test_a_part_of_a_foreign_name_is_named(tmp_path):
    out = _folder(tmp_path)
    os.replace(out / "parts" / "part-00002.parquet", out / "parts" / "part-2b.parquet")
    with pytest.raises(sweep.IncompleteSweepError, match=r"part-2b\.parquet: not a part a sweep writes"):
        sweep.load(out)


_RECORDS = st.one_of(
    st.binary(max_size=40).filter(lambda b: b.strip() != b""),  # garbage, truncated JSON, a binary file
    st.sampled_from([b"", b"{", b'{"plan": ', b"[1, 2, 3]", b"42", b"null", b'"text"']),  # JSON, not an object
    st.sampled_from(
        [
            b'{"sweep_text": 3}',
            b'{"plan": [6, 3]}',
            b'{"plan": {"chunks": "3", "scenarios": 6}}',
            b'{"sessions": {}}',
            b'{"sessions": [1]}',
        ]
    ),  # an object of the wrong form
)


@given(record=_RECORDS)
@settings(max_examples=30, deadline=None)
def test_a_damaged_manifest_names_the_file_and_the_way_out(tmp_path_factory, record):
    out = _folder(tmp_path_factory.mktemp("manifest"))
    (out / "manifest.json").write_bytes(record)  # (an object without a plan lacks what a complete load reads)
    for call in (lambda: sweep.load(out), lambda: sweep.load_aggregates(out)):
        with pytest.raises(sweep.IncompleteSweepError) as e:
            call()
        msg = str(e.value)
        assert str(out / "manifest.json") in msg and "corrupt" in msg and "delete it and rerun" in msg, msg
        assert "\n" not in msg


@pytest.mark.parametrize("record", [b"garbage", b"[]", b'{"sweep_text": "x"}', b"\xff\xfe\x00"])
def test_a_damaged_manifest_refuses_the_run_in_one_line(tmp_path, record):
    out = _folder(tmp_path)
    (out / "manifest.json").write_bytes(record)
    line = _ijoy("sweep", "run", write(tmp_path, TINY), "--out", out, "--chunk", CHUNK)
    assert f"{out / 'manifest.json'}: corrupt" in line and "delete it and rerun `ijoy sweep run`" in line, line


def test_the_way_out_of_a_damaged_manifest_works(tmp_path):
    """Deleted as the message says, the manifest is written anew by a run without --chunk: the parts' plan records
    give the chunk size (no chunk is computed: all are done)."""
    out = _folder(tmp_path)
    (out / "manifest.json").write_text("{")
    parts = {p: p.read_bytes() for p in (out / "parts").iterdir()}
    (out / "manifest.json").unlink()
    stats = sweep.run(write(tmp_path, TINY), out, progress=False)
    assert (stats.computed, stats.skipped, stats.complete) == (0, 3, True)
    assert json.loads((out / "manifest.json").read_text())["plan"] == _plan(TINY, CHUNK)
    assert {p: p.read_bytes() for p in (out / "parts").iterdir()} == parts
    assert sweep.load(out)["scenario"].tolist() == list(range(6))


def test_a_damaged_process_record_is_named(tmp_path):
    out = _folder(tmp_path)
    (out / "parts" / "part-00002.parquet").unlink()  # incomplete: load reads every process's sessions
    (out / "processes").mkdir()
    bad = out / "processes" / "process-00001.json"
    bad.write_text('{"sessions": [')
    with pytest.raises(sweep.IncompleteSweepError, match=f"{bad}: corrupt or truncated record"):
        sweep.load(out)


def test_summarize_names_a_file_given_as_the_folder(tmp_path):
    f = write(tmp_path, TINY)
    assert f"{f} is a file, not a sweep's output folder" in _ijoy("sweep", "summarize", f)


# --------------------------------------------------------------------------- (b) another sweep in the folder


@pytest.mark.parametrize(
    "text, chunk, want, absent",
    [
        (OTHER, CHUNK, ["grid.robot.w [0.5, 2.0] -> [1.0, 4.0]"], ["plan.", "sweep.", "chunk_size is rounded"]),
        (
            TINY.replace("seed = 3", "seed = 4").replace("num_steps = 6", "num_steps = 5"),
            CHUNK,
            ["sweep.num_steps 6 -> 5, sweep.seed 3 -> 4"],
            ["plan.", "grid."],
        ),
        (TINY, 4, ["plan.chunk_size 2 -> 4", "plan.chunks 3 -> 2", "chunk_size is rounded"], ["grid.", "sweep."]),
        (TINY.replace("[grid]\n", "[grid]\n# the weights\n"), CHUNK, ["comments or layout, line "], ["plan.", "grid."]),
    ],
)
def test_another_sweep_is_refused_naming_only_what_differs(tmp_path, text, chunk, want, absent):
    if jax.local_device_count() > 2 and chunk != CHUNK:
        pytest.skip("the chunk sizes round to the same multiple of the device count")
    out = _folder(tmp_path)
    before = {p: p.read_bytes() for p in [out / "manifest.json", *(out / "parts").iterdir()]}
    line = _ijoy("sweep", "run", write(tmp_path, text), "--out", out, "--chunk", chunk)
    assert f"{out} holds results of a different sweep or chunk plan" in line, line
    for w in want:
        assert w in line, line
    for a in absent:
        assert a not in line, line
    assert "'chunk_size'" not in line  # no plan dict printed
    assert {p: p.read_bytes() for p in [out / "manifest.json", *(out / "parts").iterdir()]} == before


_VALUES = st.one_of(st.integers(-3, 3), st.lists(st.integers(0, 2), max_size=2), st.sampled_from(["a", "b"]))
_TABLES = st.dictionaries(
    st.sampled_from(["grid", "sweep", "robot"]),
    st.dictionaries(st.sampled_from(["robot.w", "seed", "x"]), _VALUES, min_size=1, max_size=3),
    max_size=3,
)


@given(old=_TABLES, new=_TABLES)
def test_differences_lists_exactly_the_changed_keys_sorted(old, new):
    """Against a brute-force flattening: every key whose value differs, once, sorted, old -> new; no other."""
    a = {f"{s}.{k}": v for s, t in old.items() for k, v in t.items()}
    b = {f"{s}.{k}": v for s, t in new.items() for k, v in t.items()}
    unset = object()
    show = lambda v: "unset" if v is unset else json.dumps(v)  # noqa: E731
    want = [
        f"{k} {show(a.get(k, unset))} -> {show(b.get(k, unset))}"
        for k in sorted(set(a) | set(b))
        if a.get(k, unset) != b.get(k, unset)
    ]
    assert sweep_results.differences(old, new, limit=100) == ", ".join(want)
    if len(want) > 2:
        assert sweep_results.differences(old, new, limit=2) == ", ".join(want[:2]) + f" and {len(want) - 2} more"


# --------------------------------------------------------------------------- (c) paths a sweep file names


def _command_file(value: str) -> str:
    return TINY.replace("vx = [0.1, 0.3]\nvy = [-0.05, 0.05]\nwz = 0.0\n", f"file = {json.dumps(value)}\n")


def _terrain_recording(value: str) -> str:
    head, _, rest = TINY.partition("[terrain]\n")
    return (
        head
        + f"[terrain]\nrecording = {json.dumps(value)}\n\n"
        + rest.partition("[command]")[1]
        + rest.partition("[command]")[2]
    )


@pytest.mark.parametrize(
    "key, sweep_text", [("command.file", _command_file), ("terrain.recording", _terrain_recording)]
)
@pytest.mark.parametrize(
    "target, reason",
    [
        ("inputs", "is a directory, not a file"),
        (".", "is a directory, not a file"),
        ("/dev/null", "is not a regular file (a device, pipe or socket)"),
        ("pipe.mcap", "is not a regular file (a device, pipe or socket)"),
        ("sweep.toml/drive.mcap", "does not exist: a folder on its path is a file"),
        ("missing.mcap", "does not exist"),
    ],
)
def test_a_path_that_is_not_a_readable_file_says_what_it_is(tmp_path, key, sweep_text, target, reason):
    (tmp_path / "inputs").mkdir()
    os.mkfifo(tmp_path / "pipe.mcap")  # a read would block: never opened
    (tmp_path / "sweep.toml").write_text("")
    path = write(tmp_path, sweep_text(target))
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: ") and reason in msg, msg


def test_a_binary_sweep_file_is_named(tmp_path):
    f = tmp_path / "sweep.toml"
    f.write_bytes(b"PAR1\x15\x04\xff\xfe" + bytes(range(256)))
    assert f"{f}: <file>: not a TOML text file" in _ijoy("sweep", "run", f, "--out", tmp_path / "o")
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- (d) tune --set and --config values


def _fields(cls, kind) -> list[str]:
    return [f.name for f in dataclasses.fields(cls) if f.type in (kind, kind.__name__)]


# Values no float field takes: not finite, not a number (JSON's true, a string, a list, an object, null).
_NOT_FINITE = ["nan", "NaN", "inf", "-inf", "Infinity", "-Infinity", "1e999", "-1e400", "9" * 400]
_NOT_NUMBERS = ["true", "false", "null", '"0.1"', "abc", "[0.1]", "{}", ""]


@given(field=st.sampled_from(_fields(ForwardConfig, float)), value=st.sampled_from(_NOT_FINITE + _NOT_NUMBERS))
@settings(max_examples=40, deadline=None)
def test_tune_forward_set_names_the_field_and_its_type(tmp_path_factory, field, value):
    out = tmp_path_factory.mktemp("tune") / "o"
    # --steps 0 would be refused too: nothing is tuned whatever the check finds
    line = _ijoy("tune", "forward", "--out", out, "--set", f"{field}={value}", "--steps", "0")
    assert f"--set '{field}=" in line and f"{field} takes a finite number" in line, line
    assert not out.exists()


@given(
    field=st.sampled_from(_fields(ForwardConfig, int) + _fields(InverseConfig, int)),
    value=st.sampled_from(["1.5", "1e3", "true", "nan", '"3"', "[3]", str(2**63), str(-(2**63) - 1)]),
)
@settings(max_examples=30, deadline=None)
def test_tune_integer_fields_refuse_other_values(tmp_path_factory, field, value):
    command = "forward" if field in _fields(ForwardConfig, int) else "inverse"
    out = tmp_path_factory.mktemp("tune") / "o"
    safe = () if field == "steps" else ("--steps", "0")  # refused too: nothing is tuned whatever the check finds
    line = _ijoy("tune", command, "--out", out, "--set", f"{field}={value}", *safe)
    assert f"{field} takes an integer within int64" in line, line


@pytest.mark.parametrize(
    "command, item, want",
    [
        ("forward", "shape=[60.5, 60]", "shape takes a list of integers"),
        ("forward", "shape=60", "shape takes a list of integers"),
        ("forward", 'command_low=["a", 0, 0]', "command_low takes a list of finite numbers"),
        ("forward", "command_high=[0.1, NaN, 0]", "command_high takes a list of finite numbers"),
        ("forward", "has_height=yes", "has_height takes true or false"),
        ("forward", "family=3", "family takes a string"),
        ("inverse", "noise=nan", "noise takes a finite number"),
        ("inverse", 'starts=[1, "x"]', "starts takes a list of finite numbers"),
        ("inverse", 'hidden={"w": "x"}', "InverseConfig: hidden must map parameter names to finite numbers > 0"),
        ("inverse", "num_train=0", "InverseConfig: num_train must be >= 1"),
        ("inverse", 'terrain={"shape": [60.5, 60]}', "InverseConfig: terrain.shape takes a list of integers"),
        ("inverse", 'terrain={"bogus": 1}', "InverseConfig: unknown field(s) ['terrain.bogus']"),
    ],
)
def test_tune_set_values_of_every_kind_name_the_field(tmp_path, command, item, want):
    line = _ijoy("tune", command, "--out", tmp_path / "o", "--set", item, "--steps", "0")
    assert want in line, line
    assert not (tmp_path / "o").exists()


def test_tune_config_file_values_are_checked_and_a_bad_toml_named(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("tau = = 1\n")
    assert f"--config {bad}: not a valid TOML file" in _ijoy(
        "tune", "inverse", "--out", tmp_path / "o", "--config", bad
    )
    nan = tmp_path / "nan.toml"
    nan.write_text("distance = nan\n")
    line = _ijoy("tune", "forward", "--out", tmp_path / "o", "--config", nan)
    assert f"--config {nan}: distance takes a finite number, got nan" in line, line


@given(name=st.sampled_from(["w", "metrics.support_limit"]), value=st.sampled_from(_NOT_FINITE))
def test_robot_leaf_assignments_refuse_values_that_are_not_finite(name, value):
    with pytest.raises(ValueError, match=f"--set '{name}=.*': {name} takes a finite number"):
        number_assignments([f"{name}={value}"], ("w", "metrics.support_limit"), "w=1")
    assert math.isfinite(number_assignments([f"{name}=1e300"], ("w", "metrics.support_limit"), "w=1")[name])
