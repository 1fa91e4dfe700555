"""Transfer to a new arm, measured: DPC's fall rate and return against the encoder's data budget.

    python experiments/transfer_curve.py --arm longer [--export DIR] [--budgets 1000 3000 10000
        30000 100000] [--episodes 64] [--seed 2000] [--full RUN_EXPORT] [--engine native]
        [--out FILE.md]

The paper's protocol (§III-C): the export's policy and decoder stay frozen; only a new encoder is
trained, on MBC random-motion samples of the new arm. One collection of max(budgets) samples
(seed `--data-seed`); each budget's encoder is trained on its first n samples (nested subsets:
what a collection of n samples with the same 64 envs gives, i.e. n / 64 steps of each env).
Every controller runs the same `--episodes` episodes of the reaching task (seeds `--seed`..,
under the export's env options: yaw-frame u, the robot's sensors): MBC, the observer, the arms'
model fed forward with and without the observer and the oracle (given the measured mount wrench:
privileged) once, DPC once per budget, and with
`--full`, the DPC of a policy trained from scratch for this arm with the whole pipeline.
Prints one table: falls, fall rate and return with 95% intervals, the paired return difference
against MBC on the same episodes, and with `--full` the share of the full policy's gain over MBC
that each budget reaches, (R - R_MBC) / (R_full - R_MBC). `--engine native` collects and
evaluates in MuJoCo C (`EnvConfig.engine`; for heavy arms such as `z1`, which MJX steps slowly
on a CPU).
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib

from dpc_mjx import adapter, io
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.eval import evaluate, table_row
from dpc_mjx.run.report import versus_baseline
from dpc_mjx.sac import dpc_policy

TASK = DEFAULT_TASK
HEADER = (
    "| arm | controller | falls | fall rate [95% CI] | mean return [95% CI] | return - MBC, "
    "paired [95% CI] | McNemar p vs MBC | share of the full policy's gain |\n"
    "|---|---|---|---|---|---|---|---|"
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arm", required=True, help="the new arm variant")
    ap.add_argument("--export", default=str(SHIPPED), help="the export to transfer from")
    ap.add_argument("--budgets", type=int, nargs="+", default=[1000, 3000, 10_000, 30_000, 100_000])
    ap.add_argument("--episodes", type=int, default=64)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=2000, help="first evaluation seed")
    ap.add_argument("--data-seed", type=int, default=0)
    ap.add_argument("--full", help="the export of a policy trained from scratch for this arm")
    ap.add_argument("--engine", default="mjx", help="mjx or native (physics of every stage)")
    ap.add_argument("--out", help="also write the table to this markdown file")
    args = ap.parse_args()

    art = io.load(args.export)
    overrides = {**env_overrides(art), "engine": args.engine}
    data = adapter.collect(
        make(TASK, arm=args.arm, controller="mbc", **overrides),
        max(args.budgets),
        seed=args.data_seed,
    )
    config = dataclasses.replace(art.adapter_config, seed=args.data_seed)

    def show(c) -> None:
        print(table_row(c), flush=True)

    def run(controllers: list[str], policy=None, on_result=show) -> list:
        """The protocol's cells (`run.eval.evaluate`) on this arm and the episodes above."""
        return evaluate(
            [args.arm],
            controllers,
            task=TASK,
            episodes=args.episodes,
            steps=args.steps,
            seed=args.seed,
            dpc_policy_for=None if policy is None else (lambda _: policy),
            overrides=overrides,
            on_result=on_result,
        )

    def cell(policy, label: str):
        c = dataclasses.replace(run(["dpc"], policy, on_result=None)[0], controller=label)
        show(c)
        return c

    cells = run(["mbc", "observer", "feedforward", "feedforward_observer", "oracle"])
    for n in sorted(args.budgets):
        encoder, history = adapter.transfer(data.take(slice(0, n)), art.decoder, config)
        print(f"{n:,} samples: held-out NLL {min(history['val_nll']):.3f}", flush=True)
        cells.append(
            cell(dpc_policy(art.adapter_config, encoder, art.policy), f"dpc, {n:,} samples")
        )
    if args.full:
        full = io.load(args.full)
        policy = dpc_policy(full.adapter_config, full.encoder(args.arm), full.policy)
        cells.append(cell(policy, "dpc, trained for this arm"))

    mbc = cells[0]
    full_return = cells[-1].mean_return if args.full else None
    lines = [HEADER]
    for c in cells:
        paired, p, share = versus_baseline(c, mbc, full_return)
        lines.append(
            f"| {args.arm} | {c.controller} | {c.falls} | {c.fall_rate:.2f} "
            f"[{c.fall_ci[0]:.2f}, {c.fall_ci[1]:.2f}] | {c.mean_return:.1f} "
            f"[{c.return_ci[0]:.1f}, {c.return_ci[1]:.1f}] | {paired} | {p} | {share} |"
        )
    table = "\n".join(lines)
    print(table)
    if args.out:
        pathlib.Path(args.out).write_text(table + "\n")


if __name__ == "__main__":
    main()
