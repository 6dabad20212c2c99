"""The footstep server process's network loop: a ZeroMQ ROUTER socket in front of a :class:`Service`.

One thread owns the socket and the service: it polls, reads a whole request (ZeroMQ delivers a multipart
message whole or not at all, assembled by its I/O thread, so a client that sends slowly holds up no one),
answers it with :meth:`Service.handle` and sends the reply without blocking (a reply to a client that has
gone, or that does not read and has ``SNDHWM`` replies queued, is dropped: ZeroMQ's ROUTER never blocks on
one peer). Decisions are therefore serialised: one at a time, in arrival order across clients.

Map shapes: a request runs programs compiled for its map's kind (shape in cells, resolution, 2D or 2.5D).
The first request on a new kind compiles them (a second or more) and, decisions being serialised, every
other client's replies wait behind that compile; the service keeps the programs of its ``max_programs``
most recently used kinds (``ijoy serve --max-programs``) and drops the least recently used, so a client
that sends a new shape for every map makes everyone wait on compiles but does not grow the server's memory
without end. Use a few fixed map shapes per deployment and compile them before serving (``ijoy serve
--warm-up``). Compiles are not moved off this loop: a request that needs one would have to be parked while
later requests, also that client's own, are answered in its place, and ``set_terrain`` and ``set_robot``
from others would change what it decides on; the loop would lose its one guarantee (replies in arrival
order, each equal to ``select_step`` on the state it arrived to) for a case warm-up avoids.

Clients may use DEALER sockets (the Python :class:`~ijoy_jax.server.Client` does) or REQ sockets: a
request that begins with an empty delimiter frame (REQ's envelope) gets its reply with the delimiter.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import socket
import threading
import time

import zmq
from zmq.utils.monitor import recv_monitor_message

from ijoy_jax.server.service import Service

log = logging.getLogger("ijoy_jax.server")

POLL_MS = 200
"""How often (ms) the loop wakes to check for a stop request when idle."""

SNDHWM = 64
"""Replies queued per client before further replies to it are dropped (a client that does not read)."""


class ListenError(OSError):
    """The server cannot listen where asked (a bad host, a port in use); the message says which and why."""


@dataclasses.dataclass
class Listener:
    """A bound ROUTER socket: ``host`` and ``port`` are where it listens (``port`` resolved when 0 was asked);
    ``monitor`` receives its connection events from before it was bound, so :func:`run` logs every connection,
    also one accepted while the server was still warming up."""

    context: zmq.Context
    socket: zmq.Socket
    host: str
    port: int
    monitor: zmq.Socket | None = None

    @property
    def address(self) -> str:
        """``host:port`` (``[host]:port`` for IPv6)."""
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"

    def close(self) -> None:
        """Close the socket and its context at once (pending replies are dropped)."""
        if self.monitor is not None:
            self.socket.disable_monitor()
            self.monitor.close(linger=0)
            self.monitor = None
        self.socket.close(linger=0)
        self.context.term()


def listen(host: str, port: int, *, max_frame_bytes: int) -> Listener:
    """Bind a ROUTER socket on ``host:port`` (``port`` 0: a free port) with ZeroMQ's frame limit.

    Raises:
      ListenError: the host does not resolve to an address of this machine, or the port is taken or
        not allowed, in one line.
    """
    if not 0 <= port <= 65535:
        raise ListenError(f"port must be in 0..65535, got {port}")
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as e:
        raise ListenError(f"cannot listen on {host!r}: the host does not resolve ({e})") from None
    infos.sort(key=lambda i: i[0] != socket.AF_INET)  # IPv4 first where a name has both
    family, ip = infos[0][0], infos[0][4][0]
    ctx = zmq.Context()
    sock = ctx.socket(zmq.ROUTER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.MAXMSGSIZE, max_frame_bytes)
    sock.setsockopt(zmq.SNDHWM, SNDHWM)
    sock.setsockopt(zmq.SNDTIMEO, 0)
    if family == socket.AF_INET6:
        sock.setsockopt(zmq.IPV6, 1)
    # Watched before it is bound: a client may connect the moment the port is open (ijoy serve warms up, then
    # prints its listening line; a monitor attached later would never hear of a connection accepted before).
    listener = Listener(ctx, sock, ip, port, sock.get_monitor_socket(zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED))
    where = f"[{ip}]" if family == socket.AF_INET6 else ip
    try:
        if port == 0:
            listener.port = sock.bind_to_random_port(f"tcp://{where}", min_port=49152, max_port=65536,
                                                     max_tries=200)
        else:
            sock.bind(f"tcp://{where}:{port}")
    except zmq.ZMQError as e:
        listener.close()
        raise ListenError(f"cannot listen on {host}:{port} ({ip}): {os.strerror(e.errno)}") from None
    return listener


def _peer(fd: int) -> str:
    """The remote address of a connection's file descriptor (best effort: it may already be closed)."""
    try:
        s = socket.socket(fileno=fd)
    except OSError:
        return f"fd {fd}"
    try:
        addr = s.getpeername()
        return f"{addr[0]}:{addr[1]}" if s.family == socket.AF_INET else f"[{addr[0]}]:{addr[1]}"
    except OSError:
        return f"fd {fd}"
    finally:
        s.detach()  # the fd is ZeroMQ's: do not close it


def run(listener: Listener, service: Service, stop: threading.Event, *, verbose: bool = False) -> dict:
    """Serve requests until ``stop`` is set (checked every :data:`POLL_MS` ms and between requests).

    Logs one line per accepted connection (``logging`` at INFO, logger ``ijoy_jax.server``); with
    ``verbose`` also each request (type, code, milliseconds) and each disconnection.

    Returns:
      ``{"requests", "dropped_replies", "connections"}`` counted by this loop.
    """
    sock = listener.socket
    if listener.monitor is None:  # a Listener made by hand: from now on
        listener.monitor = sock.get_monitor_socket(zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED)
    monitor = listener.monitor
    poller = zmq.Poller()
    poller.register(sock, zmq.POLLIN)
    poller.register(monitor, zmq.POLLIN)
    counts = {"requests": 0, "dropped_replies": 0, "connections": 0}
    try:
        while not stop.is_set():
            try:
                ready = dict(poller.poll(POLL_MS))
            except zmq.ZMQError as e:
                if e.errno == zmq.EINTR:  # a signal: its handler set stop (or not); look again
                    continue
                raise
            if monitor in ready:
                _on_monitor(monitor, counts, verbose)
            if sock in ready:
                _serve_pending(sock, monitor, service, stop, counts, verbose)
        _on_monitor(monitor, counts, verbose)  # connections not logged yet
    finally:
        poller.unregister(monitor)
    return counts


def _on_monitor(monitor, counts: dict, verbose: bool) -> None:
    while monitor.poll(0):
        event = recv_monitor_message(monitor)
        if event["event"] == zmq.EVENT_ACCEPTED:
            counts["connections"] += 1
            log.info("connection from %s", _peer(event["value"]))
        elif verbose:
            log.info("connection closed (fd %s)", event["value"])


def _serve_pending(sock, monitor, service: Service, stop: threading.Event, counts: dict, verbose: bool) -> None:
    """Answer every request waiting on the socket (up to 256 before polling again), logging new connections
    first (while their address can still be read)."""
    for _ in range(256):
        if stop.is_set():
            return
        _on_monitor(monitor, counts, verbose)
        try:
            frames = sock.recv_multipart(flags=zmq.NOBLOCK, copy=False)
        except zmq.Again:
            return
        envelope, body = frames[:1], frames[1:]
        if body and len(body[0]) == 0:  # a REQ client's empty delimiter frame
            envelope, body = frames[:2], frames[2:]
        t0 = time.perf_counter()
        reply = service.handle(body)
        counts["requests"] += 1
        if verbose:
            log.info("request: %s (%.2f ms)", reply[0][:120].decode("utf-8", "replace"),
                     (time.perf_counter() - t0) * 1e3)
        try:
            sock.send_multipart([*envelope, *reply], flags=zmq.NOBLOCK, copy=False)
        except zmq.Again:  # the client does not read (its queue is full): drop this reply, serve the others
            counts["dropped_replies"] += 1
        except zmq.ZMQError as e:  # e.g. EHOSTUNREACH with ROUTER_MANDATORY: the client has gone
            counts["dropped_replies"] += 1
            if verbose:
                log.info("reply dropped: %s", e.strerror)
