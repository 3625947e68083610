"""Joint simplification: motion levels of detail with rigid constraints (paper 003 §4–6).

- :mod:`~jcrowd.simplify.analysis`: posture error, key posture, joint importance (Eq. 1–3);
- :mod:`~jcrowd.simplify.levels`: frozen joints, level skeletons, the position problem (Eq. 5–8);
- :mod:`~jcrowd.simplify.sqp`: the per-frame SQP with jaxopt QP subproblems;
- :mod:`~jcrowd.simplify.pipeline`: :func:`simplify_motion`; :mod:`~jcrowd.simplify.recover`:
  rotation recovery from the optimised positions.
"""

from jcrowd.simplify.analysis import analyse_motion as analyse_motion
from jcrowd.simplify.analysis import elimination_order as elimination_order
from jcrowd.simplify.analysis import joint_importance as joint_importance
from jcrowd.simplify.analysis import key_posture as key_posture
from jcrowd.simplify.analysis import posture_error as posture_error
from jcrowd.simplify.levels import Weights as Weights
from jcrowd.simplify.levels import joint_counts as joint_counts
from jcrowd.simplify.levels import pair_safe_counts as pair_safe_counts
from jcrowd.simplify.pipeline import SimplifiedLevel as SimplifiedLevel
from jcrowd.simplify.pipeline import SimplifiedLevels as SimplifiedLevels
from jcrowd.simplify.pipeline import simplify_motion as simplify_motion
from jcrowd.simplify.sqp import RESULT as RESULT
