import gc
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
    which this cache does not change."""
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


@pytest.hookimpl(optionalhook=True)  # xdist's hook: without xdist (-p no:xdist) it is never called
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` (pyproject's addopts), with the files of :data:`ONE_WORKER` one unit of work."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class Scheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            file = super()._split_scope(nodeid)
            return ONE_WORKER_SCOPE if Path(file).name in ONE_WORKER else file

    return Scheduling(config, log)


# The two tiers (pyproject's addopts and its ``slow`` marker): test files mark their slow tests themselves; the
# notebooks (collected by nbmake) are marked here: each runs end to end in its own kernel and compiles every
# program it shows (20 s to 2 minutes each on 2 cores; simulated_walking compiles the MJX biped's rollout).


@pytest.hookimpl(tryfirst=True)  # before the mark plugin deselects by -m
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.suffix == ".ipynb":
            item.add_marker(pytest.mark.slow)


class _WorkerTime:
    """The sum of every test's setup, call and teardown durations (seconds), over all xdist workers: the
    worker-minutes a run costs, whatever the wall time (the controller receives every worker's reports)."""

    total = 0.0


def pytest_runtest_logreport(report):
    _WorkerTime.total += report.duration


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if hasattr(config, "workerinput"):  # an xdist worker: the controller reports
        return
    terminalreporter.write_line(f"worker time: {_WorkerTime.total / 60:.1f} worker-minutes "
                                "(the sum of every test's setup, call and teardown)")
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
