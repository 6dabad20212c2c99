"""``ijoy serve``: the footstep server as its own process (:mod:`ijoy_jax.server`; protocol: docs/server.md).

It binds first (a port in use or a bad host fails at once, in one line), compiles the programs a request on
the warm-up map shapes runs (so the first request does not wait for a compile), prints ``listening on
HOST:PORT`` on stdout (the line a script waits for; port 0 takes a free port and prints it), and serves
until SIGINT or SIGTERM, then closes and exits 0. Logs go to stderr: the warm-up (what it compiles and the
seconds elapsed while it lasts more than a few seconds, then a line per map shape), one line per connection,
a line when a map kind's compiled programs are dropped (``--max-programs``), and the totals at exit;
``--verbose`` adds a line per request.

Map shapes: every map kind (shape in cells, resolution, 2D or 2.5D) has programs of its own, compiled on its
first request while every client waits; the server keeps those of the ``--max-programs`` most recently used
kinds. A deployment uses a few fixed map shapes and lists them in ``--warm-up``.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading

DEFAULT_PORT = 5555
DEFAULT_WARM_UP = "200x200@0.02"

SHAPES_HELP = ("Map shapes: each map kind (shape in cells, resolution, 2D or 2.5D) runs programs compiled for it "
               "on its first request (a second or more, while every client waits); the server keeps those of the "
               "--max-programs most recently used kinds. Use a few fixed map shapes per deployment and list them "
               "in --warm-up.")


def add_parser(sub) -> None:
    """Add ``ijoy serve`` to the ``ijoy`` command's subparsers."""
    p = sub.add_parser("serve", help="run the footstep server (ZeroMQ; protocol in docs/server.md) for a robot "
                                     "stack to call",
                       description="The footstep server of the paper's Fig. 6: terrain maps in, the chosen step's "
                                   "foothold, validity, cost and cost terms out (ij.select_step, bit for bit). "
                                   "Prints 'listening on HOST:PORT' once it answers; stops on SIGINT/SIGTERM. "
                                   + SHAPES_HELP)
    p.add_argument("--host", default="127.0.0.1", help="address or name to listen on (default: %(default)s; "
                                                       "0.0.0.0 for every interface: the protocol has no "
                                                       "authentication, expose it on a trusted network only)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="TCP port (default: %(default)s; 0: a free port, "
                                                                  "printed in the listening line)")
    robot = p.add_argument_group("robot", "the HRP-2 preset (ij.robots.hrp2) the server decides for")
    robot.add_argument("--margin", type=float, default=0.02, help="safety margin in metres (default: %(default)s)")
    robot.add_argument("--density", type=float, default=1.0, help="action-set density (default: %(default)s: 496 "
                                                                  "actions)")
    robot.add_argument("--reach", type=float, default=None, help="largest forward/backward step in metres "
                                                                 "(default: the paper's 0.20; 0.30 for stairs)")
    robot.add_argument("--max-margin", type=float, default=None,
                       help="largest margin set_robot may set later (m; default max(margin, 0.10))")
    robot.add_argument("--set", action="append", default=[], metavar="LEAF=VALUE",
                       help="a traced robot leaf (ijoy_jax.robots.SCALAR_LEAVES: w, rotation_weight, "
                            "metrics.bump_limit, ...); repeatable")
    lim = p.add_argument_group("limits")
    lim.add_argument("--max-cells", type=int, default=None, help="largest map in cells (default: 1048576)")
    lim.add_argument("--max-maps", type=int, default=None, help="maps held at once (default: 4)")
    lim.add_argument("--max-programs", default=None, metavar="N",
                     help="map kinds (shape, resolution, 2D or 2.5D) whose compiled programs are kept, the least "
                          "recently used dropped first and compiled again when next needed (default: 8; each "
                          "--warm-up shape is two kinds)")
    p.add_argument("--warm-up", action="append", default=None, metavar="NXxNY[@RES]",
                   help=f"map shape (cells) and resolution (m) to compile for before listening; repeatable; "
                        f"'none' for no warm-up (default: {DEFAULT_WARM_UP})")
    p.add_argument("--verbose", "-v", action="store_true", help="log every request and disconnection")


def build_robot(args):
    """The robot and its description from ``ijoy serve``'s options (ValueError names a bad one)."""
    from ijoy_jax import robots
    from ijoy_jax.apps.options import number_assignments

    kwargs = {"margin": args.margin, "density": args.density}
    if args.reach is not None:
        kwargs["reach"] = args.reach
    if args.max_margin is not None:
        kwargs["max_margin"] = args.max_margin
    leaves = number_assignments(args.set, robots.SCALAR_LEAVES, "w=2.0")
    robot = robots.hrp2(**kwargs)
    if leaves:
        import jax.numpy as jnp

        robot = robots.set_leaves(robot, {k: jnp.asarray(v, jnp.float32) for k, v in leaves.items()})
        robots.check_robot(robot)
    return robot, {**kwargs, **leaves}


def main(args) -> int:
    """Run ``ijoy serve`` (bad options raise ValueError, printed by the ``ijoy`` command in one line)."""
    log = logging.getLogger("ijoy_jax.server")  # its own handler: JAX's and other libraries' INFO lines stay out
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("ijoy serve: %(message)s"))
    log.addHandler(handler)
    level, propagate = log.level, log.propagate
    log.setLevel(logging.INFO)
    log.propagate = False
    try:
        return _serve(args, log)
    finally:  # the logger as it was (ijoy serve run in a caller's process, e.g. a test, leaves nothing behind)
        log.removeHandler(handler)
        log.setLevel(level)
        log.propagate = propagate


def max_programs(text: str | None) -> int:
    """``--max-programs`` as an integer of at least 1 (ValueError in one line naming the flag otherwise)."""
    from ijoy_jax.server.service import DEFAULT_MAX_PROGRAMS

    if text is None:
        return DEFAULT_MAX_PROGRAMS
    try:
        value = int(text.strip())
    except ValueError:
        value = None
    if value is None or value < 1:
        raise ValueError(f"--max-programs must be a positive integer (map kinds whose compiled programs are "
                         f"kept), got {text!r}")
    return value


def _serve(args, log) -> int:
    """:func:`main` once its log handler is in place."""
    from ijoy_jax.progress import compiling
    from ijoy_jax.server import Limits, Service
    from ijoy_jax.server import server as net
    from ijoy_jax.server.service import parse_shape

    warm = args.warm_up or [DEFAULT_WARM_UP]
    try:
        shapes = [] if [w.lower() for w in warm] == ["none"] else list(dict.fromkeys(parse_shape(w) for w in warm))
    except ValueError as e:
        raise ValueError(f"--warm-up: {e}") from None
    programs = max_programs(args.max_programs)
    if 2 * len(shapes) > programs:  # each is compiled for 2D and 2.5D maps: two kinds
        raise ValueError(f"--warm-up: {len(shapes)} map shapes are {2 * len(shapes)} map kinds (2D and 2.5D), "
                         f"above --max-programs {programs}: the first would be dropped before the server "
                         "listens; warm up fewer shapes or raise --max-programs")
    limit_kw = {k: v for k, v in (("max_cells", args.max_cells), ("max_maps", args.max_maps)) if v is not None}
    limits = Limits(**limit_kw)
    for shape, _ in shapes:  # before the robot is built or anything allocated
        if not limits.holds(shape):
            raise ValueError(f"--warm-up {shape[0]}x{shape[1]}: {limits.shape_refusal(shape)}; raise --max-cells "
                             f"or warm up a smaller shape")
    robot, options = build_robot(args)
    try:
        listener = net.listen(args.host, args.port, max_frame_bytes=limits.max_frame_bytes)
    except net.ListenError as e:
        raise ValueError(str(e)) from None
    stop = threading.Event()
    try:
        service = Service(robot, name="hrp2", options=options, limits=limits, max_programs=programs)
        for shape, res in shapes:
            # the warm-up is its compiles (its requests on an empty map run in milliseconds): said while they
            # last, ended by the line below
            with compiling(f"the footstep programs for {shape[0]}x{shape[1]} maps at {res:g} m (2D and 2.5D)",
                           prefix="ijoy serve: ", final=False):
                w = service.warm_up(shape, res)
            log.info("warm-up for %dx%d maps at %g m: %d programs in %.1f s", *shape, res, w["programs"],
                     w["seconds"])
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        print(f"listening on {listener.address}", flush=True)
        log.info("robot hrp2 (%s), %d actions; limits %s", ", ".join(f"{k}={v}" for k, v in options.items()),
                 robot.num_actions, limits.to_json())
        counts = net.run(listener, service, stop, verbose=args.verbose)
    except KeyboardInterrupt:  # during the warm-up, before the handlers
        return 130
    finally:
        listener.close()
    log.info("stopped: %d requests (%d errors), %d connections, %d replies dropped", counts["requests"],
             service.stats["errors"], counts["connections"], counts["dropped_replies"])
    return 0
