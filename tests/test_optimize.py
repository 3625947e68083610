"""Layout optimisation (jcrowd.rollouts.layout_opt, jcrowd optimize): key paths, the walls as a
function of θ against shapely's outlines, the optimiser on closed-form quadratics, the gradient
against central differences of the forward objective, jit against eager, the CLI's written
scenario, and bad input.

The rollout scene (``SMALL``): a 6 m × 5 m room whose south wall has two doors, 1.2 m and 0.8 m
wide, on either side of a 2 m wall piece (the varied numbers: its x and the east piece's x)
and a round pillar in the room; 8 people walk out for 3 s (60 steps at 20 /s). Few enough
that nobody queues: the exact gradient is usable there (jcrowd.rollouts.rollout, "Limits").
Compiling a rollout's gradient takes about 45 s on a 2-core CPU, so the tests that need one
are marked slow and share one scene.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jcrowd.cli import main
from jcrowd.cli.optimize import set_toml_values
from jcrowd.errors import JcrowdError
from jcrowd.rollouts.layout_opt import (
    _forward,
    forward_value,
    layout_objective,
    layout_problem,
    layout_setup,
    obstacle_walls,
    value_and_gradient,
)
from jcrowd.rollouts.search import projected_gradient
from jcrowd.scenario.keys import parse_key_path, varied_parameter, with_values
from jcrowd.scenario.layout import region_shape
from jcrowd.scenario.parse import parse_scenario

SMALL = """\
seed = 4
duration = 3.0
fps = 20

[ground]
center = [3, 1.5]
size = [6, 7]

[camera]
eye = [3, 6, -6]
target = [3, 0, 2]

[dynamics]
avoid = true

[[obstacles]]   # west of door A (x in [1, 2.2])
shape = "rect"
center = [0.5, -0.1]
size = [1.0, 0.2]

[[obstacles]]   # between the doors
shape = "rect"
center = [3.2, -0.1]
size = [2.0, 0.2]

[[obstacles]]   # east of door B (x in [4.2, 5])
shape = "rect"
center = [5.5, -0.1]
size = [1.0, 0.2]

[[obstacles]]   # a pillar
shape = "circle"
center = [3.0, 3.6]
radius = 0.3

[[groups]]
name = "room"
count = 8
speed = [1.2, 1.4]
spawn = { shape = "rect", center = [3, 1.9], size = [5, 2.0] }
goal = { shape = "rect", center = [3, -1.6], size = [6, 0.8] }
"""
KEYS = ("obstacles[1].center[0]", "obstacles[2].center[0]")  # door A / door B edges
BOUNDS = ((3.0, 3.4), (5.3, 5.7))


def _scenario():
    return parse_scenario(SMALL, "small.toml")


# ------------------------------------------------------------------------- key paths, geometry


def test_key_paths_parse_and_bad_ones_are_errors() -> None:
    assert parse_key_path("obstacles[1].center[0]") == ("obstacles", 1, "center", 0)
    assert parse_key_path("obstacles[0].points[2][1]") == ("obstacles", 0, "points", 2, 1)
    with pytest.raises(JcrowdError, match="names joined by dots"):
        parse_key_path("obstacles[x].center")
    sc = _scenario()
    v = varied_parameter(sc, "obstacles[3].radius")
    np.testing.assert_allclose([v.lower, v.upper], [0.15, 0.45])  # ×0.5 … ×1.5 by default
    cases = {
        "groups[0].count": "an \\[\\[obstacles\\]\\] table",  # unknown for the optimiser
        "obstacles[9].center[0]": "obstacle index below 4",
        "obstacles[1].radius": "center, size",  # a rect has no radius
        "obstacles[1].center": "found an array",  # not a number
        "obstacles[1].center[0][1]": "too many indexes",
        "obstacles[1].center[2]": "indexes within",
    }
    for key, message in cases.items():
        with pytest.raises(JcrowdError, match=message):
            varied_parameter(sc, key)
    with pytest.raises(JcrowdError, match="lo < hi"):
        varied_parameter(sc, KEYS[0], (3.4, 3.0))
    with pytest.raises(JcrowdError, match="holding its value"):
        varied_parameter(sc, KEYS[0], (3.3, 3.5))


def test_obstacle_walls_follow_shapely_outlines() -> None:
    """The oracle: region_shape's polygon of each moved obstacle (built on the host by shapely
    from the scenario with the new numbers). Its vertices and the JAX outline's agree to float32
    rounding (1e-5 m)."""
    sc = _scenario()
    keys, bounds = (KEYS[0], "obstacles[3].center[1]"), (BOUNDS[0], (3.4, 3.8))
    varied = [varied_parameter(sc, k, b) for k, b in zip(keys, bounds, strict=True)]
    problem = layout_problem(sc, varied, "travel_time")
    theta = np.asarray([3.35, 3.45])
    walls = np.asarray(obstacle_walls(problem.geometry, jnp.asarray(theta, jnp.float32)))
    moved = with_values(sc, varied, theta).layout.obstacles
    fixed = len(problem.geometry.fixed)
    for start, count, region in ((fixed, 4, moved[1]), (fixed + 4, 64, moved[3])):
        ours = walls[start : start + count, 0]
        theirs = np.asarray(region_shape(region).exterior.coords)[:-1]
        dist = np.linalg.norm(ours[:, None] - theirs[None], axis=-1)
        np.testing.assert_allclose(dist.min(axis=1), 0.0, atol=1e-5)
        np.testing.assert_allclose(dist.min(axis=0), 0.0, atol=1e-5)
    # The fixed walls are the room without the moved obstacles: the two outer wall pieces'
    # ends are among them, the middle piece's are not.
    ends = problem.geometry.fixed.reshape(-1, 2)
    assert np.any(np.all(np.isclose(ends, [1.0, 0.0], atol=1e-5), axis=1))
    assert not np.any(np.all(np.isclose(ends, [2.2, 0.0], atol=1e-5), axis=1))


# ------------------------------------------------------------------------- the optimiser


def _quadratic(center: np.ndarray, scale: np.ndarray):
    def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
        d = x - center
        return float(np.sum(scale * d * d)), 2 * scale * d

    return fun


def test_projected_gradient_finds_a_quadratic_minimum_inside_and_on_the_bounds() -> None:
    """Closed form: the minimum of Σ s_i (x_i − c_i)² over a box is c clipped to the box, here
    with an ill-conditioned scale (1 : 20). The steps shrink to the tolerance 1e-4 of the box;
    2e-3 allows for the zig-zag of normalised steps across the narrow valley."""
    lo, hi = np.zeros(2), np.ones(2)
    inside = projected_gradient(
        _quadratic(np.array([0.3, 0.7]), np.array([1.0, 20.0])),
        [0.9, 0.1],
        lo,
        hi,
        max_evaluations=40,
        tol=1e-4,
    )
    np.testing.assert_allclose(inside.x, [0.3, 0.7], atol=2e-3)
    edge = projected_gradient(
        _quadratic(np.array([1.4, 0.5]), np.array([1.0, 1.0])),
        [0.2, 0.2],
        lo,
        hi,
        max_evaluations=40,
        tol=1e-4,
    )
    np.testing.assert_allclose(edge.x, [1.0, 0.5], atol=2e-3)
    assert edge.evaluations <= 40 and "converged" in edge.message


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.floats(-1.0, 2.0), min_size=2, max_size=2),
    st.lists(st.floats(0.1, 10.0), min_size=2, max_size=2),
    st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2),
)
def test_projected_gradient_never_leaves_the_box_nor_ends_worse(center, scale, start) -> None:
    """Properties: every point evaluated is within the bounds, the result is the best of them,
    and it is no worse than the start (only a lower value is kept)."""
    fun = _quadratic(np.asarray(center), np.asarray(scale))
    res = projected_gradient(fun, start, [0.0, 0.0], [1.0, 1.0], max_evaluations=8)
    for x, _ in res.path:
        assert np.all((x >= 0.0) & (x <= 1.0))
    assert res.value == min(v for _, v in res.path)
    assert res.value <= fun(np.asarray(start))[0]
    assert 1 <= res.evaluations <= 8


def test_projected_gradient_rejects_bad_bounds() -> None:
    fun = _quadratic(np.zeros(1), np.ones(1))
    with pytest.raises(JcrowdError, match="lower < upper"):
        projected_gradient(fun, [0.5], [1.0], [0.0])
    with pytest.raises(JcrowdError, match="start within"):
        projected_gradient(fun, [2.0], [0.0], [1.0])
    with pytest.raises(JcrowdError, match="budget"):
        projected_gradient(fun, [0.5], [0.0], [1.0], max_evaluations=0)


def test_problem_and_setup_refuse_bad_input() -> None:
    sc = _scenario()
    v = varied_parameter(sc, KEYS[0], BOUNDS[0])
    with pytest.raises(JcrowdError, match="objective in"):
        layout_problem(sc, [v], "fastest")
    with pytest.raises(JcrowdError, match="distinct keys"):
        layout_problem(sc, [v, v], "flow")
    problem = layout_problem(sc, [v], "flow")
    with pytest.raises(JcrowdError, match=r"value in \[3, 3.4\]"):
        layout_setup(problem, [3.6])
    # A pillar moved onto the crowd.
    pillar = [varied_parameter(sc, f"obstacles[3].center[{k}]", (0.0, 6.0)) for k in (0, 1)]
    onto = layout_problem(sc, pillar, "flow")
    with pytest.raises(JcrowdError, match="off the agents"):
        layout_setup(onto, np.asarray(onto.peds.position[0]))


# ------------------------------------------------------------------------- the written scenario


def test_set_toml_values_changes_only_the_key_and_keeps_comments() -> None:
    text = set_toml_values(SMALL, {"obstacles[1].center[0]": 3.25, "obstacles[3].radius": 0.35})
    doc, before = tomllib.loads(text), tomllib.loads(SMALL)
    before["obstacles"][1]["center"][0] = 3.25
    before["obstacles"][3]["radius"] = 0.35
    assert doc == before
    assert "# between the doors" in text and text.count("\n") == SMALL.count("\n")
    with pytest.raises(JcrowdError, match=r"\[\[obstacles\]\] header"):
        set_toml_values(SMALL, {"obstacles[7].center[0]": 1.0})


# ------------------------------------------------------------------------- gradients (slow)


@pytest.mark.slow
def test_gradient_matches_central_differences_of_the_forward_objective() -> None:
    """The oracle: central differences of the forward objective with the world held at θ (the
    gradient's own reading: the field is rebuilt between iterates, not inside a derivative), in
    float64, for both varied numbers (the middle wall piece's x, the east piece's x) and all
    three objectives. Step h = 1e-7 m: at h = 1e-5 a hard switch of the step (a neighbour or
    wall entering the corridor ahead of an agent squeezing through door B, whose position moves
    ~14 m per m of θ there) fell within ±h and the differences were off by 8e-3 (travel time),
    1.8e-2 (evacuation) and 0.59 (flow: −0.0300 against the gradient's −0.0123); from h = 1e-6
    down to 1e-8 they agree with the gradient to ≤ 1.2e-7 relative (measured). Bound 1e-4
    relative: rounding is ~1e-16/h ≈ 1e-9 of the value, truncation ~h² far below.
    """
    with jax.enable_x64(True):
        sc = _scenario()
        varied = [varied_parameter(sc, k, b) for k, b in zip(KEYS, BOUNDS, strict=True)]
        theta = np.asarray([3.23, 5.5])
        h = 1e-7
        for objective in ("travel_time", "evacuation", "flow"):
            problem = layout_problem(sc, varied, objective, dtype=jnp.float64)
            setup = layout_setup(problem, theta)
            # One compiled program per objective: its primal output is the forward objective
            # the differences are taken of (a separate forward program costs a compile).
            both = jax.jit(jax.value_and_grad(layout_objective, has_aux=True))
            _, grad = both(jnp.asarray(theta), setup)
            for j in range(len(KEYS)):
                e = np.zeros(len(KEYS))
                e[j] = h
                num = (
                    float(both(jnp.asarray(theta + e), setup)[0][0])
                    - float(both(jnp.asarray(theta - e), setup)[0][0])
                ) / (2 * h)
                assert abs(num) > 1e-3, (objective, j, num)  # something to check
                assert abs(float(grad[j]) - num) <= 1e-4 * abs(num), (objective, j, grad, num)


@pytest.mark.slow
def test_objective_jit_equals_eager_and_value_and_gradient_agrees() -> None:
    """Separately compiled programs may fuse (and round) differently: float32 over 60 steps,
    1e-4 relative."""
    sc = _scenario()
    varied = [varied_parameter(sc, k, b) for k, b in zip(KEYS, BOUNDS, strict=True)]
    problem = layout_problem(sc, varied, "travel_time")
    theta = problem.start
    setup = layout_setup(problem, theta)
    eager, overflow = layout_objective(jnp.asarray(theta, jnp.float32), setup)
    jitted, _ = _forward(jnp.asarray(theta, jnp.float32), setup)
    assert int(overflow) == 0
    np.testing.assert_allclose(float(eager), float(jitted), rtol=1e-4)
    value, grad = value_and_gradient(problem, theta)
    np.testing.assert_allclose(value, forward_value(problem, theta), rtol=1e-4)
    assert np.all(np.isfinite(grad))
    # 0 ≤ mean censored exit time ≤ the horizon.
    assert 0.0 < value <= 3.0


@pytest.mark.slow
def test_cli_writes_a_scenario_that_parses_and_reruns(tmp_path: Path, capsys) -> None:
    """The written file parses, differs from the input only in the varied numbers (within the
    bounds), and its forward objective is the one reported (to float32 rounding and the 0.1 mm
    rounding of the written numbers: 1e-3 relative)."""
    src = tmp_path / "small.toml"
    src.write_text(SMALL)
    out = tmp_path / "best.toml"
    argv = [
        "optimize",
        str(src),
        "--vary",
        f"{KEYS[0]}=3.0:3.4",
        "--objective",
        "travel_time",
        "--max-evaluations",
        "3",
        "--out",
        str(out),
        "--json",
    ]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["out"] == str(out) and result["evaluations"] <= 3
    assert result["value_optimum"] <= result["value_start"]
    written = parse_scenario(out.read_text(), str(out))
    x = float(tomllib.loads(out.read_text())["obstacles"][1]["center"][0])
    assert 3.0 <= x <= 3.4 and x == result["varied"][0]["optimum"]
    doc, before = tomllib.loads(out.read_text()), tomllib.loads(SMALL)
    before["obstacles"][1]["center"][0] = x
    assert doc == before
    v = varied_parameter(written, KEYS[0], (3.0, 3.4))
    again = forward_value(layout_problem(written, [v], "travel_time"), [x])
    np.testing.assert_allclose(again, result["value_optimum"], rtol=1e-3)
    # Bad input through the CLI: exit status 2 and a JSON error naming the key.
    assert main(["optimize", str(src), "--vary", "groups[0].count", "--json"]) == 2
    err = json.loads(capsys.readouterr().out)["error"]["message"]
    assert "groups[0].count" in err
    assert main(["optimize", str(src), "--vary", f"{KEYS[0]}=a:b", "--json"]) == 2
    assert "LO:HI" in json.loads(capsys.readouterr().out)["error"]["message"]
