"""Shared test fixtures: where the CMU captures are, strict JAX settings, the cmu16 tensor fit
once per run, and the GL context of the tests that draw.

Tests that need the captures take the ``cmu_dir`` / ``cmu16_dir`` fixtures. They look at
``$JCROWD_DATA`` (the folder holding ``cmu/`` and ``cmu16/``, or ``cmu/`` itself) and then at
``../shared/data`` beside the checkout. When the data is absent the test is skipped with that
reason (a user's fresh clone), unless ``JCROWD_REQUIRE_DATA=1`` (set by ``.ci/run``), which makes
the absence a failure so CI always runs them.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

# One persistent XLA compilation cache for the test run's processes: the xdist workers and the
# `jcrowd` subprocesses the CLI tests start (through the environment) compile the same crowd
# step over and over, 1–4 min each on 2 cores. Compilations of at least 0.05 s are stored: also a
# fit's hundred-odd small programs, which the run's several fits of cmu16 share.
# The cache changes no result: an entry is keyed by the computation, the jax/XLA version and
# the compile options, and the in-memory counts the no-recompile checks read are unaffected.
# Kept under .pytest_cache/ (ignored by git) between local runs; JAX_COMPILATION_CACHE_DIR=""
# switches it off.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(ROOT / ".pytest_cache" / "jax"))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.05")
# A size limit makes jax lock the cache's files (filelock), so that no process reads an entry
# another is still writing; 4 GB is far above one run's ~100 MB.
os.environ.setdefault("JAX_COMPILATION_CACHE_MAX_SIZE", str(4 << 30))
# XLA's cheaper compile (backend optimisation level 0, no expensive LLVM passes): a test runs
# most of its programs once or a few times, so compiling takes longer than running; the results
# the tests check are the same within their tolerances (the whole suite passes either way).
# The benches and the CLI outside the tests compile with XLA's defaults;
# JAX_DISABLE_MOST_OPTIMIZATIONS=0 runs the tests that way too.
os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")

import jax  # noqa: E402  (after the cache settings, which jax reads on import)
import pytest  # noqa: E402

jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Drop every compiled function after each test module.

    Each XLA:CPU executable holds its machine code in memory maps, and a jit cache keeps the
    executable alive; an xdist worker runs half the suite in one process, and its maps reached
    Linux's per-process limit (``vm.max_map_count``, 65,530): LLVM then failed to map the next
    executable's sections ("Cannot allocate memory", "LLVM ERROR: Unable to allocate section
    memory!", abort) — in CI and locally, in tests/test_steering.py after test_calibrate
    (measured: test_calibrate alone leaves 21,000 maps; with this fixture every module ends at
    ~1,450). Tests inside a module keep sharing what they compiled.
    """
    yield
    jax.clear_caches()


def _data_root() -> Path | None:
    env = os.environ.get("JCROWD_DATA")
    candidates = []
    if env:
        p = Path(env)
        candidates += [p, p.parent] if p.name == "cmu" else [p]
    candidates.append(ROOT.parent / "shared" / "data")
    for c in candidates:
        if (c / "cmu").is_dir():
            return c
    return None


def _need(sub: str) -> Path:
    root = _data_root()
    if root is None or not (root / sub).is_dir():
        msg = (
            f"CMU captures not found ({sub}/ under $JCROWD_DATA or ../shared/data); "
            "set JCROWD_DATA to the folder holding cmu/ and cmu16/"
        )
        if os.environ.get("JCROWD_REQUIRE_DATA") == "1":
            pytest.fail(msg + " — JCROWD_REQUIRE_DATA=1 makes this a failure")
        pytest.skip(msg)
    return root / sub


@pytest.fixture(scope="session")
def cmu_dir() -> Path:
    """``.../data/cmu`` (31-joint skeleton, 120 fps, CMU units, T-pose at frame 0)."""
    return _need("cmu")


@pytest.fixture(scope="session")
def cmu16_dir() -> Path:
    """``.../data/cmu16`` (19-joint skeleton, 30 fps, centimetres, CRLF, no T-pose)."""
    return _need("cmu16")


@pytest.fixture(scope="session")
def hermes_dir() -> Path:
    """``.../data/pedestrians/hermes_uo`` (HERMES corridor runs, cm, 16 fps, steady_state.csv)."""
    return _need("pedestrians/hermes_uo")


@pytest.fixture(scope="session")
def cmu16_tensor(cmu16_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Any:
    """The default tensor fit of ``cmu16`` (about 35 s: the per-level refit), built once per
    test run and shared by the files that only read it.

    Under pytest-xdist the first worker to ask builds it and saves it (the model file's round
    trip is bit-identical, ``test_tensor_model``) in the run's shared temporary folder; the
    others wait for that file and load it. If the builder fails, the waiters fail too, naming
    the builder's error file.
    """
    from helpers import fully_optimised

    from jcrowd.io import load_dataset, load_tensor_model, save_tensor_model
    from jcrowd.model import build_tensor_model

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    path, lock, failed = (root / f"cmu16-tensor{x}" for x in (".jcm", ".lock", ".failed"))
    try:
        os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        deadline = time.monotonic() + 600.0
        while not path.exists():
            if failed.exists():
                pytest.fail(f"the cmu16 tensor fit failed in another worker: {failed}")
            if time.monotonic() > deadline:
                pytest.fail(f"waited 600 s for another worker's cmu16 tensor fit ({path})")
            time.sleep(0.5)
        return load_tensor_model(path)
    try:
        with fully_optimised():
            model = build_tensor_model(load_dataset(cmu16_dir))
        save_tensor_model(path, model)
    except BaseException as exc:
        failed.write_text(repr(exc))
        raise
    return model


@pytest.fixture(scope="session")
def step_model() -> Any:
    """The shipped model with three of its levels, for the crowd step's tests
    (``helpers.step_model``)."""
    from helpers import step_model

    return step_model()


@pytest.fixture(scope="module")
def gl_context() -> Iterator[Any]:
    """One headless GL context (``jcrowd.render.make_context``) per test module that draws."""
    from jcrowd.render import make_context

    context = make_context()
    yield context
    context.release()


@pytest.fixture
def ctx(gl_context: Any) -> Iterator[Any]:
    """The module's GL context; after the test, its error flag must be ``GL_NO_ERROR`` (a
    drawing call that failed quietly fails the test that made it)."""
    yield gl_context
    assert gl_context.error == "GL_NO_ERROR"


def all_clip_paths() -> list[Path]:
    """Every shared BVH clip (for parametrised tests); empty when the data is absent."""
    root = _data_root()
    if root is None:
        return []
    return sorted((root / "cmu").rglob("*.bvh")) + sorted((root / "cmu16").glob("*.bvh"))
