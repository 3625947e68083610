"""Tensor algebra for the fit: mode products, HOSVD/HOOI, key levels, natural-mode tensors.

Papers 000 §3.2 and §4 (reduced motion tensors, key accuracy levels by greedy search) and
004 §2 (the actor × style × repetition view).
"""

from jcrowd.tensor.algebra import RESULT as RESULT
from jcrowd.tensor.algebra import Tucker as Tucker
from jcrowd.tensor.algebra import TuckerResult as TuckerResult
from jcrowd.tensor.algebra import fold as fold
from jcrowd.tensor.algebra import hooi as hooi
from jcrowd.tensor.algebra import hosvd as hosvd
from jcrowd.tensor.algebra import mean_squared_error as mean_squared_error
from jcrowd.tensor.algebra import mode_product as mode_product
from jcrowd.tensor.algebra import multi_mode_product as multi_mode_product
from jcrowd.tensor.algebra import reconstruct as reconstruct
from jcrowd.tensor.algebra import relative_error as relative_error
from jcrowd.tensor.algebra import truncate as truncate
from jcrowd.tensor.algebra import unfold as unfold
from jcrowd.tensor.keylevels import AccuracyLevel as AccuracyLevel
from jcrowd.tensor.keylevels import KeyLevel as KeyLevel
from jcrowd.tensor.keylevels import KeyLevels as KeyLevels
from jcrowd.tensor.keylevels import StorageReport as StorageReport
from jcrowd.tensor.keylevels import accuracy_levels as accuracy_levels
from jcrowd.tensor.keylevels import accuracy_tucker as accuracy_tucker
from jcrowd.tensor.keylevels import drop_pose_elements as drop_pose_elements
from jcrowd.tensor.keylevels import key_levels as key_levels
from jcrowd.tensor.keylevels import pca_rank_for_error as pca_rank_for_error
from jcrowd.tensor.keylevels import rank_path as rank_path
from jcrowd.tensor.keylevels import storage_report as storage_report
from jcrowd.tensor.keylevels import tucker_nbytes as tucker_nbytes
from jcrowd.tensor.keylevels import tucker_storage as tucker_storage
from jcrowd.tensor.natural import NaturalModeTensor as NaturalModeTensor
from jcrowd.tensor.natural import natural_mode_tensor as natural_mode_tensor
from jcrowd.tensor.natural import synthesize as synthesize
