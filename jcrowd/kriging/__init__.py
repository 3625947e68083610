"""Universal kriging over control space (DESIGN §2 ``kriging/``, §4 step 8; papers 001, 000 §3.3).

- :mod:`~jcrowd.kriging.variogram` — experimental variograms (Matheron, Cressie–Hawkins), the
  spherical and stable models (001 §4.1–4.2);
- :mod:`~jcrowd.kriging.variogram_fit` — Cressie's weighted least-squares fit (001 App. A Eq. 4);
- :mod:`~jcrowd.kriging.system` — trend hyperplane, Γ and the solution operator of the kriging
  system, precomputed once at fit time (001 Eq. 2–3);
- :mod:`~jcrowd.kriging.crossval` — the exponent p by leave-one-out cross-validation (001 App. A);
- :mod:`~jcrowd.kriging.universal` — :class:`KrigingModel`, weights, predictions, prediction
  variance and reliability (000 Eq. 8, 001 App. B);
- :mod:`~jcrowd.kriging.reduction` — greedy sample reduction by reliability (001 §5.2);
- :mod:`~jcrowd.kriging.rbf` — the baselines: verbs-and-adverbs RBF, nearest sample.

Fit-time code is NumPy float64; the models hold float32 ``jax.Array`` by default and their
queries are ``jnp`` kernels for one control vector, batched with ``vmap``.
"""

from jcrowd.errors import KrigingError as KrigingError
from jcrowd.kriging.crossval import DEFAULT_EXPONENTS as DEFAULT_EXPONENTS
from jcrowd.kriging.crossval import ExponentChoice as ExponentChoice
from jcrowd.kriging.crossval import choose_exponent as choose_exponent
from jcrowd.kriging.crossval import leave_one_out as leave_one_out
from jcrowd.kriging.rbf import RBFModel as RBFModel
from jcrowd.kriging.rbf import fit_rbf as fit_rbf
from jcrowd.kriging.rbf import predict_nearest as predict_nearest
from jcrowd.kriging.rbf import predict_rbf as predict_rbf
from jcrowd.kriging.reduction import Reduction as Reduction
from jcrowd.kriging.reduction import greedy_reduction as greedy_reduction
from jcrowd.kriging.universal import KrigingModel as KrigingModel
from jcrowd.kriging.universal import fit_kriging as fit_kriging
from jcrowd.kriging.universal import kriging_variance as kriging_variance
from jcrowd.kriging.universal import kriging_weights as kriging_weights
from jcrowd.kriging.universal import kriging_weights_batch as kriging_weights_batch
from jcrowd.kriging.universal import normalise_controls as normalise_controls
from jcrowd.kriging.universal import predict as predict
from jcrowd.kriging.universal import predict_from_weights as predict_from_weights
from jcrowd.kriging.universal import prediction_variance as prediction_variance
from jcrowd.kriging.universal import reliability as reliability
from jcrowd.kriging.variogram import ExperimentalVariogram as ExperimentalVariogram
from jcrowd.kriging.variogram import experimental_variogram as experimental_variogram
from jcrowd.kriging.variogram import pairwise_dissimilarity as pairwise_dissimilarity
from jcrowd.kriging.variogram import semivariogram as semivariogram
from jcrowd.kriging.variogram import spherical as spherical
from jcrowd.kriging.variogram import stable as stable
from jcrowd.kriging.variogram_fit import RESULT as RESULT
from jcrowd.kriging.variogram_fit import VariogramFit as VariogramFit
from jcrowd.kriging.variogram_fit import fit_variogram as fit_variogram
from jcrowd.kriging.variogram_fit import make_variogram as make_variogram
