"""``ijoy drive``: a live drive (a person or a scripted stick on the intelligent joystick), its replay and exports.

Kept here so that :mod:`ijoy_jax.apps.cli` only registers the subcommand (:func:`add_parser`) and dispatches
to :func:`main`. The library is :mod:`ijoy_jax.live`; the format of traces and recordings: docs/drive.md.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from ijoy_jax.apps.options import output_file, output_file_in_new_folder
from ijoy_jax.robots import MODELS


def add_parser(sub) -> None:
    """Register ``drive`` on an argparse subparsers object."""
    d = sub.add_parser(
        "drive", help="drive the robot live (gamepad, keyboard, browser view or a scripted trace); record/replay",
        description="Algorithm 1 in real time: the stick's command, the decision for the future stance made while "
                    "the current step executes (its latency measured and shown), the robot stepping. "
                    "See docs/drive.md.")
    src = d.add_argument_group("input (one of)")
    src.add_argument("--script", metavar="TRACE", help="a trace file t,forward,left,turn (docs/drive.md): a scripted "
                                                       "virtual joystick")
    src.add_argument("--input", choices=["view", "keyboard", "gamepad"], default=None,
                     help="the live stick: the browser view's keys or Gamepad API (default without --script), the "
                          "terminal's keys, or a gamepad through SDL (pygame-ce)")
    src.add_argument("--replay", metavar="FILE", help="drive a recording's decisions again and check that the "
                                                      "footsteps are identical (exit 1 if not)")
    ter = d.add_argument_group("terrain (one of; default: --terrain obstacles)")
    ter.add_argument("--terrain", metavar="FAMILY", help="a generator family (obstacles, walls, stairs, rough, ...)")
    ter.add_argument("--image", metavar="PNG", help="an image height map (row 0 the top); see --height-scale")
    ter.add_argument("--scenario", metavar="SWEEP.toml:ID", help="scenario ID of a sweep file (its terrain, robot "
                                                                 "and start)")
    ter.add_argument("--seed", type=int, default=0, help="the family's seed (default: %(default)s)")
    ter.add_argument("--shape", default="200x120", help="family map size in cells NXxNY (default: %(default)s)")
    ter.add_argument("--resolution", type=float, default=0.02, help="cell size in m (default: %(default)s)")
    ter.add_argument("--height", action="store_true", help="a 2.5D family map (heights), not a 2D one")
    ter.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                     help="a family parameter (repeatable), e.g. --param count=12")
    ter.add_argument("--height-scale", type=float, default=0.5 / 255,
                     help="m per image unit of --image (default: 0.5/255, white = 0.5 m)")
    rob = d.add_argument_group("robot")
    rob.add_argument("--robot", choices=["perfect", "native", "mjx"], default="perfect",
                     help="the paper's perfect walker, the MuJoCo biped on native MuJoCo (real time on a CPU), or "
                          "the same biped on MJX (on the CPU: one robot runs faster there than on a GPU; a late "
                          "tick is reported as tick lag) (default: %(default)s)")
    rob.add_argument("--model", choices=MODELS, default="biped",
                     help="the robot: the project's HRP-2-like biped (the selector's robots.hrp2) or the Unitree G1 "
                          "(robots.g1; with --robot native or mjx the MuJoCo Menagerie G1, the robots extra) "
                          "(default: %(default)s)")
    rob.add_argument("--margin", type=float, default=0.02, help="safety margin in m (default: %(default)s)")
    rob.add_argument("--start", default=None, metavar="X,Y,THETA", help="start of the feet's midpoint (default: the "
                                                                         "terrain's start zone)")
    loop = d.add_argument_group("loop")
    loop.add_argument("--server", metavar="HOST:PORT", help="decide on the footstep server (ijoy serve) instead of "
                                                            "in this process")
    loop.add_argument("--steps", type=int, default=None, help="decisions to make (default: until the trace ends, or "
                                                              "Ctrl-C)")
    loop.add_argument("--duration", type=float, default=None, help="s of driving (default: the trace's)")
    loop.add_argument("--decide-at", type=float, default=0.0,
                      help="fraction of a step at which the stick is read and the next decision made (default: 0, "
                           "Algorithm 1: as the step starts)")
    loop.add_argument("--deadzone", type=float, default=None, help="stick dead zone, fraction of travel (default: "
                                                                   "0.1)")
    loop.add_argument("--headless", action="store_true", help="no view; with --script, faster than real time")
    loop.add_argument("--realtime", action="store_true", help="pace a headless drive to the wall clock anyway")
    loop.add_argument("--record", metavar="OUT", type=output_file_in_new_folder,
                      help="record the drive to an MCAP file (its folder is made)")
    loop.add_argument("--host", default="127.0.0.1", help="the view's address (default: %(default)s; forward it "
                                                          "with ssh -L)")
    loop.add_argument("--port", type=int, default=8765, help="the view's port (default: %(default)s)")
    loop.add_argument("--ff", default=None, metavar="DEVICE|auto|off",
                      help="force feedback: an evdev device path, the first one found (auto), or off; it says which "
                           "device plays the forces, or why none does (default: the first one found, said only "
                           "when there is one)")
    loop.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    exp = d.add_argument_group("exports of a recording (with --replay FILE, instead of replaying)")
    exp.add_argument("--export-trace", metavar="TRACE", type=output_file,
                     help="write the recorded stick as a trace file")
    exp.add_argument("--export-sweep", metavar="OUT.toml", type=output_file_in_new_folder,
                     help="write a sweep file whose scenario is the recorded drive (its commands step by step; ijoy "
                          "sweep run OUT.toml; its folder is made)")
    exp.add_argument("--sweep-terrain", choices=["recording", "family"], default="recording",
                     help="the exported sweep's terrain: the recorded map (default) or the generator family it was "
                          "drawn from (replicate 0 is the recorded map)")


def _family_params(items, family: str) -> dict:
    """``--param NAME=VALUE`` items as the terrain family's parameters (ints where written as ints, else floats).

    Raises:
      ValueError: an unknown family (naming --terrain), an item that is not NAME=VALUE, a name that is not a
        field of the family's parameters (listing them, as a sweep file's ``terrain.params`` keys are) or a
        value that is not a number, naming the flag.
    """
    import dataclasses

    from ijoy_jax.terrain import generators

    if family not in generators.FAMILIES:
        raise ValueError(f"--terrain {family}: unknown terrain family {family!r}; known: "
                         f"{', '.join(sorted(generators.FAMILIES))}")
    known = [f.name for f in dataclasses.fields(generators.FAMILIES[family].params)]
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--param must be NAME=VALUE, got {item!r}")
        if name not in known:
            raise ValueError(f"--param {item}: unknown key of terrain family {family!r}; known keys: "
                             f"{', '.join(known)}")
        try:
            out[name] = int(value) if value.strip().lstrip("-").isdigit() else float(value)
        except ValueError:
            raise ValueError(f"--param {name}: not a number: {value!r}") from None
    return out


def _terrain_spec(args) -> dict:
    chosen = [n for n in ("terrain", "image", "scenario") if getattr(args, n)]
    if len(chosen) > 1:
        raise ValueError(f"give one terrain, got --{' and --'.join(chosen)}")
    if args.image:
        return {"kind": "image", "path": str(args.image), "resolution": args.resolution,
                "height_scale": args.height_scale}
    if args.scenario:
        path, sep, ident = args.scenario.rpartition(":")
        if not sep or not ident.isdigit():
            raise ValueError(f"--scenario must be SWEEP.toml:ID, got {args.scenario!r}")
        return {"kind": "scenario", "sweep": path, "id": int(ident)}
    try:
        nx, ny = (int(v) for v in args.shape.lower().split("x"))
    except ValueError:
        raise ValueError(f"--shape must be NXxNY cells, e.g. 200x120, got {args.shape!r}") from None
    family = args.terrain or "obstacles"
    return {"kind": "family", "family": family, "seed": args.seed, "shape": [nx, ny], "resolution": args.resolution,
            "has_height": bool(args.height), "params": _family_params(args.param, family)}


def _start(text):
    """``--start X,Y,THETA`` as floats, the heading reduced by whole turns as the library's pose arguments are.

    Raises:
      ValueError: naming --start: not three numbers, not finite, a heading beyond ``geometry.MAX_HEADING`` or x
        or y beyond ``ijoy_jax.footcost.MAX_COORDINATE``, where no map reaches (float32 rounded ``1e300`` to inf
        and the refusal said only "start must be finite").
    """
    from ijoy_jax import geometry
    from ijoy_jax.footcost import MAX_COORDINATE

    if text is None:
        return None
    try:
        x, y, theta = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--start must be X,Y,THETA, got {text!r}") from None
    if not all(map(math.isfinite, (x, y, theta))):
        raise ValueError(f"--start must be finite numbers X,Y,THETA, got {text!r}")
    for name, v in (("x", x), ("y", y)):
        if abs(v) > MAX_COORDINATE:
            raise ValueError(f"--start {name} {v:g} m is beyond ijoy_jax.footcost.MAX_COORDINATE = "
                             f"{MAX_COORDINATE:g} m, where no map reaches (float32 holds millimetres within it)")
    geometry.check_headings("--start", [x, y, theta])
    x, y, theta = (float(v) for v in geometry.reduce_turns([x, y, theta]))
    return (x, y, theta)


def main(args) -> int:
    """Run ``ijoy drive`` from parsed arguments (bad values raise ValueError with a one-line message)."""
    from ijoy_jax import live
    from ijoy_jax.stick import DEFAULT_DEADZONE

    if args.replay:
        return _replay(args)
    for flag in ("export_trace", "export_sweep"):
        if getattr(args, flag):
            raise ValueError(f"--{flag.replace('_', '-')} needs --replay FILE (the recording to export)")
    if args.script and args.input:
        raise ValueError("give --script or --input, not both")
    if args.server is not None:
        live.session.server_address(args.server)  # a malformed --server: one line, before the terrain is built
    if args.duration is not None:
        live.loop.check_duration(args.duration, "--duration")  # before anything is built
    if args.steps is not None:
        live.loop.check_steps(args.steps, "--steps")
    source = None
    if args.script:
        source = live.ScriptInput(args.script)  # a missing or malformed trace fails here, before any compile
        if args.duration is None:
            live.loop.check_duration(source.duration, f"the trace's last time ({args.script})")
    kind = args.input or (None if args.script else ("keyboard" if args.headless else "view"))
    if kind == "view" and args.headless:
        raise ValueError("--input view needs the view (drop --headless)")
    settings = live.DriveSettings(
        terrain=_terrain_spec(args), body=args.robot, model=args.model, margin=args.margin,
        start=_start(args.start),
        deadzone=DEFAULT_DEADZONE if args.deadzone is None else args.deadzone,
        decide_at=args.decide_at, decider="server" if args.server else "local", server=args.server)
    if not 0.0 <= settings.deadzone < 1.0:
        raise ValueError(f"--deadzone must be in [0, 1), got {settings.deadzone}")
    if not 0.0 <= settings.decide_at < 1.0:
        raise ValueError(f"--decide-at must be in [0, 1), got {settings.decide_at}")
    # bad terrain: one line, now
    terrain, robot, start = live.open_terrain(settings.terrain, settings.margin, settings.model)
    if settings.start is not None:
        start = live.session.start_feet(settings, robot, start)
    view = None
    if not args.headless:
        from ijoy_jax.live.view import ViewServer

        view = ViewServer(args.host, args.port).start()
        view.set_scene(terrain, robot, start)
        print(f"ijoy drive: the view is at {view.url} (remote: ssh -L {view.port}:localhost:{view.port} HOST)",
              file=sys.stderr, flush=True)
    if source is None:
        source = _live_source(kind, view)

    def on_body(body):  # the drive's first-decision check, naming the flag, before the warm-up compiles
        if args.duration is not None or args.script:
            live.loop.check_first_decision(
                source.duration if args.duration is None else args.duration, settings.decide_at, body,
                "--duration" if args.duration is not None else f"the trace's last time ({args.script})")
        if view is not None:
            view.set_body(body)

    feedback = feedback_device(args.ff)
    realtime = not args.headless or args.realtime or not args.script
    if args.robot == "mjx":
        _say_where_mjx_runs(realtime, "G1" if args.model == "g1" else "biped")
    try:
        result = live.run(settings, source, realtime=realtime, num_steps=args.steps, duration=args.duration,
                          record_to=args.record, on_tick=None if view is None else view.publish,
                          on_body=on_body, feedback=feedback,
                          stop=None if (args.steps is not None or args.duration is not None or args.script)
                          else _never(), terrain=terrain, robot=robot, start=start, progress=True)
    finally:
        source.close()
        if feedback is not None:
            feedback.close()
        if view is not None:
            view.close()
    _report(result.summary(), args, extra={"record": args.record} if args.record else {})
    return 0


def _say_where_mjx_runs(realtime: bool, robot: str = "biped") -> None:
    import jax

    dev = jax.devices("cpu")[0]  # live.session.BODIES: the drive's MJX biped runs on the CPU
    print(f"ijoy drive: the MJX {robot} runs on {dev.platform} ({dev.device_kind})"
          + ("; its ticks may fall behind the wall clock on a busy machine (reported; --robot native has more "
             "headroom)" if realtime else ""), file=sys.stderr, flush=True)


def _never():
    import threading

    return threading.Event()  # a live drive ends with Ctrl-C (or --steps / --duration)


def _live_source(kind, view):
    from ijoy_jax.live import inputs

    if kind == "view":
        view.axes.name = "view"
        return view.axes
    if kind == "keyboard":
        print("ijoy drive: keys w/s forward/back, a/d left/right, q/e turn, space stop; Ctrl-C ends",
              file=sys.stderr, flush=True)
        return inputs.TerminalKeyboard()
    return inputs.Gamepad()


def feedback_device(spec: str | None):
    """The force-feedback device of ``--ff`` (None: not given, the first one found), or None for ``off``.

    ``spec`` is ``--ff``'s value: None, ``"auto"``, ``"off"`` or an evdev path; the result is what
    :func:`ijoy_jax.live.forcefeedback.open_device` opens (a ``NoFeedback`` that says why when none is found).

    Its line on stderr says which device plays the forces; that none does only where one was asked for (``--ff
    auto`` or a path): a drive without a joystick that pushes back is the usual case, not news.
    """
    if spec == "off":
        return None
    from ijoy_jax.live import forcefeedback

    out = forcefeedback.open_device(None if spec in (None, "auto") else spec)
    if spec is not None or not isinstance(out, forcefeedback.NoFeedback):
        print(f"ijoy drive: force feedback: {out.description}", file=sys.stderr, flush=True)
    return out


def _report(summary: dict, args, extra=None) -> None:
    summary = {**summary, **(extra or {})}
    if args.json:
        print(json.dumps(summary))
        return
    ms = lambda v: f"{1000 * v:.1f} ms"  # noqa: E731
    print(f"ijoy drive: {summary['steps']} steps ({summary['steps_taken']} taken), decision latency p50 "
          f"{ms(summary['latency_p50_s'])}, p99 {ms(summary['latency_p99_s'])}, max {ms(summary['latency_max_s'])}, "
          f"late {summary['late']}"
          + (f", ticks behind the wall clock by up to {ms(summary['tick_lag_max_s'])}"
             if summary.get("tick_lag_max_s", 0) >= 0.001 else "")  # a sleep's usual wake-up delay is less
          + (f"; recorded to {summary['record']}" if summary.get("record") else ""))


def _replay(args) -> int:
    from ijoy_jax import live

    if args.export_trace or args.export_sweep:
        rec = live.read_recording(args.replay)
        if args.export_trace:
            n = live.session.export_trace(rec, args.export_trace)
            print(json.dumps({"trace": args.export_trace, "samples": n}))
        if args.export_sweep:
            from ijoy_jax import sweep

            print(json.dumps(sweep.export_drive(rec, args.export_sweep, args.replay, terrain=args.sweep_terrain)))
        return 0
    if not Path(args.replay).is_file():
        what = "is a folder, not a file" if Path(args.replay).is_dir() else "does not exist"
        raise ValueError(f"recording {args.replay!r} {what}")
    result, rec, mismatches = live.replay(args.replay, server=args.server,
                                          decider="server" if args.server else "local")
    summary = {**result.summary(), "replayed": args.replay, "identical": not mismatches,
               "mismatched_steps": mismatches[:20]}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"ijoy drive: replayed {len(rec.decisions)} decisions of {args.replay}: footsteps "
              + ("identical" if not mismatches else f"DIFFER at steps {mismatches[:20]}"))
    return 0 if not mismatches else 1
