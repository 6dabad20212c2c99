"""Progress lines while a program compiles: what is compiling and for how long, on stderr.

XLA compiles a large program in one call that says nothing until it returns (the MJX walk of ``ijoy sim
render``: about a minute on a 2-core CPU). :func:`compiling` wraps such a call: once it has lasted
:data:`SHOW_AFTER_S` seconds, a daemon thread writes what is compiling and the seconds elapsed (rewritten in
place on a terminal, a line every :data:`LINE_EVERY_S` seconds in a log), and the end gets a line ``compiled
WHAT in N s``. A compile that ends sooner writes nothing: a program this process compiled before takes
milliseconds, and one the persistent compilation cache holds shows as a short compile (loaded, not built).
The thread only sleeps and writes: nothing runs inside the compiled program, which is the same with and
without the lines.

:func:`compile_and_call` makes the compile a call of its own, so the lines cover exactly the compile:
``fn.lower(*args).compile()`` under :func:`compiling`, then the compiled program on ``args``, the program a
plain ``fn(*args)`` runs (the same result, bit for bit). ``ijoy_jax.sim.walker.rollout(..., progress=True)``
uses it; the ``ijoy`` commands that compile for long turn it on.

Example (a quick compile writes nothing; a long one writes ``[ijoy] compiling a sine: 2 s`` and so on)::

    >>> import jax, jax.numpy as jnp
    >>> from ijoy_jax.progress import compile_and_call
    >>> f = jax.jit(lambda x: jnp.sin(x) * 2)
    >>> y = compile_and_call(f, jnp.ones(3), what="a sine")
    >>> bool((y == f(jnp.ones(3))).all())
    True
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TextIO

from ijoy_jax.struct import is_traced

__all__ = ["LINE_EVERY_S", "SHOW_AFTER_S", "THREAD_NAME", "TTY_EVERY_S", "compile_and_call", "compiling"]

SHOW_AFTER_S = 2.0
"""Seconds a compile lasts before its first line is written; a quicker one (a cache hit) writes nothing."""

TTY_EVERY_S = 1.0
"""On a terminal, the elapsed seconds are rewritten in place (``\\r``) this often (s)."""

LINE_EVERY_S = 10.0
"""Elsewhere (a pipe, a log file), a new line this often (s)."""

THREAD_NAME = "ijoy-compile-progress"
"""The name of the thread that writes the lines (it ends when the compile does)."""

_WIDTH = 78  # characters a terminal's line is padded to, so a shorter one overwrites a longer one


def _seconds(name: str, value, *, positive: bool) -> float:
    """``value`` as a finite number of seconds, > 0 if ``positive`` else >= 0 (ValueError names ``name``)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or (value <= 0 if positive else value < 0)
    ):
        bound = "positive" if positive else "non-negative"
        raise ValueError(f"{name} must be a finite {bound} number of seconds, got {value!r}")
    return float(value)


@contextlib.contextmanager
def compiling(
    what: str,
    *,
    prefix: str = "[ijoy] ",
    final: bool = True,
    stream: TextIO | None = None,
    show_after_s: float | None = None,
    every_s: float | None = None,
) -> Iterator[None]:
    """Write progress lines to ``stream`` while the body of the ``with`` compiles ``what``.

    Nothing before ``show_after_s``; then ``PREFIXcompiling WHAT: N s`` every ``every_s`` (on a terminal,
    one line rewritten in place), and on leaving ``PREFIXcompiled WHAT in N.N s`` (``final``; without it a
    terminal's line is cleared, for a caller that writes its own). An exception in the body ends the lines
    with ``PREFIXcompiling WHAT: stopped after N.N s (ERROR)`` and propagates. The lines come from a daemon
    thread that sleeps between them and ends before the ``with`` does.

    Args:
      what: what is compiling, in words (e.g. ``"the MJX walk (12 steps on a 200x100 map)"``).
      prefix: the start of every line (e.g. ``"ijoy serve: "``).
      final: write the ``compiled WHAT in N s`` line (when anything was written).
      stream: where to write (default: ``sys.stderr`` as it is on entry).
      show_after_s: seconds before the first line (default :data:`SHOW_AFTER_S`).
      every_s: seconds between lines (default :data:`TTY_EVERY_S` on a terminal, else :data:`LINE_EVERY_S`).

    Raises:
      ValueError: ``what`` is not a non-empty string, or a duration is not a finite number of seconds.
    """
    if not isinstance(what, str) or not what.strip():
        raise ValueError(f"what must be a non-empty string (what is compiling), got {what!r}")
    out = sys.stderr if stream is None else stream
    tty = bool(getattr(out, "isatty", lambda: False)())
    after = _seconds("show_after_s", SHOW_AFTER_S if show_after_s is None else show_after_s, positive=False)
    every = _seconds("every_s", (TTY_EVERY_S if tty else LINE_EVERY_S) if every_s is None else every_s, positive=True)
    end = "\r" if tty else "\n"
    stop = threading.Event()
    shown = threading.Event()
    t0 = time.perf_counter()

    def write(line: str, tail: str) -> None:
        print(line.ljust(_WIDTH) if tty else line, end=tail, file=out, flush=True)

    def tick() -> None:
        if stop.wait(after):
            return
        shown.set()
        while True:
            write(f"{prefix}compiling {what}: {time.perf_counter() - t0:.0f} s", end)
            if stop.wait(every):
                return

    thread = threading.Thread(target=tick, name=THREAD_NAME, daemon=True)
    thread.start()
    try:
        yield
    except BaseException as e:  # KeyboardInterrupt too: the lines end, the exception goes on
        stop.set()
        thread.join()
        if shown.is_set():
            write(
                f"{prefix}compiling {what}: stopped after {time.perf_counter() - t0:.1f} s ({type(e).__name__})", "\n"
            )
        raise
    stop.set()
    thread.join()
    if shown.is_set():
        if final:
            write(f"{prefix}compiled {what} in {time.perf_counter() - t0:.1f} s", "\n")
        elif tty:
            write("", "\r")


def compile_and_call(fn: Callable, *args: Any, what: str, **static: Any) -> Any:
    """``fn(*args, **static)`` with its compile under :func:`compiling` (``what``).

    ``fn`` is a :func:`jax.jit` function, ``args`` its traced arguments (positional) and ``static`` its
    static keyword arguments, all of them. Compiles ahead of time (``fn.lower(*args, **static).compile()``,
    which finds a program compiled before in this process or in the persistent compilation cache: a short
    compile that writes nothing), then runs that compiled program on ``args``: the program, and the result
    bit for bit, of ``fn(*args, **static)``. Inside a caller's trace (a leaf of ``args`` is a tracer) nothing
    compiles here: ``fn`` is called, to be inlined into the caller's program.

    Returns:
      What ``fn(*args, **static)`` returns.

    Raises:
      What tracing, lowering, compiling or running ``fn`` raises, after the lines end (:func:`compiling`).
    """
    if is_traced(args):
        return fn(*args, **static)
    with compiling(what):
        program = fn.lower(*args, **static).compile()
    return program(*args)
