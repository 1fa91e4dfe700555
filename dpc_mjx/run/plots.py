"""Figures of a run (matplotlib, written as PNG files; no screen needed)."""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dpc_mjx.controllers import Controller  # noqa: E402


def _save(fig, path: str | pathlib.Path) -> pathlib.Path:
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def training_curve(rows: list[dict], path) -> pathlib.Path:
    """SAC vs env steps: mean return and fall rate of the training episodes that ended in each
    epoch (exploration noise included) and, where logged, of the deterministic evaluations with
    the same episodes under MBC (u = 0) for reference."""
    steps = np.array([r["env_steps"] for r in rows], float)
    fig, (a, b) = plt.subplots(2, 1, figsize=(6.5, 5.5), sharex=True)
    for ax, key in ((a, "return"), (b, "fall_rate")):
        train_key = "mean_return" if key == "return" else key
        ax.plot(steps, [r[train_key] for r in rows], ".", color="0.6", label="training episodes")
        evals = np.array([r.get(f"eval_{key}", np.nan) for r in rows], float)
        ok = np.isfinite(evals)
        if ok.any():
            ax.plot(steps[ok], evals[ok], "o-", color="C0", label="deterministic evaluation")
            mbc = np.array([r.get(f"eval_mbc_{key}", np.nan) for r in rows], float)[ok]
            ax.plot(steps[ok], mbc, "--", color="C3", label="MBC, same episodes")
        ax.grid(alpha=0.3)
    a.set_ylabel("episode return")
    a.set_title("SAC training")
    a.legend(fontsize=8)
    b.set_ylabel("fall rate")
    b.set_xlabel("env steps")
    return _save(fig, path)


def adapter_loss(history: dict, path, title: str = "latent dynamic adapter") -> pathlib.Path:
    """Train and validation NLL per epoch, the constant predictor's validation NLL for scale."""
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(history["train_nll"], label="train")
    ax.plot(history["val_nll"], label="validation")
    ax.axhline(history["constant_val_nll"], color="gray", ls="--", label="constant predictor")
    if "body_only_val_nll" in history:
        ax.axhline(history["body_only_val_nll"], color="C3", ls=":", label="s_body alone (z = 0)")
    ax.axvline(history["best_epoch"], color="k", ls=":", lw=0.8, label="kept")
    ax.set_xlabel("epoch")
    ax.set_ylabel("NLL per sample (standardised)")
    ax.set_title(title)
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, path)


def posture_prediction(t, real, mean, std, path) -> pathlib.Path:
    """The paper's Fig. 'predicted vs real posture change': next roll and pitch rate (rad/s),
    real vs the decoder's mean +- one std, over time (s). Arrays (T,), (T, 2), (T, 2), (T, 2)."""
    fig, axes = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, ("roll rate", "pitch rate"), strict=True)):
        ax.plot(t, real[:, i], color="k", lw=1, label="real")
        ax.plot(t, mean[:, i], color="C0", lw=1, label="predicted")
        ax.fill_between(t, mean[:, i] - std[:, i], mean[:, i] + std[:, i], color="C0", alpha=0.25)
        ax.set_ylabel(f"{name} (rad/s)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right")
    axes[0].set_title("next-step roll and pitch rate: real vs adapter prediction")
    axes[1].set_xlabel("time (s)")
    return _save(fig, path)


def lifting_trajectory(runs: dict[str, dict], dt: float, path) -> pathlib.Path:
    """The paper's lifting figure. `runs[label]` holds (steps + 1, episodes, ...) arrays: 'pos'
    and 'desired' (m, world x y), 'error' (m) and 'standing' (bool). Left: episode 0's path per
    controller against the desired one (a cross where it fell); right: the mean distance from
    the desired position over the episodes still standing, and the fraction standing."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    first = next(iter(runs.values()))
    a.plot(*first["desired"][:, 0].T, "k--", lw=1.5, label="desired")
    t = np.arange(first["error"].shape[0]) * dt
    twin = b.twinx()
    for i, (label, r) in enumerate(runs.items()):
        color = f"C{i}"
        up = r["standing"][:, 0]
        a.plot(*r["pos"][up, 0].T, color=color, label=label)
        if not up[-1]:
            a.plot(*r["pos"][np.argmin(up), 0], "x", color=color, ms=10, mew=2)
        n = r["standing"].sum(1)
        mean = np.where(n > 0, (r["error"] * r["standing"]).sum(1) / np.maximum(n, 1), np.nan)
        b.plot(t, mean, color=color, label=f"{label}: distance from desired")
        twin.plot(t, n / r["standing"].shape[1], ":", color=color, label=f"{label}: standing")
    a.set_xlabel("x (m)")
    a.set_ylabel("y (m)")
    a.set_aspect("equal", adjustable="datalim")
    a.set_title("episode 0: body path")
    a.legend()
    a.grid(alpha=0.3)
    b.set_xlabel("time (s)")
    b.set_ylabel("mean distance from the desired position (m)")
    twin.set_ylabel("fraction of episodes standing")
    twin.set_ylim(0, 1.05)
    b.set_title(f"{first['error'].shape[1]} episodes")
    lines = b.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    b.legend(lines, [h.get_label() for h in lines], fontsize=8, loc="upper left")
    b.grid(alpha=0.3)
    return _save(fig, path)


def latent_by_arm(per_arm: dict[str, tuple[np.ndarray, np.ndarray]], path) -> pathlib.Path:
    """The paper's latent figure. `per_arm[name] = (z (N, 2), s_drp_next (N, 2) rad/s)`: one
    column per arm, z_0 against z_1 coloured by the next roll rate (top row) and pitch rate
    (bottom row), one colour scale per row shared by every arm."""
    n = len(per_arm)
    fig, axes = plt.subplots(
        2, n, figsize=(2.6 * n + 1.2, 5.4), squeeze=False, sharex=True, sharey=True,
        layout="constrained",
    )  # fmt: skip
    for row, label in enumerate(("next roll rate (rad/s)", "next pitch rate (rad/s)")):
        values = np.concatenate([rates[:, row] for _, rates in per_arm.values()])
        lim = np.percentile(np.abs(values), 98)
        for col, (name, (z, rates)) in enumerate(per_arm.items()):
            ax = axes[row, col]
            art = ax.scatter(
                z[:, 0], z[:, 1], c=rates[:, row], s=2, cmap="coolwarm", vmin=-lim, vmax=lim
            )
            ax.set_title(name if row == 0 else "")
            if row == 1:
                ax.set_xlabel("z_0")
            if col == 0:
                ax.set_ylabel("z_1")
            ax.grid(alpha=0.3)
        fig.colorbar(art, ax=axes[row, :].tolist(), label=label, shrink=0.9, pad=0.01)
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def sweep_heatmaps(result, out: str | pathlib.Path) -> dict[str, pathlib.Path]:
    """Heatmaps of a `run.sweep.SweepResult` over (upper-arm length, gripper mass), one panel
    per controller: fall rate (sweep_fall_rate.png), mean return (sweep_return.png) and, with
    MBC and DPC in the sweep, DPC - MBC paired return (sweep_dpc_minus_mbc.png)."""
    out = pathlib.Path(out)
    names = list(result.cells)
    panels = {
        "fall_rate": ("fall rate", [result.grid(n, "fall_rate") for n in names], names, "Reds"),
        "return": ("mean return", [result.grid(n, "mean_return") for n in names], names, "viridis"),
    }
    if Controller.MBC in names and Controller.DPC in names:
        diff = result.minus_mbc(Controller.DPC)[..., 0]
        panels["dpc_minus_mbc"] = ("DPC - MBC return (paired)", [diff], ["dpc - mbc"], "RdBu")
    paths = {}
    for key, (label, grids, titles, cmap) in panels.items():
        fig, axes = plt.subplots(1, len(grids), figsize=(3.4 * len(grids) + 0.8, 3.3))
        axes = np.atleast_1d(axes)
        lo, hi = min(g.min() for g in grids), max(g.max() for g in grids)
        if cmap == "RdBu":  # differences: white at 0
            hi = max(abs(lo), abs(hi), 1e-9)
            lo = -hi
        for ax, g, title in zip(axes, grids, titles):
            im = ax.imshow(g, origin="lower", aspect="auto", cmap=cmap, vmin=lo, vmax=hi)
            ax.set_xticks(range(len(result.gripper_mass)))
            ax.set_xticklabels([f"{m:.2f}" for m in result.gripper_mass], rotation=90, fontsize=7)
            ax.set_yticks(range(len(result.upper_arm)))
            ax.set_yticklabels([f"{u:.3f}" for u in result.upper_arm], fontsize=7)
            ax.set_xlabel("gripper mass (kg)")
            ax.set_title(title)
        axes[0].set_ylabel("upper-arm length (m)")
        fig.colorbar(im, ax=list(axes), label=label, shrink=0.9)
        fig.savefig(out / f"sweep_{key}.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
        paths[f"heatmap {key}"] = out / f"sweep_{key}.png"
    return paths
