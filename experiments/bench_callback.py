"""What a host callback costs per call, by how many arrays cross: the native engine's choice.

    .venv/bin/python experiments/bench_callback.py [--batches 64 256] [--calls 50]
    taskset -c 0 .venv/bin/python experiments/bench_callback.py   # one core, as bench_limit

`jax.pure_callback` inside `jit(vmap(scan(...)))`, as `dpc_mjx.physics.NativePhysics` calls it
once per physics tick, with a host function that does no work (it returns a preallocated
array): what is left is the callback's own cost. The arrays have the shapes of the reaching
env's `physics.INPUTS` and `physics.OUTPUTS` (`regular`): passed as one array per field (7 in,
14 out), or packed into one array each way (what `NativePhysics` does). "no callback" is the
same scan with the host call replaced by a trivial XLA op: the loop's own floor. Times are the
best of 5 runs of `--calls` scanned calls, compile apart; all rows in one process.
"""

from __future__ import annotations

import argparse
import math

import jax
import jax.numpy as jp
import numpy as np
from mujoco import mjx

import dpc_mjx
from dpc_mjx.physics import INPUTS, OUTPUTS
from dpc_mjx.timing import run_calls, timed


def field_shapes() -> tuple[list[tuple], list[tuple]]:
    """Per env shapes of `INPUTS` and `OUTPUTS` in the reaching env (`regular`)."""
    d = mjx.make_data(dpc_mjx.make("reaching", arm="regular", engine="native").mx)
    return [getattr(d, k).shape for k in INPUTS], [getattr(d, k).shape for k in OUTPUTS]


def per_field(ins, outs, batch):
    """One array per field each way: (B, *field)."""
    results = [np.zeros((batch, *s), np.float32) for s in outs]
    specs = [jax.ShapeDtypeStruct(s, jp.float32) for s in outs]

    def tick(xs):
        out = jax.pure_callback(lambda *_: results, specs, *xs, vmap_method="broadcast_all")
        return [x + out[0] for x in xs]  # its output feeds every input: nothing is hoisted

    return tick, [jp.zeros(s) for s in ins]


def packed(ins, outs, batch):
    """One array each way: (B, sum of the field sizes)."""
    n_in, n_out = (sum(math.prod(s) for s in shapes) for shapes in (ins, outs))
    result = np.zeros((batch, n_out), np.float32)
    spec = jax.ShapeDtypeStruct((n_out,), jp.float32)

    def tick(x):
        return x + jax.pure_callback(lambda _: result, spec, x, vmap_method="broadcast_all")[0]

    return tick, jp.zeros(n_in)


def no_callback(ins, outs, batch):
    del outs, batch
    return (lambda x: x + 1.0), jp.zeros(sum(math.prod(s) for s in ins))


def time_per_call(make_tick, ins, outs, batch: int, calls: int) -> tuple[float, float]:
    """(compile + first run s, s per scanned call) of `calls` ticks under jit(vmap(scan))."""
    tick, x = make_tick(ins, outs, batch)
    xs = jax.tree.map(lambda a: jp.broadcast_to(a, (batch, *a.shape)), x)
    body = jax.vmap(tick)
    run = jax.jit(lambda xs: jax.lax.scan(lambda c, _: (body(c), None), xs, None, calls)[0])
    _, first = timed(run, xs)
    best = min(run_calls(lambda _: run(xs), None, 1)[0] for _ in range(5))
    return first, best / calls


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--batches", type=int, nargs="+", default=[64, 256])
    p.add_argument("--calls", type=int, default=50, help="scanned callback calls per run")
    args = p.parse_args()
    ins, outs = field_shapes()
    print(f"jax {jax.__version__}; per env {sum(map(math.prod, ins))} floats in, "
          f"{sum(map(math.prod, outs))} out\n")  # fmt: skip
    print("| batch | arrays crossing | compile + first run (s) | us per call |")
    print("|---|---|---|---|")
    variants = {
        "no callback": no_callback,
        f"one per field ({len(ins)} in, {len(outs)} out)": per_field,
        "packed (1 in, 1 out)": packed,
    }
    for batch in args.batches:
        for name, make_tick in variants.items():
            first, per_call = time_per_call(make_tick, ins, outs, batch, args.calls)
            print(f"| {batch} | {name} | {first:.2f} | {per_call * 1e6:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
