"""Per-agent synthesis (jcrowd.crowd.synthesis) against the offline decode of
jcrowd.model.motion_model."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd import load_default_model
from jcrowd.crowd.synthesis import (
    _factor_cores,
    build_decoders,
    clip_core,
    clip_weights,
    coeffs_at,
    decode_coeffs,
    level_points,
    pose_from_coeffs,
    root_rates,
)
from jcrowd.model import decode_pose_vectors, level_pose_vectors, synthesize_clip
from jcrowd.motion import end_site_positions, forward_kinematics, rest_forward
from jcrowd.motion.rotation import quat_yaw


@pytest.fixture(scope="module")
def setup():
    model = load_default_model()
    return model, build_decoders(model)


def _closed(y):
    """The cycle closed by hand: every element but the rates (velocity 1–2, yaw rate 3, ΔA
    last) minus its end-to-start difference times τ / (T − 1)."""
    t = np.arange(len(y))[:, None] / (len(y) - 1)
    rows = np.ones(y.shape[1], bool)
    rows[[1, 2, 3, y.shape[1] - 1]] = False
    return y - t * (y[-1] - y[0]) * rows


def _reference_points(model, c, level, height):
    """Oracle: the offline path — kriged pose vectors closed over the cycle (:func:`_closed`),
    full decode, full-skeleton FK."""
    y = _closed(level_pose_vectors(model, np.asarray(c), level))
    skel = model.skeleton.scaled(height)
    motion, _ = decode_pose_vectors(y, model.layout, skel, height, model.fps)
    rot, pos = forward_kinematics(
        skel, np.asarray(motion.rotations, np.float64), np.asarray(motion.root_positions)
    )
    ends = end_site_positions(skel, rot, pos)
    yaw = np.concatenate([[0.0], np.cumsum(y[:-1, model.layout.yaw_rate])])
    return np.concatenate([pos, ends], axis=1), np.asarray(motion.root_positions), yaw


@pytest.mark.parametrize("level", [0, 2, 5])
def test_agent_decode_equals_offline_synthesis(setup, level):
    model, dec = setup
    c = np.array([0.1, 1.2, 0.4])
    height = 1.7
    ref, root, yaw = _reference_points(model, c, level, height)
    a = clip_weights(dec, jnp.asarray(c, jnp.float32))
    lv = dec.levels[level]
    for t in (0, 17, 50, 99):
        y = pose_from_coeffs(lv, decode_coeffs(lv, a, jnp.float32(t)))
        pts = level_points(lv, y, jnp.asarray(root[t, [0, 2]]), jnp.float32(yaw[t]), height)
        # float32 decode (tables, FK) vs the float64 offline path on a 1.7 m body: 1 mm.
        np.testing.assert_allclose(np.asarray(pts), ref[t], atol=1e-3)


@pytest.mark.parametrize("level", [0, 3, 5])
def test_a_cycle_ends_in_the_pose_it_starts_with(setup, level):
    """The step's decode closes each clip's cycle (:func:`jcrowd.model.posevec.cycle_closing`):
    at τ = T − 1 every pose element equals its value at τ = 0 (the offline, unclosed cycles
    differ there by tenths of a radian), the rates equal the offline ones at every τ, and a
    fractional τ matches the hand-closed offline vectors interpolated linearly."""
    model, dec = setup
    lv = dec.levels[level]
    last = lv.u_time.shape[0] - 1
    rows = np.ones(model.layout.size, bool)
    rows[[1, 2, 3, model.layout.size - 1]] = False
    keep = np.concatenate(
        [np.arange(7), model.layout.joint_elements(sorted(set(model.levels[level].joints) - {0}))]
    )
    for c in ([0.1, 1.2, 0.4], [-0.2, 0.9, -0.6], [0.0, 1.5, 0.0]):
        y_off = level_pose_vectors(model, np.asarray(c), level)
        assert np.abs(y_off[-1, rows] - y_off[0, rows]).max() > 0.02  # open offline
        core = clip_core(lv, clip_weights(dec, jnp.asarray(c, jnp.float32)))
        y = {
            t: np.asarray(pose_from_coeffs(lv, coeffs_at(lv, core, jnp.float32(t))))
            for t in (0, 37.5, last)
        }
        body = rows[keep]  # pose rows among the level's own (root rows and kept joints)
        np.testing.assert_allclose(y[last][:-1][body], y[0][:-1][body], atol=1e-5)
        want = _closed(y_off)
        mid = 0.5 * (want[37] + want[38])
        np.testing.assert_allclose(y[37.5][:-1], mid[keep], atol=2e-4)
        np.testing.assert_allclose(y[37.5][-1], mid[-1], rtol=1e-4)
        np.testing.assert_allclose(y[0][[1, 2, 3]], y_off[0, [1, 2, 3]], atol=1e-5)


def test_root_rates_integrate_to_the_offline_root_path(setup):
    """One agent's heading and root position, integrated from :func:`root_rates` the way the
    crowd step does (``_agent_level``: ``dτ = dt·fps/ΔA``, ``dyaw = yaw_rate·dτ``, velocity
    rotated by the heading), follow the root of the offline :func:`synthesize_clip` of the same
    turning clip frame by frame. Guards against a wrong sign, row or scale of the root rates
    (a flipped yaw rate turns the agent right where the clip turns left)."""
    model, dec = setup
    c = [0.0, 1.3, 0.5]  # 1.3 m forward, turning 0.5 rad left over the cycle
    clip = synthesize_clip(model, c, 0)  # default height, from the origin facing +Z
    root = np.asarray(clip.root_positions, np.float64)[:, [0, 2]]
    rot = np.asarray(clip.rotations, np.float64)[:, 0]
    heading_ref = np.unwrap(quat_yaw(rot, rest_forward(clip.skeleton)))
    assert heading_ref[-1] > 0.4  # the oracle turns left, far more than the tolerance below

    lv = dec.levels[0]
    core = clip_core(lv, clip_weights(dec, jnp.asarray(c, jnp.float32)))

    @jax.jit
    def rates(tau):
        r = root_rates(pose_from_coeffs(lv, coeffs_at(lv, core, tau)))
        return r.velocity, r.yaw_rate, r.delta_a

    h, dt = model.default_height, 1.0 / model.fps  # one step per frame of the offline clip
    tau, heading, xz = 0.0, 0.0, np.zeros(2)
    headings, path = [heading], [xz]
    for _ in range(clip.num_frames - 1):
        v, yaw_rate, delta_a = (np.asarray(r, np.float64) for r in rates(jnp.float32(tau)))
        dtau = dt * model.fps / delta_a
        d = v * h * dtau  # (x left, z forward) in the heading frame; heading θ faces (sin, cos)
        s, co = np.sin(heading), np.cos(heading)
        xz = xz + np.array([d[0] * co + d[1] * s, -d[0] * s + d[1] * co])
        heading, tau = heading + yaw_rate * dtau, tau + dtau
        headings.append(heading)
        path.append(xz)
    assert tau < lv.u_time.shape[0] - 1  # the cycle was not cut short by τ's clamp

    # The agent integrates the rates linearly interpolated in τ with the step's Euler rule;
    # the offline decode sums them per aligned frame, then resamples onto the model clock,
    # and its heading (read from the root rotation) carries the tilt's small yaw wobble.
    # Measured: 0.009 rad and 5 mm at most over the 66 frames; a flipped yaw rate is ~1 rad off.
    np.testing.assert_allclose(np.array(headings), heading_ref, rtol=0, atol=0.03)
    # 2 cm on a 1.2 m cycle of a 1.42 m character (same sources as above).
    np.testing.assert_allclose(np.array(path), root, rtol=0, atol=0.02)


def test_fractional_tau_interpolates_rows(setup):
    """w_T(τ) is linear between rows (000 Eq. 5): g(t + f) = (1 − f) g(t) + f g(t + 1)."""
    _, dec = setup
    lv = dec.levels[1]
    a = clip_weights(dec, jnp.asarray([0.0, 1.3, -0.2], jnp.float32))
    g0, g1 = decode_coeffs(lv, a, jnp.float32(10)), decode_coeffs(lv, a, jnp.float32(11))
    g = decode_coeffs(lv, a, jnp.float32(10.25))
    np.testing.assert_allclose(
        np.asarray(g), 0.75 * np.asarray(g0) + 0.25 * np.asarray(g1), rtol=1e-5, atol=1e-5
    )


def test_weights_are_level_independent(setup):
    """One variogram per model: the kriging operators of every level are identical."""
    model, _ = setup
    ops = [np.asarray(lv.kriging.gamma_operator) for lv in model.levels]
    for op in ops[1:]:
        np.testing.assert_array_equal(op, ops[0])


def test_vmap_equals_loop_and_jit_equals_eager(setup):
    _, dec = setup
    lv = dec.levels[3]
    rng = np.random.default_rng(0)
    c = jnp.asarray(rng.uniform([-0.3, 0.9, -0.8], [0.3, 1.5, 0.8], (5, 3)), jnp.float32)
    tau = jnp.asarray(rng.uniform(0, 99, 5), jnp.float32)

    def one(ci, ti):
        y = pose_from_coeffs(lv, decode_coeffs(lv, clip_weights(dec, ci), ti))
        return level_points(lv, y, jnp.zeros(2), jnp.float32(0.3), jnp.float32(1.6))

    batched = jax.jit(jax.vmap(one))(c, tau)
    loop = np.stack([np.asarray(one(ci, ti)) for ci, ti in zip(c, tau, strict=True)])
    # Same float32 operations, fused differently by XLA: a few ulps of metre-sized values.
    np.testing.assert_allclose(np.asarray(batched), loop, atol=2e-6)


def test_coarse_level_keeps_bone_lengths(setup):
    """Frozen joints ride rigidly on their kept ancestor: every bone keeps its rest length."""
    model, dec = setup
    lv = dec.levels[5]
    a = clip_weights(dec, jnp.asarray([0.0, 1.2, 0.0], jnp.float32))
    y = pose_from_coeffs(lv, decode_coeffs(lv, a, jnp.float32(33.3)))
    pts = np.asarray(level_points(lv, y, jnp.zeros(2), jnp.float32(0.0), jnp.float32(1.0)))
    skel = model.skeleton
    parents = list(skel.parents) + list(skel.end_parents)
    rest = np.concatenate(
        [np.asarray(skel.offsets), np.asarray(skel.end_offsets_or_empty())], axis=0
    )
    for i, p in enumerate(parents):
        if p >= 0:
            length = np.linalg.norm(pts[i] - pts[p])
            assert length == pytest.approx(np.linalg.norm(rest[i]), abs=1e-5)


def _stored_cores(model, level):
    """``V`` as the model file holds it: residual cores, then trend planes (float64)."""
    k = model.levels[level].kriging
    v = np.concatenate([np.asarray(k.residuals, np.float64), np.asarray(k.trend, np.float64)])
    return v.reshape(v.shape[0], -1)


@pytest.mark.parametrize("level", [0, 3, 5])
def test_factored_cores_reproduce_the_stored_cores(setup, level):
    """``V = M W`` (synthesis._factor_cores) holds to float32 rounding, and the core of a clip
    through the factors equals ``a V`` computed in float64 from the model file."""
    model, dec = setup
    lv = dec.levels[level]
    v = _stored_cores(model, level)
    assert lv.mix_basis is not None  # the default model's V is low rank at every level
    assert lv.mix_basis.shape[1] < v.shape[0]
    scale = np.abs(v).max()
    # Two float32 factors (entries ~|V|) multiplied in float32: ~1e-6 of the largest entry.
    np.testing.assert_allclose(np.asarray(lv.mix_cores()), v, atol=2e-6 * scale)
    a = clip_weights(dec, jnp.asarray([0.05, 1.1, -0.3], jnp.float32))
    core = np.asarray(clip_core(lv, a)).ravel()
    oracle = np.asarray(a, np.float64) @ v
    np.testing.assert_allclose(core, oracle, atol=2e-6 * np.abs(a).sum() * scale)


@settings(max_examples=25, deadline=None)
@given(
    st.integers(2, 12),
    st.integers(1, 12),
    st.integers(20, 60),
    st.integers(0, 2**31 - 1),
)
def test_factor_cores_finds_the_rank(rows, rank, cols, seed):
    """A product of random ``(A, q)`` and ``(q, RR)`` factors is found to have rank ``min(q,
    A)``, and the factors multiply back to it; when factoring would not save work it is left
    whole."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(rows, rank)) @ rng.normal(size=(rank, cols))
    q = min(rank, rows)
    basis, cores = _factor_cores(v)
    if q * (rows + cols) >= rows * cols:
        assert basis is None
        np.testing.assert_array_equal(cores, v)
    else:
        assert basis is not None
        assert basis.shape == (rows, q) and cores.shape == (q, cols)
        np.testing.assert_allclose(basis @ cores, v, atol=1e-9 * np.abs(v).max())


def test_full_rank_cores_stay_whole():
    v = np.random.default_rng(0).normal(size=(6, 40))
    basis, cores = _factor_cores(v)
    assert basis is None and cores is v
