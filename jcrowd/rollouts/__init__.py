"""Differentiable rollouts of the pedestrian model and what is built on them.

:func:`rollout` steps :func:`jcrowd.pedestrians.pedestrian_step` under ``jax.lax.scan`` with
the parameters as traced inputs, and smooth surrogates of what a run yields (travel time,
exits, flow) make it a function ``jax.grad`` differentiates (:mod:`~jcrowd.rollouts.rollout`,
doors and walls in :mod:`~jcrowd.rollouts.doors`). On it: calibration of the model to measured
trajectories by Levenberg–Marquardt (:mod:`~jcrowd.rollouts.calibrate`, windows of measured
states in :mod:`~jcrowd.rollouts.windows`) and layout optimisation of a scenario's obstacles
by projected gradient (:mod:`~jcrowd.rollouts.layout_opt`, :mod:`~jcrowd.rollouts.search`).
The animated crowd step (:mod:`jcrowd.crowd`) never imports this package.
"""

from jcrowd.rollouts.calibrate import DEFAULT_NAMES as DEFAULT_NAMES
from jcrowd.rollouts.calibrate import EXTRA_NAMES as EXTRA_NAMES
from jcrowd.rollouts.calibrate import RADIUS_NAME as RADIUS_NAME
from jcrowd.rollouts.calibrate import RESIDUALS as RESIDUALS
from jcrowd.rollouts.calibrate import SPEED_NAME as SPEED_NAME
from jcrowd.rollouts.calibrate import Calibration as Calibration
from jcrowd.rollouts.calibrate import calibrate as calibrate
from jcrowd.rollouts.calibrate import parameter_values as parameter_values
from jcrowd.rollouts.calibrate import person_residuals as person_residuals
from jcrowd.rollouts.calibrate import window_residuals as window_residuals
from jcrowd.rollouts.doors import Door as Door
from jcrowd.rollouts.doors import door_walls as door_walls
from jcrowd.rollouts.doors import every_wall as every_wall
from jcrowd.rollouts.doors import find_door as find_door
from jcrowd.rollouts.layout_opt import EMPTY_TEMPERATURE as EMPTY_TEMPERATURE
from jcrowd.rollouts.layout_opt import OBJECTIVES as OBJECTIVES
from jcrowd.rollouts.layout_opt import OUT_DEPTH as OUT_DEPTH
from jcrowd.rollouts.layout_opt import LayoutProblem as LayoutProblem
from jcrowd.rollouts.layout_opt import forward_value as forward_value
from jcrowd.rollouts.layout_opt import layout_objective as layout_objective
from jcrowd.rollouts.layout_opt import layout_problem as layout_problem
from jcrowd.rollouts.layout_opt import layout_setup as layout_setup
from jcrowd.rollouts.layout_opt import obstacle_walls as obstacle_walls
from jcrowd.rollouts.layout_opt import value_and_gradient as value_and_gradient
from jcrowd.rollouts.rollout import COUNT_TEMPERATURE as COUNT_TEMPERATURE
from jcrowd.rollouts.rollout import ENTRY_TEMPERATURE as ENTRY_TEMPERATURE
from jcrowd.rollouts.rollout import RolloutParams as RolloutParams
from jcrowd.rollouts.rollout import RolloutSetup as RolloutSetup
from jcrowd.rollouts.rollout import Trajectory as Trajectory
from jcrowd.rollouts.rollout import entry_weights as entry_weights
from jcrowd.rollouts.rollout import initial_params as initial_params
from jcrowd.rollouts.rollout import mean_travel_time as mean_travel_time
from jcrowd.rollouts.rollout import rollout as rollout
from jcrowd.rollouts.rollout import soft_exit_count as soft_exit_count
from jcrowd.rollouts.search import OptimizeResult as OptimizeResult
from jcrowd.rollouts.search import projected_gradient as projected_gradient
from jcrowd.rollouts.windows import WindowBatch as WindowBatch
from jcrowd.rollouts.windows import corridor_scene as corridor_scene
from jcrowd.rollouts.windows import make_windows as make_windows
from jcrowd.rollouts.windows import merge_windows as merge_windows
