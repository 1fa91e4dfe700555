"""The paper's Table I on its tasks: each arm on the task it suits, with the policy and decoder
trained once on `regular`/reaching and only the arm's encoder transferred (the paper's protocol).

    python experiments/table_one.py [--export DIR] [--episodes 64] [--seed 13000]
        [--engine native] [--out runs/table_one]

Cells, and the paper's rows they stand for (its Table I names arms, not tasks; the text maps
them: "a heavier but flat robotic arm is used for [pushing]", the longer arm for the higher table,
two arms for several balls):

    reaching / regular         the paper's `regular` row (the training task)
    lifting / regular          the paper's Fig. "ball lifting" (no row)
    carrying_high / longer     the `longer` row
    carrying / double          the `double` row
    pushing / pusher           the `heavier` row (our `pusher`: the `regular` links with a 0.5 kg
                               flat plate; our `heavier` keeps a 0.5 kg gripper)

Every cell runs every controller (`Controller`: MBC, the observer, the feedforward, the
feedforward observer, DPC and the oracle, privileged: the measured arm wrench) on
the same `--episodes` episodes of each task's default config (seeds `--seed`..: say in the docs
that they chose nothing), for the task's episode length. Writes, per cell, the evaluation's
markdown and per-episode CSV to `--out`, and prints a summary: per controller the fall rate and
the return [95% CI], DPC - MBC paired on the same episodes, and the task's measures [95% CI].
"""

from __future__ import annotations

import argparse
import pathlib

from dpc_mjx.controllers import Controller
from dpc_mjx.io.shipped import SHIPPED
from dpc_mjx.run.pipeline import evaluate_export
from dpc_mjx.run.report import ci_text, paired_text, read_cells

CELLS = (  # (task, arm, the paper's row, the task's main measure: a CSV column)
    ("reaching", "regular", "regular", "ee_rmse"),
    ("lifting", "regular", "(Fig. lifting)", "pos_rmse"),
    ("carrying_high", "longer", "longer", "ball_on_target"),
    ("carrying", "double", "double", "ball_on_target"),
    ("pushing", "pusher", "heavier", "box_dx"),
)
CONTROLLERS = tuple(Controller)  # MBC, the classical ones, DPC, the oracle: the table's columns
_NAMES = " | ".join(
    "oracle (privileged)" if c is Controller.ORACLE else c.value for c in CONTROLLERS
)
HEADER = (
    f"| task / arm | paper's row | {_NAMES} "
    "| DPC - MBC return, paired [95% CI] | DPC - MBC fall rate, paired [95% CI] |\n"
    f"|{'---|' * (len(CONTROLLERS) + 4)}"
)
MEASURE_HEADER = (
    f"| task / arm | measure (per episode) | {_NAMES} "
    "| DPC - MBC, paired [95% CI] | oracle - MBC, paired [95% CI] |\n"
    f"|{'---|' * (len(CONTROLLERS) + 4)}"
)


def summarize(out: pathlib.Path) -> str:
    """The two summary tables from the cells' CSVs in `out`."""
    rows, measures = [], []
    for task, arm, paper, measure in CELLS:
        path = out / f"{task}-{arm}.csv"
        if not path.exists():
            continue
        c = read_cells(path)
        figures = " | ".join(
            f"{c[k]['fell'].mean():.2f}, {ci_text(c[k]['return'], '.1f')}" for k in CONTROLLERS
        )
        dpc, mbc = c["dpc"], c["mbc"]
        rows.append(
            f"| {task} / {arm} | {paper} | {figures} | "
            f"{paired_text(dpc['return'], mbc['return'], '+.1f')} | "
            f"{paired_text(dpc['fell'], mbc['fell'])} |"
        )
        per = " | ".join(ci_text(c[k][measure]) for k in CONTROLLERS)
        measures.append(
            f"| {task} / {arm} | {measure} | {per} | {paired_text(dpc[measure], mbc[measure])} | "
            f"{paired_text(c['oracle'][measure], mbc[measure])} |"
        )
    return "\n".join([HEADER, *rows, "", MEASURE_HEADER, *measures])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--export", default=str(SHIPPED))
    ap.add_argument("--episodes", type=int, default=64)
    ap.add_argument("--seed", type=int, default=13000)
    ap.add_argument("--engine", default="native", help="mjx or native (the faster on a CPU)")
    ap.add_argument("--out", default="runs/table_one")
    ap.add_argument(
        "--summarize", action="store_true", help="only the summary, from the CSVs in --out"
    )
    args = ap.parse_args()

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for task, arm, _, _ in [] if args.summarize else CELLS:
        print(f"\n## {task} / {arm}", flush=True)
        evaluate_export(
            args.export,
            arms=[arm],
            controllers=list(CONTROLLERS),
            task=task,
            episodes=args.episodes,
            seed=args.seed,
            out=out / f"{task}-{arm}.md",
            csv=out / f"{task}-{arm}.csv",
            env={"engine": args.engine},
        )
    table = summarize(out)
    print("\n" + table, flush=True)
    (out / "summary.md").write_text(table + "\n")


if __name__ == "__main__":
    main()
