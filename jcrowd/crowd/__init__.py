"""The online step: crowd state, LOD buckets, per-level synthesis, clip scheduling.

One ``jit``-compiled step advances every agent (papers 000 §4–5, 003 §3);
:func:`prepare` builds it from a scenario and a motion model, and :func:`agent_motion` turns
a recorded agent back into a clip. It never touches files, rendering or the CLI (an import
contract checked in CI).
"""

from jcrowd.crowd.avoidance import AvoidanceParams as AvoidanceParams
from jcrowd.crowd.avoidance import avoid as avoid
from jcrowd.crowd.avoidance import avoid_one as avoid_one
from jcrowd.crowd.avoidance import closest_on_segments as closest_on_segments
from jcrowd.crowd.clips import CrowdModel as CrowdModel
from jcrowd.crowd.clips import build_crowd_model as build_crowd_model
from jcrowd.crowd.clips import choose_controls as choose_controls
from jcrowd.crowd.clips import local_to_world as local_to_world
from jcrowd.crowd.clips import next_clip as next_clip
from jcrowd.crowd.clips import next_clips as next_clips
from jcrowd.crowd.clips import next_clips_lod as next_clips_lod
from jcrowd.crowd.dynamics import Pedestrians as Pedestrians
from jcrowd.crowd.dynamics import StepInfo as StepInfo
from jcrowd.crowd.dynamics import World as World
from jcrowd.crowd.dynamics import build_world as build_world
from jcrowd.crowd.dynamics import pedestrian_step as pedestrian_step
from jcrowd.crowd.dynamics import wall_segments as wall_segments
from jcrowd.crowd.export import RECORD_KEYS as RECORD_KEYS
from jcrowd.crowd.export import agent_motion as agent_motion
from jcrowd.crowd.lod import Buckets as Buckets
from jcrowd.crowd.lod import CameraView as CameraView
from jcrowd.crowd.lod import assign_buckets as assign_buckets
from jcrowd.crowd.lod import distance_levels as distance_levels
from jcrowd.crowd.lod import in_frustum as in_frustum
from jcrowd.crowd.lod import screen_height_px as screen_height_px
from jcrowd.crowd.navigation import UNREACHABLE as UNREACHABLE
from jcrowd.crowd.navigation import FieldGrid as FieldGrid
from jcrowd.crowd.navigation import Navigation as Navigation
from jcrowd.crowd.navigation import desired_directions as desired_directions
from jcrowd.crowd.navigation import distance_field as distance_field
from jcrowd.crowd.navigation import field_grid as field_grid
from jcrowd.crowd.navigation import field_values as field_values
from jcrowd.crowd.navigation import rasterize as rasterize
from jcrowd.crowd.neighbours import CellList as CellList
from jcrowd.crowd.neighbours import GridSpec as GridSpec
from jcrowd.crowd.neighbours import candidates as candidates
from jcrowd.crowd.neighbours import cell_list as cell_list
from jcrowd.crowd.neighbours import compact_candidates as compact_candidates
from jcrowd.crowd.neighbours import grid_spec as grid_spec
from jcrowd.crowd.schedule import schedule as schedule
from jcrowd.crowd.simulate import Simulation as Simulation
from jcrowd.crowd.simulate import agent_mesh as agent_mesh
from jcrowd.crowd.simulate import agent_order as agent_order
from jcrowd.crowd.simulate import check_divisible as check_divisible
from jcrowd.crowd.simulate import in_agent_order as in_agent_order
from jcrowd.crowd.simulate import on_all_devices as on_all_devices
from jcrowd.crowd.simulate import per_device_config as per_device_config
from jcrowd.crowd.simulate import prepare as prepare
from jcrowd.crowd.simulate import shard_state as shard_state
from jcrowd.crowd.simulate import step_compiler_options as step_compiler_options
from jcrowd.crowd.simulate import thresholds_for as thresholds_for
from jcrowd.crowd.state import DEFAULT_RADIUS as DEFAULT_RADIUS
from jcrowd.crowd.state import CrowdState as CrowdState
from jcrowd.crowd.state import Frame as Frame
from jcrowd.crowd.state import StepConfig as StepConfig
from jcrowd.crowd.state import init_state as init_state
from jcrowd.crowd.state import refresh_far_cores as refresh_far_cores
from jcrowd.crowd.steering import SPARSE_SLOTS as SPARSE_SLOTS
from jcrowd.crowd.steering import TURN_RATE as TURN_RATE
from jcrowd.crowd.steering import aim_point as aim_point
from jcrowd.crowd.steering import steer as steer
from jcrowd.crowd.steering import turn_towards as turn_towards
from jcrowd.crowd.steering import waypoint_xz as waypoint_xz
from jcrowd.crowd.stepping import bucket_chunk as bucket_chunk
from jcrowd.crowd.stepping import decode_bucket as decode_bucket
from jcrowd.crowd.stepping import default_capacities as default_capacities
from jcrowd.crowd.stepping import step as step
from jcrowd.crowd.synthesis import Decoders as Decoders
from jcrowd.crowd.synthesis import LevelDecoder as LevelDecoder
from jcrowd.crowd.synthesis import RootRates as RootRates
from jcrowd.crowd.synthesis import build_decoders as build_decoders
from jcrowd.crowd.synthesis import clip_core as clip_core
from jcrowd.crowd.synthesis import clip_weights as clip_weights
from jcrowd.crowd.synthesis import coeffs_at as coeffs_at
from jcrowd.crowd.synthesis import decode_coeffs as decode_coeffs
from jcrowd.crowd.synthesis import level_points as level_points
from jcrowd.crowd.synthesis import pose_from_coeffs as pose_from_coeffs
from jcrowd.crowd.synthesis import root_rates as root_rates
