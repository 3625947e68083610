"""Planted feet (jcrowd.motion.planting): the two-bone solution against its closed form, a
planted foot held still while the decoded one slides, its release eased, and the transforms."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.motion.planting import (
    MAX_SLIP,
    RELEASE_SHARE,
    SOFT_REACH,
    STANCE_SHARE,
    leg_chains,
    plant_feet,
    plant_sequence,
    reach,
    warp_stride,
)

# A toy skeleton's points: root 0; left hip 1, knee 2, ankle 3, toe 4; right 5–8; the toes' End
# Sites 9 and 10 (children of the toes).
PARENTS = (-1, 0, 1, 2, 3, 0, 5, 6, 7, 4, 8)
FEET = (3, 4, 7, 8)
LAST = 99.0
START = (0.0, 49.5)


def _leg(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    hip = rng.normal(size=3)
    knee = hip + np.array([0.0, -0.45, 0.0]) + rng.normal(scale=0.08, size=3)
    ankle = knee + np.array([0.0, -0.42, 0.0]) + rng.normal(scale=0.08, size=3)
    toe = ankle + np.array([0.0, -0.05, 0.14])
    return hip, knee, ankle, toe


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(-0.25, 0.25), st.floats(-0.25, 0.25))
def test_reach_keeps_bones_and_hits_reachable_targets(seed, dx, dz):
    """Thigh and shin keep their lengths; a target within the soft reach is met; one beyond it
    is met on the hip–target line at the softened distance (closed form)."""
    hip, knee, ankle, toe = _leg(np.random.default_rng(seed))
    target = ankle + np.array([dx, 0.0, dz])
    k, a = (
        np.asarray(v, np.float64) for v in reach(*map(jnp.asarray, (hip, knee, ankle, toe, target)))
    )
    l1, l2 = np.linalg.norm(knee - hip), np.linalg.norm(ankle - knee)
    np.testing.assert_allclose(np.linalg.norm(k - hip), l1, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(a - k), l2, atol=1e-5)
    d = np.linalg.norm(target - hip)
    full = l1 + l2
    start = max((1 - SOFT_REACH) * full, np.linalg.norm(ankle - hip))
    if abs(l1 - l2) + 1e-4 < d <= start:
        np.testing.assert_allclose(a, target, atol=1e-5)
    elif d > start:
        soft = full - start
        want = start + soft * (1 - np.exp(-(d - start) / soft))
        np.testing.assert_allclose(a, hip + want * (target - hip) / d, atol=1e-4)


def test_the_knee_straightens_at_a_bounded_rate():
    """A target pulled past full reach straightens the knee at most as fast as the target
    moves (a hard clamp at full reach swings it by 1.4 cm over the last millimetre here)."""
    hip, knee, ankle = (
        np.array([0.0, 1.0, 0.0]),
        np.array([0.0, 0.55, 0.12]),
        np.array([0, 0.1, 0.0]),
    )
    toe = ankle + np.array([0.0, 0.0, 0.14])
    down = np.array([0.0, -1.0, 0.0])
    steps = np.arange(0.0, 0.2, 0.001)
    go = jax.vmap(lambda t: reach(*map(jnp.asarray, (hip, knee, ankle, toe)), t))
    k, _ = go(jnp.asarray(ankle + steps[:, None] * down))
    moved = np.linalg.norm(np.diff(np.asarray(k), axis=0), axis=-1)
    assert moved.max() < 2 * 0.001


def test_reach_at_the_decoded_ankle_keeps_a_bent_knee():
    """Asked for the ankle where it is, a bent leg comes back unchanged."""
    hip, knee, ankle = (
        np.array([0.0, 1.0, 0.0]),
        np.array([0.0, 0.55, 0.1]),
        np.array([0, 0.1, 0.0]),
    )
    toe = ankle + np.array([0.0, 0.0, 0.14])
    k, a = reach(*map(jnp.asarray, (hip, knee, ankle, toe, ankle)))
    np.testing.assert_allclose(k, knee, atol=1e-5)
    np.testing.assert_allclose(a, ankle, atol=1e-5)


def test_reach_bends_the_knee_forward_not_back():
    """The ankle pulled in under the hip bends the knee to the side it was bent to."""
    hip, knee, ankle = (
        np.array([0.0, 1.0, 0.0]),
        np.array([0.0, 0.55, 0.02]),
        np.array([0, 0.1, 0.0]),
    )
    toe = ankle + np.array([0.0, 0.0, 0.14])
    k, _ = reach(*map(jnp.asarray, (hip, knee, ankle, toe, ankle + np.array([0.0, 0.1, 0.0]))))
    assert float(k[2]) > 0.05


def _walker(frames: int, slide: float) -> tuple[np.ndarray, np.ndarray]:
    """Points of a toy walker standing still whose left ankle and toe slide along +x by
    ``slide`` m per frame (a decoded foot sliding in stance), and its phases (a cycle over
    ``frames`` frames, the left stance from phase 0)."""
    p = np.zeros((len(PARENTS), 3))
    p[1], p[2], p[3], p[4] = [0.1, 1.0, 0], [0.1, 0.55, 0.08], [0.1, 0.1, 0], [0.1, 0.05, 0.14]
    p[5:9] = p[1:5] * [-1, 1, 1]
    p[9], p[10] = p[4] + [0, 0, 0.05], p[8] + [0, 0, 0.05]
    pts = np.repeat(p[None], frames, axis=0)
    move = np.arange(frames)[:, None] * slide
    for j in (3, 4, 9):
        pts[:, j, 0] += move[:, 0]
    tau = np.arange(frames) * LAST / frames
    return pts.astype(np.float32), tau.astype(np.float32)


def test_a_planted_foot_stays_and_lets_go_smoothly():
    """Over its stance the left toe (the planted joint: lower than the ankle) does not move
    while the decoded foot slides; after the stance the offset eases out over the swing's
    first part, continuous at the release (no step larger than the decoded slide plus the
    eased offset's largest per-frame change, 1.5 offset ÷ frames of the ease)."""
    legs = leg_chains(PARENTS, FEET)
    frames, slide = 100, 0.001
    pts, tau = _walker(frames, slide)
    out = np.asarray(plant_sequence(legs, START, LAST, jnp.asarray(pts), jnp.asarray(tau), 1.0))
    stance = int(STANCE_SHARE * frames)  # frames 0 .. stance − 1 planted
    toe = out[:stance, 4, [0, 2]]
    np.testing.assert_allclose(toe, np.repeat(toe[:1], stance, axis=0), atol=1e-5)
    held = slide * stance  # the offset let go of at the release frame
    assert held < MAX_SLIP
    ease = RELEASE_SHARE * (frames - stance)
    steps = np.linalg.norm(np.diff(out[stance - 1 :, 4, [0, 2]], axis=0), axis=1)
    assert steps[0] <= slide + 1e-5  # continuous at the release itself
    assert steps.max() <= slide + 1.5 * held / ease + 1e-5
    # Eased out: past the release the foot is back on its decoded path.
    np.testing.assert_allclose(out[-5:, 4], pts[-5:, 4], atol=1e-6)
    # The right foot's decoded points do not move, and planted they stay where they are.
    np.testing.assert_allclose(out[:, 5:9], pts[:, 5:9], atol=1e-5)


@settings(max_examples=25, deadline=None)
@given(
    heading=st.floats(-np.pi, np.pi),
    stride=st.floats(0.0, 1.0),
    ahead=st.floats(-0.4, 0.4),
)
def test_a_stride_warp_scales_the_feet_forward_offset_from_the_hips(heading, stride, ahead):
    """warp_stride on a toy walker turned to ``heading`` with its left foot ``ahead`` m in front
    of its hip: in the body's frame (a rotation by −heading, by hand) the left ankle sits
    ``stride · ahead`` in front of the hip, sideways and vertically where it was; the toe and
    its End Site move with the ankle; hips, knees and the right foot (under its hip) stay."""
    legs = leg_chains(PARENTS, FEET)
    p, _ = _walker(1, 0.0)
    p = p[0].astype(np.float64)
    p[[3, 4, 9], 2] += ahead  # body frame: +z forward
    c, s = np.cos(heading), np.sin(heading)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # +z → (sin θ, 0, cos θ)
    world = p @ rot.T
    out = np.asarray(
        warp_stride(
            legs, jnp.asarray(world, jnp.float32), jnp.float32(heading), jnp.float32(stride)
        ),
        np.float64,
    )
    body = out @ rot  # back into the body frame
    want = p.copy()
    want[[3, 4, 9], 2] -= (1.0 - stride) * ahead
    np.testing.assert_allclose(body, want, atol=2e-6)


def test_stride_warp_transforms():
    """warp_stride and plant_feet with a warp: jit == eager, and vmap over agents == a loop."""
    legs = leg_chains(PARENTS, FEET)
    pts, tau = _walker(3, 0.0)
    pts[:, [3, 4, 9], 2] += np.array([0.3, -0.2, 0.1])[:, None]
    heading = jnp.array([0.3, -2.0, 3.0], jnp.float32)
    stride = jnp.array([0.0, 0.4, 1.0], jnp.float32)
    carry = (jnp.zeros((2, 2)), jnp.zeros(2, bool), jnp.zeros(2, bool))

    def one(p, t, h, k):
        return plant_feet(legs, START, LAST, p, t, jnp.float32(1.0), *carry, h, k)

    batched = jax.vmap(one)(jnp.asarray(pts), jnp.asarray(tau), heading, stride)
    jitted = jax.jit(one)
    for i in range(3):
        args = (jnp.asarray(pts[i]), jnp.asarray(tau[i]), heading[i], stride[i])
        with jax.disable_jit():
            eager = one(*args)
        for b, j, e in zip(batched, jitted(*args), eager, strict=True):
            np.testing.assert_allclose(b[i], e, atol=1e-6)
            np.testing.assert_allclose(j, e, atol=1e-6)


def test_planting_transforms():
    """The scanned sequence == the per-frame step in a Python loop, eager; jit == eager for
    one frame; and vmap over agents == a loop."""
    legs = leg_chains(PARENTS, FEET)
    pts, tau = _walker(40, 0.002)
    args = (jnp.asarray(pts), jnp.asarray(tau), jnp.float32(1.0))
    scanned = plant_sequence(legs, START, LAST, *args)
    carry = (jnp.zeros((2, 2)), jnp.zeros(2, bool), jnp.zeros(2, bool))
    for f in range(len(pts)):
        with jax.disable_jit():
            out, *rest = plant_feet(legs, START, LAST, args[0][f], args[1][f], 1.0, *carry)
        carry = tuple(rest)
        np.testing.assert_allclose(scanned[f], out, atol=1e-6)
    jitted = jax.jit(lambda p, t, *c: plant_feet(legs, START, LAST, p, t, 1.0, *c))
    with jax.disable_jit():
        eager = plant_feet(legs, START, LAST, args[0][7], args[1][7], 1.0, *carry)
    for a, b in zip(jitted(args[0][7], args[1][7], *carry), eager, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    pins = jnp.asarray(np.random.default_rng(0).normal(scale=0.02, size=(3, 2, 2)), jnp.float32)
    on = jnp.array([[True, False], [False, False], [True, True]])
    many = jnp.stack([args[0][5], args[0][20], args[0][30]])
    phases = jnp.array([5.0, 40.0, 70.0])

    def one(p, t, pin, o):
        return plant_feet(legs, START, LAST, p, t, jnp.float32(1.0), pin, o, o)

    batched = jax.vmap(one)(many, phases, pins, on)
    for i in range(3):
        single = one(many[i], phases[i], pins[i], on[i])
        for b, s in zip(batched, single, strict=True):
            np.testing.assert_allclose(b[i], s, atol=1e-6)


def _straight_walk(model, frames: int = 90) -> dict:
    """A recording (``--record all`` keys) of one agent walking straight along +z at the
    model's mean controls, its phase advancing a cycle per second."""
    c = np.asarray(model.levels[0].kriging.controls, np.float32).mean(axis=0)
    last = model.levels[0].u_time.shape[0] - 1
    t = np.arange(frames)
    return {
        "position": np.stack([np.zeros(frames), 1.2 * t / 30.0], axis=1)[:, None].astype(
            np.float32
        ),
        "heading": np.zeros((frames, 1), np.float32),
        "tau": (np.remainder(t * last / 30.0, last)[:, None]).astype(np.float32),
        "control": np.repeat(c[None, None], frames, axis=0),
        "control_next": np.repeat(c[None, None], frames, axis=0),
        "has_next": np.zeros((frames, 1), bool),
        "height": np.array([1.75], np.float32),
        "fps": np.float32(30.0),
    }


def test_a_planted_clip_puts_the_legs_where_the_points_were_planted():
    """``agent_motion(plant=True)`` writes the planting as joint rotations: its forward
    kinematics equal the planted points (oracle: :func:`plant_sequence` on the unplanted clip's
    joints) to 0.1 mm, the root and the upper body untouched, and its feet slide less. The
    heel strikes it plants by are the crowd step's double-support phases."""
    from jcrowd import load_default_model
    from jcrowd.crowd.clips import build_crowd_model
    from jcrowd.model import agent_motion, foot_skate
    from jcrowd.model.resynthesis import heel_strikes
    from jcrowd.motion.clip import joint_positions
    from jcrowd.motion.gait import find_feet

    model = load_default_model()
    strikes = heel_strikes(model)
    assert strikes == build_crowd_model(model).double_support
    rec = _straight_walk(model)
    loose = agent_motion(model, rec, 0)
    planted = agent_motion(model, rec, 0, plant=True)
    before = np.asarray(joint_positions(loose))
    f = find_feet(model.skeleton)
    legs = leg_chains(
        model.skeleton.parents, (f.left_ankle, f.left_toe, f.right_ankle, f.right_toe)
    )
    scale = 1.75 / model.body_height
    last = float(model.levels[0].u_time.shape[0] - 1)
    want = plant_sequence(
        legs, strikes, last, jnp.asarray(before), jnp.asarray(rec["tau"][:, 0]), scale
    )
    got = np.asarray(joint_positions(planted))
    np.testing.assert_allclose(got, np.asarray(want), atol=1e-4)
    assert np.abs(got - before).max() > 0.005  # premise: the planting moved the legs
    moved = sorted({j for leg in legs for j in (leg[1], *leg[4])})
    still = [j for j in range(got.shape[1]) if j not in moved]
    np.testing.assert_allclose(got[:, still], before[:, still], atol=1e-5)
    assert foot_skate(planted) < 0.5 * foot_skate(loose)
