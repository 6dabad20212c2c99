"""The Python client of the footstep server, and a helper that runs ``ijoy serve`` as a subprocess.

:class:`Client` speaks the protocol of :mod:`ijoy_jax.server.schema` over a ZeroMQ DEALER socket: each
request carries an id and the client waits for the reply with that id (a late reply to a request that
timed out is discarded), so a timeout never leaves the connection out of step. One client per thread
(ZeroMQ sockets are not thread-safe); many clients may talk to one server at once.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import itertools
import math
import numbers
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import zmq

from ijoy_jax.server import schema
from ijoy_jax.server.schema import DEFAULT_MAP, float_from_json

DEFAULT_TIMEOUT_S = 60.0
"""Seconds a request waits for its reply by default (a map of a new shape compiles for a few seconds)."""
CONNECT_TIMEOUT_S = 5.0
"""Seconds :class:`Client` waits for the TCP connection itself (before its ``hello``): nothing listening there
is said in seconds, while a server that is there but busy compiling still gets the request timeout."""


def _connected(monitor: zmq.Socket, timeout: float) -> bool:
    """Whether the monitored socket reports its connection established within ``timeout`` seconds (ZeroMQ
    connects in the background and retries a refused connection without telling the sender)."""
    from zmq.utils.monitor import recv_monitor_message

    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        if monitor.poll(max(1, int(left * 1000))) and recv_monitor_message(monitor)["event"] == zmq.EVENT_CONNECTED:
            return True
    return False


class ServerError(RuntimeError):
    """An error reply: ``code`` (one of :data:`~ijoy_jax.server.schema.ERROR_CODES`) and the server's message.

    :class:`Client` raises it too, before sending, for a value the server would refuse that the client can
    tell by itself (NaN or infinity, which JSON cannot carry; a field that is not a number; a stance side
    other than +-1; an offset that is not a whole number), with the code the server would answer and a
    message naming the field; ``header`` is then empty. So one ``except ServerError`` handles every
    refused request, wherever it was found.
    """

    def __init__(self, code: str, message: str, header: Mapping | None = None):
        super().__init__(f"{code}: {message}")
        self.code, self.message, self.header = code, message, dict(header or {})


@dataclasses.dataclass(frozen=True)
class StepReply:
    """The server's answer to one step request: :class:`ijoy_jax.StepChoice`'s fields and the chosen step's terms.

    Fields::

      pose: (3,) float32 world pose of the chosen swing foot (m, rad); the step in place when not valid.
      foothold: (6,) float32 the sole's full pose x, y, z (m), roll, pitch, yaw (rad).
      valid: bool, False when no step is valid (the robot should stop).
      cost: float32 FootCost + w dist of the choice (+inf when not valid).
      foot_cost: float32 the FootCost part (+inf when not valid).
      index: int, the chosen action of the robot's action set (-1 when not valid).
      target: (3,) float32 world pose the choice was scored against.
      command_ok, unsupported: bool, as :class:`ijoy_jax.StepChoice`.
      evaluated: int, actions whose FootCost was computed.
      terms: name -> float32 (``action_index``: int), :class:`ijoy_jax.FootCostTerms` of ``pose`` (the
        chosen action; the step in place when not valid): which term refused or cost what.
      map_name: the map decided on; revision: its revision (bumped by every terrain update).
      compute_s: seconds the server spent on the decision; round_trip_s: seconds from send to reply.
    """

    pose: np.ndarray
    foothold: np.ndarray
    valid: bool
    cost: np.float32
    foot_cost: np.float32
    index: int
    target: np.ndarray
    command_ok: bool
    unsupported: bool
    evaluated: int
    terms: dict
    map_name: str
    revision: int
    compute_s: float
    round_trip_s: float

    @classmethod
    def from_header(cls, h: Mapping, round_trip_s: float) -> StepReply:
        """Read a step reply's header."""
        vec = lambda v: np.asarray([float_from_json(x) for x in v], np.float32)  # noqa: E731
        f32 = lambda v: np.float32(float_from_json(v))  # noqa: E731
        return cls(pose=vec(h["pose"]), foothold=vec(h["foothold"]), valid=bool(h["valid"]), cost=f32(h["cost"]),
                   foot_cost=f32(h["foot_cost"]), index=int(h["index"]), target=vec(h["target"]),
                   command_ok=bool(h["command_ok"]), unsupported=bool(h["unsupported"]),
                   evaluated=int(h["evaluated"]),
                   terms={k: v if isinstance(v, int) else f32(v) for k, v in h["terms"].items()},
                   map_name=h["map"], revision=int(h["revision"]), compute_s=float(h["compute_us"]) * 1e-6,
                   round_trip_s=round_trip_s)


class Client:
    """A connection to a footstep server (``ijoy serve``).

    Args:
      host, port: where the server listens.
      timeout: seconds each request waits for its reply (:data:`DEFAULT_TIMEOUT_S`); then TimeoutError.
      hello: negotiate the protocol version at once (a ``hello`` request), so that a wrong address or an
        incompatible server fails here, not at the first step.
      context: a ``zmq.Context`` to share (default: the process's shared instance).

    Raises:
      ConnectionError: with ``hello``, nothing accepts a TCP connection at ``host:port`` within
        :data:`CONNECT_TIMEOUT_S` (no server there).
      TimeoutError: no reply (a server that is busy compiling for longer than ``timeout``).
      ServerError: an error reply, e.g. ``unsupported_version``; every request method raises it, with the
        code the server would answer, for a field the server would refuse (NaN in ``stance``: ``non_finite``).

    Example (against a server started by :func:`serve_subprocess`)::

      with serve_subprocess() as server, Client(server.host, server.port) as client:
          client.set_terrain(terrain)
          reply = client.step([1.0, 1.1, 0.0], -1, [0.25, 0.0, 0.0])
          reply.foothold, reply.valid, reply.cost, reply.index, reply.terms["obstacle"]
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 5555, *, timeout: float = DEFAULT_TIMEOUT_S,
                 hello: bool = True, context: zmq.Context | None = None):
        self.host, self.port, self.timeout = host, int(port), float(timeout)
        self.version = schema.PROTOCOL_VERSION
        self._ids = itertools.count(1)
        self._socket = (context or zmq.Context.instance()).socket(zmq.DEALER)
        self._socket.setsockopt(zmq.LINGER, 0)
        where = f"[{host}]" if ":" in host else host
        if ":" in host:
            self._socket.setsockopt(zmq.IPV6, 1)
        monitor = self._socket.get_monitor_socket(zmq.EVENT_CONNECTED) if hello else None
        self._socket.connect(f"tcp://{where}:{self.port}")
        self.server_hello: dict = {}
        if hello:
            try:
                up = _connected(monitor, min(CONNECT_TIMEOUT_S, self.timeout))
            finally:
                self._socket.disable_monitor()
                monitor.close(linger=0)
            if not up:
                self.close()
                raise ConnectionError(f"no footstep server at {host}:{self.port}: nothing accepted a connection "
                                      f"within {min(CONNECT_TIMEOUT_S, self.timeout):g} s (start one with "
                                      f"`ijoy serve --port {self.port}`)")
            try:
                self.server_hello = self.request({"type": "hello", "versions": list(schema.SUPPORTED_VERSIONS),
                                                  "client": f"ijoy_jax.server.Client (pid {os.getpid()})"}).header
            except BaseException:
                self.close()
                raise
            self.version = self.server_hello["version"]

    # ------------------------------------------------------------------------------------------------ plumbing

    def request(self, header: Mapping[str, Any], arrays: Mapping[str, np.ndarray] | None = None, *,
                timeout: float | None = None) -> schema.Reply:
        """Send one request (``version`` and ``id`` are filled in) and return its reply.

        Raises:
          ServerError: an error reply, or ``non_finite`` before sending when a float in ``header`` is NaN or
          infinite (JSON cannot carry it; the message names the field). TimeoutError: no reply within
          ``timeout`` seconds (default the client's).
        """
        rid = next(self._ids)
        msg = {"version": self.version, **header, "id": rid}
        try:
            frames = schema.encode(msg, arrays)
        except ValueError:  # the JSON encoder refuses NaN and infinity: say which field, as the server would
            where = _first_non_finite(msg)
            if where is None:
                raise
            raise _non_finite(*where) from None
        self._socket.send_multipart(frames, copy=False)
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not self._socket.poll(max(1, int(left * 1000))):
                raise TimeoutError(f"no reply from the footstep server at {self.host}:{self.port} within "
                                   f"{self.timeout if timeout is None else timeout:g} s ({header.get('type')} "
                                   "request)")
            frames = self._socket.recv_multipart(copy=False)
            if frames and len(frames[0]) == 0:  # tolerate a delimiter (a server that treats us as REQ)
                frames = frames[1:]
            reply = schema.decode_reply(frames)
            if reply.header.get("id") != rid:
                continue  # the late reply of a request that timed out
            if not reply.header.get("ok", False):
                raise ServerError(reply.header.get("code", "internal"), reply.header.get("message", ""), reply.header)
            return reply

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if not self._socket.closed:
            self._socket.close(linger=0)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --------------------------------------------------------------------------------------------- requests

    def info(self) -> dict:
        """The server's description: protocol, robot (options, leaves, units), limits, maps, term names and
        statistics; ``"actions"`` (N, 3) and ``"p0"`` (3,) float32 hold the robot's action set (left swing
        foot, stance frame) and step in place."""
        reply = self.request({"type": "info"})
        return {**reply.header, **{k: np.array(v) for k, v in reply.arrays.items()}}

    def set_terrain(self, terrain, *, map_name: str = DEFAULT_MAP) -> dict:
        """Send a whole :class:`ijoy_jax.Terrain` (2D or 2.5D) as map ``map_name`` (replacing one of that name).

        Returns:
          The reply header: ``revision`` (1 for a new map, then +1 per change), ``shape``, ``has_height``,
          ``compute_us`` (the server's index build).
        """
        t = terrain.to_numpy()
        arrays = {"free": np.asarray(t["free"], bool)}
        if t["has_height"]:
            arrays["height"] = np.asarray(t["height"], np.float32)
        header = {"type": "set_terrain", "map": map_name, "resolution": _number("resolution", t["resolution"]),
                  "origin": _floats("origin", t["origin"])}
        return self.request(header, arrays).header

    def update_terrain(self, offset: Sequence[int], *, free=None, height=None, map_name: str = DEFAULT_MAP) -> dict:
        """Overwrite a window of a held map: ``free`` ((wx, wy) bool) and/or ``height`` ((wx, wy) float32, m)
        at cells ``[offset[0]:offset[0] + wx, offset[1]:offset[1] + wy]``.

        Returns:
          The reply header (``revision``, ``rebuilt_columns``: the index columns the server rebuilt).

        Raises:
          ServerError: the server's refusal, or before sending an offset that is not a whole number
          (``invalid_field``; 2.0 is taken, 2.5 is not truncated) or is not finite (``non_finite``).
        """
        arrays = {}
        if free is not None:
            arrays["free"] = np.asarray(free, bool)
        if height is not None:
            arrays["height"] = np.asarray(height, np.float32)
        header = {"type": "update_terrain", "map": map_name, "offset": _ints("offset", offset)}
        return self.request(header, arrays).header

    def drop_terrain(self, map_name: str = DEFAULT_MAP) -> dict:
        """Forget a map."""
        return self.request({"type": "drop_terrain", "map": map_name}).header

    def step(self, stance, stance_side, command, swing_from=None, *, map_name: str = DEFAULT_MAP) -> StepReply:
        """One decision: ``ij.select_step(terrain, robot, stance, stance_side, command, swing_from=swing_from)``
        on the server's map and robot, bit for bit.

        Args:
          stance: (3,) world pose of the stance foot (m, rad).
          stance_side: +1 (left foot stands) or -1 (right foot stands).
          command: (3,) joystick command (m/s, m/s, rad/s) in the stance foot's frame.
          swing_from: (3,) current world pose of the swing foot (2.5D swing-path check), or None.

        Returns:
          :class:`StepReply`.

        Raises:
          ServerError: the server's error reply, or before sending the code the server would answer: a pose
          or command holding NaN or infinity (``non_finite``), something that is not a number or a side other
          than +-1 (``invalid_field``); the message names the field, e.g. ``stance[0]``.
        """
        header = {"type": "step", "map": map_name, "stance": _floats("stance", stance),
                  "stance_side": _side(stance_side), "command": _floats("command", command),
                  "swing_from": None if swing_from is None else _floats("swing_from", swing_from)}
        t0 = time.perf_counter()
        reply = self.request(header)
        return StepReply.from_header(reply.header, time.perf_counter() - t0)

    def set_robot(self, leaves: Mapping[str, float] | None = None, **more: float) -> dict:
        """Change the robot's traced scalar leaves (``ijoy_jax.robots.SCALAR_LEAVES``: ``w``, ``margin``,
        ``"metrics.bump_limit"``, ...) for every later step; the server does not recompile.

        Returns:
          Every scalar leaf's value after the change.

        Raises:
          ServerError: the server's refusal (``invalid_field`` for an unknown leaf, ``invalid_value`` for one out
          of range), or before sending a value that is not a number (``invalid_field``) or is NaN or infinite
          (``non_finite``), naming the leaf.
        """
        values = {**(leaves or {}), **more}
        for k in values:
            if not isinstance(k, str):
                raise ServerError("invalid_field", f"leaves: a leaf's name must be a string, got {_shown(k)}")
        return self.request(
            {"type": "set_robot", "leaves": {k: _number(f"leaves[{k!r}]", v) for k, v in values.items()}}
        ).header["leaves"]


# ------------------------------------------------------------------------------- fields checked before sending


def _shown(x) -> str:
    """A value as a one-line message shows it (a 400-digit integer is cut)."""
    text = " ".join(repr(x).split())
    return text if len(text) <= 40 else f"{text[:37]}..."


def _non_finite(field: str, value, why: str = "is not finite") -> ServerError:
    """The server's ``non_finite`` refusal of ``field``, found before sending (JSON cannot carry the value)."""
    return ServerError(
        "non_finite",
        f"{field} = {_shown(value)} {why}: every number sent must be finite (the server refuses NaN and infinity)",
    )


def _number(field: str, x) -> float:
    """One value (a Python or NumPy scalar, or a 0-d array such as a JAX scalar) as a float64 JSON number, or
    the ServerError the server would answer for it: ``invalid_field`` when it is not a real number (a string,
    None, a bool), ``non_finite`` when NaN, infinite or beyond float64."""
    if hasattr(x, "__array__") and np.ndim(x) == 0:
        x = np.asarray(x).item()
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        if (found := _first_non_finite(x, field)) is not None:  # NaN inside a list: refused first, as the
            raise _non_finite(*found)  # server's JSON parser refuses it before any field is read
        raise ServerError("invalid_field", f"{field} = {_shown(x)} is not a number")
    try:
        v = float(x)
    except OverflowError:  # a Python int beyond float64
        raise _non_finite(field, x, "is beyond float64") from None
    if not math.isfinite(v):
        raise _non_finite(field, x)
    return v


def _floats(field: str, v) -> list[float]:
    """A pose or command (any shape, read flat) as JSON numbers, each checked by :func:`_number` and named by
    its index (``stance[0]``): float32 inputs pass exactly (via float64), others as float64."""
    try:
        items = np.asarray(v).ravel().tolist()
    except (TypeError, ValueError):  # a ragged nesting
        items = None
    if items is None or any(isinstance(x, (list, tuple)) for x in items):
        if (found := _first_non_finite(v, field)) is not None:
            raise _non_finite(*found) from None
        raise ServerError("invalid_field", f"{field} = {_shown(v)} is not a flat list of numbers")
    return _each(field, items, _number)


def _ints(field: str, v) -> list[int]:
    """Cell indices as JSON integers: a float is taken when it is whole (2.0), refused when it is not (2.5:
    ``invalid_field``, not truncated) or not finite (``non_finite``)."""

    def whole(name: str, x) -> int:
        if isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_)):
            return int(x)
        f = _number(name, x)
        if not f.is_integer():
            raise ServerError("invalid_field", f"{name} = {_shown(x)} is not a whole number of cells")
        return int(f)

    return _each(field, np.asarray(v, dtype=object).ravel().tolist(), whole)


def _each(field: str, items: list, convert) -> list:
    """``convert(f"{field}[i]", item)`` for each item; of several refusals, a ``non_finite`` one is raised
    first, as the server's JSON parser refuses NaN before any field is read."""
    out, refused = [], []
    for i, x in enumerate(items):
        try:
            out.append(convert(f"{field}[{i}]", x))
        except ServerError as e:
            refused.append(e)
    if refused:
        raise next((e for e in refused if e.code == "non_finite"), refused[0])
    return out


def _side(side) -> int:
    """The stance side as the JSON integer +1 or -1 (``invalid_field`` otherwise, as the server answers)."""
    s = _number("stance_side", side)
    if s not in (1.0, -1.0):
        raise ServerError("invalid_field", f"stance_side must be +1 (left foot stands) or -1, got {_shown(side)}")
    return int(s)


def _first_non_finite(value, path: str = "") -> tuple[str, float] | None:
    """The first NaN or infinite float in a JSON-like header (dicts, lists, numbers) and where it is
    (``stance[0]``, ``leaves['w']``), or None."""
    if isinstance(value, float):
        return None if math.isfinite(value) else (path or "the header", value)
    if isinstance(value, Mapping):
        items = ((f"{path}[{k!r}]" if path else str(k), v) for k, v in value.items())
    elif isinstance(value, (list, tuple)):
        items = ((f"{path}[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    for where, v in items:
        found = _first_non_finite(v, where)
        if found is not None:
            return found
    return None


# ---------------------------------------------------------------------------------------------- a subprocess


_LISTENING = re.compile(r"^listening on (\S+):(\d+)$")


@dataclasses.dataclass
class ServerProcess:
    """A running ``ijoy serve`` subprocess (from :func:`serve_subprocess`)."""

    process: subprocess.Popen
    host: str
    port: int
    output: collections.deque  # the last lines of its stdout and stderr

    def client(self, **kwargs) -> Client:
        """A :class:`Client` connected to this server."""
        return Client(self.host, self.port, **kwargs)

    def stop(self, timeout: float = 20.0) -> int:
        """SIGTERM, then wait (SIGKILL after ``timeout`` s); the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode


@contextlib.contextmanager
def serve_subprocess(
    *args: str, host: str = "127.0.0.1", port: int = 0, timeout: float = 300.0, env: Mapping[str, str] | None = None
) -> Iterator[ServerProcess]:
    """Run ``ijoy serve --host HOST --port PORT ARGS...`` in a subprocess until the block ends.

    Waits for its ``listening on HOST:PORT`` line (after its warm-up compile), so the server answers as
    soon as the block starts; port 0 (default) takes a free port, read from that line. On exit the server
    gets SIGTERM and is waited for.

    Args:
      *args: more ``ijoy serve`` options, e.g. ``"--margin", "0.05"`` or ``"--warm-up", "none"``.
      host, port: where to listen.
      timeout: seconds to wait for the listening line.
      env: the subprocess's environment (default this process's).

    Yields:
      :class:`ServerProcess` (``.host``, ``.port``, ``.client()``, ``.output``).

    Raises:
      RuntimeError: the server exited or did not listen within ``timeout`` (with its last output lines).
    """
    cmd = [sys.executable, "-m", "ijoy_jax.apps.cli", "serve", "--host", host, "--port", str(port), *args]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=None if env is None else dict(env)
    )
    output: collections.deque = collections.deque(maxlen=200)
    found = threading.Event()
    where: dict = {}

    def read(stream, is_stdout):
        for line in stream:
            line = line.rstrip("\n")
            output.append(line)
            m = _LISTENING.match(line) if is_stdout else None
            if m and not found.is_set():
                where["host"], where["port"] = m.group(1).strip("[]"), int(m.group(2))
                found.set()

    readers = [
        threading.Thread(target=read, args=(s, s is proc.stdout), daemon=True) for s in (proc.stdout, proc.stderr)
    ]
    for r in readers:
        r.start()
    server = ServerProcess(proc, host, port, output)
    try:
        deadline = time.monotonic() + timeout
        while not found.wait(0.05):
            if proc.poll() is not None or time.monotonic() > deadline:
                for r in readers:
                    r.join(1.0)
                why = (
                    f"exited with code {proc.returncode}"
                    if proc.poll() is not None
                    else f"did not listen within {timeout:g} s"
                )
                raise RuntimeError(f"ijoy serve {why}:\n" + "\n".join(output))
        server.host, server.port = where["host"], where["port"]
        yield server
    finally:
        server.stop()
        for r in readers:
            r.join(2.0)
