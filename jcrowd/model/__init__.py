"""The motion model: gait samples, pose vectors, the tensor model, kriging over controls.

The second stage of the fit (papers 000 and 001): gait-cycle samples → pose vectors → the
multi-level motion tensor (:func:`build_tensor_model`) → per-level kriging of the cores
(:func:`fit_motion_model`), and leave-one-clip-out evaluation. Pure: files are
:mod:`jcrowd.io`'s (``tensor_file``, ``model_file``).
"""

from jcrowd.model.evaluate import ALL_CV_METHODS as ALL_CV_METHODS
from jcrowd.model.evaluate import CV_METHODS as CV_METHODS
from jcrowd.model.evaluate import evaluate_captures as evaluate_captures
from jcrowd.model.evaluate import foot_skate as foot_skate
from jcrowd.model.evaluate import leave_one_clip_out as leave_one_clip_out
from jcrowd.model.footprints import FootprintControls as FootprintControls
from jcrowd.model.footprints import controls_for_footprints as controls_for_footprints
from jcrowd.model.footprints import cycle_footprints as cycle_footprints
from jcrowd.model.footprints import footprint_errors as footprint_errors
from jcrowd.model.footprints import footprints_for_controls as footprints_for_controls
from jcrowd.model.footprints import forward_rule_controls as forward_rule_controls
from jcrowd.model.motion_model import METHODS as METHODS
from jcrowd.model.motion_model import MotionLevel as MotionLevel
from jcrowd.model.motion_model import MotionModel as MotionModel
from jcrowd.model.motion_model import clamp_controls as clamp_controls
from jcrowd.model.motion_model import fit_motion_model as fit_motion_model
from jcrowd.model.motion_model import level_cores as level_cores
from jcrowd.model.motion_model import level_pose_vectors as level_pose_vectors
from jcrowd.model.motion_model import model_reliability as model_reliability
from jcrowd.model.motion_model import sample_cores as sample_cores
from jcrowd.model.motion_model import synthesize_clip as synthesize_clip
from jcrowd.model.posevec import PoseLayout as PoseLayout
from jcrowd.model.posevec import decode_clip as decode_clip
from jcrowd.model.posevec import decode_pose_vectors as decode_pose_vectors
from jcrowd.model.posevec import encode_sample as encode_sample
from jcrowd.model.posevec import mean_rotations as mean_rotations
from jcrowd.model.posevec import sample_at as sample_at
from jcrowd.model.posevec import unwarp as unwarp
from jcrowd.model.resynthesis import RECORD_KEYS as RECORD_KEYS
from jcrowd.model.resynthesis import agent_motion as agent_motion
from jcrowd.model.samples import CONTROL_NAMES as CONTROL_NAMES
from jcrowd.model.samples import Sample as Sample
from jcrowd.model.samples import gait_samples as gait_samples
from jcrowd.model.samples import reference_skeleton as reference_skeleton
from jcrowd.model.tensor_model import TensorLevel as TensorLevel
from jcrowd.model.tensor_model import TensorModel as TensorModel
from jcrowd.model.tensor_model import TensorModelConfig as TensorModelConfig
from jcrowd.model.tensor_model import build_tensor_model as build_tensor_model
from jcrowd.model.tensor_model import level_errors as level_errors
from jcrowd.model.tensor_model import reconstruct_level as reconstruct_level
from jcrowd.model.tensor_model import root_frame_positions as root_frame_positions
from jcrowd.model.tensor_model import storage as storage
