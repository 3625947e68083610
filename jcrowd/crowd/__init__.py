"""The animated crowd step: crowd state, LOD buckets, per-level synthesis, clip scheduling.

One ``jit``-compiled step advances every agent (papers 000 §4–5, 003 §3): its dynamics stage
is the pedestrian step of :mod:`jcrowd.pedestrians`, then levels of detail, per-level decode
and forward kinematics, level blending and the next clips. :func:`prepare` builds it from a
scenario and a motion model. It never touches files, rendering, the CLI or the rollouts
(import contracts checked in CI).
"""

from jcrowd.crowd.clips import CrowdModel as CrowdModel
from jcrowd.crowd.clips import build_crowd_model as build_crowd_model
from jcrowd.crowd.clips import choose_controls as choose_controls
from jcrowd.crowd.clips import local_to_world as local_to_world
from jcrowd.crowd.clips import next_clip as next_clip
from jcrowd.crowd.clips import next_clips as next_clips
from jcrowd.crowd.clips import next_clips_lod as next_clips_lod
from jcrowd.crowd.devices import agent_mesh as agent_mesh
from jcrowd.crowd.devices import agent_order as agent_order
from jcrowd.crowd.devices import check_divisible as check_divisible
from jcrowd.crowd.devices import in_agent_order as in_agent_order
from jcrowd.crowd.devices import on_all_devices as on_all_devices
from jcrowd.crowd.devices import per_device_config as per_device_config
from jcrowd.crowd.devices import shard_state as shard_state
from jcrowd.crowd.devices import split_step as split_step
from jcrowd.crowd.lod import Buckets as Buckets
from jcrowd.crowd.lod import CameraView as CameraView
from jcrowd.crowd.lod import assign_buckets as assign_buckets
from jcrowd.crowd.lod import distance_levels as distance_levels
from jcrowd.crowd.lod import in_frustum as in_frustum
from jcrowd.crowd.lod import screen_height_px as screen_height_px
from jcrowd.crowd.schedule import schedule as schedule
from jcrowd.crowd.simulate import Record as Record
from jcrowd.crowd.simulate import Simulation as Simulation
from jcrowd.crowd.simulate import prepare as prepare
from jcrowd.crowd.simulate import record_shapes as record_shapes
from jcrowd.crowd.simulate import step_compiler_options as step_compiler_options
from jcrowd.crowd.simulate import thresholds_for as thresholds_for
from jcrowd.crowd.state import DEFAULT_RADIUS as DEFAULT_RADIUS
from jcrowd.crowd.state import CrowdState as CrowdState
from jcrowd.crowd.state import Frame as Frame
from jcrowd.crowd.state import StepConfig as StepConfig
from jcrowd.crowd.state import init_state as init_state
from jcrowd.crowd.state import refresh_far_cores as refresh_far_cores
from jcrowd.crowd.steering import aim_point as aim_point
from jcrowd.crowd.steering import current_field as current_field
from jcrowd.crowd.steering import walk as walk
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
