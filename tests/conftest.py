import gc
import json
import os
import subprocess
import sys
from pathlib import Path

# XLA's CPU backend compiles fused loops with its MLIR fusion emitters by default; its classic emitters compile
# the same programs in about 30 % less time (measured: the MJX rollout of tests/test_sim_rollouts.py's shapes,
# 57-65 s -> 39-46 s, the same run time, results equal to float32 rounding), and the suite is compile-bound on
# a 2-core CI machine. Set before JAX starts its backend, so this process, the xdist workers, the notebooks'
# kernels and the subprocess tests all compile alike (a caller's own XLA_FLAGS are kept, ours appended).
# XLA aborts the process on a flag it does not know, and jaxlib is not pinned: the flag is set only where a
# child process with it starts JAX's CPU backend (one probe per run; the workers inherit the result).
_XLA_FLAG = "--xla_cpu_use_fusion_emitters=false"


def _with_flag(flags: str, flag: str) -> str:
    return (flags + " " + flag).strip()


def _xla_knows(flag: str) -> bool:
    env = dict(os.environ, XLA_FLAGS=_with_flag(os.environ.get("XLA_FLAGS", ""), flag), JAX_PLATFORMS="cpu")
    probe = subprocess.run([sys.executable, "-c", "import jax; jax.devices()"], env=env, capture_output=True,
                           timeout=300)
    return probe.returncode == 0


if _XLA_FLAG.split("=")[0] not in os.environ.get("XLA_FLAGS", "") and _xla_knows(_XLA_FLAG):
    os.environ["XLA_FLAGS"] = _with_flag(os.environ.get("XLA_FLAGS", ""), _XLA_FLAG)

import hypothesis  # noqa: E402
import jax  # noqa: E402
import pytest  # noqa: E402

import ijoy_jax.sim  # noqa: F401, E402  headless: selects MUJOCO_GL=egl before any test module imports mujoco
from ijoy_jax.jit_cache import COMPILE_EVENTS  # noqa: E402

hypothesis.settings.register_profile("ci", derandomize=True, deadline=None, max_examples=40,
                                     print_blob=True)
hypothesis.settings.load_profile("ci")

# Programs that took at least this long to compile (s) are cached; below, an entry costs about what a hit saves.
_CACHE_MIN_COMPILE_S = "0.2"

# The test files of the footstep server and of live drives run on one xdist worker, one after the other (in
# collection order): they start real processes (ijoy serve, ijoy drive, Chromium) and compile the same programs
# for the same small map (tests/_server_util.py: MAP), so on one worker they share one ijoy serve process
# (footstep_server below) and every compiled program in memory, and they do not compete for the CI's 2 cores.
# Every other file is its own unit, as with --dist loadfile.
ONE_WORKER = frozenset({"test_live.py", "test_live_view.py", "test_server.py", "test_server_schema.py"})
ONE_WORKER_SCOPE = "footstep server and live drives"


def pytest_configure(config):
    """One persistent XLA compilation cache for the run and the next ones (unless the caller names another): the
    same programs are compiled in several test files, on both xdist workers, in the notebooks' kernels and in
    subprocess tests, which inherit it through the environment. Compiled code is keyed by its program, JAX
    version and flags, so a hit runs the same code; the no-recompile tests count traces and jit cache entries,
    which this cache does not change. Every run counts the seconds spent compiling (:class:`_Compiling`)."""
    jax.monitoring.register_event_duration_secs_listener(_count_compiling)
    if getattr(config, "cache", None) is None:  # -p no:cacheprovider
        return
    path = os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(config.cache.mkdir("jax_compilation_cache")))
    min_s = os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", _CACHE_MIN_COMPILE_S)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_s))


def pytest_sessionfinish(session):
    """Free JAX's compiled programs and collect the garbage while an xdist worker still counts as running.

    Under xdist the worker reports "finished" at the end of this hook; from then on the controller gives it
    5 s to return (execnet's ``_terminate_execution``) before it sends the worker a SIGINT. What the worker
    still did then was pytest's unraisable-exception check, a ``gc.collect()`` in ``pytest_unconfigure``,
    which after a few hundred tests frees the JAX/XLA executables and buffers in one long collection. A
    SIGINT during a collection is delivered to the first Python code that runs, hypothesis's ``gc.callbacks``
    timer (installed by any ``@given`` test), hence the stray "Exception ignored in gc_callback ...
    KeyboardInterrupt" at the end of a clean run. Doing the expensive part here, before the worker reports,
    leaves the late collection nothing to do.
    """
    _free_compiled_programs()
    _write_durations(session.config)


def _free_compiled_programs():
    """Drop every program JAX holds compiled in this process and collect the garbage that frees them."""
    jax.clear_caches()
    gc.collect()


def _mapped_regions() -> int | None:
    """How many memory mappings this process holds (Linux: lines of /proc/self/maps), or None elsewhere."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None


def _mapping_limit() -> int:
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return 65530  # Linux's default


# Free JAX's compiled programs between two test files once this process holds this fraction of the kernel's
# mappings limit (vm.max_map_count, 65530 by default).
MAPPINGS_FRACTION = 1 / 3


def pytest_runtest_teardown(item, nextitem):
    """Free JAX's compiled programs at the end of a test file when this process holds many memory mappings.

    Every program XLA compiles for the CPU keeps its code and constants in mappings of their own (about 2000
    for tests/test_family.py alone), and JAX keeps every compiled program while its function lives. An xdist
    worker that runs half the suite (~30 files) heads for the kernel's limit of 65530 mappings (21 k after 8
    of them), where an mmap fails inside LLVM: such a worker crashed with a segfault while compiling in its
    last file, tests/test_tune_haptic.py (CI and here, also with its 27 files run in one process; not with
    this hook: 2026-11-26). Clearing
    JAX's caches (and collecting the garbage) frees them (4171 -> 1292 after tests/test_generators.py); a
    later file that needs a freed program compiles it again or loads it from the persistent cache. Below
    the threshold nothing is freed, so files that share programs keep sharing them.
    """
    if nextitem is not None and nextitem.path == item.path:
        return
    n = _mapped_regions()
    if n is not None and n > MAPPINGS_FRACTION * _mapping_limit():
        _free_compiled_programs()


def work_unit(nodeid: str) -> str:
    """The unit of work a test belongs to: its file (``--dist loadfile``), or :data:`ONE_WORKER_SCOPE`."""
    file = nodeid.split("::", 1)[0]
    return ONE_WORKER_SCOPE if Path(file).name in ONE_WORKER else file


@pytest.hookimpl(optionalhook=True)  # xdist's hook: without xdist (-p no:xdist) it is never called
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` (pyproject's addopts), with the files of :data:`ONE_WORKER` one unit of work, handed
    out in the order of the collection, which :func:`heaviest_first` sets. xdist would otherwise re-sort the
    units by their count of tests (its ``--loadscope-reorder``, on by default), which hands out a file of one
    long test (the README's examples, the notebooks) last."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    config.option.loadscopereorder = False

    class Scheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

    return Scheduling(config, log)


# The order in which the files run: heaviest first. xdist's LoadFile scheduler starts each worker on the next file
# in the collection's order (and on one more where that file has at most 2 tests), then hands a worker the next
# file whenever at most 2 of its tests are still to run (xdist/scheduler/loadscope.py). Ordering the collection
# by cost, largest first, makes that longest-processing-time-first scheduling: the two workers start on the
# heaviest files and the small ones fill in at the end, where they even out the finishing times. Costs are the
# worker-seconds (setup, call and teardown) each file's tests took in a full run of each tier, kept in
# tests/durations.json; `--update-durations` rewrites the entries of the files a run ran (refresh after changing a
# heavy file: `python -m pytest -q --update-durations`, then the same with `-m slow`). A file missing from the
# table counts as DEFAULT_FILE_S per tier, and each run names such files.
DURATIONS = Path(__file__).with_name("durations.json")
DEFAULT_FILE_S = 60.0
TIERS = ("fast", "slow")


def tier_of(item) -> str:
    return "slow" if item.get_closest_marker("slow") is not None else "fast"


def load_durations(path: Path = DURATIONS) -> dict[str, dict[str, float]]:
    """``{tier: {file: worker-seconds}}`` from ``path`` (empty tiers where the file is absent)."""
    table = json.loads(path.read_text()) if path.exists() else {}
    return {tier: dict(table.get(tier, {})) for tier in TIERS}


def heaviest_first(items, durations: dict[str, dict[str, float]]) -> list:
    """``items`` reordered by work unit (:func:`work_unit`), the unit of the largest estimated cost first.

    A unit's cost is the sum over its files, and over the tiers of the file's selected tests, of ``durations``'
    worker-seconds (:data:`DEFAULT_FILE_S` where the table has no entry). Items keep their order within a unit,
    and units of equal cost the order of their first items.
    """
    tiers: dict[str, set[str]] = {}
    first: dict[str, int] = {}
    for i, item in enumerate(items):
        file = item.nodeid.split("::", 1)[0]
        tiers.setdefault(file, set()).add(tier_of(item))
        first.setdefault(work_unit(item.nodeid), i)
    cost = dict.fromkeys(first, 0.0)
    for file, present in tiers.items():
        cost[work_unit(file)] += sum(durations[t].get(file, DEFAULT_FILE_S) for t in present)
    order = {unit: rank for rank, unit in enumerate(sorted(first, key=lambda u: (-cost[u], first[u])))}
    return sorted(items, key=lambda item: order[work_unit(item.nodeid)])


# The two tiers (pyproject's addopts and its ``slow`` marker): test files mark their slow tests themselves; the
# notebooks (collected by nbmake) are marked here: each runs end to end in its own kernel and compiles every
# program it shows (20 s to 2 minutes each on 2 cores; simulated_walking compiles the MJX biped's rollout).


@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config, items):
    """Around every other plugin's hook: the notebooks are marked slow before the mark plugin deselects by -m, and
    the tests left after -m and -k are ordered heaviest file first (:func:`heaviest_first`)."""
    for item in items:
        if item.path.suffix == ".ipynb":
            item.add_marker(pytest.mark.slow)
    result = yield
    items[:] = heaviest_first(items, load_durations())
    return result


COMPILE_REPORT_FILES = 10  # the terminal summary names the files that compiled longest, this many


class _WorkerTime:
    """The sum of every test's setup, call and teardown durations (seconds), over all xdist workers: the
    worker-minutes a run costs, whatever the wall time (the controller receives every worker's reports), in
    all and by tier and file (``{tier: {file: seconds}}``, what tests/durations.json holds)."""

    total = 0.0
    by_file: dict[str, dict[str, float]] = {tier: {} for tier in TIERS}


class _Compiling:
    """Seconds JAX spent compiling (:data:`ijoy_jax.jit_cache.COMPILE_EVENTS`) in this process since the last
    test phase's report, which carries them to the controller (``user_properties``, as xdist sends them)."""

    seconds = 0.0
    total = 0.0  # the controller's sums over every worker: all, and by file
    by_file: dict[str, float] = {}


def _count_compiling(event, duration, **_):
    if event in COMPILE_EVENTS:
        _Compiling.seconds += float(duration)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    outcome.get_result().user_properties.append(("compile_s", _Compiling.seconds))
    _Compiling.seconds = 0.0


def pytest_runtest_logreport(report):
    _WorkerTime.total += report.duration
    files = _WorkerTime.by_file["slow" if "slow" in report.keywords else "fast"]
    file = report.nodeid.split("::", 1)[0]
    files[file] = files.get(file, 0.0) + report.duration
    compiling = sum(v for k, v in report.user_properties if k == "compile_s")
    _Compiling.total += compiling
    _Compiling.by_file[file] = _Compiling.by_file.get(file, 0.0) + compiling


def pytest_addoption(parser):
    parser.addoption("--update-durations", action="store_true",
                     help="write the worker-seconds each file's tests took in this run into tests/durations.json "
                          "(the costs that order the files, heaviest first); other files' entries are kept")


def updated_durations(durations: dict[str, dict[str, float]], measured: dict[str, dict[str, float]],
                      root: Path) -> dict[str, dict[str, float]]:
    """``durations`` with the entries of ``measured`` (seconds, rounded to 1 s) in their place, less the files
    that no longer exist under ``root``; each tier sorted by file."""
    out = {}
    for tier in TIERS:
        merged = {**durations[tier], **{f: round(s) for f, s in measured[tier].items()}}
        out[tier] = {f: merged[f] for f in sorted(merged) if (root / f).exists()}
    return out


def _controller(config) -> bool:
    return not hasattr(config, "workerinput")  # an xdist worker has workerinput; the controller reports


def _write_durations(config):
    if _controller(config) and config.getoption("update_durations", False):
        table = updated_durations(load_durations(), _WorkerTime.by_file, config.rootpath)
        DURATIONS.write_text(json.dumps(table, indent=1) + "\n")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _controller(config):
        return
    terminalreporter.write_line(f"worker time: {_WorkerTime.total / 60:.1f} worker-minutes "
                                "(the sum of every test's setup, call and teardown)")
    top = [f"{Path(f).name} {v:.0f} s" for f, v in sorted(_Compiling.by_file.items(), key=lambda kv: -kv[1])
           if v >= 1.0][:COMPILE_REPORT_FILES]
    terminalreporter.write_line(f"of which compiling: {_Compiling.total / 60:.1f} worker-minutes (JAX's tracing, "
                                "lowering and XLA compiles)" + (f"; most in {', '.join(top)}" if top else ""))
    durations = load_durations()
    missing = sorted(f for tier in TIERS for f in _WorkerTime.by_file[tier] if f not in durations[tier])
    if missing:
        terminalreporter.write_line(f"{len(missing)} files ran without a cost in {DURATIONS.name} and were "
                                    f"ordered as {DEFAULT_FILE_S:.0f} s each: {', '.join(missing[:5])}"
                                    f"{' ...' if len(missing) > 5 else ''} (refresh it with --update-durations)")
    elif config.getoption("update_durations", False):
        terminalreporter.write_line(f"wrote this run's worker-seconds per file into {DURATIONS}")
    if config.getoption("markexpr") == "not slow":
        terminalreporter.write_line("this was the fast tier: `python -m pytest -m slow` runs the slow tier, "
                                    "`-m \"slow or not slow\"` both")


@pytest.fixture(scope="session")
def footstep_server():
    """One real ``ijoy serve`` process on 127.0.0.1 (a free port) for the session, warmed up for MAP's shape and
    resolution, with small limits (tests/_server_util.py): tests/test_server.py's module and tests/test_live.py's
    end-to-end drive share it (on one xdist worker, ONE_WORKER)."""
    from _server_util import MAX_CELLS, MAX_MAPS, WARM_UP  # tests/ is on sys.path (pytest rootdir import)

    from ijoy_jax.server import serve_subprocess

    with serve_subprocess("--warm-up", WARM_UP, "--max-cells", str(MAX_CELLS), "--max-maps", str(MAX_MAPS)) as srv:
        yield srv
        assert srv.process.poll() is None, "the server died during the tests:\n" + "\n".join(srv.output)
