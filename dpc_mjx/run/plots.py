"""Figures of a run (matplotlib, written as PNG files; no screen needed)."""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


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
