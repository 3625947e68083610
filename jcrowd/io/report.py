"""The fit report: a text summary and PNG plots (matplotlib, headless ``Agg`` backend)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from jcrowd.errors import JcrowdError
from jcrowd.io.atomic import write_atomic

__all__ = ["summary_text", "write_fit_report"]


def summary_text(result: dict[str, Any]) -> str:
    """Human-readable summary of a ``jcrowd fit`` result."""
    lines = [
        f"{result['data_dir']}: {result['clips']} clips, {result['samples']} samples, tensor "
        f"{'×'.join(map(str, result['tensor_shape']))}, {result['seconds']:.1f} s",
        f"controls {', '.join(result['controls'])}; variogram p = {result['variogram']['p']:.1f}, "
        f"θ = {np.round(result['variogram']['theta'], 4).tolist()}",
        f"{'level':>5} {'ranks':>12} {'joints':>6} {'bytes':>9} {'joint err cm':>12} "
        f"{'root err cm':>11}",
    ]
    for i, lv in enumerate(result["levels"]):
        lines.append(
            f"{i:>5} {'×'.join(map(str, lv['ranks'])):>12} {lv['joints']:>6} {lv['bytes']:>9,} "
            f"{100 * lv['error_m']:>12.2f} {100 * lv['root_error_m']:>11.2f}"
        )
    lines.append(
        f"storage {result['bytes_total']:,} B vs {result['bytes_raw']:,} B raw float32 "
        f"({result['bytes_raw'] / result['bytes_total']:.1f}×)"
    )
    if result.get("cv"):
        cv, root = result["cv"], result["cv_root"]
        lines.append(
            "leave-one-clip-out (joint / root error, cm): "
            + ", ".join(f"{k[:-2]} {100 * v:.2f} / {100 * root[k]:.2f}" for k, v in cv.items())
        )
        if result.get("cv_z_rms") is not None:
            lines.append(
                f"kriging's predicted std vs its left-out error: z RMS {result['cv_z_rms']:.2f} "
                "(1 = calibrated, < 1 cautious)"
            )
    lines.append(f"model: {result['out']}")
    return "\n".join(lines) + "\n"


def write_fit_report(
    folder: str | os.PathLike[str], result: dict[str, Any], tensor: Any, model: Any
) -> Path:
    """Write ``report.txt`` and the PNG plots into ``folder``; returns the folder."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jcrowd.model.motion_model import model_reliability

    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise JcrowdError(f"{out}: cannot create the report folder: {e.strerror or e}") from e
    write_atomic(out / "report.txt", summary_text(result))

    levels = result["levels"]
    fig, ax = plt.subplots(figsize=(6, 4))
    idx = np.arange(len(levels))
    ax.plot(idx, [100 * lv["error_m"] for lv in levels], "o-", label="mean joint error (cm)")
    ax.plot(idx, [100 * lv["root_error_m"] for lv in levels], "s--", label="root error (cm)")
    ax.set_xlabel("key level")
    ax.set_ylabel("error (cm)")
    ax2 = ax.twinx()
    ax2.bar(idx, [lv["bytes"] / 1024 for lv in levels], alpha=0.25, color="gray")
    ax2.set_ylabel("KiB stored")
    ax.legend(loc="upper left")
    ax.set_title("error and size per key level")
    _save(fig, out / "levels.png")

    c = np.asarray(tensor.controls)[:, [list(_names()).index(n) for n in model.control_names]]
    if c.shape[1] >= 2:
        lo, hi = np.asarray(model.control_ranges)[:2].T
        pad = 0.25 * (hi - lo)
        gx, gz = np.meshgrid(
            np.linspace(lo[0] - pad[0], hi[0] + pad[0], 60),
            np.linspace(lo[1] - pad[1], hi[1] + pad[1], 60),
        )
        q = np.tile(np.median(c, axis=0), (gx.size, 1))
        q[:, 0], q[:, 1] = gx.ravel(), gz.ravel()
        rho = model_reliability(model, q, 0).reshape(gx.shape)
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
        im = ax.contourf(gx, gz, np.clip(rho, 0, 1), levels=np.linspace(0, 1, 11), cmap="viridis")
        ax.scatter(c[:, 0], c[:, 1], s=10, c="white", edgecolors="black", linewidths=0.5)
        fig.colorbar(im, ax=ax, label="reliability ρ")
        others = ", ".join(
            f"{n}={v:.2f}" for n, v in zip(model.control_names[2:], q[0, 2:], strict=True)
        )
        ax.set_xlabel(model.control_names[0])
        ax.set_ylabel(model.control_names[1])
        ax.set_title("level-0 reliability" + (f" ({others})" if others else ""))
        _save(fig, out / "reliability.png")

    from jcrowd.kriging.variogram import experimental_variogram, semivariogram

    k = model.levels[0].kriging
    res = np.asarray(k.residuals, np.float64)
    cn = (np.asarray(k.controls, np.float64) - np.asarray(k.control_mean)) / np.asarray(
        k.control_scale
    )
    exp = experimental_variogram(cn, res)
    h = np.linspace(0, float(np.max(exp.lags)) * 1.05, 100)
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.plot(exp.lags, exp.gamma, "o", label="experimental (Cressie–Hawkins)")
    ax.plot(
        h,
        np.asarray(semivariogram(h, np.asarray(k.variogram.theta), float(k.variogram.p))),
        "-",
        label="fitted",
    )
    ax.set_xlabel("lag (normalised controls)")
    ax.set_ylabel("γ")
    ax.set_title(f"level-0 variogram, p = {float(k.variogram.p):.1f}")
    ax.legend()
    _save(fig, out / "variogram.png")
    return out


def _names() -> tuple[str, ...]:
    from jcrowd.model.samples import CONTROL_NAMES

    return CONTROL_NAMES


def _save(fig: Any, path: Path) -> None:
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    write_atomic(path, buf.getvalue())
