"""Live drives: a person (or a scripted stick) on the intelligent joystick, in real time.

The paper's Algorithm 1 and Fig. 6 as a running system on a CPU: a stick (:mod:`.inputs`: a trace
file, :mod:`ijoy_jax.stick`; the terminal's keys, a gamepad through SDL, or the browser view's keyboard and
Gamepad API) mapped through a dead zone onto the robot's command range; a footstep decider (:mod:`.deciders`: the
selector in this process, or the footstep server ``ijoy serve`` over the network); a robot that
executes the steps tick by tick (:mod:`.bodies`: the perfect walker; :mod:`ijoy_jax.sim.native`: the
MuJoCo biped on native MuJoCo; :mod:`ijoy_jax.sim.mjx_biped`: the same biped on MJX, on a GPU); the
loop (:mod:`.loop`) that makes the decision for the future stance while the current step executes and
measures its latency; a recording in MCAP
(:mod:`ijoy_jax.recordings`) that :func:`replay` reproduces bit for bit; the live view in a browser
(:mod:`.view`: a top-down map at ``/`` and the robot's bodies in 3D at ``/3d``, from :class:`.bodies.BodyGeoms`);
force feedback on a Linux device (:mod:`.forcefeedback`).

Command line: ``ijoy drive`` (docs/drive.md).
"""

# ruff: noqa: E402  (the package's imports follow the check of its extra)
from ijoy_jax.extras import require as _require

_require("live", "mcap", "aiohttp", "jsonschema", "PIL")

from ijoy_jax.live import bodies as bodies
from ijoy_jax.live import deciders as deciders
from ijoy_jax.live import inputs as inputs
from ijoy_jax.live import loop as loop
from ijoy_jax.live import session as session
from ijoy_jax.live.bodies import BodyGeoms as BodyGeoms
from ijoy_jax.live.bodies import PerfectBody as PerfectBody
from ijoy_jax.live.deciders import Decision as Decision
from ijoy_jax.live.deciders import LocalDecider as LocalDecider
from ijoy_jax.live.deciders import RemoteDecider as RemoteDecider
from ijoy_jax.live.inputs import ScriptInput as ScriptInput
from ijoy_jax.live.inputs import SharedAxes as SharedAxes
from ijoy_jax.live.inputs import gamepad_axes as gamepad_axes
from ijoy_jax.live.loop import DriveResult as DriveResult
from ijoy_jax.live.loop import drive as drive
from ijoy_jax.live.loop import latency_stats as latency_stats
from ijoy_jax.live.session import DriveSettings as DriveSettings
from ijoy_jax.live.session import open_terrain as open_terrain
from ijoy_jax.live.session import replay as replay
from ijoy_jax.live.session import run as run
from ijoy_jax.recordings import Recorder as Recorder
from ijoy_jax.recordings import Recording as Recording
from ijoy_jax.recordings import read_recording as read_recording
from ijoy_jax.stick import InputError as InputError
from ijoy_jax.stick import Trace as Trace
from ijoy_jax.stick import axes_to_command as axes_to_command
from ijoy_jax.stick import read_trace as read_trace

__all__ = [
    "BodyGeoms",
    "Decision",
    "DriveResult",
    "DriveSettings",
    "InputError",
    "LocalDecider",
    "PerfectBody",
    "Recorder",
    "Recording",
    "RemoteDecider",
    "ScriptInput",
    "SharedAxes",
    "Trace",
    "axes_to_command",
    "bodies",
    "deciders",
    "drive",
    "gamepad_axes",
    "inputs",
    "latency_stats",
    "loop",
    "open_terrain",
    "read_recording",
    "read_trace",
    "replay",
    "run",
    "session",
]
