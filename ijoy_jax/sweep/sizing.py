"""The chunk size of a run: how many scenarios one call of a chunk program computes.

Chunk size. Given, or (``chunk_size=None``) the manifest's when resuming, else
:func:`default_chunk_size`: :data:`DEFAULT_CHUNK` on CPU; on an accelerator
the compiled chunk function's memory for one scenario of the largest action
set (:func:`scenario_bytes`, ahead-of-time ``memory_analysis()``, nothing
runs; split into per-scenario and shared bytes) sets :func:`auto_chunk_size`,
a power of two per device filling :data:`MEMORY_FRACTION` of
``memory_stats()["bytes_limit"]``. A physics sweep's chunks are balanced (:func:`balanced_chunk_size`) so
that its last chunk is not mostly padding.
"""

from __future__ import annotations

from ijoy_jax.sweep.programs import scenario_bytes
from ijoy_jax.sweep.schema import SweepConfig

__all__ = [
    "DEFAULT_CHUNK",
    "MAX_AUTO_CHUNK",
    "MEMORY_FRACTION",
    "auto_chunk_size",
    "balanced_chunk_size",
    "default_chunk_size",
    "device_memory",
]

DEFAULT_CHUNK = 32
"""Scenarios per jitted call on CPU (and wherever the device reports no memory figure)."""
MEMORY_FRACTION = 0.5
"""Share of an accelerator's memory a default-sized chunk may fill (the rest: XLA workspace, fragmentation)."""
MAX_AUTO_CHUNK = 4096
"""Largest chunk per device :func:`auto_chunk_size` picks: large enough to amortise dispatch and fill a GPU
(the MJX walker's physics steps/s still grow from 1024 to 4096 robots), small enough to resume often."""


def device_memory(device) -> int | None:
    """Bytes an accelerator lets XLA allocate (``memory_stats()["bytes_limit"]``); None on CPU or unknown.

    What :func:`default_chunk_size` sizes chunks to: ``device`` is a ``jax.Device`` (e.g.
    ``jax.local_devices()[0]``); None means the backend reports no limit and the chunk is :data:`DEFAULT_CHUNK`.
    """
    if device.platform == "cpu":
        return None
    try:
        stats = device.memory_stats()
    except Exception:  # noqa: BLE001 - some backends raise instead of returning None
        return None
    limit = (stats or {}).get("bytes_limit")
    return int(limit) if limit else None


def auto_chunk_size(
    bytes_per_scenario: int,
    device_bytes: int,
    num_devices: int = 1,
    *,
    shared_bytes: int = 0,
    fraction: float = MEMORY_FRACTION,
    max_chunk: int = MAX_AUTO_CHUNK,
) -> int:
    """The chunk size that fills ``fraction`` of each device's memory, as a power of two per device.

    ``per_device = 2 ** floor(log2((fraction * device_bytes - shared_bytes) / bytes_per_scenario))``
    (at least 1; ``shared_bytes`` is held once per device), at most ``max_chunk``, times ``num_devices``:
    each device runs the batch it would run alone. Powers of two keep the plan (and so
    resume) stable when the estimate moves a little.

    Example:
      >>> auto_chunk_size(2**20, 80 * 2**30, 1)   # 1 MiB per scenario on an 80 GiB GPU: capped
      4096
      >>> auto_chunk_size(100 * 2**20, 16 * 2**30, 2)   # 100 MiB per scenario, 2 x 16 GiB
      128
    """
    if bytes_per_scenario <= 0 or device_bytes <= 0 or num_devices < 1 or shared_bytes < 0:
        raise ValueError(
            f"need positive sizes, got bytes_per_scenario={bytes_per_scenario}, "
            f"device_bytes={device_bytes}, num_devices={num_devices}, shared_bytes={shared_bytes}"
        )
    fit = int((fraction * device_bytes - shared_bytes) // bytes_per_scenario)
    per_device = 1 << (fit.bit_length() - 1) if fit >= 1 else 1
    return min(per_device, max_chunk) * num_devices


def balanced_chunk_size(cap: int, total: int, num_devices: int = 1) -> int:
    """The smallest chunk (a multiple of ``num_devices``) that runs ``total`` scenarios in as many chunks as
    ``cap`` does, so the last chunk is not mostly padding.

    A physics rollout costs thousands of decisions, so a 4608-scenario sweep in chunks of 4096 would simulate
    8192 robots; in two chunks of 2304 it simulates 4608.

    Example:
      >>> balanced_chunk_size(4096, 4608), balanced_chunk_size(4096, 2816), balanced_chunk_size(4096, 2816, 3)
      (2304, 2816, 2817)
    """
    if cap < 1 or total < 1 or num_devices < 1:
        raise ValueError(f"need cap, total and num_devices >= 1, got {cap}, {total}, {num_devices}")
    chunks = -(-total // cap)
    per_chunk = -(-total // chunks)
    return -(-per_chunk // num_devices) * num_devices


def default_chunk_size(cfg: SweepConfig, table, bases: dict, devices: list, sim=None) -> int:
    """The chunk size used when none is given: :data:`DEFAULT_CHUNK` on CPU, else sized to device memory.

    On an accelerator with a known memory limit: :func:`auto_chunk_size` of
    :func:`scenario_bytes` for the largest action set (one extra ahead-of-time
    compile; ``sim``: a physics sweep's MJX biped); :data:`DEFAULT_CHUNK` when
    the backend reports no memory figure. ``table``: rows covering every cell (a run passes replicate 0 of
    each); a physics sweep's chunks are balanced over the whole sweep's scenarios, so a slice of it plans the
    chunks the whole sweep does.
    """
    mem = device_memory(devices[0])
    if mem is None:
        return DEFAULT_CHUNK
    base = max(bases.values(), key=lambda b: b.num_actions)
    try:
        per, shared = scenario_bytes(cfg, table, base, sim)
    except RuntimeError:
        return DEFAULT_CHUNK
    cap = auto_chunk_size(per, mem, len(devices), shared_bytes=shared)
    # a physics sweep's padded rollouts cost as much as real ones: balance the chunks (a perfect-robot sweep
    # keeps the power of two, whose compiled program other sweeps' sizes reuse)
    return cap if sim is None else balanced_chunk_size(cap, cfg.num_scenarios, len(devices))
