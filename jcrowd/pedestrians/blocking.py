"""Compiled multi-device steps that return only once every device has finished.

See :class:`OneStepAtATime` for why the crowd steps split over several devices need it.
"""

from __future__ import annotations

from typing import Any

import jax

__all__ = ["OneStepAtATime"]


class OneStepAtATime:
    """A compiled multi-device step that returns only once every device has finished it.

    Why: with several CPU devices in one process, XLA launches each device's part of a step on
    a small shared thread pool. When the caller queues step ``n + 1`` before step ``n`` is done
    (JAX dispatches asynchronously), device 0's part of ``n + 1`` can take the last free thread
    while device 1's part of ``n`` still waits for one; device 0's part of ``n`` then waits in
    the positions' all-gather for a device that never starts, and XLA aborts the process after
    40 s ("Termination timeout for `all gather`", seen in about 1 run in 10 of 40 avoiding
    steps on two devices, under load more often; a thread dump showed the launch blocked on
    XLA's per-device semaphore). Waiting for each step keeps one step in flight. It costs the
    overlap of the host's dispatch with the devices' work, a fraction of a millisecond per step.

    Calls and ``_cache_size`` (compilations so far) pass through to the jitted step.
    """

    def __init__(self, jitted: Any) -> None:
        self._jitted = jitted

    def __call__(self, *args: Any) -> Any:
        return jax.block_until_ready(self._jitted(*args))

    def _cache_size(self) -> int:
        return int(self._jitted._cache_size())

    def lower(self, *args: Any, **kwargs: Any) -> Any:
        return self._jitted.lower(*args, **kwargs)
