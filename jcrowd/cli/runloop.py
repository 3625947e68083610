"""The run loop ``jcrowd run`` and ``jcrowd render`` share: compile the step once, then step.

:class:`RunLoop` compiles a prepared simulation's step (timed apart as ``compile_s``: one step
on a copy of the state, dropped), then :meth:`RunLoop.frames` advances it frame by frame with a
progress bar on stderr, timing each step (to the state being ready) and handing the caller the
frame. The step donates its input state, so anything the caller needs from the state *before*
a step (a host snapshot for a recording, the positions for the dots it draws) is read by the
``before`` hook. Also here: the model a scenario runs with and its obstacles as prisms.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

__all__ = ["RunLoop", "load_model", "scenario_obstacles"]


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


class RunLoop:
    """A prepared simulation's compiled step and the state it advances.

    Attributes:
        sim: the :class:`~jcrowd.crowd.simulate.Simulation`.
        state: the crowd state now (placed on the devices by the caller).
        compile_s: seconds to compile the step (and run it once on a copy).
        step_seconds: each step's wall time, to its state being ready.
        first: the frame of the compiling step (shapes as the step returns them).
    """

    def __init__(self, sim: Any, state: Any):
        import jax

        self.sim = sim
        self.step = sim.compiled()
        t0 = time.perf_counter()
        warm = jax.tree.map(jax.numpy.copy, state)  # the step donates its input state
        _, self.first = jax.block_until_ready(self.step(warm, sim.view_at(0.0), sim.dt_array))
        self.compile_s = time.perf_counter() - t0
        self.state = state
        self.step_seconds: list[float] = []

    @property
    def recompiles(self) -> int:
        """Compilations after the first (0 is the contract)."""
        return int(self.step._cache_size()) - 1

    def frames(
        self, count: int, label: str, before: Callable[[Any, Any], Any] | None = None
    ) -> Iterator[tuple[int, Any, Any]]:
        """Advance ``count`` steps; yield ``(i, before(state, view), frame)`` after each, the
        frame being the step's start and :attr:`state` the state after it."""
        import jax
        from rich.console import Console
        from rich.progress import Progress

        sim = self.sim
        with Progress(console=Console(file=sys.stderr), transient=True) as bar:
            task = bar.add_task(label, total=count)
            for i in range(count):
                view = sim.view_at(i * sim.dt)
                pre = None if before is None else before(self.state, view)
                t = time.perf_counter()
                new, frame = self.step(self.state, view, sim.dt_array)
                jax.block_until_ready(new)
                self.step_seconds.append(time.perf_counter() - t)
                self.state = new
                yield i, pre, frame
                bar.advance(task)
