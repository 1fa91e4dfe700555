"""How good is each estimate of u: R^2 and RMSE per component against the oracle, and the paper's
figure "output parameters under a sudden force".

    python experiments/u_estimation.py [--export DIR] [--other DIR] [--other-label NAME]
        [--arm regular] [--controller dpc] [--episodes 32] [--seed 5000] [--engine auto]
        [--own-loop feedforward_observer ...]

Held-out rollouts: `--episodes` episodes of the reaching task with `--arm` (the export's env
options, sensors as configured there) under `--controller` (default the export's own DPC; the
oracle gives the states where a perfect estimate is asked for), from seeds `--seed`.. that
chose nothing. On every step before an episode's end, each estimator's u is compared with the
oracle's (the measured mount wrench, privileged) in the yaw frame (heading-aligned: x forward,
y left, z up; torques about the base's COM):

    observer   the disturbance observer's estimate u_obs (what the `observer` controller uses)
    gravity    the arms' weight and its torque at their pose (`DpcEnv.arm_gravity`; what DPC
               with `u_base` 'gravity' adds its policy's u to)
    feedforward   the arms' model wrench from measured inputs (`control/arm_estimate.py`; the
               `feedforward` controller's u, what DPC with `u_base` 'model' adds its u to)
    dpc        the export's u: u_scale * pi(obs), plus u_obs, u_gravity or the model wrench by
               its base
    other      `--other`'s u on the same observations (e.g. another recipe's export; named
               `--other-label`)
    other, own loop   `--other`'s u on rollouts under its own control (same seeds; with
               `--controller dpc` only)
    C, own loop   the u a classical controller C of `--own-loop` (observer, feedforward,
               feedforward_observer) gives its balance QP, on rollouts under C itself (same
               seeds): for feedforward_observer, the model wrench plus its observer's estimate
               of what the model leaves, which no other controller's rollout computes

A learned estimate is only as good as the states it is asked on: the first rows share the
states of `--controller` (the figure needs one episode), the last shows `--other` where it acts.
A second table gives each component's mean (the oracle's, and each estimate's) and the share of
steps where the policy's target (the oracle's u minus what the export adds its u to) exceeds its
bound u_scale (a policy's u cannot go there).

The figure (`--figure`) shows f_z, tau_x and tau_y around the first push onset (an end-effector
force that starts after at least 1 s of quiet) of an episode that does not fall.
"""

from __future__ import annotations

import argparse
import pathlib

import jax
import matplotlib.pyplot as plt
import numpy as np

from dpc_mjx import io, stats
from dpc_mjx.controllers import Controller
from dpc_mjx.envs import rollout
from dpc_mjx.envs.observations import PRIVILEGED, U_OBS_SIZE
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_yaw_frame

COMPONENTS = ("f_x", "f_y", "f_z", "tau_x", "tau_y", "tau_z")
PUSH_ONSET = 5.0  # N: an end-effector force above this starts a push


def rollouts(export: pathlib.Path, args: argparse.Namespace) -> dict:
    """Per-step records (steps, episodes, ...) of `args.controller` on the reaching task with
    `args.arm`, the export's env options."""
    artefacts = io.load(export)
    options = env_overrides(artefacts) | {"engine": args.engine}
    env = make(DEFAULT_TASK, arm=args.arm, controller=args.controller, **options)
    env.use_arm_model(True)  # the feedforward's estimate, whoever controls
    policy = artefacts.dpc_policy(args.arm)

    def record(before, after):
        yaw = roll_pitch_yaw(before.pipeline_state.qpos[:, 3:7])[:, 2]  # (B,) rad
        privileged = before.info["privileged"]
        return {
            "obs": before.obs,
            "yaw": yaw,
            "u_oracle": privileged[:, PRIVILEGED["u_oracle"]],
            "u_gravity": jax.vmap(env.arm_gravity)(before.pipeline_state),  # (B, 6) world
            "u_model": before.info["ctrl"].arm.wrench,  # (B, 6) world, the last tick's
            "u_observer": before.info["ctrl"].observer.estimate,  # (B, 6) world, this controller's
            "push": privileged[:, PRIVILEGED["ee_force"]],
            "done": after.done,
        }

    carry, key = rollout.start(env, args.episodes, args.seed)
    run_chunk = rollout.make_chunk(jax.vmap(env.step), policy, 50, record)
    parts = []
    for carry, records in rollout.chunks(run_chunk, carry, key, args.steps // 50):
        parts.append(records)
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    done_before = np.cumsum(out["done"], axis=0) - out["done"]  # dones before this step
    out["alive"] = done_before == 0
    out["u_scale"] = np.asarray(env.config.u_scale)
    out["gravity"] = np.asarray(wrench_to_yaw_frame(out["u_gravity"], out["yaw"]))
    out["model"] = np.asarray(wrench_to_yaw_frame(out["u_model"], out["yaw"]))
    out["observer"] = np.asarray(wrench_to_yaw_frame(out["u_observer"], out["yaw"]))
    out["truth"] = np.asarray(wrench_to_yaw_frame(out["u_oracle"], out["yaw"]))
    out["u_base"] = options.get("u_base", "zero")  # what the export's policy adds its u to
    return out


def classical_u(rec: dict, controller: str) -> np.ndarray:
    """(steps, episodes, 6) yaw frame: the u `controller` gave its balance QP, from its own
    rollout's records (`Controller.adds`: the observer's estimate, the model wrench, or both)."""
    add_estimate, add_model = Controller(controller).adds()
    return add_model * rec["model"] + add_estimate * rec["observer"]


def policy_base(rec: dict, u_base: str) -> np.ndarray | float:
    """(steps, episodes, 6) yaw frame: what a policy's u is added to by its `u_base` (u_obs,
    the arms' gravity or model wrench; 0 in the paper's form)."""
    base = {"observer": rec["obs"][..., -U_OBS_SIZE:], "gravity": rec["gravity"]}
    base["model"] = rec["model"]
    return base.get(u_base, 0.0)


def estimates(rec: dict, export: pathlib.Path, arm: str) -> np.ndarray:
    """(steps, episodes, 6) the export's u on the recorded observations, yaw frame: its
    policy's u_scale * a, plus u_obs, the arms' gravity or model wrench by its `u_base`."""
    artefacts = io.load(export)
    options = env_overrides(artefacts)
    scale = np.asarray(make(DEFAULT_TASK, arm=arm, **options).config.u_scale)
    act = jax.jit(lambda p, obs: p(obs, None))(artefacts.dpc_policy(arm), rec["obs"])
    u = np.asarray(act) * scale
    if options["u_frame"] != "yaw":
        u = np.asarray(wrench_to_yaw_frame(u, rec["yaw"]))
    return u + policy_base(rec, options.get("u_base", "zero"))


def accuracy_table(rows: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """R^2 per component and RMSE of force and torque of each estimate against its truth."""
    print(
        "| estimate | " + " | ".join(f"R^2 {c}" for c in COMPONENTS) + " | RMSE f (N) | "
        "RMSE tau (N·m) |"
    )
    print("|---|" + "---|" * 8)
    for name, (u, true) in rows.items():
        r2, rmse = stats.r2(true, u), stats.rmse(true, u)  # per component
        cells = " | ".join(f"{v:.2f}" for v in r2)
        f_rmse = np.sqrt((rmse[:3] ** 2).mean())
        t_rmse = np.sqrt((rmse[3:] ** 2).mean())
        print(f"| {name} | {cells} | {f_rmse:.2f} | {t_rmse:.2f} |")


def bias_table(rows: dict, truth: np.ndarray, target: np.ndarray, u_scale: np.ndarray) -> None:
    """Each component's mean (N, N·m; the oracle's, then each estimate's on the same steps) and
    the share of steps where the policy's `target` (the oracle's u minus what the policy's u is
    added to) exceeds the policy's bound `u_scale`: where a policy's u cannot go."""
    print("\n| mean | " + " | ".join(COMPONENTS) + " |")
    print("|---|" + "---|" * 6)
    print("| oracle (privileged) | " + " | ".join(f"{v:+.2f}" for v in truth.mean(0)) + " |")
    for name, (u, _) in rows.items():
        print(f"| {name} | " + " | ".join(f"{v:+.2f}" for v in u.mean(0)) + " |")
    beyond = np.mean(np.abs(target) > u_scale, axis=0)
    print("| the policy's target beyond u_scale (share of steps) | ", end="")
    print(" | ".join(f"{v:.2f}" for v in beyond) + " |")


def figure(rec: dict, series: dict[str, np.ndarray], truth: np.ndarray, path: pathlib.Path):
    plt.switch_backend("Agg")  # PNG files, no screen needed
    force = np.linalg.norm(rec["push"], axis=-1)  # (T, B) N
    quiet = round(1.0 / 0.02)
    chosen = None
    for b in np.flatnonzero(rec["alive"][-1]):  # episodes that never fell
        on = np.flatnonzero((force[1:, b] > PUSH_ONSET) & (force[:-1, b] <= PUSH_ONSET)) + 1
        on = [t for t in on if t >= quiet and force[t - quiet : t, b].max() <= PUSH_ONSET]
        if on and on[0] + 100 < len(force):
            chosen = (b, on[0])
            break
    if chosen is None:
        print("figure: no push onset found in an episode that did not fall")
        return
    b, t0 = chosen
    window = np.arange(t0 - 25, t0 + 100)
    t = (window - t0) * 0.02
    fig, axes = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    axes[0].plot(t, force[window, b], "k")
    axes[0].set_ylabel("push |F| (N)")
    styles = {"oracle": "k", "observer": "tab:orange", "dpc": "tab:blue"}
    for ax, i, unit in zip(axes[1:], (2, 3, 4), ("N", "N·m", "N·m"), strict=True):
        ax.plot(t, truth[window, b, i], styles["oracle"], label="oracle (measured)")
        for name, u in series.items():
            ax.plot(t, u[window, b, i], color=styles.get(name, "tab:green"), label=name)
        ax.set_ylabel(f"{COMPONENTS[i]} ({unit})")
    axes[1].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time from push onset (s)")
    fig.suptitle(f"u under a sudden force (episode {b}, yaw frame)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"figure: {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--export", default=str(SHIPPED))
    ap.add_argument("--other", help="a second export, evaluated on the same observations")
    ap.add_argument("--other-label", default="other", help="its name in the table and figure")
    ap.add_argument("--episodes", type=int, default=32)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=5000)
    ap.add_argument("--arm", default="regular", help="an arm the export has an encoder of")
    ap.add_argument("--controller", default="dpc", help="whose states: dpc, oracle, ...")
    ap.add_argument("--engine", default="auto", help="auto, mjx or native")
    ap.add_argument("--figure", default="docs/figures/u_estimation.png")
    ap.add_argument(
        "--own-loop",
        nargs="*",
        default=[],
        choices=["observer", "feedforward", "feedforward_observer"],
        help="classical controllers whose u is also measured on rollouts under their own control",
    )
    args = ap.parse_args()
    rec = rollouts(pathlib.Path(args.export), args)
    truth = rec["truth"]
    u_obs = rec["obs"][..., -U_OBS_SIZE:]  # the observation's last entries
    series = {"observer": u_obs, "gravity": rec["gravity"], "feedforward": rec["model"]}
    series["dpc"] = estimates(rec, args.export, args.arm)
    rows = {}
    if args.other:
        series[args.other_label] = estimates(rec, args.other, args.arm)
    if args.other and args.controller == "dpc":
        own = rollouts(pathlib.Path(args.other), args)
        own_truth = np.asarray(wrench_to_yaw_frame(own["u_oracle"], own["yaw"]))
        own_u = estimates(own, args.other, args.arm)
        rows[f"{args.other_label}, own loop"] = (own_u[own["alive"]], own_truth[own["alive"]])
    for name in args.own_loop:
        own_args = argparse.Namespace(**{**vars(args), "controller": name})
        own = rollouts(pathlib.Path(args.export), own_args)
        u = classical_u(own, name)
        rows[f"{name}, own loop"] = (u[own["alive"]], own["truth"][own["alive"]])
    alive = rec["alive"]
    rows = {name: (u[alive], truth[alive]) for name, u in series.items()} | rows
    print(
        f"{args.arm}, under {args.controller}: {int(alive.sum()):,} steps of {args.episodes} "
        f"episodes (seeds from {args.seed})"
    )
    accuracy_table(rows)
    target = (truth - policy_base(rec, rec["u_base"]))[alive]  # what the export's policy must give
    bias_table({name: rows[name] for name in series}, truth[alive], target, rec["u_scale"])
    figure(rec, series, truth, pathlib.Path(args.figure))


if __name__ == "__main__":
    main()
