"""What DPC on the arms' model costs to train and to transfer, against the paper's form, side by
side in one run.

    python experiments/bench_train.py [--rounds 2] [--arm z1] [--samples 10000] [--out DIR]

Per round, each form in turn (so that the shared machine's drift hits both alike):
- 'paper': `recipe("default")` with `env.u_base='zero'`, the actor regressed on the oracle's u;
- 'model': `recipe("default")` as shipped, `env.u_base='model'`, the model wrench computed at
  every tick of the collection and the regression on what the model cannot know;
the whole `dpc-mjx train` pipeline (`run.pipeline.train_and_evaluate`: the adapter's 100,000
samples, its training, the actor's regression, the export) with an evaluation of one 10-step
episode (its time not counted), then `dpc-mjx transfer` of `--arm` with `--samples` samples
(`run.pipeline.transfer_arm`). Prints the stages' times (s; compiles included, as a user waits
for them) and the model form's over the paper's, the median of the rounds'.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import tempfile

from dpc_mjx.run.config import recipe
from dpc_mjx.run.pipeline import train_and_evaluate, transfer_arm
from dpc_mjx.timing import Stopwatch

FORMS = {"paper": {"env.u_base": "zero"}, "model": {}}  # over recipe("default")
# the adapter's data, its training, the rest of the training (the actor's regression, the
# export), all of the training, the transfer's collection and encoder
STAGES = ("data", "adapter", "regression and export", "training", "transfer")


def one_round(form: str, out: pathlib.Path, arm: str, samples: int) -> dict[str, float]:
    """The stages' times (s) of one training and one transfer in `form` (`FORMS`)."""
    config = recipe("default").replace(eval_episodes=1, eval_steps=10, **FORMS[form])
    run = out / form
    with Stopwatch() as train:
        summary = train_and_evaluate(config, run, progress=False)
    timings = summary["timings_seconds"]
    with Stopwatch() as transfer:
        transfer_arm(run / "export", arm, samples=samples, progress=False)
    training = train.seconds - timings["eval_seconds"]
    data, adapter = timings["data_seconds"], timings["adapter_seconds"]
    return dict(zip(STAGES, (data, adapter, training - data - adapter, training, transfer.seconds)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--arm", default="z1", help="the arm each export is transferred to")
    p.add_argument("--samples", type=int, default=10_000, help="the transfer's samples")
    p.add_argument("--out", help="the runs' folder (default: a temporary one)")
    args = p.parse_args()
    times: dict[str, list[dict]] = {form: [] for form in FORMS}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for form in FORMS:
                out = pathlib.Path(args.out or tmp) / f"round{r}"
                times[form].append(one_round(form, out, args.arm, args.samples))
                print(f"round {r + 1}/{args.rounds}, {form}: {times[form][-1]}", flush=True)
    print("\n| stage | paper (s) | model (s) | model / paper |\n|---|---|---|---|")
    for stage in STAGES:
        paper = statistics.median(t[stage] for t in times["paper"])
        model = statistics.median(t[stage] for t in times["model"])
        rounds = zip(times["paper"], times["model"], strict=True)
        ratio = statistics.median(m[stage] / q[stage] for q, m in rounds)
        print(f"| {stage} | {paper:.1f} | {model:.1f} | {ratio:.2f} |")


if __name__ == "__main__":
    main()
