"""Paper 004 (Krüger et al., multi-mode tensor representation): multiscale DTW and Table 1.

Multiscale against exact DTW (§3, reusing bench/dtw.py) and the natural-mode truncation table
(§4.3 Table 1, :func:`natural_mode_truncation`): an actor × style × repetition tensor of
``cmu/walk`` gait cycles, truncated mode by mode, with core size, memory and the quaternion
angle error E_total.

E_total, as read here. The paper defines ``E_mot`` as a normalised sum over the f frames and m
quaternions of the angle between original and reconstructed joint quaternions, and ``E_total``
as the sum of ``E_mot`` over all motions; its equations are lost in our copy and the unit is
not stated. Reading: ``E_mot = (1/(f·m)) Σ_t Σ_j ∠(q_org, q_rec)`` in radians (the
reconstructed quaternion normalised first), ``E_total = Σ_motions E_mot``. The paper's walking
tensor holds 60 motions and 180/π ≈ 57.3 ≈ 60, so its E_total is within 5 % of the mean per
motion in degrees, also under the other reading (a mean over motions in degrees, which its
"E_total is still less than one degree" suggests); we therefore print E_total and the mean
per motion in degrees, and compare the paper's E_total with the latter.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import dtw as dtw_bench
import matplotlib.pyplot as plt
import numpy as np
from common import data_root
from repro_common import save_figure

from jcrowd.io import load_dataset
from jcrowd.model import TensorModelConfig, build_tensor_model
from jcrowd.motion import quat_angle, quat_from_expmap, quat_mul, quat_normalize
from jcrowd.tensor import hosvd, natural_mode_tensor, reconstruct

ACTORS = ("07", "08")
STYLES = {"walk": "walk", "slow walk": "slow walk", "slow walk/stride": "slow walk"}
"""CMU description → style; other descriptions (brisk walk, walk/stride, ...) are left out."""
FRAMES = 60  # the paper's walking motions were "time-warped and sampled down to 60 frames"
ROOT_DOFS = 3  # root height and the two horizontal velocities, as the paper's 3 root DOFs

# Paper Table 1 (walking, quaternions) E_total for the truncation that corresponds to ours:
# the same fraction of the lossless Data Mode rank (60 there, A·S·R here), a natural mode cut
# to 1 (repetition: 3 → 2 as ours), and the Frame × DOF rank pairs, used as given.
_PAPER_DATA = {1.0: 0.0, 0.5: 2.1221, 1 / 3: 3.6258, 1 / 6: 6.3961, 1 / 12: 9.3932}
_PAPER_NATURAL = {"actor": 10.7773, "style": 8.5770, "repetition 2": 2.7639, "repetition 1": 5.0}
_PAPER_FRAME_DOF = {
    (26, 91): 0.5492,
    (21, 91): 0.7418,
    (21, 46): 0.9771,
    (15, 34): 1.9478,
    (14, 35): 1.9817,
    (13, 37): 1.9724,
    (12, 39): 1.9907,
}


def _styles(index: Path) -> dict[str, tuple[str, str]]:
    """``{take: (actor, style)}`` for the kept actors' walk and slow-walk takes (index.csv)."""
    out = {}
    with index.open(newline="") as f:
        for row in csv.DictReader(f):
            take = Path(row["file"]).stem
            actor = take.split("_")[0]
            style = STYLES.get(row["cmu_description"].strip())
            if row["file"].startswith("walk/") and actor in ACTORS and style is not None:
                out[take] = (actor, style)
    return out


def _quaternion_samples(y: np.ndarray, layout: Any) -> np.ndarray:
    """``(n, f, 3 + 4m)`` per frame: root height and velocity, then m joint quaternions.

    From pose vectors ``y`` ``(n, f, P)``: the root's tilt ``exp(tilt)`` (its heading is a rate
    in our pose vectors, not an orientation) and each joint's local rotation
    ``r_j ⊗ exp(e_j)``, on the side of its reference ``r_j`` (continuous over frames and samples,
    so the tensor can interpolate them), as 004 §4.1 represents joints by quaternions.
    """
    n, f, _ = y.shape
    ref = np.asarray(layout.reference, np.float64)
    e = y[..., 7 : 7 + 3 * (layout.num_joints - 1)].reshape(n, f, -1, 3)
    joints = quat_mul(ref[None, None, 1:], quat_from_expmap(e))
    quats = np.concatenate([quat_from_expmap(y[..., layout.tilt])[:, :, None], joints], axis=2)
    root = y[..., [layout.height, layout.velocity.start, layout.velocity.start + 1]]
    return np.concatenate([root, quats.reshape(n, f, -1)], axis=-1)


def _row(x: np.ndarray, ranks: tuple[int, ...], frames: int) -> dict[str, Any]:
    """Truncated N-mode SVD of ``x`` at ``ranks``: sizes, memory and E_total (module doc)."""
    tk = hosvd(x, ranks)
    rec = reconstruct(tk).reshape(frames, -1, *x.shape[-3:])
    org = x.reshape(rec.shape)
    # (f, m, 4, A, S, R) → (A, S, R, f, m, 4)
    q_org = np.moveaxis(
        org[:, ROOT_DOFS:].reshape(frames, -1, 4, *x.shape[-3:]), (0, 1, 2), (3, 4, 5)
    )
    q_rec = np.moveaxis(
        rec[:, ROOT_DOFS:].reshape(frames, -1, 4, *x.shape[-3:]), (0, 1, 2), (3, 4, 5)
    )
    e_mot = quat_angle(q_org, quat_normalize(q_rec)).mean(axis=(-2, -1))  # (A, S, R), radians
    core = int(np.prod(ranks))
    memory = core + sum(i * r for i, r in zip(x.shape, ranks, strict=True))
    return {
        "dims": list(ranks),
        "core_entries": core,
        "core_pct": 100 * core / x.size,
        "memory_pct": 100 * memory / x.size,
        "e_total_rad": float(e_mot.sum()),
        "e_mean_deg": float(np.degrees(e_mot.mean())),
    }


def natural_mode_truncation() -> dict[str, Any]:
    """004 Table 1 on a fully filled actor × style × repetition grid of ``cmu/walk`` cycles.

    Actors 07 and 08, styles walk and slow walk (index.csv descriptions; 08_11 "slow
    walk/stride" counts as slow walk), repetitions = left-started gait cycles (no mirrors):
    every cell gives k cycles, k the smallest cell's count, taken evenly spaced over the cell's
    cycles in take order (so several takes contribute). The cycles are DTW-aligned to their
    medoid and resampled to 60 frames by the tensor-model pipeline
    (:func:`jcrowd.model.tensor_model.build_tensor_model`, 004 §3's multiscale DTW; its key levels
    are unused), then written as quaternions (:func:`_quaternion_samples`).

    Two tensors, as in the paper: Data Mode ``(f·n) × A × S × R`` and Frame × DOF
    ``f × n × A × S × R``; each truncation is a truncated N-mode SVD (the same as cutting the
    full one, 004 §2.2). Memory = core entries + Σ_k I_k R_k factor entries, over the tensor's
    entries (the paper's "memory usage"); core % = core entries over the tensor's entries.
    """
    root = data_root() / "cmu"
    labels = _styles(root / "index.csv")
    clips = [c for c in load_dataset(root / "walk") if Path(c.path).stem in labels]
    tm = build_tensor_model(clips, TensorModelConfig(frames=FRAMES, mirror=False, key_levels=2))
    y = np.transpose(tm.tensor, (2, 1, 0)) * tm.layout.scale
    cells: dict[tuple[str, str], list[int]] = {}
    for s, g in enumerate(tm.groups):
        cells.setdefault(labels[Path(tm.sources[g]).stem], []).append(s)
    k = min(len(v) for v in cells.values())
    chosen = {
        c: [v[i] for i in np.linspace(0, len(v) - 1, k).round().astype(int)]
        for c, v in cells.items()
    }
    order = [(c, s) for c in sorted(chosen) for s in chosen[c]]
    data = _quaternion_samples(y[[s for _, s in order]], tm.layout)
    nm = natural_mode_tensor(
        data, [c[0] for c, _ in order], [c[1] for c, _ in order], fill="require"
    )
    a, st, r = nm.tensor.shape[-3:]
    frame_dof = nm.tensor
    data_mode = frame_dof.reshape(-1, a, st, r)
    lossless = a * st * r
    rows: list[dict[str, Any]] = []
    for frac in (1.0, 0.5, 1 / 3, 1 / 4, 1 / 6, 1 / 12):
        d = max(1, round(lossless * frac))
        row = _row(data_mode, (d, a, st, r), FRAMES)
        rows.append({**row, "group": "Data Mode", "paper": _PAPER_DATA.get(frac)})
    for mode, dims in (
        ("actor", (lossless, 1, st, r)),
        ("style", (lossless, a, 1, r)),
        *((f"repetition {q}", (lossless, a, st, q)) for q in range(r - 1, 0, -1)),
    ):
        row = _row(data_mode, dims, FRAMES)
        rows.append(
            {**row, "group": f"natural: {mode.split()[0]}", "paper": _PAPER_NATURAL.get(mode)}
        )
    n_dof = frame_dof.shape[1]
    pairs = [*_PAPER_FRAME_DOF, (FRAMES // 3, n_dof), (FRAMES, 3)]
    for f_r, d_r in pairs:
        row = _row(frame_dof, (f_r, d_r, a, st, r), FRAMES)
        rows.append({**row, "group": "Frame × DOF", "paper": _PAPER_FRAME_DOF.get((f_r, d_r))})
    return {
        "cells": {f"{c[0]} {c[1]}": len(v) for c, v in cells.items()},
        "repetitions": k,
        "takes": sorted({Path(tm.sources[tm.groups[s]]).stem for _, s in order}),
        "shape": list(frame_dof.shape),
        "joints": int((n_dof - ROOT_DOFS) // 4),
        "rows": rows,
    }


def section_004(repeats: int) -> dict[str, Any]:
    return {
        "dtw_rows": dtw_bench.bench("pose", repeats, cycles=True),
        "natural": natural_mode_truncation(),
    }


def markdown_004(r: dict[str, Any]) -> list[str]:
    L = [
        "## 004 — DTW and natural modes (Krüger et al.)",
        "",
        "| frames (A×B) | exact s | multiscale s | speed-up (ours) | paper speed-up | cost ratio |",
        "|---|---|---|---|---|---|",
    ]
    paper = {300: "≈10×", 3000: "≈100×"}
    for x in r["004"]["dtw_rows"]:
        L.append(
            f"| {x['frames']}×{x['frames_b']} | {x['exact_s']:.4f} | {x['multiscale_s']:.4f} | "
            f"{x['speedup']:.1f}× | {paper.get(x['frames'], '—')} | {x['cost_ratio']:.5f} |"
        )
    nat = r["004"]["natural"]
    f, n, a, s, k = nat["shape"]
    cells = ", ".join(f"{c}: {m}" for c, m in nat["cells"].items())
    L += [
        "",
        "Where ours is worse: our exact DTW fills each row with a few vectorised NumPy calls "
        "(a min-plus prefix scan), so its cost is mostly a per-row Python overhead, which "
        "multiscale DTW pays on every one of its levels too; it evaluates only a few % of the "
        "cells at 3000 frames, but the wall-clock gain is far below the paper's ×10 / ×100 "
        "against a cell-by-cell loop (implementation). The cost ratio 1.00000 shows the "
        "multiscale path is as good as the exact one.",
        "",
        "Natural-mode truncation (paper Table 1, walking, quaternions). Tensor: "
        f"{f} frames × {n} DOF ({ROOT_DOFS} root + {nat['joints']} quaternions) × {a} actors "
        f"(07, 08) × {s} styles (walk, slow walk) × {k} repetitions (gait cycles; cycles per "
        f"cell {cells}, k = {k} taken from each, from takes {', '.join(nat['takes'])}); the "
        "paper's: 60 × 119 × 5 × 4 × 3. E per motion = E_total / motions in degrees, beside "
        "the paper's E_total (module doc of `bench/repro_004.py` for the reading). The paper "
        "rows are the same fraction of the lossless Data Mode rank (its 60, our "
        f"{a * s * k}), the natural mode cut to 1 (repetition: same 3 → 2 → 1), and its own "
        "Frame × DOF rank pairs.",
        "",
        "| truncated | core dims | core entries | core % | memory % | E_total (Σ, rad) | "
        "ours: E per motion (°) | paper E_total |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in nat["rows"]:
        p = row["paper"]
        L.append(
            f"| {row['group']} | {' × '.join(map(str, row['dims']))} | {row['core_entries']:,} "
            f"| {row['core_pct']:.4f} % | {row['memory_pct']:.2f} % | {row['e_total_rad']:.4f} "
            f"| {row['e_mean_deg']:.3f} | {'—' if p is None else f'{p:.4f}'} |"
        )
    L += ["", _differs_004(nat), ""]
    return L


def _differs_004(nat: dict[str, Any]) -> str:
    rows = {(r["group"], tuple(r["dims"])): r for r in nat["rows"]}
    f, _, a, s, k = nat["shape"]
    dof3 = rows.get(("Frame × DOF", (f, 3, a, s, k)))
    nat_rows = [r for r in nat["rows"] if r["group"].startswith("natural")]
    worst = max(nat_rows, key=lambda r: r["e_mean_deg"])
    paired = [r for r in nat["rows"] if r["group"] == "Frame × DOF" and r["paper"] is not None]
    small = min(paired, key=lambda r: r["memory_pct"])
    compared = [r for r in nat["rows"] if r["paper"] is not None and r["paper"] > 0]
    worse = [r for r in compared if r["e_mean_deg"] > r["paper"]]
    versus = (
        f"Ours is below the paper's error in all {len(compared)} rows with a paper figure: "
        "fewer motions leave less variance for each cut to lose, and cutting a natural mode "
        "of 2 entries to 1 drops less than the paper's 5 actors or 4 styles to 1 (data)."
        if not worse
        else "Ours is worse than the paper's in "
        + ", ".join(f"{r['group']} {' × '.join(map(str, r['dims']))}" for r in worse)
        + " (not established why)."
    )
    return (
        "What differs, and the readings taken: our grid is small (2 actors × 2 styles × "
        f"{k} repetitions = {a * s * k} motions, the paper's 60), because the shared walks hold "
        "only two actors with a second labelled style (slow walk), and the rarest cell "
        f"limits every cell to {k} cycles (data). A motion here is one gait cycle, DTW-aligned "
        f"by the project's pipeline and resampled to {FRAMES} frames as in the paper (which "
        "does not say how much of a walk one of its motions holds). Our root DOFs are the "
        "height and heading-frame velocity (the position of a cycle relative to its start has "
        "no global meaning), and the root's quaternion is its tilt with the heading removed. "
        "E_total is the sum over our motions, so it is not comparable with the paper's sum "
        "over 60; the per-motion mean is. The visual rating column is not reproduced. "
        + versus
        + " Natural modes weigh most, as in the paper: cutting the "
        f"{worst['group'].split(': ')[1]} mode to one entry costs {worst['e_mean_deg']:.2f}° "
        f"per motion, against {small['e_mean_deg']:.2f}° for the Frame × DOF cut to "
        f"{small['dims'][0]} × {small['dims'][1]} ({small['memory_pct']:.1f} % of the memory)."
        + (
            f" Keeping only 3 DOF-mode components costs {dof3['e_mean_deg']:.2f}° per motion "
            "here, where the paper's Fig. 6 reports under 1° mean error for its walks; its own "
            "Table 1 shows about 2 with 34–39 DOF components, so Fig. 6 probably uses another "
            "measure or tensor, which we could not reconstruct (not compared)."
            if dof3
            else ""
        )
    )


def plot_004(r: dict[str, Any]) -> str:
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    rows = r["004"]["dtw_rows"]
    frames = [x["frames"] for x in rows]
    ax[0].loglog(frames, [x["exact_s"] for x in rows], "o-", label="exact")
    ax[0].loglog(frames, [x["multiscale_s"] for x in rows], "o-", label="multiscale")
    ax[0].set(xlabel="frames", ylabel="seconds", title="004: DTW")
    ax[0].legend()
    for group in ("Data Mode", "Frame × DOF"):
        pts = [x for x in r["004"]["natural"]["rows"] if x["group"] == group]
        ax[1].plot([x["memory_pct"] for x in pts], [x["e_mean_deg"] for x in pts], "o", label=group)
    ax[1].set(xlabel="memory % of the tensor", ylabel="E per motion (°)", title="004: truncation")
    ax[1].set_xscale("log")
    ax[1].legend()
    return save_figure(fig, "004_dtw.png")
