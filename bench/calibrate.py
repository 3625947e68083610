"""Calibration of the dynamics to the six HERMES runs, judged by the fundamental diagram (issue 22,
item 2).

- **Fit**: :func:`jcrowd.rollouts.calibrate.calibrate` (short windows from the measured states,
  the coarse grid's best point or the start, then Levenberg–Marquardt on the logarithms;
  ``--no-search``: from the start) from three starts: every fitted parameter ×1.3, ×0.7,
  and alternately ×1.3 / ×0.7 of the model's default (``--names``; ×1.15 third for one name).
- **Judge**: each fit's parameters run the crowd-dynamics bench's fundamental-diagram section
  (``bench/pedestrians.py``: each run re-simulated from its measured entry times, PedPy's
  Voronoi speed in the measurement area over the steady state) and give its
  ``fd_speed_rmse_m_s``; the defaults' is measured in the same process. A fitted
  ``desired_speed`` is every agent's free speed in that run, a fitted ``radius`` every agent's
  body radius.
- Done-when: every fit's RMSE ≤ the defaults', and each fitted parameter within ±10 % of the
  three fits' median.

``python bench/calibrate.py [--names time_gap,radius] [--residual person|speed] [--horizon 0.5]
[--every 1.0] [--max-steps 100] [--no-search] [--json] [--no-record]``
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pedestrians as ped
from common import machine, report

from jcrowd.io.trajectories import load_hermes_runs
from jcrowd.pedestrians.params import AvoidanceParams
from jcrowd.rollouts.calibrate import (
    COARSE_GRID,
    EXTRA_NAMES,
    RADIUS_NAME,
    SPEED_NAME,
    calibrate,
    window_residuals,
)
from jcrowd.rollouts.windows import make_windows, merge_windows


def fd_rmse(folder, params, speed, radius=ped.RADIUS):
    """``fd_speed_rmse_m_s`` of jcrowd alone under ``params``, free speed ``speed`` and body
    radius ``radius``."""
    steady = pd.read_csv(folder / "steady_state.csv").set_index("run")
    rows = []
    for f in sorted(folder.glob("uo-*.txt")):
        m = re.match(r"uo-(\d+)-(\d+)-(\d+)", f.stem)
        if not m or f.stem not in steady.index:
            continue
        d = np.loadtxt(f, comments="#")
        d[:, 2:4] /= 100.0
        spawn_xy, spawn_t = ped.hermes_feed(d)
        area, target = ped.hermes_scene(float(m.group(3)))
        measured = ped._fd_measure(d, ped.HERMES_FPS, steady.loc[f.stem], ped.HERMES_AREA)
        t_ref = d[:, 1].max() / ped.HERMES_FPS
        p, a, _ = ped.run_jcrowd(
            area, target, spawn_xy, spawn_t, 3 * t_ref, speed, radius=radius, params=params
        )
        sim = ped._fd_measure_sim(p, a, steady.loc[f.stem], area)
        rows.append((f.stem, measured[1], sim[1], measured[0], sim[0]))
    err = np.array([r[2] - r[1] for r in rows])
    return float(np.sqrt(np.mean(err**2))), rows


def per_run_bias(runs, per_run, names, defaults, fitted):
    """Per run (its windows in ``per_run``): the mean window residual (simulated − measured
    speed, m/s) at the defaults and at ``fitted``: where the windows want the model faster (−)
    or slower (+)."""
    out = {}
    for r, batch in zip(runs, per_run, strict=True):
        at = {}
        for key, vals in (("default", defaults), ("fitted", fitted)):
            v = jnp.asarray([vals[n] for n in names], jnp.float32)
            at[key] = round(float(jnp.mean(window_residuals(names, v, batch))), 3)
        out[r.name] = {"windows": int(batch.position.shape[0]), **at}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hermes", default=str(ped.DATA / "hermes_uo"))
    ap.add_argument("--names", default="time_gap,radius")
    ap.add_argument("--horizon", type=float, default=0.5)
    ap.add_argument("--every", type=float, default=1.0, help="seconds between windows")
    ap.add_argument("--residual", default="person", choices=("person", "speed"))
    ap.add_argument("--max-steps", type=int, default=100)
    ap.add_argument("--no-search", action="store_true", help="LM from the start, no grid")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    names = tuple(args.names.split(","))
    defaults = AvoidanceParams()
    extra = {SPEED_NAME: ped.SPEED, RADIUS_NAME: ped.RADIUS}
    base = {n: extra[n] if n in extra else float(getattr(defaults, n)) for n in names}
    factors = [
        [1.3] * len(names),
        [0.7] * len(names),
        [1.3 if k % 2 == 0 else 0.7 for k in range(len(names))],
    ]
    if len(names) == 1:
        factors[2] = [1.15]  # one parameter has two ±30 % starts; the third lies between
    runs = load_hermes_runs([args.hermes])
    per_run = [
        make_windows(
            r.rows,
            r.fps,
            r.steady,
            r.corridor_m,
            r.exit_m,
            horizon_s=args.horizon,
            every_s=args.every,
        )[0]
        for r in runs
    ]
    batches = merge_windows(per_run)
    folder = Path(args.hermes)
    t0 = time.perf_counter()
    rmse_default, rows_default = fd_rmse(folder, defaults, ped.SPEED)
    print(f"defaults: fd_speed_rmse {rmse_default:.3f} m/s", file=sys.stderr, flush=True)
    fits = []
    for fac in factors:
        start = {n: base[n] * f for n, f in zip(names, fac, strict=True)}
        t1 = time.perf_counter()
        cal = calibrate(
            batches,
            start,
            max_steps=args.max_steps,
            residual=args.residual,
            grid=None if args.no_search else COARSE_GRID,
        )
        fit_s = time.perf_counter() - t1
        fitted = dict(zip(names, map(float, cal.values), strict=True))
        params = defaults
        for n, v in fitted.items():
            if n not in EXTRA_NAMES:
                params = eqx.tree_at(lambda p, n=n: getattr(p, n), params, jnp.asarray(v))
        rmse, rows = fd_rmse(
            folder,
            params,
            fitted.get(SPEED_NAME, ped.SPEED),
            fitted.get(RADIUS_NAME, ped.RADIUS),
        )
        fits.append(
            {
                "start": {n: round(v, 4) for n, v in start.items()},
                "searched_from": {
                    n: round(float(v), 4) for n, v in zip(names, cal.searched_from, strict=True)
                },
                "fitted": {n: round(v, 4) for n, v in fitted.items()},
                "window_rms_start_m_s": round(cal.rms_start, 4),
                "window_rms_searched_m_s": round(cal.rms_searched, 4),
                "window_rms_m_s": round(cal.rms, 4),
                "steps": cal.steps,
                "converged": cal.converged,
                "singular_values": [round(float(s), 4) for s in cal.singular_values],
                "fit_seconds": round(fit_s, 1),
                "fd_speed_rmse_m_s": round(rmse, 3),
                "fd_speeds": {r[0]: round(r[2], 3) for r in rows},
            }
        )
        print(f"fit {fits[-1]}", file=sys.stderr, flush=True)
    med = {n: float(np.median([f["fitted"][n] for f in fits])) for n in names}
    spread = max(abs(f["fitted"][n] / med[n] - 1) for f in fits for n in names)
    bias = per_run_bias(runs, per_run, names, base, med)
    out = {
        "names": list(names),
        "horizon_s": args.horizon,
        "every_s": args.every,
        "residual": args.residual,
        "search": not args.no_search,
        "windows": int(sum(b.position.shape[0] for b in batches)),
        "fd_speed_rmse_default_m_s": round(rmse_default, 3),
        "fd_measured_speeds": {r[0]: round(r[1], 3) for r in rows_default},
        "fd_default_speeds": {r[0]: round(r[2], 3) for r in rows_default},
        "fits": fits,
        "window_bias_m_s": bias,
        "max_rel_spread": round(spread, 4),
        "fd_not_worse": all(f["fd_speed_rmse_m_s"] <= round(rmse_default, 3) for f in fits),
        "stable_10pct": spread <= 0.10,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    lines = [
        f"names {', '.join(names)}; {args.residual} residuals; "
        f"{'coarse grid then LM' if out['search'] else 'LM from the start'}; "
        f"horizon {args.horizon} s every {args.every} s; "
        f"{out['windows']} windows; "
        f"defaults' fd_speed_rmse {out['fd_speed_rmse_default_m_s']} m/s",
        "",
        "| start | LM started from | fitted | window RMS (m/s) | LM steps | fit s | "
        "fd_speed_rmse (m/s) |",
        "|---|---|---|---|---|---|---|",
        *(
            f"| {f['start']} | {f['searched_from']} | {f['fitted']} | "
            f"{f['window_rms_start_m_s']} → {f['window_rms_searched_m_s']} → "
            f"{f['window_rms_m_s']} | {f['steps']} | {f['fit_seconds']} | "
            f"{f['fd_speed_rmse_m_s']} |"
            for f in fits
        ),
        "",
        f"largest deviation from the fits' median: {100 * spread:.1f} %; fd not worse than the "
        f"defaults: {out['fd_not_worse']}",
        "",
        "| HERMES run | windows | window bias at the defaults (m/s) | at the fits' median | "
        "measured fd speed | defaults' fd speed |",
        "|---|---|---|---|---|---|",
        *(
            f"| {k} | {b['windows']} | {b['default']:+.3f} | {b['fitted']:+.3f} | "
            f"{out['fd_measured_speeds'][k]} | {out['fd_default_speeds'][k]} |"
            for k, b in bias.items()
        ),
    ]
    report(
        "calibrate", f"{machine()}, dt 1/30 s", out, "\n".join(lines), args.json, not args.no_record
    )


if __name__ == "__main__":
    main()
