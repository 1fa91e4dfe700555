"""The disturbance observer's noise-versus-lag trade: its estimate against the oracle's u for
several gains, aligned to the sensor delay or not, on the same rollouts.

    python experiments/observer_gain.py [--arm regular] [--gains 5 10 20 40] [--episodes 16]
        [--steps 500] [--seed 43000] [--engine native]

The rollouts run under the oracle controller (u = the measured mount wrench, privileged) on the
reaching task with the shipped export's env options (sensor noise and the 4 ms delay on), so
the observer only estimates and meets the same states at every gain. Its estimate u_obs (the
observation's, yaw frame) is compared with the oracle's u (yaw frame) at every 20 ms step
before an episode's end, per component:

    bias   the mean error (the legs' weight term is most of it: `control/observer.py`)
    slow   the RMS error of both signals averaged over 0.1 s (5 steps): lag and bias
    fast   the RMS of what is left (the error minus its 0.1 s average): noise and ripple
    rmse   the whole RMS error

A higher gain shortens the lag (1/K) and passes more of the measurement noise, so slow falls
and fast rises with K. Seeds 43000.. chose nothing (the gains of the fall-rate screen were
chosen on other seeds: docs/results-observer.md).
"""

from __future__ import annotations

import argparse

import numpy as np

from dpc_mjx.envs import rollout
from dpc_mjx.envs.observations import PRIVILEGED
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io import load
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_yaw_frame

COMPONENTS = ("f_x", "f_y", "f_z", "tau_x", "tau_y", "tau_z")
SHOWN = (2, 3, 4)  # f_z, tau_x, tau_y: the arm's weight and its moments
SMOOTH = 5  # steps of 20 ms: the 0.1 s average that splits slow from fast


def errors(arm: str, gain: float, aligned: bool, args: argparse.Namespace) -> np.ndarray:
    """(steps, episodes, 6) u_obs - u_oracle (yaw frame), NaN from each episode's end on."""
    options = env_overrides(load(SHIPPED)) | {"observer_gain": gain, "observer_aligned": aligned}
    env = make(DEFAULT_TASK, arm=arm, controller="oracle", engine=args.engine, **options)
    u_obs = env.obs_layout.u_obs

    def record(before, after):
        yaw = roll_pitch_yaw(before.pipeline_state.qpos[:, 3:7])[:, 2]  # (B,) rad
        oracle = wrench_to_yaw_frame(before.info["privileged"][:, PRIVILEGED["u_oracle"]], yaw)
        return {"error": before.obs[:, u_obs] - oracle, "done": after.done}

    rec = rollout.record_episodes(env, args.episodes, args.steps, args.seed, record)
    done_before = np.cumsum(rec["done"], axis=0) - rec["done"]
    return np.where((done_before == 0)[..., None], rec["error"], np.nan)[1:]


def split(e: np.ndarray) -> dict[str, np.ndarray]:
    """(6,) bias, slow, fast and rmse of the errors e (steps, episodes, 6) (see module doc)."""
    kernel = np.ones(SMOOTH) / SMOOTH
    slow = np.apply_along_axis(lambda x: np.convolve(x, kernel, mode="valid"), 0, e)
    fast = e[SMOOTH - 1 :] - slow  # the error minus its trailing 0.1 s average
    return {
        "bias": np.nanmean(e, axis=(0, 1)),
        "slow": np.sqrt(np.nanmean(slow**2, axis=(0, 1))),
        "fast": np.sqrt(np.nanmean(fast**2, axis=(0, 1))),
        "rmse": np.sqrt(np.nanmean(e**2, axis=(0, 1))),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arm", default="regular")
    ap.add_argument("--gains", type=float, nargs="+", default=[5.0, 10.0, 20.0, 40.0])
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--seed", type=int, default=43000)
    ap.add_argument("--engine", default="native", choices=("mjx", "native"))
    args = ap.parse_args()
    runs = [(g, True) for g in args.gains] + [(20.0, False)]  # and the observer before alignment
    names = [COMPONENTS[i] for i in SHOWN]
    print(f"{args.arm}, {args.episodes} episodes x {args.steps} steps from seed {args.seed}")
    print("| K (rad/s) | aligned | " + " | ".join(f"{c} bias / slow / fast / rmse" for c in names))
    print("|---|---|" + "---|" * len(names))
    for gain, aligned in runs:
        figures = split(errors(args.arm, gain, aligned, args))
        cells = [
            " / ".join(
                f"{figures[k][i]:+.2f}" if k == "bias" else f"{figures[k][i]:.2f}"
                for k in ("bias", "slow", "fast", "rmse")
            )
            for i in SHOWN
        ]
        print(
            f"| {gain:g} | {'yes' if aligned else 'no'} | " + " | ".join(cells) + " |", flush=True
        )


if __name__ == "__main__":
    main()
