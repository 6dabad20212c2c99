"""A drive from its settings: the terrain (a generator family, an image height map, a sweep scenario), the robot,
the body, the decider; recording, replay and the export of a recording's stick.

:func:`open_terrain` turns a terrain spec (a dict, kept in the recording) into the terrain, the robot and
the start feet; :func:`run` drives and records; :func:`replay` drives a recording's decisions again and
compares the footsteps bit for bit; :func:`export_trace` writes a recording's stick as a trace file (a
person's drive becomes a scripted one, on any terrain or robot); :func:`ijoy_jax.sweep.export_drive` writes
a sweep file whose scenario is the recorded drive (its commands step by step).
"""

from __future__ import annotations

import dataclasses
import datetime
import platform
from importlib import metadata
from pathlib import Path

import jax
import numpy as np

from ijoy_jax import recordings, robots, select
from ijoy_jax import terrain as terrain_mod
from ijoy_jax.live.bodies import PerfectBody
from ijoy_jax.live.deciders import LocalDecider, RemoteDecider
from ijoy_jax.live.loop import DriveResult, drive
from ijoy_jax.robots import Robot
from ijoy_jax.stick import DEFAULT_CONTROL_DT, DEFAULT_DEADZONE, TRACE_HEADER, Trace
from ijoy_jax.terrain import Terrain, generators

__all__ = ["BODIES", "DriveSettings", "ReplayInput", "build_body", "export_trace",
           "open_terrain", "replay", "run", "server_address", "start_feet"]

BODIES = ("perfect", "native", "mjx")
"""The robots a drive can step: the paper's perfect walker, the MuJoCo biped on native MuJoCo, or the same biped
on MJX (:class:`ijoy_jax.sim.mjx_biped.MjxBiped`), which a drive runs on the CPU whatever the machine: one robot's
tick is many small kernels, and on a GPU each waits for its launch, so there it falls behind the wall clock
(measured in docs/drive.md)."""
@dataclasses.dataclass(frozen=True)
class DriveSettings:
    """What a drive is (recorded as the ``ijoy.drive`` metadata; every field JSON-ready).

    Fields::

      terrain: the terrain spec (:func:`open_terrain`).
      body: one of :data:`BODIES`.
      model: the robot (:data:`ijoy_jax.robots.MODELS`): ``"biped"``, the project's HRP-2-like biped stepped by
        ``robots.hrp2``, or ``"g1"``, the Unitree G1 stepped by ``robots.g1`` (the perfect body steps the
        selector's robot; the MuJoCo bodies simulate the model's, the G1's with the ``robots`` extra). A
        recording made before the G1 has no ``model``: it was the biped.
      margin: the robot's safety margin (m; ignored for a sweep scenario, whose robot is the sweep's).
      start: (x, y, theta) of the feet's midpoint (m, rad), or None: the terrain's start zone.
      first_swing: +1 left foot first, -1 right.
      deadzone, decide_at: as :func:`ijoy_jax.live.drive`.
      control_dt: s per tick of the perfect body (the MuJoCo bipeds' is their controller's).
      decider: "local" or "server" (the footstep server at ``server``, "host:port").
    """

    terrain: dict = dataclasses.field(default_factory=lambda: {"kind": "family", "family": "obstacles", "seed": 0})
    body: str = "perfect"
    model: str = "biped"
    margin: float = 0.02
    start: tuple | None = None
    first_swing: int = 1
    deadzone: float = DEFAULT_DEADZONE
    decide_at: float = 0.0
    control_dt: float = DEFAULT_CONTROL_DT
    decider: str = "local"
    server: str | None = None


def open_terrain(spec: dict, margin: float = 0.02, model: str = "biped") -> tuple[Terrain, Robot, np.ndarray]:
    """The terrain, robot and start feet (2, 3) of a terrain spec: the robot is ``model``'s
    (:func:`ijoy_jax.robots.for_model`) with safety margin ``margin`` (m), but for a sweep scenario, whose robot
    is the sweep's (the project's biped, HRP-2: ``model`` must be ``"biped"`` there). Raises ValueError (one
    line) for a bad spec or model.

    Specs::

      {"kind": "family", "family": NAME, "seed": S, "shape": [nx, ny], "resolution": m, "has_height": bool,
       "params": {field: value}}   a generator family (:data:`ijoy_jax.terrain.generators.FAMILIES`); the
                                   terrain key is ``fold_in(key(S), 0)``, replicate 0 of a sweep with seed S;
                                   the start is the family's start zone
      {"kind": "image", "path": P, "resolution": m, "height_scale": m per unit, "obstacle_above": m or None}
                                   an image height map (:func:`ijoy_jax.terrain.from_image`); start: 0.5 m
                                   in from the left edge, half way up
      {"kind": "scenario", "sweep": FILE, "id": N}
                                   scenario N of a sweep file (:func:`ijoy_jax.sweep.scenario`): its terrain,
                                   robot and start
    """
    kind = spec.get("kind")
    robot = robots.for_model(model, margin=margin)
    if kind == "family":
        name = spec.get("family")
        if name not in generators.FAMILIES:
            raise ValueError(f"unknown terrain family {name!r}; known: {', '.join(sorted(generators.FAMILIES))}")
        fam = generators.FAMILIES[name]
        try:
            params = fam.params(**spec.get("params", {}))
        except TypeError as e:
            raise ValueError(f"terrain family {name!r}: bad parameter ({e})") from None
        shape = tuple(int(v) for v in spec.get("shape", (200, 120)))
        res = float(spec.get("resolution", 0.02))
        static = dict(shape=shape, resolution=res, has_height=bool(spec.get("has_height", False)))
        if fam.max_count is not None and spec.get("max_count") is not None:
            static["max_count"] = int(spec["max_count"])
        key = jax.random.fold_in(jax.random.key(int(spec.get("seed", 0))), 0)
        try:
            terrain = generators.generate(name, key, params, **static)
        except (TypeError, ValueError) as e:
            raise ValueError(f"terrain family {name!r}: {e}") from None
        centre = np.asarray(generators.start_point(params, shape=shape, resolution=res))
        return terrain, robot, np.asarray(robots.start_stance(robot, centre[0], centre[1]), np.float32)
    if kind == "image":
        path = Path(spec.get("path", ""))
        if not path.is_file():
            what = "is a folder, not a file" if path.is_dir() else "does not exist"
            raise ValueError(f"height map image {str(path)!r} {what}")
        try:
            terrain = terrain_mod.from_image(path, float(spec.get("resolution", 0.02)),
                                             float(spec.get("height_scale", 0.5 / 255)),
                                             obstacle_above=spec.get("obstacle_above"))
        except (OSError, ValueError) as e:
            raise ValueError(f"height map image {str(path)!r}: {e}") from None
        nx, ny = terrain.shape
        start = robots.start_stance(robot, 0.5, 0.5 * ny * terrain.resolution)
        return terrain, robot, np.asarray(start, np.float32)
    if kind == "scenario":
        from ijoy_jax import sweep

        if model != "biped":
            raise ValueError(f"model {model!r} with a sweep scenario: its robot is the sweep's, HRP-2 (a sweep "
                             "walks the project's biped)")
        try:
            cfg = sweep.load_config(spec["sweep"])
            sc = sweep.scenario(cfg, int(spec["id"]))
        except (OSError, KeyError) as e:
            raise ValueError(f"sweep scenario {spec!r}: {e}") from None
        return sc.terrain, sc.robot, sc.start
    raise ValueError(f"terrain spec kind must be 'family', 'image' or 'scenario', got {kind!r}")


def start_feet(settings: DriveSettings, robot: Robot, default) -> np.ndarray:
    """(2, 3) float32 start feet (x, y, yaw; row 0 left): ``settings.start`` (x, y, heading) as
    :func:`ijoy_jax.robots.start_stance` places them, or ``default`` when it is None."""
    if settings.start is None:
        return np.asarray(default, np.float32)
    x, y, theta = (float(v) for v in settings.start)
    return np.asarray(robots.start_stance(robot, x, y, theta), np.float32)


def build_body(kind: str, terrain: Terrain, robot: Robot, start, first_swing=1, control_dt=DEFAULT_CONTROL_DT, *,
               model: str = "biped"):
    """A standing robot of kind ``kind`` (:data:`BODIES`) at ``start`` (2, 3) (x, y, yaw of the feet, row 0 left).

    ``control_dt`` (s) is the perfect body's tick; the MuJoCo bipeds tick at their controller's period and
    simulate ``model`` (:data:`ijoy_jax.robots.MODELS`; its selector robot is ``robot``). The MJX biped's
    programs compile when the first one of a model, grid and terrain kind (2D or 2.5D) is built (about a
    minute on a 2-core CPU) and are shared by the next ones (a replay's).
    """
    if kind == "perfect":
        return PerfectBody(robot, start, first_swing, control_dt)
    if kind == "native":
        from ijoy_jax.sim import native

        sim = _sim_for(float(terrain.resolution), robot, model=model)
        return native.NativeBiped(sim, terrain, robot, start, first_swing)
    if kind == "mjx":
        from ijoy_jax.sim import mjx_biped

        sim = _sim_for(float(terrain.resolution), robot, tuple(int(n) for n in terrain.shape), model=model)
        # One robot runs faster on the CPU than on a GPU (BODIES): the drive's MJX body runs there on any machine.
        return mjx_biped.MjxBiped(sim, terrain, robot, start, first_swing, device=jax.devices("cpu")[0])
    raise ValueError(f"body must be one of {BODIES}, got {kind!r}")


_SIMS: dict = {}


def _sim_for(resolution: float, robot: Robot, shape: tuple[int, int] = (2, 2), *, model: str = "biped"):
    """One Sim per model, grid, footprint and step time in this process, so its compiled programs are shared (the
    native biped builds its own model per terrain: its Sim's grid is a placeholder, (2, 2); the MJX biped's
    height field is the Sim's, of the terrain's grid)."""
    from ijoy_jax.sim import walker

    key = (model, shape, resolution, float(robot.foot_length), float(robot.foot_width), float(robot.step_time))
    if key not in _SIMS:
        _SIMS[key] = walker.make_sim(shape, resolution, robot=robot, model=model)
    return _SIMS[key]


def _decider(settings: DriveSettings, terrain, robot, prepared):
    if settings.decider == "local":
        return LocalDecider(terrain, robot, prepared=prepared)
    if settings.decider == "server":
        from ijoy_jax import server

        return RemoteDecider(server.Client(*server_address(settings.server)), terrain, robot)
    raise ValueError(f"decider must be 'local' or 'server', got {settings.decider!r}")


def server_address(text) -> tuple[str, int]:
    """``(host, port)`` of a footstep server's ``"HOST:PORT"``; ValueError (one line) otherwise."""
    host, _, port = (text or "").rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"server must be HOST:PORT, got {text!r}")
    if not 1 <= int(port) <= 65535:
        raise ValueError(f"server port must be in 1..65535, got {port} in {text!r}")
    return host, int(port)


def _versions() -> dict:
    out = {"python": platform.python_version()}
    for pkg in ("ijoy_jax", "jax", "jaxlib", "mujoco", "numpy", "mcap"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return out


def run(settings: DriveSettings, source, *, realtime: bool = True, num_steps=None, duration=None, record_to=None,
        on_tick=None, feedback=None, stop=None, terrain=None, robot=None, start=None, on_ready=None,
        on_body=None, progress: bool = False) -> DriveResult:
    """Open the terrain, build the body and decider, and drive (:func:`ijoy_jax.live.drive`; ``progress``: say
    what its warm-up compiles, on stderr), recording to ``record_to`` (an MCAP path) when given. ``terrain``,
    ``robot``, ``start`` override the spec's (a replay); ``on_ready(terrain, robot, start)`` is called once they
    exist (the view's scene); ``on_body(body)`` once the body is built, before the drive starts (the view's 3D
    robot: :meth:`ijoy_jax.live.view.ViewServer.set_body`)."""
    if terrain is None:
        terrain, robot_spec, start_spec = open_terrain(settings.terrain, settings.margin, settings.model)
        robot = robot_spec if robot is None else robot
        start = start_feet(settings, robot, start_spec) if start is None else start
    if on_ready is not None:
        on_ready(terrain, robot, start)
    prepared = select.prepare(terrain, robot)
    body = build_body(settings.body, terrain, robot, start, settings.first_swing, settings.control_dt,
                      model=settings.model)
    if on_body is not None:
        on_body(body)
    decider = _decider(settings, terrain, robot, prepared)
    recorder = None
    if record_to is not None:
        config = {"settings": dataclasses.asdict(settings), "start": np.asarray(start).tolist(),
                  "realtime": realtime, "versions": _versions(),
                  "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
                  "machine": platform.node()}
        recorder = recordings.Recorder(record_to, config, terrain, robot)
    try:
        result = drive(terrain, robot, body, source, decider, deadzone=settings.deadzone,
                       decide_at=settings.decide_at, realtime=realtime, num_steps=num_steps, duration=duration,
                       recorder=recorder, on_tick=on_tick, feedback=feedback, stop=stop, prepared=prepared,
                       progress=progress)
    finally:
        decider.close()
        if recorder is not None:
            summary = None
            if "result" in locals():
                summary = {"t": result.states[-1]["t"] if result.states else 0.0, **result.summary()}
            recorder.close(summary)
    return result


class ReplayInput:
    """A recording's stick: its axes at the recorded times and, for each decision, its recorded command."""

    name = "replay"

    def __init__(self, recording: recordings.Recording):
        dec = recording.decisions
        self.commands = [np.asarray(d["command"], np.float64) for d in dec]
        inputs = recording.inputs
        if inputs:
            self.trace = Trace(np.asarray([m["t"] for m in inputs]), np.asarray([m["axes"] for m in inputs]))
        else:
            self.trace = Trace(np.zeros(1), np.zeros((1, 3)))

    def axes(self, t: float) -> np.ndarray:
        return self.trace.at(t)

    def command_at(self, step: int) -> np.ndarray:
        return self.commands[step]

    def close(self) -> None:
        pass


def replay(path, *, decider: str = "local", server: str | None = None, on_tick=None, realtime: bool = False):
    """Drive a recording's decisions again (its terrain, robot, body and commands) and compare the footsteps.

    The decisions are made again by ``decider``: "local" (default, this process's selector, whichever decided
    the recording) or "server" (the footstep server at ``server``, "HOST:PORT").

    Returns ``(result, recording, mismatches)``: ``mismatches`` lists the steps whose sent foothold, ``go``
    or feet after the step differ from the recording in any bit (empty: identical footsteps).
    """
    rec = recordings.read_recording(path)  # ValueError (one line) for a corrupt or hand-edited file
    s = rec.config["settings"]
    unknown = sorted(set(s) - {f.name for f in dataclasses.fields(DriveSettings)})
    if unknown:
        raise ValueError(f"{str(path)!r}: the 'ijoy.drive' metadata: config.settings has keys a drive does not know: "
                         f"{', '.join(unknown)}")
    if s["body"] not in BODIES:
        raise ValueError(f"{str(path)!r}: the 'ijoy.drive' metadata: config.settings.body must be one of {BODIES}, "
                         f"got {s['body']!r}")
    settings = DriveSettings(**{**s, "start": None if s.get("start") is None else tuple(s["start"]),
                                "decider": decider, "server": server})
    result = run(settings, ReplayInput(rec), realtime=realtime, num_steps=len(rec.decisions),
                 terrain=rec.terrain, robot=rec.robot, start=np.asarray(rec.config["start"], np.float32),
                 on_tick=on_tick)
    mismatches = []
    for k, (a, b) in enumerate(zip(rec.states, result.states, strict=False)):
        same = (np.array_equal(np.asarray(a["sent"], np.float32), np.asarray(b["sent"], np.float32))
                and bool(a["go"]) == bool(b["go"])
                and np.array_equal(np.asarray(a["feet"], np.float32), np.asarray(b["feet"], np.float32)))
        if not same:
            mismatches.append(k)
    if len(rec.states) != len(result.states):
        mismatches.append(min(len(rec.states), len(result.states)))
    return result, rec, mismatches


def export_trace(recording: recordings.Recording, path) -> int:
    """Write a recording's stick as a trace file that drives the recorded decisions again; returns the samples
    written.

    Driven with the recording's terrain, robot, body, dead zone and ``decide_at`` (``ijoy drive --script``), the
    file makes the drive's decisions: as many, read at the same times (s) from the same axes, so with the same
    commands (m/s, m/s, rad/s). Its samples are the ``/ijoy/input`` axes and each ``/ijoy/decision``'s own
    axes at its time (the two agree in a drive's recording; the decision's win, so a recording whose stick was
    recorded late, or not at all, still gives every decision its axes), clipped to [-1, 1] as the drive reads
    them, consecutive equal samples merged. Its last line (axes 0) is the drive's end: the end of the step
    period in which the drive read its last decision (that period's ``/ijoy/state`` ``t``), the start of the
    period in which it read none. A scripted drive makes no decision at or after its trace's last time
    (:func:`ijoy_jax.live.drive`), so it stops deciding where the recorded drive did, whatever ended that
    drive: its script, a duration, a step count or the stop event. Samples from the end on decided nothing
    and are left out.

    Raises:
      ValueError: (one line, naming ``path``) the recording holds no decision (a drive stopped before its
        first, by Ctrl-C): no trace makes no decision (with ``decide_at`` 0 a scripted drive reads its
        first at 0 s, before any trace's last time, which is > 0 s).
    """
    decisions, states = recording.decisions, recording.states
    if not decisions:
        raise ValueError(f"{str(path)!r}: no trace to export: the recording holds no decision (its drive stopped "
                         "before its first), and a scripted drive reads its first at 0 s")
    last = float(decisions[-1]["t"])
    # states[j] ends step period j (period 0 is the warm-up), and period j reads decision j + 1
    end = float(states[len(decisions) - 1]["t"]) if len(states) >= len(decisions) else last
    if not end > last:  # a hand-made recording without that period's end: one step period after the last read
        end = last + float(recording.robot.step_time)
    axes = {float(m["t"]): m["axes"] for m in recording.inputs}
    axes.update({float(d["t"]): d["axes"] for d in decisions})
    lines = [",".join(TRACE_HEADER)]
    held = None
    for t in sorted(axes):
        a = tuple(float(v) for v in np.clip(np.asarray(axes[t], np.float64), -1.0, 1.0))
        if t < end and a != held:
            lines.append(f"{t!r},{a[0]!r},{a[1]!r},{a[2]!r}")
            held = a
    lines.append(f"{end!r},0.0,0.0,0.0")
    Path(path).write_text("\n".join(lines) + "\n")
    return len(lines) - 1
