"""The 2-D pedestrian model: one step of walking people on the ground plane.

Navigation fields (:mod:`~jcrowd.pedestrians.navigation`), a neighbour cell grid
(:mod:`~jcrowd.pedestrians.neighbours`), the collision-free speed model with our changes and
its reaction time or anticipation (:mod:`~jcrowd.pedestrians.avoidance`,
:mod:`~jcrowd.pedestrians.reaction`), walls and the world they make
(:mod:`~jcrowd.pedestrians.world`, :mod:`~jcrowd.pedestrians.scene`), and
:func:`pedestrian_step`, the one implementation of a step that the animated crowd
(:mod:`jcrowd.crowd`), the differentiable rollouts (:mod:`jcrowd.rollouts`) and
``bench/pedestrians.py`` all call. It imports neither of those packages (a contract CI checks).
"""

from jcrowd.pedestrians.avoidance import approach_cap as approach_cap
from jcrowd.pedestrians.avoidance import avoid as avoid
from jcrowd.pedestrians.avoidance import avoid_one as avoid_one
from jcrowd.pedestrians.avoidance import closest_on_segments as closest_on_segments
from jcrowd.pedestrians.blocking import OneStepAtATime as OneStepAtATime
from jcrowd.pedestrians.grid_avoidance import CANDIDATE_TIERS as CANDIDATE_TIERS
from jcrowd.pedestrians.grid_avoidance import avoid_in_grid as avoid_in_grid
from jcrowd.pedestrians.navigation import UNREACHABLE as UNREACHABLE
from jcrowd.pedestrians.navigation import FieldGrid as FieldGrid
from jcrowd.pedestrians.navigation import Navigation as Navigation
from jcrowd.pedestrians.navigation import desired_directions as desired_directions
from jcrowd.pedestrians.navigation import distance_field as distance_field
from jcrowd.pedestrians.navigation import field_grid as field_grid
from jcrowd.pedestrians.navigation import field_values as field_values
from jcrowd.pedestrians.navigation import rasterize as rasterize
from jcrowd.pedestrians.neighbours import CellList as CellList
from jcrowd.pedestrians.neighbours import GridSpec as GridSpec
from jcrowd.pedestrians.neighbours import candidates as candidates
from jcrowd.pedestrians.neighbours import cell_index as cell_index
from jcrowd.pedestrians.neighbours import cell_list as cell_list
from jcrowd.pedestrians.neighbours import compact_candidates as compact_candidates
from jcrowd.pedestrians.neighbours import grid_spec as grid_spec
from jcrowd.pedestrians.neighbours import near_places as near_places
from jcrowd.pedestrians.params import AvoidanceParams as AvoidanceParams
from jcrowd.pedestrians.reaction import Motion as Motion
from jcrowd.pedestrians.scene import CLEARANCE_M as CLEARANCE_M
from jcrowd.pedestrians.scene import MAX_FIELD_BYTES as MAX_FIELD_BYTES
from jcrowd.pedestrians.scene import NAV_CELL_M as NAV_CELL_M
from jcrowd.pedestrians.scene import build_scene as build_scene
from jcrowd.pedestrians.scene import field_ids as field_ids
from jcrowd.pedestrians.scene import scene_bytes as scene_bytes
from jcrowd.pedestrians.step import Pedestrians as Pedestrians
from jcrowd.pedestrians.step import StepInfo as StepInfo
from jcrowd.pedestrians.step import pedestrian_step as pedestrian_step
from jcrowd.pedestrians.step import split_pedestrian_step as split_pedestrian_step
from jcrowd.pedestrians.world import WALL_REACH_M as WALL_REACH_M
from jcrowd.pedestrians.world import World as World
from jcrowd.pedestrians.world import build_world as build_world
from jcrowd.pedestrians.world import open_world as open_world
from jcrowd.pedestrians.world import wall_segments as wall_segments
from jcrowd.pedestrians.world import walls_near_cells as walls_near_cells
