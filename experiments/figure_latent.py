"""The paper's Fig. "comparison of the latent state with different robotic arm": each arm's
encoder's latent z against the body's next roll and pitch rate (what the shared decoder predicts).

    python experiments/figure_latent.py [--export DIR] [--arms regular longer ...]
        [--samples 4096] [--seed 6000] [--out docs/figures/latent_z.png]

For each arm with an encoder in the export (`--arms` default: all), `--samples` random-motion
samples of that arm under MBC (`adapter.collect`, seed `--seed`, the export's env options), each
encoded by the arm's own encoder. The figure: one column per arm, z_0 against z_1 coloured by the
next roll rate (top) and pitch rate (bottom), same colour scale for every arm. The table: how much
of the next roll and pitch rate a linear map of z explains (R^2), and the angle between each arm's
direction of increasing roll (pitch) rate in z and the first arm's: small angles mean the arms'
encoders share the structure of z, which is what lets the frozen policy and decoder serve them.
"""

from __future__ import annotations

import argparse

import numpy as np

from dpc_mjx import adapter, io, stats
from dpc_mjx.adapter.networks import encode
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.plots import latent_by_arm

TASK = DEFAULT_TASK


def linear_fit(z: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares y ~ z w + b: the direction w (2,) and the R^2 (the explained variance: with
    an intercept, R^2 up to float rounding)."""
    a = np.concatenate([z, np.ones((len(z), 1))], 1)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return coef[:2], stats.explained_variance(y, a @ coef)


def angle(u: np.ndarray, v: np.ndarray) -> float:
    """Degrees between two directions."""
    cos = u @ v / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--export", default=str(SHIPPED))
    ap.add_argument("--arms", nargs="+")
    ap.add_argument("--samples", type=int, default=4096)
    ap.add_argument("--seed", type=int, default=6000)
    ap.add_argument("--out", default="docs/figures/latent_z.png")
    args = ap.parse_args()

    art = io.load(args.export)
    arms = args.arms or sorted(art.encoders, key=lambda a: (a != "regular", a))
    per_arm = {}
    for name in arms:
        env = make(TASK, arm=art.arm_spec(name), controller="mbc", **env_overrides(art, TASK))
        data = adapter.collect(env, args.samples, seed=args.seed)
        z = np.asarray(encode(art.adapter_config, art.encoder(name), data.encoder_input))
        per_arm[name] = (z, data.s_drp_next)
    print(
        "| arm | R^2 roll rate from z | R^2 pitch rate from z | roll direction vs "
        f"{arms[0]} (deg) | pitch direction vs {arms[0]} (deg) |\n|---|---|---|---|---|"
    )
    ref = None
    for name, (z, rates) in per_arm.items():
        (w_roll, r2_roll), (w_pitch, r2_pitch) = (linear_fit(z, rates[:, i]) for i in (0, 1))
        ref = ref or (w_roll, w_pitch)
        print(
            f"| {name} | {r2_roll:.2f} | {r2_pitch:.2f} | {angle(w_roll, ref[0]):.0f} | "
            f"{angle(w_pitch, ref[1]):.0f} |",
            flush=True,
        )
    print(f"figure: {latent_by_arm(per_arm, args.out)}")


if __name__ == "__main__":
    main()
