"""The footstep server (the paper's Fig. 6): FootCost and step selection as a process a robot stack calls.

``ijoy serve --host H --port P`` runs it (:mod:`ijoy_jax.apps.cli`); a robot's joystick control, vision and
walking control talk to it over ZeroMQ with a versioned message schema (:mod:`~ijoy_jax.server.schema`, the
JSON Schema file ``protocol.schema.json`` beside it, and ``docs/server.md`` for implementers in C++ or ROS):
terrain maps (whole, or a window of one), step requests answered with the chosen step's full foothold,
validity, cost and named cost terms, equal bit for bit to :func:`ijoy_jax.select_step` on the same inputs.

Public API:
  Client, StepReply, ServerError       the Python client
  serve_subprocess, ServerProcess      run ``ijoy serve`` as a subprocess (scripts, tests, notebooks)
  Service                              the server's state and handlers, frames in, frames out (no network)
  schema                               the wire format: encode/decode, Limits, error codes, the JSON Schema
  server                               the network loop (listen, run)
"""

# ruff: noqa: E402  (the package's imports follow the check of its extra)
from ijoy_jax.extras import require as _require

_require("server", "zmq", "jsonschema")

from ijoy_jax.server import schema as schema
from ijoy_jax.server import server as server
from ijoy_jax.server import service as service
from ijoy_jax.server.client import Client as Client
from ijoy_jax.server.client import ServerError as ServerError
from ijoy_jax.server.client import ServerProcess as ServerProcess
from ijoy_jax.server.client import StepReply as StepReply
from ijoy_jax.server.client import serve_subprocess as serve_subprocess
from ijoy_jax.server.schema import ERROR_CODES as ERROR_CODES
from ijoy_jax.server.schema import PROTOCOL_VERSION as PROTOCOL_VERSION
from ijoy_jax.server.schema import Limits as Limits
from ijoy_jax.server.schema import ProtocolError as ProtocolError
from ijoy_jax.server.service import TERM_NAMES as TERM_NAMES
from ijoy_jax.server.service import Service as Service

__all__ = [
    "ERROR_CODES",
    "PROTOCOL_VERSION",
    "TERM_NAMES",
    "Client",
    "Limits",
    "ProtocolError",
    "ServerError",
    "ServerProcess",
    "Service",
    "StepReply",
    "schema",
    "serve_subprocess",
    "server",
    "service",
]
