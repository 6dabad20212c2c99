"""The footstep server's wire format, version 1: one ZeroMQ multipart message per request and per reply.

Frame 0 is a UTF-8 JSON header (an object); frames 1..k hold the raw bytes of the arrays that the header's
``arrays`` list describes, in that order (``{"name", "dtype", "shape"}``: C order, NumPy array-interface
``dtype`` strings ``|b1``, ``|u1``, ``<f4``, ``<f8``: little-endian). Small vectors (poses, commands) travel
as JSON numbers, maps as binary frames. Replies carry float32 results as JSON numbers that round-trip
exactly, and non-finite ones as the strings ``"Infinity"``, ``"-Infinity"``, ``"NaN"`` (proto3's JSON
mapping). The JSON Schema of every header ships beside this module (``protocol.schema.json``,
:func:`json_schema`); the protocol for implementers in other languages is ``docs/server.md``.

:func:`decode_request` is the server's whole input boundary: bytes in, a checked :class:`Request` or a
:class:`ProtocolError` with a code of :data:`ERROR_CODES` out, never another exception.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import Any, NamedTuple

import numpy as np

from ijoy_jax import limits

PROTOCOL_VERSION = 1
"""The protocol version this package speaks by default (the newest)."""

SUPPORTED_VERSIONS = (1,)
"""Every protocol version this package speaks."""

REQUEST_TYPES = ("hello", "info", "set_terrain", "update_terrain", "drop_terrain", "step", "set_robot")
"""The request types of version 1."""

DEFAULT_MAP = "default"
"""The map a request names when it names none."""

ARRAY_FIELDS: Mapping[str, Mapping[str, tuple[str, ...]]] = {
    "set_terrain": {"free": ("|b1", "|u1"), "height": ("<f4", "<f8")},
    "update_terrain": {"free": ("|b1", "|u1"), "height": ("<f4", "<f8")},
}
"""The arrays each request type may carry: name -> accepted dtypes (array-interface typestr); each is 2D (nx, ny)."""

_REPLY_DTYPES = ("|b1", "|u1", "<i4", "<f4", "<f8")  # what a reply's frames may hold (the info reply's actions)


@functools.cache
def json_schema() -> dict:
    """The protocol's JSON Schema (draft 2020-12) as a dict: ``$defs`` holds every request and reply header.

    The file is ``ijoy_jax/server/protocol.schema.json`` in the installed package.
    """
    text = resources.files(__package__).joinpath("protocol.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


ERROR_CODES: Mapping[str, str] = json_schema()["x-error-codes"]
"""Every error code of an error reply, and what it means (the schema's ``x-error-codes``)."""


class ProtocolError(Exception):
    """A request the server refuses: ``code`` (one of :data:`ERROR_CODES`) and a message naming what is wrong."""

    def __init__(self, code: str, message: str, **extra: Any):
        if code not in ERROR_CODES:
            raise ValueError(f"unknown error code {code!r}")
        super().__init__(f"{code}: {message}")
        self.code, self.message, self.extra = code, message, extra


@dataclasses.dataclass(frozen=True)
class Limits:
    """The server's input limits (reported in the ``info`` reply).

    Fields::

      max_cells: largest map, nx * ny cells (default 2**20: 20 m x 20 m at 2 cm).
      max_side: largest nx or ny.
      max_maps: maps held at once.
      max_header_bytes: largest JSON header (bytes).
      max_window_cells: largest footprint or swing-path window, in cells, that a map's resolution may
        give the robot (:func:`ijoy_jax.footcost.window_cells`): a finer map makes every FootCost
        evaluation and the index grow with its square (HRP-2: its swing window is 47 cells at 2 cm;
        resolutions finer than about 3.5 mm are refused by the default).

    ``max_cells`` and ``max_window_cells`` may be set lower than the library's bounds
    (:data:`ijoy_jax.limits.MAX_MAP_CELLS`, :data:`ijoy_jax.limits.MAX_WINDOW_CELLS`), never higher.

    ``max_frame_bytes`` (ZeroMQ's per-frame limit; a larger frame makes ZeroMQ drop the connection without a
    reply) is twice a float64 map of ``max_cells`` plus a header, so a map up to twice too large still gets a
    ``too_large`` reply.
    """

    max_cells: int = 1 << 20
    max_side: int = 8192
    max_maps: int = 4
    max_header_bytes: int = 1 << 16
    max_window_cells: int = 256

    def __post_init__(self):
        for name in ("max_cells", "max_side", "max_maps", "max_header_bytes", "max_window_cells"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"Limits.{name} must be a positive integer, got {v!r}")
        for name, bound in (("max_cells", "MAX_MAP_CELLS"), ("max_window_cells", "MAX_WINDOW_CELLS")):
            if getattr(self, name) > getattr(limits, bound):
                raise ValueError(f"Limits.{name} must be <= ijoy_jax.limits.{bound} = {getattr(limits, bound)} (the "
                                 f"library's memory budget), got {getattr(self, name)!r}")

    def holds(self, shape) -> bool:
        """Whether a map of ``shape`` (nx, ny) cells is within ``max_side`` and ``max_cells``."""
        return max(shape) <= self.max_side and shape[0] * shape[1] <= self.max_cells

    def shape_refusal(self, shape) -> str:
        """Why a map of ``shape`` cells is refused (for a message)."""
        return (f"shape {list(shape)} ({shape[0] * shape[1]} cells) is above the server's limits (max_cells = "
                f"{self.max_cells}, max_side = {self.max_side})")

    @property
    def max_frame_bytes(self) -> int:
        """Largest frame ZeroMQ accepts (bytes)."""
        return 16 * self.max_cells + self.max_header_bytes

    def to_json(self) -> dict:
        """The limits as the ``info`` reply reports them."""
        return {**dataclasses.asdict(self), "max_frame_bytes": self.max_frame_bytes}


class Request(NamedTuple):
    """A decoded, checked request: its JSON ``header`` and its ``arrays`` by name (read-only NumPy views)."""

    header: dict
    arrays: dict[str, np.ndarray]

    @property
    def type(self) -> str:
        """The request's type."""
        return self.header["type"]


class Reply(NamedTuple):
    """A decoded reply: its JSON ``header`` (floats as Python floats, non-finite ones decoded) and ``arrays``."""

    header: dict
    arrays: dict[str, np.ndarray]


# ---------------------------------------------------------------------------------------------------- encoding


def json_float(x) -> float | str:
    """A float32/float64 value as a reply carries it: a JSON number, or "Infinity", "-Infinity", "NaN"."""
    x = float(x)
    if math.isfinite(x):
        return x
    return "NaN" if math.isnan(x) else ("Infinity" if x > 0 else "-Infinity")


def float_from_json(v) -> float:
    """Inverse of :func:`json_float`."""
    if isinstance(v, str):
        return {"Infinity": math.inf, "-Infinity": -math.inf, "NaN": math.nan}[v]
    return float(v)


def encode(header: Mapping[str, Any], arrays: Mapping[str, np.ndarray] | None = None) -> list[bytes]:
    """The frames of one message: the JSON header (with its ``arrays`` list) and each array's bytes.

    Arrays are sent little-endian and C-contiguous; booleans as ``|b1``. Floats in ``header`` must be
    finite (use :func:`json_float` for results that may not be).
    """
    header = dict(header)
    frames = []
    specs = []
    for name, a in (arrays or {}).items():
        a = np.asarray(a)
        if a.dtype.byteorder == ">" or (a.dtype.byteorder == "=" and np.little_endian is False):
            a = a.astype(a.dtype.newbyteorder("<"))
        a = np.ascontiguousarray(a)
        specs.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape)})
        frames.append(a.tobytes())
    if specs:
        header["arrays"] = specs
    text = json.dumps(header, allow_nan=False, separators=(",", ":"))
    return [text.encode("utf-8"), *frames]


# ---------------------------------------------------------------------------------------------------- decoding


def _no_constant(name: str):
    raise ProtocolError("non_finite", f"the header holds {name}, which is not a JSON number (values must be finite)")


def _finite_float(text: str) -> float:
    v = float(text)
    if not math.isfinite(v):
        raise ProtocolError("non_finite", f"the header holds the number {text[:40]}, beyond float64 (values must be "
                                          "finite)")
    return v


def _float64_int(text: str) -> int:
    """A JSON integer, refused (``non_finite``) beyond float64's range: every number field is read as a float
    somewhere (a 400-digit integer in ``stance`` raised OverflowError there, answered ``internal``)."""
    v = int(text)
    if abs(v) > sys.float_info.max:
        raise ProtocolError("non_finite", f"the header holds the integer {text[:40]}... ({len(text)} digits), "
                                          "beyond float64 (values must be finite)")
    return v


def _parse_header(frame, limits: Limits) -> dict:
    raw = bytes(frame)
    if len(raw) > limits.max_header_bytes:
        raise ProtocolError("malformed", f"header of {len(raw)} bytes is above max_header_bytes = "
                                         f"{limits.max_header_bytes}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ProtocolError("malformed", f"header is not UTF-8 ({e.reason} at byte {e.start})") from None
    try:
        header = json.loads(text, parse_constant=_no_constant, parse_float=_finite_float, parse_int=_float64_int)
    except ProtocolError:
        raise
    except RecursionError:
        raise ProtocolError("malformed", "header is nested too deeply") from None
    except ValueError as e:  # json.JSONDecodeError, or an integer literal too long for int()
        raise ProtocolError("malformed", f"header is not JSON: {e}") from None
    if not isinstance(header, dict):
        raise ProtocolError("malformed", f"header must be a JSON object, got {type(header).__name__}")
    return header


@functools.cache
def _validator(name: str):
    from jsonschema import Draft202012Validator

    schema = json_schema()
    return Draft202012Validator({"$ref": f"#/$defs/{name}", "$defs": schema["$defs"]},
                                format_checker=None)


def _check_schema(name: str, header: dict, code: str = "invalid_field") -> None:
    from jsonschema.exceptions import best_match

    error = best_match(_validator(name).iter_errors(header))
    if error is not None:
        where = "/".join(str(p) for p in error.absolute_path) or "the header"
        raise ProtocolError(code, f"{where}: {error.message}")


def _json_id(header: Mapping) -> Any:
    """The request's id if it is one the protocol allows (to echo in an error reply), else None."""
    i = header.get("id")
    if isinstance(i, bool):
        return None
    if isinstance(i, int) and abs(i) <= 9007199254740991:
        return i
    if isinstance(i, str) and len(i) <= 128:
        return i
    return None


def request_id(frames: Sequence) -> Any:
    """Best effort: the id of a request whose decoding failed (None when the header is unreadable)."""
    try:
        return _json_id(json.loads(bytes(frames[0])[:65536].decode("utf-8")))
    except Exception:  # noqa: BLE001  any unreadable header: no id to echo
        return None


def _decode_array(rtype: str, spec: dict, frame, limits: Limits) -> np.ndarray:
    # whole numbers, as the schema checked them; JSON Schema's integers include 60.0, which NumPy refuses
    name, dtype, shape = spec["name"], spec["dtype"], tuple(int(v) for v in spec["shape"])
    accepted = ARRAY_FIELDS.get(rtype, {})
    if name not in accepted:
        raise ProtocolError("invalid_field", f"arrays: {rtype} takes no array {name!r} (it takes "
                                             f"{sorted(accepted) or 'none'})")
    if dtype not in accepted[name]:
        raise ProtocolError("bad_dtype", f"{name}: dtype {dtype!r} is not one of {list(accepted[name])}")
    if len(shape) != 2:
        raise ProtocolError("bad_shape", f"{name}: shape {list(shape)} must be 2D (nx, ny)")
    if min(shape) < 1:
        raise ProtocolError("bad_shape", f"{name}: shape {list(shape)} is empty")
    if not limits.holds(shape):
        raise ProtocolError("too_large", f"{name}: {limits.shape_refusal(shape)}")
    dt = np.dtype(dtype)
    nbytes = len(frame)
    if nbytes != shape[0] * shape[1] * dt.itemsize:
        raise ProtocolError("bad_shape", f"{name}: frame of {nbytes} bytes does not hold shape {list(shape)} of "
                                         f"{dtype} ({shape[0] * shape[1] * dt.itemsize} bytes)")
    a = np.frombuffer(frame, dt).reshape(shape)
    if dt.kind == "f" and not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0].tolist()
        raise ProtocolError("non_finite", f"{name}: NaN or infinity at cell {bad}")
    if dt.kind == "u" and (a > 1).any():
        bad = np.argwhere(a > 1)[0].tolist()
        raise ProtocolError("invalid_value", f"{name}: |u1 values must be 0 or 1, got {int(a[tuple(bad)])} at cell "
                                             f"{bad}")
    return a


def decode_request(frames: Sequence, limits: Limits | None = None) -> Request:
    """Decode and check one request message (its frames, the envelope already stripped).

    Checks, in order: the frames are there and the header is a UTF-8 JSON object within
    ``limits.max_header_bytes`` with finite numbers (``malformed``, ``non_finite``); the envelope (``version``,
    ``type``, ``id``, ``arrays``; ``invalid_field``); the version (``unsupported_version``, except in a
    ``hello``, which negotiates); the type (``unknown_type``); the type's schema (``invalid_field``); each
    array's name, dtype, shape, byte length and values (``invalid_field``, ``bad_dtype``, ``bad_shape``,
    ``too_large``, ``non_finite``, ``invalid_value``) and that the frames match ``arrays`` (``malformed``).

    Args:
      frames: the message's frames (bytes, memoryview or ``zmq.Frame``; arrays are read without copies).
      limits: the server's :class:`Limits` (default ``Limits()``).

    Returns:
      :class:`Request`.

    Raises:
      ProtocolError: whatever is wrong, with its code; never another exception.

    Example:
      >>> from ijoy_jax.server import schema
      >>> frames = schema.encode({"version": 1, "type": "step", "stance": [1, 1, 0], "stance_side": -1,
      ...                         "command": [0.2, 0, 0]})
      >>> schema.decode_request(frames).header["stance_side"]
      -1
      >>> try:
      ...     schema.decode_request([b'{"version": 1, "type": "step", "stance": [1, 1]}'])
      ... except schema.ProtocolError as e:
      ...     print(e.code)
      invalid_field
    """
    limits = limits or Limits()
    if len(frames) == 0:
        raise ProtocolError("malformed", "empty message (no header frame)")
    header = _parse_header(frames[0], limits)
    rtype, version = header.get("type"), header.get("version")
    if not (rtype in REQUEST_TYPES and isinstance(version, int) and not isinstance(version, bool)):
        _check_schema("envelope", header)  # names what is wrong with version, type, id or arrays (the type's
        # own schema below checks them too: validating the envelope first only costs time, ~0.1 ms)
    if rtype != "hello" and header["version"] not in SUPPORTED_VERSIONS:
        raise ProtocolError("unsupported_version", f"protocol version {header['version']} is not supported (this "
                                                   f"server speaks {list(SUPPORTED_VERSIONS)})",
                            supported=list(SUPPORTED_VERSIONS))
    if rtype not in REQUEST_TYPES:
        raise ProtocolError("unknown_type", f"unknown request type {rtype!r} (version 1 has {list(REQUEST_TYPES)})")
    _check_schema(rtype, header)
    specs = header.get("arrays", [])
    if len(frames) - 1 != len(specs):
        raise ProtocolError("malformed", f"the header describes {len(specs)} array(s) but {len(frames) - 1} frame(s) "
                                         "follow it")
    arrays: dict[str, np.ndarray] = {}
    for spec, frame in zip(specs, frames[1:], strict=True):
        if spec["name"] in arrays:
            raise ProtocolError("invalid_field", f"arrays: {spec['name']!r} is given twice")
        buf = frame.buffer if hasattr(frame, "buffer") else frame  # zmq.Frame: its memory, no copy
        arrays[spec["name"]] = _decode_array(rtype, spec, buf, limits)
    shapes = {a.shape for a in arrays.values()}
    if len(shapes) > 1:
        raise ProtocolError("bad_shape", f"free and height must have one shape, got {[list(s) for s in shapes]}")
    return Request(header, arrays)


def decode_reply(frames: Sequence) -> Reply:
    """Decode a reply (the client's side): the JSON header and its arrays; float fields stay as sent
    (:func:`float_from_json` reads them).

    Raises:
      ProtocolError: ``malformed`` for a reply that cannot be read.
    """
    if len(frames) == 0:
        raise ProtocolError("malformed", "empty reply")
    try:
        header = json.loads(bytes(frames[0]).decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ProtocolError("malformed", f"reply header is not JSON: {e}") from None
    if not isinstance(header, dict):
        raise ProtocolError("malformed", "reply header is not a JSON object")
    specs = header.get("arrays", [])
    if len(specs) != len(frames) - 1:
        raise ProtocolError("malformed", f"reply describes {len(specs)} arrays but has {len(frames) - 1} frames")
    arrays = {}
    for spec, frame in zip(specs, frames[1:], strict=True):
        if spec.get("dtype") not in _REPLY_DTYPES:
            raise ProtocolError("malformed", f"reply array {spec.get('name')!r} has dtype {spec.get('dtype')!r}")
        buf = frame.buffer if hasattr(frame, "buffer") else frame
        arrays[spec["name"]] = np.frombuffer(buf, np.dtype(spec["dtype"])).reshape(spec["shape"])
    return Reply(header, arrays)


def error_header(code: str, message: str, request_id=None, request_type=None, **extra) -> dict:
    """The header of an error reply (see the schema's ``error_reply``)."""
    out = {"version": PROTOCOL_VERSION, "type": "error", "ok": False, "id": request_id, "code": code,
           "message": message, "request_type": request_type}
    out.update(extra)
    return out


def negotiate(versions: Sequence[int]) -> int:
    """The highest protocol version in ``versions`` that this package speaks.

    Raises:
      ProtocolError: ``unsupported_version`` when there is none.
    """
    common = sorted(set(versions) & set(SUPPORTED_VERSIONS))
    if not common:
        raise ProtocolError("unsupported_version", f"no common protocol version: the client speaks {list(versions)}, "
                                                   f"this server {list(SUPPORTED_VERSIONS)}",
                            supported=list(SUPPORTED_VERSIONS))
    return common[-1]
