"""The fitted universal-kriging model: its arrays and their shapes (paper 000 Eq. 8).

:func:`~jcrowd.kriging.universal.fit_kriging` builds it; the queries in
:mod:`~jcrowd.kriging.universal` read it. An :class:`equinox.Module` of arrays (float32 by
default), so it passes through ``jit``, ``vmap`` and the model file as a pytree.
"""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Float, Int

from jcrowd.errors import KrigingError
from jcrowd.kriging.variogram_fit import VariogramFit

__all__ = ["KrigingModel"]


class KrigingModel(eqx.Module):
    """A fitted universal-kriging model (paper 000 Eq. 8), arrays only.

    Attributes:
        controls: ``(S, d)`` sample controls in the caller's units.
        control_mean, control_scale: ``(d,)`` normalisation ``ĉ = (c − mean) / scale``. Lags
            are ``‖(c − c_i) / scale‖``, computed from the differences in caller units so that
            a query equal to a sample is at lag exactly 0 (normalising both first would round
            them apart, and with a nugget γ jumps from 0 to θ0 there).
        trend: ``(d + 1, V)`` hyperplane, ``trend(c) = [1, ĉ] @ trend`` (ĉ normalised).
        residuals: ``(S, V)`` flattened residuals K_{r,i} = K_i − trend(c_i).
        gamma_operator, drift_operator: ``(S, S)``, ``(S, q)``: ``b = M_γ γ(c) + M_f f(c)``.
        lagrange_gamma, lagrange_drift: ``(q, S)``, ``(q, q)``: the multipliers likewise.
        variogram: the :class:`~jcrowd.kriging.variogram_fit.VariogramFit` in normalised units.
        dropped: eigen-directions cut from the system as numerically singular (0 normally).
        value_shape: shape of one sample value (static).
        system: ``"residual"`` (the papers) or ``"drift"`` (static; see
            :mod:`~jcrowd.kriging.system`). q = 1 or d + 1.
    """

    controls: Float[jax.Array, "S d"]
    control_mean: Float[jax.Array, " d"]
    control_scale: Float[jax.Array, " d"]
    trend: Float[jax.Array, "d1 V"]
    residuals: Float[jax.Array, "S V"]
    gamma_operator: Float[jax.Array, "S S"]
    drift_operator: Float[jax.Array, "S q"]
    lagrange_gamma: Float[jax.Array, "q S"]
    lagrange_drift: Float[jax.Array, "q q"]
    variogram: VariogramFit
    dropped: Int[jax.Array, ""]
    value_shape: tuple[int, ...] = eqx.field(static=True)
    system: str = eqx.field(static=True)

    def __check_init__(self) -> None:
        s, d = self.controls.shape
        q = 1 if self.system == "residual" else d + 1
        expected = {
            "control_mean": (d,),
            "control_scale": (d,),
            "trend": (d + 1, self.residuals.shape[1]),
            "residuals": (s, int(np.prod(self.value_shape, dtype=np.int64))),
            "gamma_operator": (s, s),
            "drift_operator": (s, q),
            "lagrange_gamma": (q, s),
            "lagrange_drift": (q, q),
        }
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise KrigingError(
                    f"KrigingModel.{name}: expected shape {shape}, found "
                    f"{getattr(self, name).shape}"
                )

    @property
    def num_samples(self) -> int:
        return int(self.controls.shape[0])
