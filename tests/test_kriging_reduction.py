"""Greedy sample reduction by reliability (paper 001 §5.2) against fitted models on subsets."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from jcrowd.errors import KrigingError
from jcrowd.kriging import fit_kriging, greedy_reduction, make_variogram, reliability

VG = make_variogram([0.0, 1.0, 0.5], 1.0)  # exponential, no nugget, control units


def _design():
    """A 5×5 grid plus four points close to grid points (the redundant ones)."""
    g = np.linspace(0, 1, 5)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    extra = grid[[6, 8, 16, 18]] + 0.02
    c = np.concatenate([grid, extra])
    return c, np.sin(3 * c[:, 0]) + c[:, 1]


def _loo_reliability(c, z, active, i):
    """ρ at c_i from a model fitted (float64) on the active samples without i."""
    keep = [k for k in active if k != i]
    with jax.enable_x64(True):
        model = fit_kriging(c[keep], z[keep], VG, normalise=False, dtype=np.float64)
        return float(reliability(model, c[i][None])[0])


def test_first_step_matches_refits_and_stops_below_tau():
    c, z = _design()
    tau = 0.6
    red = greedy_reduction(c, z, tau, variogram=VG, normalise=False)
    s = len(c)
    assert sorted([*red.kept.tolist(), *red.removed.tolist()]) == list(range(s))
    assert red.counts.tolist() == list(range(s, s - len(red.counts), -1))
    assert np.all(red.max_reliability[: len(red.removed)] >= tau)
    assert red.stopped == "threshold" and red.max_reliability[-1] < tau
    # Oracle for the first decision: refit without each sample and ask the model.
    rho = [_loo_reliability(c, z, range(s), i) for i in range(s)]
    assert red.removed[0] == int(np.argmax(rho))
    # float64 both ways; cut-off n·eps32 vs none: ~1e-9 on this regular design.
    assert red.max_reliability[0] == pytest.approx(max(rho), abs=1e-8)
    assert set(red.removed[:4].tolist()) & set(range(25, 29))  # a near-duplicate goes first
    # The paper's greedy checks a sample only when it is removed; report where they end up.
    assert red.final_reliability.shape == red.removed.shape


def test_strict_keeps_every_removed_sample_reliable():
    c, z = _design()
    tau = 0.6
    red = greedy_reduction(c, z, tau, variogram=VG, normalise=False, strict=True)
    assert len(red.removed) > 0
    assert np.all(red.final_reliability >= tau - 1e-12)


def test_limits_and_errors():
    c, z = _design()
    none = greedy_reduction(c, z, 1.5, variogram=VG)
    assert len(none.removed) == 0 and none.stopped == "threshold"
    floor = greedy_reduction(c, z, -10.0, variogram=VG)
    assert len(floor.kept) == 4 and floor.stopped == "min_samples"  # d + 2
    auto = greedy_reduction(c, z, 0.9)  # variogram fitted by cross-validation
    assert len(auto.kept) + len(auto.removed) == len(c)
    with pytest.raises(KrigingError, match="finite"):
        greedy_reduction(c, z, float("nan"))
