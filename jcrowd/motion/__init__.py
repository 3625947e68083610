"""Motion capture as data: rotations, skeletons and forward kinematics, clips, gait cycles.

Quaternions (w, x, y, z) and exp maps, the joint tree and FK, ``Motion`` clips and their
operations (resample, root normalisation, mirroring), foot contacts and gait cycles, foot
locking, and the procedural walker (paper 004 §4.2). This package imports nothing of jcrowd but
:mod:`jcrowd.errors` (an import contract checked in CI): everything else builds on it.
"""

from jcrowd.motion.clip import Clip as Clip
from jcrowd.motion.clip import Motion as Motion
from jcrowd.motion.clip import drop_tpose_frames as drop_tpose_frames
from jcrowd.motion.clip import headings as headings
from jcrowd.motion.clip import joint_positions as joint_positions
from jcrowd.motion.clip import mirror as mirror
from jcrowd.motion.clip import mirror_map as mirror_map
from jcrowd.motion.clip import normalize_root as normalize_root
from jcrowd.motion.clip import resample as resample
from jcrowd.motion.clip import rest_forward as rest_forward
from jcrowd.motion.clip import slice_frames as slice_frames
from jcrowd.motion.fastmath import sincos as sincos
from jcrowd.motion.footlock import lock_feet as lock_feet
from jcrowd.motion.footlock import planted_slides as planted_slides
from jcrowd.motion.gait import ContactThresholds as ContactThresholds
from jcrowd.motion.gait import FootContacts as FootContacts
from jcrowd.motion.gait import FootJoints as FootJoints
from jcrowd.motion.gait import GaitCycle as GaitCycle
from jcrowd.motion.gait import character_height as character_height
from jcrowd.motion.gait import find_feet as find_feet
from jcrowd.motion.gait import foot_contacts as foot_contacts
from jcrowd.motion.gait import gait_cycles as gait_cycles
from jcrowd.motion.rotation import EULER_ORDERS as EULER_ORDERS
from jcrowd.motion.rotation import euler_to_quat as euler_to_quat
from jcrowd.motion.rotation import quat_angle as quat_angle
from jcrowd.motion.rotation import quat_canonical as quat_canonical
from jcrowd.motion.rotation import quat_conj as quat_conj
from jcrowd.motion.rotation import quat_from_axis_angle as quat_from_axis_angle
from jcrowd.motion.rotation import quat_from_expmap as quat_from_expmap
from jcrowd.motion.rotation import quat_from_matrix as quat_from_matrix
from jcrowd.motion.rotation import quat_identity as quat_identity
from jcrowd.motion.rotation import quat_inv as quat_inv
from jcrowd.motion.rotation import quat_mul as quat_mul
from jcrowd.motion.rotation import quat_normalize as quat_normalize
from jcrowd.motion.rotation import quat_rotate as quat_rotate
from jcrowd.motion.rotation import quat_slerp as quat_slerp
from jcrowd.motion.rotation import quat_to_euler as quat_to_euler
from jcrowd.motion.rotation import quat_to_expmap as quat_to_expmap
from jcrowd.motion.rotation import quat_to_matrix as quat_to_matrix
from jcrowd.motion.rotation import quat_yaw as quat_yaw
from jcrowd.motion.rotation import yaw_quat as yaw_quat
from jcrowd.motion.skeleton import Skeleton as Skeleton
from jcrowd.motion.skeleton import bone_lengths as bone_lengths
from jcrowd.motion.skeleton import end_site_positions as end_site_positions
from jcrowd.motion.skeleton import forward_kinematics as forward_kinematics
from jcrowd.motion.skeleton import joint_bone_lengths as joint_bone_lengths
from jcrowd.motion.skeleton import kept_ancestor_frame as kept_ancestor_frame
from jcrowd.motion.skeleton import rest_positions as rest_positions
from jcrowd.motion.walker import STANCE_FRACTION as STANCE_FRACTION
from jcrowd.motion.walker import WalkTruth as WalkTruth
from jcrowd.motion.walker import procedural_walk as procedural_walk
from jcrowd.motion.walker import walker_skeleton as walker_skeleton
