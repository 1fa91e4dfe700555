"""Does an export's policy and decoder carry to another base with only a new encoder?

    python experiments/carry_over.py [--export dpc_mjx/artefacts/regular] [--base go1]
        [--arm regular] [--samples 10000] [--episodes 128] [--seed 33000] [--engine native]
        [--controllers mbc observer feedforward feedforward_observer dpc oracle]

The paper's transfer step (`run.pipeline.transfer_arm`: random-motion samples under MBC, a new
encoder trained against the frozen decoder), but on the base `--base` instead of the one the
export was trained on: a copy of the export (in a temporary folder; the export itself is not
touched) gets the new encoder, under the arm's name. Then MBC, DPC (the export's policy with the
new encoder) and the oracle (privileged: the measured mount wrench) run the same episodes on
`--base` with the export's env options (its pushes and u's bounds, not rescaled to the base's
weight); `run.eval.evaluate_table` prints the table and the paired 95% intervals of DPC minus
each other controller.
`dpc-mjx eval --export` refuses another base than the export's; this script is the measurement
behind that refusal.
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import sys
import tempfile

from dpc_mjx import io
from dpc_mjx.controllers import Controller
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.run.eval import evaluate_table
from dpc_mjx.run.pipeline import transfer_arm


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--export", default=str(SHIPPED))
    p.add_argument("--base", default="go1")
    p.add_argument("--arm", default="regular")
    p.add_argument("--samples", type=int, default=10_000)
    p.add_argument("--episodes", type=int, default=128)
    p.add_argument("--seed", type=int, default=33000, help="the evaluation's first episode")
    p.add_argument("--engine", default="native")
    p.add_argument("--controllers", nargs="+", default=list(Controller), choices=list(Controller))
    a = p.parse_args()
    print(f"`python {shlex.join(sys.argv)}`\n", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        export = shutil.copytree(a.export, f"{tmp}/export")
        options = {"base": a.base, "engine": a.engine}
        transfer_arm(export, a.arm, samples=a.samples, env=options)
        artefacts = io.load(export)
        evaluate_table(
            [artefacts.arm_spec(a.arm)], a.controllers, episodes=a.episodes,
            seed=a.seed, dpc_policy_for=artefacts.dpc_policy,
            overrides={**env_overrides(artefacts), **options},
        )  # fmt: skip


if __name__ == "__main__":
    main()
