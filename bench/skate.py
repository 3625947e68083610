"""Foot skate of level-0 agents in the plaza run vs the captures' own (issue 7, as jcrowd eval).

Runs ``examples/plaza.toml`` for ``--steps`` steps recording everything, re-synthesizes every
agent that stayed at level 0 throughout (:func:`jcrowd.model.resynthesis.agent_motion`: the
level-0 pose with the root where the run put it) and measures its foot skate (mean horizontal
slide of a planted foot per frame, cm) with :func:`jcrowd.model.evaluate.foot_skate`; the same
measure on the ``cmu16`` captures (the default model's data, same 30 fps) is the reference.

``python bench/skate.py [--steps 240] [--json]``; appends a row to bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import numpy as np
from common import ROOT, data_root, machine, report

from jcrowd import load_default_model
from jcrowd.cli.run import simulate
from jcrowd.crowd import prepare
from jcrowd.io import load_dataset
from jcrowd.model import agent_motion, foot_skate
from jcrowd.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=240)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    model = load_default_model()
    sim, state = prepare(load_scenario(Path(ROOT) / "examples" / "plaza.toml"), model)
    _, rec = simulate(sim, state, args.steps, "all")
    rec["fps"] = np.asarray(sim.scenario.fps)
    ids = np.nonzero((rec["level"] == 0).all(axis=0))[0]
    run = [100 * foot_skate(agent_motion(model, rec, int(i))) for i in ids]
    captures = [100 * foot_skate(c.motion) for c in load_dataset(data_root() / "cmu16")]
    out = {
        "agents_level0": len(ids),
        "skate_level0_cm": float(np.mean(run)),
        "skate_captures_cm": float(np.mean(captures)),
        "ratio": float(np.mean(run) / np.mean(captures)),
        "steps": args.steps,
        "machine": machine(),
        "jax": jax.__version__,
    }
    text = (
        f"plaza, {args.steps} steps at 30 fps: {out['agents_level0']} agents at level 0 "
        f"throughout skate {out['skate_level0_cm']:.2f} cm/frame; cmu16 captures "
        f"{out['skate_captures_cm']:.2f} cm/frame → {out['ratio']:.2f}×"
    )
    report("skate", f"{out['machine']}, jax {out['jax']}", out, text, args.json, not args.no_record)


if __name__ == "__main__":
    main()
