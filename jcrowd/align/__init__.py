"""Time alignment of motion samples (DESIGN §2 ``align``, §4 step 4; papers 001 §3.5, 004 §3).

- :mod:`~jcrowd.align.features` — per-frame features: joint point cloud in the heading frame,
  physics features (COM acceleration, segment angular momenta).
- :mod:`~jcrowd.align.anthropometry` — segment masses and COM positions for any skeleton.
- :mod:`~jcrowd.align.costs` — local costs (Euclidean, paper 004's inner product).
- :mod:`~jcrowd.align.dtw` — exact DTW, full or banded, on features or a cost matrix.
- :mod:`~jcrowd.align.multiscale` — coarse-to-fine DTW.
- :mod:`~jcrowd.align.warp` — time warp ``A``, resampling to ``T`` frames, ``ΔA`` and back.

Everything here is NumPy float64 host code: DTW is a sequential dynamic programme over
data-dependent lengths, run once per sample at fit time.
"""

from __future__ import annotations

from jcrowd.align.anthropometry import DE_LEVA_MALE as DE_LEVA_MALE
from jcrowd.align.anthropometry import BodySegments as BodySegments
from jcrowd.align.anthropometry import body_segments as body_segments
from jcrowd.align.costs import AlignError as AlignError
from jcrowd.align.costs import Metric as Metric
from jcrowd.align.costs import cost_matrix as cost_matrix
from jcrowd.align.dtw import DTWResult as DTWResult
from jcrowd.align.dtw import band_window as band_window
from jcrowd.align.dtw import dtw as dtw
from jcrowd.align.features import center_of_mass as center_of_mass
from jcrowd.align.features import physics_features as physics_features
from jcrowd.align.features import pose_features as pose_features
from jcrowd.align.features import to_heading_frame as to_heading_frame
from jcrowd.align.multiscale import downsample_pairs as downsample_pairs
from jcrowd.align.multiscale import multiscale_dtw as multiscale_dtw
from jcrowd.align.warp import Alignment as Alignment
from jcrowd.align.warp import align_to_reference as align_to_reference
from jcrowd.align.warp import invert_warp as invert_warp
from jcrowd.align.warp import resample_warp as resample_warp
from jcrowd.align.warp import sample_motion as sample_motion
from jcrowd.align.warp import time_warp as time_warp
from jcrowd.align.warp import warp_from_increments as warp_from_increments
from jcrowd.align.warp import warp_increments as warp_increments
