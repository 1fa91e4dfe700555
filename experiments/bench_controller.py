"""Cost of the low-level controller relative to MJX physics, at the same batch, in one run.

    python experiments/bench_controller.py [--batches 1 256 1024]

Rows: MJX physics alone (robot standing on leg servos), the controller tick alone (state read,
balance QP, swing PD, tau = J^T f) on fixed data, and the closed loop (controller + physics),
all jit(vmap) with `CHUNK` ticks scanned per call; compile time apart.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jp
import numpy as np

import dpc_mjx  # noqa: F401
from dpc_mjx import sim
from dpc_mjx.control import gait
from dpc_mjx.control.closed_loop import init_loop, make_chunk
from dpc_mjx.control.controller import make_controller
from dpc_mjx.robots import build
from dpc_mjx.robots.standing import home_ctrl, perturbed_home, with_leg_servos
from dpc_mjx.timing import time_calls

CHUNK = 50


def bench(variant: str, batch: int, calls: int) -> list[tuple[str, float, float]]:
    model = build(variant)
    servo = with_leg_servos(model)
    mx_servo = sim.put_model(servo)
    data = sim.batched_data(
        mx_servo, perturbed_home(servo, batch), np.tile(home_ctrl(servo), (batch, 1))
    )
    physics = sim.make_rollout(mx_servo, CHUNK)
    c_phys, t_phys, _ = time_calls(physics, data, calls)

    mx = sim.put_model(model)
    controller = make_controller(model, gait_=gait.trot())
    ls = init_loop(
        controller,
        sim.batched_data(mx, perturbed_home(model, batch), np.tile(model.key_ctrl[0], (batch, 1))),
    )
    cmd = jp.tile(jp.array([0.3, 0.0, 0.0]), (batch, 1))
    zeros = jp.zeros((batch, 6))

    def ctrl_only(cs):
        def one(c, d, command):
            return jax.lax.scan(
                lambda c, _: (controller.step(c, d, command, jp.zeros(6))[0], None),
                c,
                None,
                length=CHUNK,
            )[0]

        return jax.vmap(one)(cs, ls.data, cmd)

    c_ctrl, t_ctrl, _ = time_calls(jax.jit(ctrl_only), ls.ctrl, calls)
    loop = make_chunk(mx, controller, CHUNK, kind="mbc")
    c_loop, t_loop, _ = time_calls(lambda s: loop(s, cmd, zeros, zeros), ls, calls)
    per = batch * CHUNK
    return [
        ("MJX physics step", c_phys, t_phys / per),
        ("controller tick", c_ctrl, t_ctrl / per),
        ("controller + physics", c_loop, t_loop / per),
    ]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variant", default="regular")
    p.add_argument("--batches", type=int, nargs="*", default=[1, 256, 1024])
    p.add_argument("--calls", type=int, default=4)
    a = p.parse_args()
    print(f"variant {a.variant}, {CHUNK} ticks per call, jax {jax.__version__}")
    print("| batch | what | compile (s) | us per env-tick | env-ticks/s | relative to physics |")
    print("|---|---|---|---|---|---|")
    for b in a.batches:
        rows = bench(a.variant, b, a.calls)
        phys = rows[0][2]
        for name, comp, per in rows:
            print(
                f"| {b} | {name} | {comp:.1f} | {per * 1e6:.1f} | {1 / per:,.0f} | "
                f"{per / phys:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
