"""The devices a chunk runs on: its rows split evenly over the local devices, the one-device program on each.

Devices. A chunk's rows are split evenly over the local devices (all of them
by default, or the first ``devices``), and each device runs the one-device
program on its slice (:class:`OnDevices`): the shared inputs (base robot,
targets, key, MJX model) are copied to every device, each device's call is
made from its own thread (a new program compiles side by side; the calls
return once dispatched, so the devices compute at the same time), and the
summaries are gathered to the host. No program spans devices and nothing is
exchanged between them, so a device's rows come out exactly as one device
alone computes them; each device's program is the one-device program, compiled
for the devices side by side (a later run loads it from JAX's persistent
compilation cache, which ``ijoy`` turns on). The chunk size
is rounded up to a multiple of the device count (the plan's ``chunk_size``)
and a padded chunk is padded to a multiple of it too. Each session in the
manifest records ``devices`` and ``sharding`` (how rows were split).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import jax
import numpy as np

__all__ = ["OnDevices", "local_devices"]


class OnDevices:
    """A chunk's rows split evenly over ``devices``, each slice run by the one-device program on its own device.

    With one device nothing is placed: the arrays go to the default device uncommitted, as other callers pass
    them, so a sweep shares the program they compiled (e.g. :func:`ijoy_jax.sim.walker.rollout_batch`'s).
    With several, the shared inputs are copied to every device once per density, and each device's call is
    made from its own thread: a new program traces and compiles for the devices side by side (one compile's
    wall time on two H200s), and the calls return as soon as their work is dispatched, so the devices
    compute at the same time. Nothing is exchanged between devices, and a device computes exactly what one
    device alone computes on those rows. Handing the whole batch to jit
    with a sharding instead, the partitioner gathered whole batches where it has no per-row rule (the rough
    terrain's FFT, a Pallas kernel's custom call) and reduced vmapped while loops' predicates over all
    devices at every iteration (the selector's search, MJX's solver): a perfect-robot sweep ran far slower
    on two GPUs than on one (docs/benchmarks_history.md has the figures). A ``shard_map`` over the rows
    fixed that, but a physics sweep's program crashed XLA's GPU compiler (SIGSEGV).
    """

    def __init__(self, devices: list):
        self.devices = list(devices)

    def put_shared(self, shared) -> list:
        """``shared`` committed to each device (one copy per device); as it is with one device."""
        if len(self.devices) == 1:
            return [shared]
        return [jax.device_put(shared, d) for d in self.devices]

    def dispatch(self, run, static, shared: list, batch) -> list:
        """``run(static, *shared[i], *rows_i)`` on device i for the i-th of equal slices of the host ``batch``
        (its leading axis a multiple of the device count). Returns each device's outputs once its work is
        dispatched (a new program is traced and compiled first); :meth:`collect` waits for them."""
        k = len(self.devices)
        m = len(batch[0]) // k

        def one(i):
            rows = jax.tree.map(lambda x: x[i * m : (i + 1) * m], batch)
            # With one device: uncommitted, on the default device (the program other callers compiled).
            return run(static, *shared[i], *jax.device_put(rows, self.devices[i] if k > 1 else None))

        if k == 1:
            return [one(0)]
        with ThreadPoolExecutor(k) as pool:  # a thread per device; they return once dispatched
            return list(pool.map(one, range(k)))

    @staticmethod
    def collect(outs: list) -> dict:
        """The devices' summaries (from :meth:`dispatch`) on the host, concatenated in device order."""
        outs = jax.device_get(outs)
        return {name: np.concatenate([np.asarray(o[name]) for o in outs]) for name in outs[0]}


def local_devices(devices) -> list:
    """The first ``devices`` local devices (all when None); ValueError when there are not that many."""
    local = jax.local_devices()
    if devices is None:
        return local
    if isinstance(devices, bool) or not isinstance(devices, int) or not 1 <= devices <= len(local):
        raise ValueError(f"devices must be an int in [1, {len(local)}] (local devices) or None, got {devices!r}")
    return local[:devices]
