"""The live drive: Algorithm 1 in real time, the decision for the future stance made while the current step executes.

One *step period* is ``robot.step_time`` seconds of control ticks (``body.control_dt`` each). When step
``j`` begins (the robot is sent its foothold, SendRobotCmd), the loop reads the stick
(GetJoystickCommand; ``decide_at`` of the way into the step, 0 by default as in the paper's
Algorithm 1), takes the stance the robot will stand on when step ``j`` ends
(ComputeStanceLocation: the foot now swinging, where it was sent) and hands the decision for step
``j + 1`` to a worker thread (GetNextStep: :mod:`ijoy_jax.live.deciders`, in this process or the
footstep server) while the robot's ticks go on. At the end of the step the decision must be there
(WaitForNextStep); its *latency* (command read to decision ready) and its *slack* (decision ready to
the step's end; negative when late, the robot then waits) are measured for every decision. A
decision without a valid step makes the robot stand one step (StopWalking) and the next decision is
made from the same stance, so a person can steer out of a dead end. The first step period stands
(the walker's warm-up) while the first decision is made.

After each decision the worker also prepares what the operator feels and sees for the *next* one:
the feasible command set of the next stance (:func:`ijoy_jax.cue.feasible_commands`, one FootCost
evaluation of every action, which is also the next decision's candidates), the haptic cue's
prepared tick (:func:`ijoy_jax.cue.prepare_tick`) played every control tick at the current
command, and the cue's reach per direction (:func:`ijoy_jax.cue.reach`).

Clock. ``t`` (s) counts control ticks from the drive's start (``ticks * control_dt``): with
``realtime=True`` each tick is paced to the wall clock (a late tick is not made up; the lag is
counted); headless (``realtime=False``) the ticks run as fast as the CPU allows and ``t`` is
virtual, so a scripted drive is exactly reproducible (:func:`replay`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import gc
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import jax.numpy as jnp
import numpy as np

from ijoy_jax import cue, footcost, limits, robots, select
from ijoy_jax.live.deciders import Decision
from ijoy_jax.progress import compiling
from ijoy_jax.robots import Robot
from ijoy_jax.stick import DEFAULT_DEADZONE, axes_to_command
from ijoy_jax.terrain import Terrain

__all__ = ["DEFAULT_REACH_DIRECTIONS", "MAX_DURATION", "TERM_NAMES", "DriveResult", "check_duration",
           "check_first_decision", "check_steps", "drive", "latency_stats"]

MAX_DURATION = 86400.0
"""s: the longest drive (a day). A drive keeps every tick's state for its result and its recording, so a longer
one (a trace whose last time is 1e30, ``--duration 1e30``) would grow without end; end a longer session with
the stop event instead."""

DEFAULT_REACH_DIRECTIONS = 32
"""Directions of the cue's reach polygon shown in the live view."""
TERM_NAMES = footcost.COST_TERMS
"""The chosen foothold's named FootCost terms recorded with each decision (:data:`ijoy_jax.footcost.COST_TERMS`)."""


@dataclasses.dataclass
class DriveResult:
    """What a drive did (host values).

    Attributes:
      decisions: one dict per decision (the ``/ijoy/decision`` record of :mod:`ijoy_jax.recordings`).
      states: one dict per executed step period (``/ijoy/state``), the warm-up first.
      latencies: (n,) s, each decision's latency (command read to decision ready).
      slacks: (n,) s, decision ready to the end of the step it had to be ready by (< 0: late).
      tick_lag_max: s, the largest lag of a tick behind the wall clock, after its sleep (realtime only; 0 when
        not paced).
      wall_s: s, the drive's wall time.
      stopped_by: "duration", "steps" or "stop" (the stop event or Ctrl-C).
      warmup_s: s, the warm-up before the clock started (the first calls' compiles).
    """

    decisions: list
    states: list
    latencies: np.ndarray
    slacks: np.ndarray
    tick_lag_max: float
    wall_s: float
    stopped_by: str
    warmup_s: float = 0.0

    def footsteps(self) -> np.ndarray:
        """(n, 6) float32 the footholds of the steps taken, in order (what a replay must reproduce)."""
        rows = [s["sent"] for s in self.states if s["go"]]
        return np.asarray(rows, np.float32).reshape(-1, 6)

    def summary(self) -> dict:
        return {"steps": len(self.states) - 1, "decisions": len(self.decisions),
                "steps_taken": int(sum(bool(s["go"]) for s in self.states)), **latency_stats(self.latencies),
                "late": int(np.sum(self.slacks < 0)), "min_slack_s": float(np.min(self.slacks)) if len(self.slacks)
                else float("nan"), "tick_lag_max_s": self.tick_lag_max, "wall_s": self.wall_s,
                "warmup_s": self.warmup_s, "stopped_by": self.stopped_by}


def latency_stats(latencies) -> dict:
    """p50, p99 and max of decision latencies (s); NaN when there are none."""
    lat = np.asarray(latencies, np.float64)
    if lat.size == 0:
        return {"latency_p50_s": float("nan"), "latency_p99_s": float("nan"), "latency_max_s": float("nan")}
    return {"latency_p50_s": float(np.percentile(lat, 50)), "latency_p99_s": float(np.percentile(lat, 99)),
            "latency_max_s": float(lat.max())}


class _Outlook:
    """What the operator sees and feels for the next decision (set by the worker, read by the ticks)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.tick = None  # cue.CueTick of the next decision's stance
        self.view: dict = {}  # the latest decision's picture for the live view


def _stance_key(info) -> bytes:
    return b"".join(np.asarray(v, np.float32).tobytes() for v in (info.stance, info.stance_side, info.swing_from))


def _terms(terrain, robot, prepared, info, decision: Decision) -> dict:
    """The chosen foothold's named FootCost terms (+inf where one rejected it); {} when no step was valid."""
    if decision.index < 0:
        return {}
    pose = decision.foothold[[0, 1, 5]]
    t = footcost.foot_cost_terms(terrain, robot, jnp.asarray(info.stance, jnp.float32), int(info.stance_side),
                                 jnp.asarray(pose[None], jnp.float32),
                                 swing_from=jnp.asarray(info.swing_from, jnp.float32),
                                 action_index=jnp.asarray([decision.index], jnp.int32), index=prepared.index)
    return {name: float(np.asarray(getattr(t, name))[0]) for name in TERM_NAMES}


def check_duration(duration, what: str = "duration") -> float:
    """``duration`` (s) as a float, or ValueError naming ``what`` unless it is in ``(0, MAX_DURATION]`` (NaN and
    -1 ran no step and exited 0; 1e30 ran without end)."""
    try:
        value = float(duration)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a number of seconds, got {duration!r}") from None
    if not 0.0 < value <= MAX_DURATION:
        raise ValueError(f"{what} must be in (0, {MAX_DURATION:g}] s, got {duration!r}")
    return value


def check_steps(num_steps, what: str = "num_steps") -> int:
    """``num_steps`` (decisions to make) as an int, or ValueError naming ``what`` unless it is a whole number in
    ``[1, ijoy_jax.limits.MAX_NUM_STEPS]`` (0 compiled everything, drove nothing and exited 0, as a NaN duration
    did; every decision is kept for the result and the recording)."""
    if (isinstance(num_steps, bool) or not isinstance(num_steps, (int, float, np.number))
            or not 1 <= num_steps <= limits.MAX_NUM_STEPS or int(num_steps) != num_steps):
        raise ValueError(f"{what} must be a whole number in [1, ijoy_jax.limits.MAX_NUM_STEPS = "
                         f"{limits.MAX_NUM_STEPS}] (decisions to make), got {num_steps!r}")
    return int(num_steps)


def check_first_decision(duration: float, decide_at: float, body, what: str = "duration") -> None:
    """ValueError naming ``what`` if a drive of ``duration`` s ends before its first decision, made ``decide_at``
    of the way into the first step of ``body`` (its ``ticks_per_step`` of ``control_dt`` s): such a drive
    compiled everything and drove nothing."""
    first = math.floor(decide_at * int(body.ticks_per_step)) * float(body.control_dt)
    if not first < duration - 1e-9:  # the loop's own test for making a decision
        raise ValueError(f"{what} {duration!r} s ends before the first decision, {first:g} s into the drive "
                         f"(decide_at {decide_at:g} of the step): nothing would be driven")


def drive(terrain: Terrain, robot: Robot, body, source, decider, *, deadzone: float = DEFAULT_DEADZONE,
          decide_at: float = 0.0, realtime: bool = True, num_steps: int | None = None,
          duration: float | None = None, recorder=None, on_tick: Callable[[dict], Any] | None = None,
          feedback=None, stop: threading.Event | None = None, reach_directions: int = DEFAULT_REACH_DIRECTIONS,
          prepared: select.Prepared | None = None, view_every: float = 0.05, progress: bool = False) -> DriveResult:
    """Drive ``body`` with the stick ``source`` and the footstep ``decider`` until the end (Algorithm 1 live).

    Args:
      terrain, robot: the ground and the robot model the decisions are made for.
      body: the robot that executes the steps (:class:`ijoy_jax.live.PerfectBody`,
        :class:`ijoy_jax.sim.native.NativeBiped` or :class:`ijoy_jax.sim.mjx_biped.MjxBiped`), standing at its
        start. A body slower than real time sets the pace: its ticks run behind the wall clock (the schedule
        stays ``t0 + k * control_dt``, caught up only as fast as the body can) and the largest lag is
        :attr:`DriveResult.tick_lag_max` (realtime only).
      source: the stick (:mod:`ijoy_jax.live.inputs`): ``axes(t)``; a source with ``command_at(step)``
        (a replay) gives each decision's command directly.
      decider: :class:`~ijoy_jax.live.LocalDecider` or :class:`~ijoy_jax.live.RemoteDecider`.
      deadzone: of :func:`~ijoy_jax.live.axes_to_command`.
      decide_at: in [0, 1): how far into a step the stick is read and the next decision made.
      realtime: pace the ticks to the wall clock (False: as fast as possible, virtual time).
      num_steps: decisions to make, 1 to :data:`ijoy_jax.limits.MAX_NUM_STEPS` (None: until ``duration``, the
        source's ``duration``, or ``stop``).
      duration: s, no decision is made at or after it (default: the source's ``duration`` if it has one).
      recorder: a :class:`~ijoy_jax.live.Recorder`, or None.
      on_tick: called about every ``view_every`` s of drive time with the live state (a dict; the view's
        ``publish``).
      feedback: a force-feedback output (:mod:`ijoy_jax.live.forcefeedback`) given the cue force each tick.
      stop: an event that ends the drive after the step in progress.
      reach_directions: directions of the cue's reach polygon.
      prepared: the terrain's :func:`ijoy_jax.select.prepare` (built here when None).
      progress: while the warm-up compiles (the body's controller, the decision and the cue's programs: about a
        minute for the MuJoCo biped on a CPU), say so on stderr with the seconds elapsed
        (:func:`ijoy_jax.progress.compiling`).

    Returns:
      :class:`DriveResult`.
    """
    if not 0.0 <= decide_at < 1.0:
        raise ValueError(f"decide_at must be in [0, 1) (a fraction of the step), got {decide_at!r}")
    if num_steps is not None:
        check_steps(num_steps)
    given = duration is not None
    duration = getattr(source, "duration", None) if duration is None else float(duration)
    if duration is not None:
        check_duration(duration, "duration" if given else "the source's duration (its last time)")
        check_first_decision(duration, decide_at, body,
                             "duration" if given else "the source duration (its last time)")
    if num_steps is None and duration is None and stop is None:
        raise ValueError("a drive without num_steps, duration or a stop event would never end")
    prepared = select.prepare(terrain, robot) if prepared is None else prepared
    lo, hi = robots.command_range(robot)
    ticks = int(body.ticks_per_step)
    dt = float(body.control_dt)
    dispatch_tick = int(math.floor(decide_at * ticks))
    outlook = _Outlook()
    feasible_cache: dict[bytes, Any] = {}
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="ijoy-decide")
    view_ticks = max(1, int(round(view_every / dt)))
    command_at = getattr(source, "command_at", None)
    stop = threading.Event() if stop is None else stop

    def feasible_of(info):
        key = _stance_key(info)
        f = feasible_cache.get(key)
        if f is None:
            f = cue.feasible_commands(terrain, robot, jnp.asarray(info.stance, jnp.float32), int(info.stance_side),
                                      jnp.asarray(info.swing_from, jnp.float32), index=prepared.index)
            feasible_cache.clear()  # one stance ahead is all the loop needs
            feasible_cache[key] = f
        return f

    def work(j, info, command, submitted):
        decision = decider.decide(info.stance, info.stance_side, command, info.swing_from)
        ready = time.perf_counter()
        latency = ready - submitted
        terms = _terms(terrain, robot, prepared, info, decision)
        candidates = feasible_of(info)  # this decision's candidates: every action's FootCost from its stance
        if decision.valid:
            nxt = type(info)(decision.foothold[[0, 1, 5]].astype(np.float32), np.float32(-info.stance_side),
                             np.asarray(info.stance, np.float32))
        else:
            nxt = info
        upcoming = feasible_of(nxt)  # the next decision's: the cue and the reach the operator gets now
        tick = cue.prepare_tick(upcoming)
        reach = np.asarray(cue.reach(upcoming, reach_directions, turn_rate=float(command[2])))
        steps = np.asarray(robots.action_steps(robot, jnp.asarray(info.stance, jnp.float32), int(info.stance_side)))
        view = {"decision": j, "stance": info.stance, "stance_side": info.stance_side, "candidates": steps[:, :2],
                "candidate_valid": np.asarray(candidates.valid), "candidate_cost": np.asarray(candidates.cost),
                "chosen": decision.index, "foothold": decision.foothold, "valid": decision.valid,
                "latency_s": latency, "next_stance": nxt.stance, "next_side": nxt.stance_side, "reach": reach,
                "reach_turn": float(command[2])}
        with outlook.lock:
            outlook.tick, outlook.view = tick, view
        return decision, latency, ready, terms

    # Warm-up, before the clock starts: one decision and the cue's programs from the start stance (their first
    # calls compile; the server's too), so the latencies measured are the drive's, not the compiler's.
    t_warm = time.perf_counter()
    what = f"the drive's programs ({type(body).__name__}, the decision, the cue)"
    with compiling(what, prefix="ijoy drive: ") if progress else contextlib.nullcontext():
        if hasattr(body, "warm_up"):
            body.warm_up()  # the physics robot's controller programs
        work(0, body.stance(), np.zeros(3), time.perf_counter())
    with outlook.lock:
        outlook.view = {}
        if outlook.tick is not None:
            cue.tick_force(outlook.tick, jnp.zeros(3, jnp.float32))
    if realtime:
        # Python's full collections scan every object, and with JAX, its compiled programs and a MuJoCo model
        # loaded one took 0.14 to 0.35 s on this project's CPU: the longest stall of a real-time drive (the MJX
        # biped's ticks fell 0.3 s behind the wall clock at one). Collect now, before the clock starts, and keep
        # what exists out of the drive's collections (gc.freeze; gc.unfreeze at its end).
        gc.collect()
        gc.freeze()
    warmup_s = time.perf_counter() - t_warm

    decisions, states, latencies, slacks = [], [], [], []
    tick_count, lag_max = 0, 0.0
    wall0 = time.perf_counter()
    stopped_by = "steps"
    pending = None
    decision: Decision | None = None
    history: list[float] = []
    j = 0  # the step period in progress (0: the warm-up)
    try:
        while True:
            if j == 0:
                foothold, go = np.zeros(6, np.float32), False
            else:
                foothold, go = decision.foothold, decision.valid
            body.begin(foothold, go)
            t_start = tick_count * dt
            k = 0
            more_decisions = ((num_steps is None or j < num_steps)
                              and (duration is None or t_start + dispatch_tick * dt < duration - 1e-9)
                              and not stop.is_set())
            dispatched = None
            while True:
                t = tick_count * dt
                axes = np.asarray(source.axes(t), np.float64)
                command = axes_to_command(axes, (lo, hi), deadzone)
                if k == dispatch_tick and more_decisions:
                    if command_at is not None:
                        command = np.asarray(command_at(j), np.float64)
                    info = body.future_stance()
                    submitted = time.perf_counter()
                    pending = pool.submit(work, j + 1, info, command, submitted)
                    dispatched = dict(t=t, axes=axes, command=command, info=info)
                force = np.zeros(3)
                with outlook.lock:
                    tick_prep = outlook.tick
                if tick_prep is not None:
                    force = np.asarray(cue.tick_force(tick_prep, jnp.asarray(command, jnp.float32)), np.float64)
                if feedback is not None:
                    feedback.update(force, command)
                if recorder is not None:
                    recorder.write("/ijoy/input", t, {"t": t, "axes": axes, "command": command,
                                                      "source": getattr(source, "name", type(source).__name__)})
                more = body.tick()
                k += 1
                tick_count += 1
                if realtime:
                    due = wall0 + tick_count * dt
                    ahead = due - time.perf_counter()
                    if ahead > 0:
                        time.sleep(ahead)
                    # measured after the sleep: a thread woken late (a loaded machine) is behind the clock too
                    lag_max = max(lag_max, time.perf_counter() - due)
                if on_tick is not None and (tick_count % view_ticks == 0 or not more):
                    with outlook.lock:
                        view = dict(outlook.view)
                    on_tick({"t": tick_count * dt, "step": j, "axes": axes, "command": command, "cue_force": force,
                             "feet": body.feet(), "progress": k / ticks, "latency_history": history[-60:],
                             "stance_side": float(body.stance().stance_side), **view})
                if not more:
                    break
            log = body.end()
            t_end = tick_count * dt
            state = {"step": j, "t": t_end, "sent": np.asarray(foothold, np.float32), "go": bool(go),
                     "feet": body.feet(), "log": {} if log is None else log._asdict()}
            states.append(state)
            if recorder is not None:
                recorder.write("/ijoy/state", t_end, state)
            if dispatched is None:
                stopped_by = ("stop" if stop.is_set() else "steps" if num_steps is not None and j >= num_steps
                              else "duration")
                break
            decision, latency, ready, terms = pending.result()  # WaitForNextStep: the decision must be here
            # the step's end as the wall clock would see it in real time: dispatch + the drive time left
            slack = (t_end - dispatched["t"]) - latency
            latencies.append(latency)
            slacks.append(slack)
            history.append(latency)
            info = dispatched["info"]
            rec = {"step": j + 1, "t": dispatched["t"], "axes": dispatched["axes"], "command": dispatched["command"],
                   "stance": np.asarray(info.stance, np.float32), "stance_side": float(info.stance_side),
                   "swing_from": np.asarray(info.swing_from, np.float32), "foothold": decision.foothold,
                   "valid": decision.valid, "cost": decision.cost, "index": decision.index, "terms": terms,
                   "latency_s": latency, "deadline_slack_s": slack, "decider": getattr(decider, "name", "")}
            decisions.append(rec)
            if recorder is not None:
                recorder.write("/ijoy/decision", dispatched["t"], rec)
            j += 1
    except KeyboardInterrupt:
        stopped_by = "stop"
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if realtime:
            gc.unfreeze()
    return DriveResult(decisions, states, np.asarray(latencies), np.asarray(slacks), lag_max,
                       time.perf_counter() - wall0, stopped_by, warmup_s)
