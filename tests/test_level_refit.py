"""Per-level refit of kept joints (jcrowd.model.level_refit) and its pieces in the tensor fit.

Oracles: SciPy's least_squares on the same objective written with 3×3 matrices joint by joint
(no shared code: our side uses quaternions and the depth-batched FK); a hand-computed lever
arm on a straight chain; a medoid by brute force for the key posture.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from jcrowd.errors import MotionError
from jcrowd.model.level_refit import refit_kept_rotations, whole_body_error
from jcrowd.model.posevec import PoseLayout
from jcrowd.model.tensor_model import dataset_key_posture, lever_weights
from jcrowd.motion.skeleton import Skeleton

# A small body: pelvis → spine → chest → head, chest → arm → hand, pelvis → thigh → shin.
PARENTS = (-1, 0, 1, 2, 2, 4, 0, 6)
OFFSETS = np.array(
    [
        [0, 0, 0],
        [0, 0.15, 0],
        [0, 0.2, 0],
        [0, 0.15, 0],
        [0.15, 0.1, 0],
        [0.25, 0, 0],
        [0.1, -0.05, 0],
        [0, -0.45, 0],
    ],
    np.float32,
)
SKELETON = Skeleton(
    tuple(f"j{i}" for i in range(8)), PARENTS, OFFSETS, (3,), np.array([[0, 0.1, 0]], np.float32)
)


def _rotations(frames: int, seed: int, spread: float = 0.5) -> np.ndarray:
    rv = np.random.default_rng(seed).normal(0, spread, size=(frames, len(PARENTS), 3))
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat()[:, [3, 0, 1, 2]].reshape(frames, -1, 4)


def _key() -> np.ndarray:
    return _rotations(1, 99, 0.15)[0]


def _positions_loop(rot: np.ndarray) -> np.ndarray:
    """Slow FK: 3×3 matrices, joint by joint, root at the origin."""
    m = Rotation.from_quat(np.asarray(rot, np.float64)[:, [1, 2, 3, 0]]).as_matrix()
    glob = np.zeros((len(PARENTS), 3, 3))
    pos = np.zeros((len(PARENTS), 3))
    for j, p in enumerate(PARENTS):
        if p < 0:
            glob[j] = m[j]
        else:
            glob[j] = glob[p] @ m[j]
            pos[j] = pos[p] + glob[p] @ OFFSETS[j]
    return pos


def _scipy_refit(rot: np.ndarray, kept: tuple[int, ...], key: np.ndarray) -> float:
    """The least sum of squares SciPy finds for one frame, same unknowns and start."""
    frozen = [j for j in range(len(PARENTS)) if j not in kept]
    start = rot.copy()
    start[frozen] = key[frozen]
    target = _positions_loop(rot)
    base = Rotation.from_quat(start[:, [1, 2, 3, 0]])

    def fun(omega: np.ndarray) -> np.ndarray:
        q = start.copy()
        turn = Rotation.from_rotvec(omega.reshape(-1, 3))
        q[list(kept)] = (base[list(kept)] * turn).as_quat()[:, [3, 0, 1, 2]]
        return (_positions_loop(q)[1:] - target[1:]).ravel()

    sol = least_squares(fun, np.zeros(3 * len(kept)), method="trf", xtol=1e-12, ftol=1e-12)
    return float(np.sum(sol.fun**2))


@pytest.mark.parametrize("kept", [(0, 1, 4, 6, 7), (0, 6, 7), (0, 2, 5)])
def test_refit_reaches_scipys_optimum_and_never_loses(kept: tuple[int, ...]) -> None:
    # Deviations of the size captured walks show (0.2 rad per joint, key 0.15 rad off): large
    # random rotations have several local optima, and LM from the same start may find either.
    rot = _rotations(6, 1, 0.2)
    key = _key()
    out = refit_kept_rotations(SKELETON, rot, kept, key)
    frozen = [j for j in range(8) if j not in kept]
    # Frozen joints sit exactly at the key posture.
    np.testing.assert_allclose(np.abs(np.sum(out[:, frozen] * key[frozen], -1)), 1.0, atol=1e-6)
    naive = rot.copy()
    naive[:, frozen] = key[frozen]
    ours = np.sum(whole_body_error(SKELETON, out, rot) ** 2, axis=1)
    before = np.sum(whole_body_error(SKELETON, naive, rot) ** 2, axis=1)
    # LM only takes steps that lower the cost: never above the plain freeze (float32 rounding).
    assert np.all(ours <= before + 1e-7)
    assert np.all(ours < before)  # every frame here has something to gain
    best = np.array([_scipy_refit(rot[f].astype(np.float64), kept, key) for f in range(len(rot))])
    # Twelve float32 LM steps reach SciPy's float64 trust-region optimum from the same start to
    # 1e-6 m² of summed squares (0.4 mm rms over 7 joints); a wrong Jacobian or FK would stall
    # centimetres away. (SciPy's MINPACK "lm" stalls on some of these frames; "trf" does not.)
    np.testing.assert_allclose(ours, best, atol=1e-6)


def test_refit_is_exact_when_the_frozen_joints_are_already_at_the_key() -> None:
    rot = _rotations(4, 2)
    key = _key()
    kept = (0, 1, 2, 3, 4, 5)
    rot[:, 6:] = key[6:]
    out = refit_kept_rotations(SKELETON, rot, kept, key)
    assert np.max(whole_body_error(SKELETON, out, rot)) < 1e-5  # float32 FK


def test_refit_batch_equals_frame_by_frame() -> None:
    # vmap == loop: each frame is its own problem. Compared by the body they put where (FK):
    # float32 rounding differs between batch sizes, and a turn the positions hardly see can
    # drift further than the places do. Run to convergence (30 steps): frame 0 lies in a flat
    # valley where, after 12 steps, batch and single differ by 6e-8 m² of cost but 1.2 mm of
    # place (rounding picks other accept/refuse paths); converged, they agree to 1.6e-5 m here
    # and to 5.3e-5 m in one full-suite run (3 of 120 places; the flat valley again). 1e-4 m
    # (0.1 mm) holds both; frames mixed up between batch and single would be centimetres off.
    rot = _rotations(5, 3, 0.2)
    key, kept = _key(), (0, 2, 6)
    whole = refit_kept_rotations(SKELETON, rot, kept, key, max_steps=30)
    single = np.concatenate(
        [refit_kept_rotations(SKELETON, rot[f : f + 1], kept, key, max_steps=30) for f in range(5)]
    )
    place = np.stack([_positions_loop(q) for q in whole])
    np.testing.assert_allclose(place, np.stack([_positions_loop(q) for q in single]), atol=1e-4)


def test_refit_rejects_bad_input() -> None:
    with pytest.raises(MotionError, match=r"expected rotations \(F, 8, 4\)"):
        refit_kept_rotations(SKELETON, np.zeros((3, 7, 4)), (0, 1), _key())
    with pytest.raises(MotionError, match="with the root"):
        refit_kept_rotations(SKELETON, _rotations(2, 0), (1, 2), _key())


def test_lever_weights_on_a_straight_chain() -> None:
    # Chain 0 → 1 → 2 along y, bones 0.5 and 0.25, an End Site 0.25 above joint 2.
    sk = Skeleton(
        ("a", "b", "c"),
        (-1, 0, 1),
        np.array([[0, 0, 0], [0, 0.5, 0], [0, 0.25, 0]], np.float32),
        (2,),
        np.array([[0, 0.25, 0]], np.float32),
    )
    layout = PoseLayout(3, np.tile([1.0, 0, 0, 0], (3, 1)), np.ones(1))
    w = lever_weights(layout, sk)
    # Points: joints at 0, 0.5, 0.75 and the End Site at 1.0; 3 points besides the root.
    root = np.sqrt((0.5**2 + 0.75**2 + 1.0**2) / 3) / 0.25
    b = np.sqrt((0.25**2 + 0.5**2) / 3) / 0.25
    c = np.sqrt(0.25**2 / 3) / 0.25
    np.testing.assert_allclose(w[layout.tilt], root, rtol=1e-6)
    np.testing.assert_allclose(w[layout.joint(1)], b, rtol=1e-6)
    np.testing.assert_allclose(w[layout.joint(2)], c, rtol=1e-6)
    assert w[layout.height] == w[layout.delta_a] == w[layout.yaw_rate] == 1.0


def test_dataset_key_posture_is_each_joints_medoid() -> None:
    # The thigh turns about x: four frames 0–0.15 rad and one at 1.2 rad. The key frame (003
    # Eq. 2, measured on the shin it carries) is the one closest to all others: the median.
    angles = np.array([0.0, 0.05, 0.1, 0.15, 1.2])
    rot = np.tile(np.array([1.0, 0, 0, 0]), (5, len(PARENTS), 1))
    rot[:, 6] = Rotation.from_rotvec(np.outer(angles, [1, 0, 0])).as_quat()[:, [3, 0, 1, 2]]
    key = dataset_key_posture(SKELETON, rot)
    np.testing.assert_allclose(key[6], rot[2, 6], atol=1e-7)
    # Key rotations are captured ones (003 §4.2): each joint's is one of its frames'.
    rnd = _rotations(30, 5)
    key = dataset_key_posture(SKELETON, rnd)
    for j in range(len(PARENTS)):
        assert np.min(np.max(np.abs(rnd[:, j] - key[j]), axis=-1)) < 1e-6
