import gc
import os

import hypothesis
import jax

import ijoy_jax.sim  # noqa: F401  headless: selects MUJOCO_GL=egl before any test module imports mujoco

hypothesis.settings.register_profile("ci", derandomize=True, deadline=None, max_examples=40,
                                     print_blob=True)
hypothesis.settings.load_profile("ci")

# Programs that took at least this long to compile (s) are cached; below, an entry costs about what a hit saves.
_CACHE_MIN_COMPILE_S = "0.2"


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
    jax.clear_caches()
    gc.collect()
