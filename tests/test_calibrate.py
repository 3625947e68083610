"""Calibration to measured trajectories (issue 22, item 2): the run reader, the parameters file
a scenario names, the window residuals against a plain loop of the step, and recovery of
known parameters from trajectories the model itself made."""

from __future__ import annotations

import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jcrowd.crowd.state import StepConfig
from jcrowd.errors import DataError, JcrowdError, ScenarioError
from jcrowd.io.trajectories import load_hermes_run, load_hermes_runs
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.pedestrians.step import Pedestrians, pedestrian_step
from jcrowd.pedestrians.world import build_world
from jcrowd.rollouts.calibrate import COARSE_GRID, calibrate, person_residuals, window_residuals
from jcrowd.rollouts.windows import corridor_scene, make_windows, merge_windows
from jcrowd.scenario.parse import parse_scenario

FPS = 30.0  # synthetic runs are recorded at the step's rate: a window is whole frames and steps

# The plain loops below call one compiled step (eager, op by op, a step compiles its many small
# operations one at a time: minutes); the loop itself stays Python, which is what they check.
_step = eqx.filter_jit(pedestrian_step)


# ------------------------------------------------------------------------------ reader


def test_hermes_run_is_read_in_metres_with_its_steady_frames(tmp_path: Path) -> None:
    (tmp_path / "uo-050-180-120.txt").write_text(
        "# id frame x y z\n1 10 90.0 -150.0 170\n1 11 90 -160 170\n"
    )
    (tmp_path / "steady_state.csv").write_text("run,first_frame,last_frame\nuo-050-180-120,10,11\n")
    run = load_hermes_run(tmp_path / "uo-050-180-120.txt")
    assert (run.entrance_m, run.corridor_m, run.exit_m) == (0.5, 1.8, 1.2)
    np.testing.assert_allclose(run.rows, [[1, 10, 0.9, -1.5], [1, 11, 0.9, -1.6]])
    assert run.steady == (10, 11) and run.fps == 16.0
    assert [r.name for r in load_hermes_runs([tmp_path])] == ["uo-050-180-120"]


def test_bad_runs_are_errors_naming_the_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "uo-050-180-180.txt"
    bad.write_text("1 10 90 -150\n1 eleven 90 -160\n")
    with pytest.raises(DataError, match=r"uo-050-180-180.txt:2: expected 'id frame x y"):
        load_hermes_run(bad)
    with pytest.raises(DataError, match="uo-<entrance>-<corridor>-<exit>"):
        load_hermes_run(tmp_path / "corridor.txt")
    with pytest.raises(DataError, match=r"no rows|found none"):
        (tmp_path / "uo-1-2-3.txt").write_text("# nothing\n")
        load_hermes_run(tmp_path / "uo-1-2-3.txt")


# ------------------------------------------------------------------------------ params file

_SCENARIO = """
duration = 2.0
ground = {{ shape = "rect", center = [0, 0], size = [20, 20] }}
camera = {{ eye = [0, 10, -20], target = [0, 0, 0] }}
[[groups]]
count = 4
spawn = {{ shape = "rect", center = [0, 0], size = [4, 4] }}
goal = {{ shape = "rect", center = [0, 8], size = [4, 2] }}
[dynamics]
avoid = true
params = "{params}"
"""


def test_a_scenario_takes_the_calibrated_parameters_and_refuses_bad_ones(tmp_path: Path) -> None:
    (tmp_path / "p.toml").write_text(
        "[avoidance]\ntime_gap = 0.45\nplain_reaction_time = 0.2\n"
        "[population]\ndesired_speed = 1.5\n"
    )
    sc = parse_scenario(_SCENARIO.format(params="p.toml"), "s.toml", base_dir=tmp_path)
    assert dict(sc.dynamics.avoidance) == {"time_gap": 0.45, "plain_reaction_time": 0.2}
    config = StepConfig((1,), (), avoidance=sc.dynamics.avoidance)
    got = config.avoidance_params()
    assert float(got.time_gap) == pytest.approx(0.45) and float(got.strength) == 8.0
    with pytest.raises(ScenarioError, match=r"s.toml: dynamics.params: expected an existing"):
        parse_scenario(_SCENARIO.format(params="nope.toml"), "s.toml", base_dir=tmp_path)
    (tmp_path / "bad.toml").write_text("[avoidance]\ntime_gap = -1\n")
    with pytest.raises(ScenarioError, match=r"avoidance.time_gap: expected a positive number"):
        parse_scenario(_SCENARIO.format(params="bad.toml"), "s.toml", base_dir=tmp_path)
    (tmp_path / "odd.toml").write_text("[avoid]\ntime_gap = 1\n")
    with pytest.raises(ScenarioError, match=r"expected an \[avoidance\] table"):
        parse_scenario(_SCENARIO.format(params="odd.toml"), "s.toml", base_dir=tmp_path)
    with pytest.raises(
        JcrowdError, match=r"avoidance\.time_gapp: expected a positive number named"
    ):
        StepConfig((1,), (), avoidance=(("time_gapp", 1.0),)).check(1)


def test_a_fitted_radius_is_the_scenarios_unless_it_names_its_own(tmp_path: Path) -> None:
    """A ``[body] radius`` (``jcrowd calibrate --fit time_gap,radius``) sets ``[dynamics]
    radius``; a radius the scenario writes itself wins; bad ``[body]`` tables are refused."""
    (tmp_path / "p.toml").write_text("[avoidance]\ntime_gap = 0.45\n[body]\nradius = 0.17\n")
    sc = parse_scenario(_SCENARIO.format(params="p.toml"), "s.toml", base_dir=tmp_path)
    assert sc.dynamics.radius == pytest.approx(0.17)
    assert dict(sc.dynamics.avoidance) == {"time_gap": 0.45}
    own = _SCENARIO.format(params="p.toml") + "radius = 0.25\n"
    assert parse_scenario(own, "s.toml", base_dir=tmp_path).dynamics.radius == 0.25
    # What the command writes for a (T, r, v0) fit is what a scenario reads.
    from jcrowd.cli.calibrate import params_toml

    result = {
        "fitted": {"time_gap": 0.61, "radius": 0.14, "desired_speed": 1.4},
        "data": ["uo-100-180-180"],
        "horizon_s": 0.5,
        "residual": "person",
        "residual_rms_start_m_s": 0.1,
        "residual_rms_searched_m_s": 0.08,
        "residual_rms_m_s": 0.07,
        "steps": 20,
    }
    (tmp_path / "cli.toml").write_text(params_toml(result))
    sc = parse_scenario(_SCENARIO.format(params="cli.toml"), "s.toml", base_dir=tmp_path)
    assert sc.dynamics.radius == 0.14 and dict(sc.dynamics.avoidance) == {"time_gap": 0.61}
    (tmp_path / "none.toml").write_text("[avoidance]\ntime_gap = 0.45\n")
    sc = parse_scenario(_SCENARIO.format(params="none.toml"), "s.toml", base_dir=tmp_path)
    assert sc.dynamics.radius == 0.2
    for name, body, match in [
        ("neg", "radius = -1", r"neg.toml: body\.radius: expected a positive number"),
        ("key", "height = 1.8", r"body: expected only radius, found keys \['height'\]"),
        ("big", "radius = 0.9", r"big.toml: body.radius: expected a radius in \[0.1, 0.4\]"),
    ]:
        (tmp_path / f"{name}.toml").write_text(f"[avoidance]\ntime_gap = 0.45\n[body]\n{body}\n")
        with pytest.raises(ScenarioError, match=match):
            parse_scenario(_SCENARIO.format(params=f"{name}.toml"), "s.toml", base_dir=tmp_path)


# ------------------------------------------------------------------------------ windows


def _synthetic_run(params: AvoidanceParams, speed: float, people: int = 10, frames: int = 75):
    """Rows ``id frame x y`` of people walking down the 1.8 m corridor, stepped by the plain
    loop of :func:`pedestrian_step` at ``FPS`` (the model making its own "measurement")."""
    area, target, _ = corridor_scene(1.8, 1.8)
    world = build_world(area, [target])
    rng = np.random.default_rng(3)
    xy = np.stack(
        [
            rng.uniform(0.35, 1.45, people),
            np.linspace(1.5, -3.0, people) + rng.uniform(0, 0.1, people),
        ],
        axis=1,
    )
    peds = Pedestrians(
        jnp.asarray(xy, jnp.float32),
        jnp.zeros(people, jnp.int32),
        jnp.full(people, speed, jnp.float32),
        jnp.full(people, 0.2, jnp.float32),
        jnp.ones(people, bool),
        jnp.zeros((people, 2), jnp.float32),
        False,
    )
    rows = []
    for f in range(frames):
        p = np.asarray(peds.position)
        rows += [[i, f, p[i, 0], p[i, 1]] for i in range(people)]
        peds, _ = _step(params, world, peds, 1.0 / FPS)
    return np.asarray(rows, np.float64)


def _loop_ends(batch, params: AvoidanceParams, speed: float, radius: float = 0.2) -> np.ndarray:
    """Every window stepped by hand in a Python loop: the end positions ``(W, N, 2)``."""
    out = []
    for w in range(batch.position.shape[0]):
        n = batch.position.shape[1]
        alive = batch.alive[w]
        peds = Pedestrians(
            batch.position[w],
            jnp.zeros(n, jnp.int32),
            jnp.full(n, speed, jnp.float32),
            jnp.full(n, radius, jnp.float32),
            alive,
            jnp.where(alive[:, None], batch.velocity[w], 0.0),
            False,
        )
        for _ in range(batch.steps):
            peds, _ = _step(params, batch.world, peds, 1.0 / 30.0)
        out.append(np.asarray(peds.position))
    return np.asarray(out)


def _loop_residuals(batch, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The residuals by hand from :func:`_loop_ends`, in NumPy: per window the counted
    people's mean speed difference, and per person the velocity difference."""
    h = batch.steps / 30.0
    p0, c = np.asarray(batch.position), np.asarray(batch.counted)
    meas = np.asarray(batch.end)
    speed = []
    for w in range(p0.shape[0]):
        sim = np.linalg.norm(ends[w] - p0[w], axis=1)
        obs = np.linalg.norm(meas[w] - p0[w], axis=1)
        speed.append(np.sum(c[w] * (sim - obs)) / h / max(c[w].sum(), 1))
    person = np.where(c[..., None], (ends - meas) / h, 0.0)
    return np.asarray(speed), person


TRUE = {"time_gap": 0.45, "radius": 0.2, "desired_speed": 1.5}


@pytest.fixture(scope="module")
def synthetic_batch():
    params = AvoidanceParams(time_gap=0.45)
    rows = _synthetic_run(params, 1.5)
    # From frame 20 on: the people start at rest, and in the first ~0.5 s (their reaction
    # time's acceleration) the backward-difference start velocity lags the true one.
    batch, starts = make_windows(rows, FPS, (20, 74), 1.8, 1.8, horizon_s=0.5, every_s=0.5)
    return batch, starts


@pytest.mark.slow
def test_window_residuals_equal_a_plain_loop_and_jit_equals_eager(synthetic_batch) -> None:
    batch, starts = synthetic_batch
    assert len(starts) >= 3 and int(batch.counted.sum()) > 0
    names = ("time_gap", "desired_speed", "radius")
    values = jnp.asarray([0.7, 1.2, 0.17], jnp.float32)
    got = window_residuals(names, values, batch)
    want, want_person = _loop_residuals(
        batch, _loop_ends(batch, AvoidanceParams(time_gap=0.7), 1.2, 0.17)
    )
    person = person_residuals(names, values, batch)
    assert person.shape == (*batch.counted.shape, 2)
    np.testing.assert_allclose(np.asarray(person), want_person, atol=1e-4)
    # The radius reaches the rollout (a dropped one would leave these equal).
    at_02 = window_residuals(names[:2], values[:2], batch)
    assert float(jnp.max(jnp.abs(got - at_02))) > 1e-3
    # float32 positions after 15 steps (~1 m): 1e-5 m/s would be rounding; 1e-4 leaves room
    # for XLA's fused sums while a wrong horizon, mask or start position is ≥ 1e-2 off.
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-4)
    jitted = jax.jit(lambda v: window_residuals(names, v, batch))(values)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(got), atol=1e-5)
    jitted = jax.jit(lambda v: person_residuals(names, v, batch))(values)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(person), atol=1e-5)
    # Merging a batch with itself is the same windows twice (padding changes nothing).
    merged = merge_windows([batch, batch])
    assert len(merged) == 1
    twice = window_residuals(names, values, merged[0])
    np.testing.assert_allclose(np.asarray(twice), np.tile(np.asarray(got), 2), atol=1e-5)


def test_at_the_generating_parameters_the_residuals_are_small(synthetic_batch) -> None:
    """The model's own trajectories are matched by the model's own parameters (the start
    velocity is a difference estimate, so not exactly: within 2 cm/s)."""
    batch, _ = synthetic_batch
    names = tuple(TRUE)
    at_truth = window_residuals(names, jnp.asarray(list(TRUE.values()), jnp.float32), batch)
    off = window_residuals(names, jnp.asarray([0.45, 0.2, 1.2], jnp.float32), batch)
    assert float(jnp.max(jnp.abs(at_truth))) < 0.02 < float(jnp.max(jnp.abs(off)))
    # Per person: the difference-estimated start velocity leaves up to ~3 cm/s on one person;
    # a 20 % slower free speed moves the free walkers by ~0.3 m/s.
    true = jnp.asarray(list(TRUE.values()), jnp.float32)
    at_truth = person_residuals(names, true, batch)
    off = person_residuals(names, jnp.asarray([0.45, 0.2, 1.2], jnp.float32), batch)
    assert float(jnp.max(jnp.abs(at_truth))) < 0.05 < float(jnp.max(jnp.abs(off)))


@pytest.mark.slow
def test_calibration_recovers_known_parameters_from_a_perturbed_start(synthetic_batch) -> None:
    """On trajectories the model made at known parameters (``TRUE``), the fit from ×1.3 (LM
    alone) and from ×0.7 and ×1.3 (coarse grid, then LM) ends within 5 % of the truth with
    finite values, the two grid-started fits agree to 1e-6, and the grid search starts at the
    least of a plain loop over the grid's per-person residual RMS (the oracle)."""
    batch, _ = synthetic_batch
    # Levenberg–Marquardt alone (no grid search) from every parameter ×1.3.
    cal = calibrate([batch], {n: v * 1.3 for n, v in TRUE.items()}, max_steps=30, grid=None)
    np.testing.assert_allclose(cal.searched_from, cal.start)
    assert cal.rms < 0.2 * cal.rms_start
    # 5 %: what the difference-estimated start velocity leaves (the residuals at the truth
    # are under 2 cm/s, not 0); a fit that stalls at the ±30 % start is 30 % off.
    np.testing.assert_allclose(cal.values, list(TRUE.values()), rtol=0.05)
    # With the coarse grid (none of its points is the truth: r 0.18/0.22, T 0.36/0.49, v0
    # 1.4/1.6): the fit starts from the grid's best from ×0.7 and from ×1.3 alike, ends at the
    # truth, and the two fits are the same numbers (the start does not decide the answer).
    low = calibrate([batch], {n: v * 0.7 for n, v in TRUE.items()}, max_steps=30)
    high = calibrate([batch], {n: v * 1.3 for n, v in TRUE.items()}, max_steps=30)
    np.testing.assert_allclose(low.values, list(TRUE.values()), rtol=0.05)
    np.testing.assert_allclose(high.values, low.values, rtol=1e-6)
    assert low.rms <= low.rms_searched < low.rms_start
    assert np.isfinite([low.values, high.values]).all(), (low.values, high.values)
    # Oracle for the search: the per-person residual RMS at the start and at every grid point,
    # one by one in the values (not their logarithms); the fit must start at that loop's least.
    names = tuple(TRUE)
    one = jax.jit(lambda v: person_residuals(names, v, batch))
    points = [tuple(low.start)] + [
        (t, r, v)
        for t in COARSE_GRID["time_gap"]
        for r in COARSE_GRID["radius"]
        for v in COARSE_GRID["desired_speed"]
    ]
    rms = [
        float(np.sqrt(np.mean(np.asarray(one(jnp.asarray(p, jnp.float32))) ** 2))) for p in points
    ]
    np.testing.assert_allclose(low.searched_from, points[int(np.argmin(rms))], rtol=1e-6)
    assert low.rms_searched == pytest.approx(min(rms), rel=1e-4)


def test_bad_names_and_starts_are_errors(synthetic_batch) -> None:
    batch, _ = synthetic_batch
    with pytest.raises(JcrowdError, match="expected distinct parameter names"):
        calibrate([batch], {"time_gapp": 0.5})
    with pytest.raises(JcrowdError, match="expected positive start values"):
        calibrate([batch], {"time_gap": -0.5})
    with pytest.raises(JcrowdError, match="expected residual in"):
        calibrate([batch], {"time_gap": 0.5}, residual="speeds")
    with pytest.raises(JcrowdError, match=r"grid\['radius'\]: expected positive values"):
        calibrate([batch], {"radius": 0.2}, grid={"radius": (0.2, -0.1)})
    with pytest.raises(JcrowdError, match="whole frames"):
        make_windows(np.zeros((1, 4)), 16.0, (0, 100), 1.8, 1.8, horizon_s=0.3)


# ------------------------------------------------------------------------------ the command


@pytest.mark.slow
def test_cli_fits_one_run_and_writes_a_file_a_scenario_takes(
    hermes_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``jcrowd calibrate RUN --fit time_gap --json`` on one measured run (a few LM steps):
    one JSON object with the keys its docstring names, the residual lowered from the ×1.3
    start, and a parameters file a scenario reads back to the printed value."""
    from jcrowd.cli import main

    run, out = hermes_dir / "uo-100-180-180.txt", tmp_path / "p.toml"
    argv = ["calibrate", str(run), "--fit", "time_gap", "--start", "time_gap=0.78"]
    code = main([*argv, "--max-steps", "4", "--every", "2", "--out", str(out), "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0
    keys = {"data", "windows", "names", "start", "fitted", "residual_rms_start_m_s"}
    assert keys | {"residual_rms_m_s", "steps", "singular_values", "seconds"} <= set(result)
    assert result["data"] == ["uo-100-180-180"] and result["names"] == ["time_gap"]
    assert result["residual"] == "person"
    assert result["start"] == {"time_gap": 0.78}
    # The fit started at the best of the start and the coarse grid's time gaps.
    assert result["searched_from"]["time_gap"] in (0.78, *COARSE_GRID["time_gap"])
    assert result["residual_rms_searched_m_s"] <= result["residual_rms_start_m_s"]
    # Four LM steps from there on this run's 19 windows lower the per-person residual.
    assert result["residual_rms_m_s"] < 0.8 * result["residual_rms_start_m_s"], result
    fitted = result["fitted"]["time_gap"]
    assert 0.05 < fitted < 0.78
    sc = parse_scenario(_SCENARIO.format(params=out.name), "s.toml", base_dir=tmp_path)
    assert dict(sc.dynamics.avoidance) == {"time_gap": pytest.approx(fitted)}
    # A run that is not there: a clear error naming it, nothing written.
    missing = tmp_path / "uo-999-180-180.txt"
    code = main(["calibrate", str(missing), "--out", str(tmp_path / "q.toml"), "--json"])
    err = json.loads(capsys.readouterr().out)
    assert code != 0 and "uo-999-180-180" in err["error"]["message"]
    assert not (tmp_path / "q.toml").exists()


def test_the_commands_default_fit_is_the_modules() -> None:
    """The parser keeps its own copy (it must not import jax): the two cannot drift."""
    from jcrowd.cli import _build_parser
    from jcrowd.rollouts.calibrate import DEFAULT_NAMES

    parser, _ = _build_parser()
    args = parser.parse_args(["calibrate", "run.txt"])
    assert tuple(args.fit.split(",")) == DEFAULT_NAMES
