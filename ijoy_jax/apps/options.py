"""Option syntax the ``ijoy`` subcommands share: repeated ``--set NAME=VALUE`` assignments."""

from __future__ import annotations

import math
from collections.abc import Iterable


def assignments(items: Iterable[str] | None, example: str) -> dict[str, str]:
    """``["a.b=1.5", ...]`` as ``{"a.b": "1.5", ...}`` (names stripped, values as written; a later item wins).

    Raises:
      ValueError: an item without ``=`` or without a name, quoting it and ``example`` (a valid item).
    """
    out: dict[str, str] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--set takes NAME=VALUE, e.g. {example}; got {item!r}")
        out[name.strip()] = value
    return out


def number_assignments(items: Iterable[str] | None, names: Iterable[str], example: str) -> dict[str, float]:
    """:func:`assignments` whose names must be among ``names`` and whose values must be finite numbers (floats).

    Raises:
      ValueError: a malformed item, an unknown name (listing ``names``), or a value that is not a number or
        not finite (``nan``, ``inf``, ``1e999``: no robot leaf takes one), quoting the item.
    """
    known = list(names)
    out: dict[str, float] = {}
    for name, value in assignments(items, example).items():
        if name not in known:
            raise ValueError(f"--set '{name}={value}': {name!r} is not one of {known}")
        try:
            out[name] = float(value)
        except ValueError:
            raise ValueError(f"--set '{name}={value}': {value!r} is not a number") from None
        if not math.isfinite(out[name]):
            raise ValueError(f"--set '{name}={value}': {name} takes a finite number, got {value!r}")
    return out
