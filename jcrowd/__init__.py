"""jcrowd: crowds whose motion is synthesized from motion capture, in JAX.

The public API is re-exported here once; each name is defined in the module that owns it.
"""

from __future__ import annotations

from jcrowd.errors import BVHError as BVHError
from jcrowd.errors import DataError as DataError
from jcrowd.errors import JcrowdError as JcrowdError
from jcrowd.errors import MotionError as MotionError
from jcrowd.errors import SkeletonError as SkeletonError
from jcrowd.io.bvh import load_bvh as load_bvh
from jcrowd.io.bvh import read_bvh as read_bvh
from jcrowd.io.bvh_write import write_bvh as write_bvh
from jcrowd.io.dataset import load_dataset as load_dataset
from jcrowd.io.model_file import load_default_model as load_default_model
from jcrowd.motion.clip import Clip as Clip
from jcrowd.motion.clip import Motion as Motion
from jcrowd.motion.gait import GaitCycle as GaitCycle
from jcrowd.motion.gait import foot_contacts as foot_contacts
from jcrowd.motion.gait import gait_cycles as gait_cycles
from jcrowd.motion.skeleton import Skeleton as Skeleton
from jcrowd.motion.skeleton import forward_kinematics as forward_kinematics
from jcrowd.motion.walker import procedural_walk as procedural_walk
from jcrowd.version import __version__ as __version__
