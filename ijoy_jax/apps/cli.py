"""The ``ijoy`` command line: the top parser, every subcommand registered the same way, and the dispatch.

Each subcommand lives in a module of its own, ``ijoy_jax/apps/<name>_cli.py``, with ``add_parser(sub)`` (its
parser, options and help) and ``main(args)`` (running it from the parsed arguments; the exit status).
:func:`main` registers them in one loop, parses, and turns bad input anywhere into one line on stderr and exit
status 2.

Every command keeps JAX's compiled programs in a persistent cache on disk (JAX's compilation cache), so a
second run of the same sweep, benchmark or tuning run loads its programs instead of compiling them (an MJX
sweep's ~1 minute of compiles becomes seconds). The cache lives in :func:`compile_cache_dir` (``$IJOY_CACHE_DIR``,
else ``$JAX_COMPILATION_CACHE_DIR``, else ``$XDG_CACHE_HOME/ijoy_jax/jax_compilation_cache``, by default
``~/.cache/ijoy_jax/jax_compilation_cache``); ``ijoy --no-compile-cache ...`` or ``IJOY_COMPILE_CACHE=0`` turns it
off. Entries are keyed by the program, the JAX/XLA versions, flags and devices, so a hit runs the same code; the
folder may be deleted at any time.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

CACHE_MIN_COMPILE_S = 0.1
"""Programs that took at least this long to compile (s) are kept in the persistent cache (tiny eager ops are not)."""


def compile_cache_dir(env=None) -> Path | None:
    """The persistent compilation cache's folder for this environment, or None where it is switched off
    (``IJOY_COMPILE_CACHE`` = 0, false, no or off). See the module docstring for the order of the variables."""
    env = os.environ if env is None else env
    if env.get("IJOY_COMPILE_CACHE", "").strip().lower() in ("0", "false", "no", "off"):
        return None
    for var in ("IJOY_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR"):
        if env.get(var):
            return Path(env[var]).expanduser()
    base = Path(env["XDG_CACHE_HOME"]).expanduser() if env.get("XDG_CACHE_HOME") else Path.home() / ".cache"
    return base / "ijoy_jax" / "jax_compilation_cache"


def _use_compile_cache(enabled: bool) -> Path | None:
    """Point JAX's persistent compilation cache at :func:`compile_cache_dir` (before any compile); its folder."""
    path = compile_cache_dir() if enabled else None
    if path is None:
        return None
    import jax

    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:  # a read-only home: run without the cache rather than not at all
        print(f"ijoy: warning: no compilation cache ({path}: {e.strerror})", file=sys.stderr)
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_S)
    return path


def main(argv: list[str] | None = None) -> int:
    """Run ``ijoy ARGV``: the exit status (0, or 2 with one line on stderr for bad input; argparse's --help and
    --version exit)."""
    import jax

    from ijoy_jax import __version__
    from ijoy_jax.apps import bench_cli, cue_cli, demo_cli, drive_cli, serve_cli, sim_cli, sweep_cli, tune_cli
    from ijoy_jax.apps.options import CommandParser
    from ijoy_jax.extras import MissingExtraError

    parser = CommandParser(prog="ijoy", description="The intelligent joystick for legged robots, in JAX.",
                           epilog="Outputs: a command that writes one file writes ijoy_<what>.<ext> in the current "
                                  "folder unless --out names another; one that writes a folder of results writes "
                                  "results/<name>/. Every output is checked (its folder exists and is writable) "
                                  "before any work starts.")
    parser.add_argument("--version", action="version", help="print the version (and JAX's, Python's) and exit",
                        version=f"ijoy {__version__} (jax {jax.__version__}, Python {sys.version.split()[0]})")
    parser.add_argument("--no-compile-cache", action="store_true",
                        help="do not keep compiled programs on disk (env IJOY_COMPILE_CACHE=0); by default they are "
                             "kept in $IJOY_CACHE_DIR, $JAX_COMPILATION_CACHE_DIR or "
                             "~/.cache/ijoy_jax/jax_compilation_cache, so a second run compiles nothing")
    sub = parser.add_subparsers(dest="command", required=True)
    # Each subcommand's module registers it (add_parser) and runs it from the parsed arguments (main).
    commands = {"demo": demo_cli, "bench": bench_cli, "sweep": sweep_cli, "sim": sim_cli, "tune": tune_cli,
                "cue": cue_cli, "serve": serve_cli, "drive": drive_cli}
    for module in commands.values():
        module.add_parser(sub)
    try:
        args = parser.parse_args(argv)  # a refused command line raises UsageError, a ValueError
        _use_compile_cache(not args.no_compile_cache)
        return commands[args.command].main(args)  # bad input raises ValueError, TypeError or OSError
    except (ValueError, TypeError, OSError, MissingExtraError) as e:  # bad input, or a file or server it names:
        # one line, argparse's refusals too (OSError: a file that is missing, a folder or read-only; a server that
        # does not answer, TimeoutError); a part of the package whose extra is not installed
        print(f"ijoy: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
