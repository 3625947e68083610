"""The run loop ``jcrowd run`` and ``jcrowd render`` share: compile the step once, then step.

:class:`RunLoop` compiles a prepared simulation's steps, many frames per call
(:meth:`~jcrowd.crowd.simulate.Simulation.compiled_steps`; compiling timed apart as
``compile_s``), then :meth:`RunLoop.frames` advances them with a progress bar on stderr, timing
each call (to the state being ready) and handing the caller each frame's record: what the
caller's ``record`` function keeps of the state at the frame's start (a recording's snapshot,
the positions of the dots it draws) and of the frame the step returns, copied to the host once
per call. Also here: the model a scenario runs with and its obstacles as prisms.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

__all__ = ["CHUNK", "RECORD_BYTES", "RunLoop", "fetch", "load_model", "scenario_obstacles"]


def load_model(scenario: Any, override: str | None) -> tuple[Any, str]:
    """The model a run uses: ``--model``, else the scenario's, else the shipped default."""
    from jcrowd.io.model_file import load_motion_model
    from jcrowd.io.resources import default_model_path

    path = override or scenario.model or str(default_model_path())
    model, _ = load_motion_model(path)
    return model, str(path)


def scenario_obstacles(scenario: Any) -> np.ndarray:
    """The scenario's obstacles, walls and the ground outside ``walkable`` as drawable prisms
    (:func:`jcrowd.render.meshes.prism_mesh`); none without a layout."""
    from jcrowd.render.meshes import prism_mesh
    from jcrowd.scenario import blocked_space

    if scenario.layout.empty:
        return np.zeros((0, 6), np.float32)
    return prism_mesh(blocked_space(scenario.ground, scenario.layout))


RECORD_BYTES = 256 << 20
"""Device memory the records of one call of the run loop may take (:data:`CHUNK` frames at
most): a record of whole frames at 1M agents would hold a few frames per call."""

CHUNK = 30
"""Frames per compiled call (:meth:`~jcrowd.crowd.simulate.Simulation.compiled_steps`)."""


def fetch(tree: Any) -> Any:
    """Host copies of (possibly multi-process) global arrays."""
    import jax

    if jax.process_count() == 1:
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)


class RunLoop:
    """A prepared simulation's compiled steps and the state they advance.

    Attributes:
        sim: the :class:`~jcrowd.crowd.simulate.Simulation`.
        state: the crowd state now (placed on the devices by the caller).
        shapes: one frame's record as shapes and dtypes (``jax.ShapeDtypeStruct``).
        chunk: frames per compiled call (:data:`CHUNK`, fewer where one frame's record is
            large: :data:`RECORD_BYTES`).
        compile_s: seconds to compile the steps (a call that runs none, on a copy).
        step_seconds: each frame's wall time: a call's time, to its state being ready, shared
            by its frames.
    """

    def __init__(self, sim: Any, state: Any, record: Any):
        import jax
        import jax.numpy as jnp

        from jcrowd.crowd.devices import on_all_devices
        from jcrowd.crowd.simulate import record_shapes

        self.sim = sim
        self.shapes = record_shapes(sim, state, record)
        leaves = jax.tree.leaves(self.shapes)
        per_frame = sum(int(np.prod(a.shape)) * a.dtype.itemsize for a in leaves)
        self.chunk = max(1, min(CHUNK, RECORD_BYTES // max(1, per_frame)))
        self.step = sim.compiled_steps(self.chunk, record)
        self._counts = {n: on_all_devices(jnp.asarray(n, jnp.int32)) for n in range(self.chunk + 1)}
        t0 = time.perf_counter()
        warm = jax.tree.map(jnp.copy, state)  # the steps donate their input state
        views = sim.views(0, self.chunk)
        jax.block_until_ready(self.step(warm, views, sim.dt_array, self._counts[0]))
        self.compile_s = time.perf_counter() - t0
        self.state = state
        self.step_seconds: list[float] = []

    @property
    def recompiles(self) -> int:
        """Compilations after the first (0 is the contract)."""
        return int(self.step._cache_size()) - 1

    def frames(self, count: int, label: str) -> Iterator[tuple[int, Any]]:
        """Advance ``count`` steps, :attr:`chunk` per call; yield ``(i, record)`` for each, the
        record as host arrays (``record(state at frame i's start, camera, frame)``), and
        :attr:`state` the state after the call that ran frame ``i``."""
        import jax
        from rich.console import Console
        from rich.progress import Progress

        sim = self.sim
        with Progress(console=Console(file=sys.stderr), transient=True) as bar:
            task = bar.add_task(label, total=count)
            for start in range(0, count, self.chunk):
                n = min(self.chunk, count - start)
                views = sim.views(start, self.chunk)
                t = time.perf_counter()
                self.state, records = self.step(self.state, views, sim.dt_array, self._counts[n])
                jax.block_until_ready(self.state)
                self.step_seconds += [(time.perf_counter() - t) / n] * n
                host = fetch(records)
                for j in range(n):
                    yield start + j, jax.tree.map(lambda a, j=j: a[j], host)
                    bar.advance(task)
