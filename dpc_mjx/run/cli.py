"""The `dpc-mjx` command line: one entry point, a subcommand per stage.

    dpc-mjx demo                       a small run, then MBC / observer / DPC (minutes)
    dpc-mjx train --run runs/x         data -> adapter -> policy (-> SAC) -> export -> evaluation
                                       (`--recipe paper`: SAC from a random actor)
    dpc-mjx train-adapter --run runs/x only the adapter stage (continue with train --resume)
    dpc-mjx transfer --export DIR --arm so100    a new arm's encoder against the frozen decoder
                                       (--arm my_arm.urdf, .xml or .json: your own arm)
    dpc-mjx eval --export DIR          MBC / observer / DPC / oracle, protocol of docs/results.md
                                       (--engine: native MuJoCo C, the CPU default, or mjx)
    dpc-mjx sim2sim --export DIR       the same cells in MJX and in native MuJoCo, side by side
    dpc-mjx sweep --upper-arm 0.10:0.30:8 --gripper-mass 0.1:0.6:8   every controller over a
                                       grid of arms, one batched model (CSV and heatmaps)
    dpc-mjx export --run runs/x        (re-)export a run's adapter and policy
    dpc-mjx onnx --export DIR --arm so100 --out policy.onnx   its encoder + policy as one ONNX graph
    dpc-mjx render --out clip.mp4      a video of an episode (--compare mbc dpc: side by side)
    dpc-mjx view --controller dpc      MuJoCo's viewer, live: keys steer, the mouse pushes
    dpc-mjx bench                      env steps/s of the full env vs MJX physics alone
    dpc-mjx variants                   every arm variant built and stood in MJX
    dpc-mjx mjcf                       write every variant's MJCF into mjcf/
    dpc-mjx base go2 --out my_dog.json what a base's file gives, as a JSON to correct

`--base go2` (a named base or your quadruped's .urdf/.xml/.json) on train, transfer, eval, sim2sim,
render and view: the same as `--env base=go2` (`--set env.base=go2` for train).

Hyperparameters are not flags: `--set name=value ...` overrides any `RunConfig` field by dotted
name (`arm=longer`, `sac.num_envs=32`, `adapter.epochs=40`, `env.push_force=[0,60]`); values are
read as JSON where they parse as JSON, else as strings.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from dpc_mjx import compile_cache
from dpc_mjx.controllers import Controller
from dpc_mjx.errors import DpcError
from dpc_mjx.run.cli_tools import (
    BASE_HELP,
    CONTROLLER_NAMES,
    TASK_HELP,
    add_episode_options,
    env_options,
    given,
    parse_sets,
    tool_commands,
)

_CONTROLLERS = [c.value for c in Controller]  # every one, `dpc_mjx.controllers`
_CONTROLLERS_HELP = f"any of {CONTROLLER_NAMES} (default: all)"


def _run_config(args: argparse.Namespace):
    from dpc_mjx.run.config import recipe  # noqa: PLC0415 (subcommand handler)

    named = {k: getattr(args, k) for k in ("arm", "samples", "task") if getattr(args, k, None)}
    if getattr(args, "timesteps", None):
        named["sac.num_timesteps"] = args.timesteps
    if getattr(args, "episodes", None):
        named["eval_episodes"] = args.episodes
    if getattr(args, "base", None):
        named["env.base"] = args.base
    base = recipe(getattr(args, "recipe", "default"), _device(args))
    return base.replace(**named, **parse_sets(args.set))


def _device(args: argparse.Namespace) -> str:
    """The device preset of `--device` ('auto': the backend JAX runs on), printed."""
    from dpc_mjx.run.config import preset_name  # noqa: PLC0415 (subcommand handler)

    preset = preset_name(getattr(args, "device", "auto"))
    import jax  # noqa: PLC0415 (after the preset's name: jax starts its backend here)

    print(
        f"device: {jax.default_backend()} ({jax.device_count()} x "
        f"{jax.devices()[0].device_kind}), {preset} sizes (run.config.DEVICE_PRESETS)"
    )
    return preset


def _train(args: argparse.Namespace) -> None:
    from dpc_mjx.run.config import read_run_config  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.run.pipeline import train_and_evaluate  # noqa: PLC0415 (subcommand handler)

    run = pathlib.Path(args.run)
    config = read_run_config(run) if args.resume and not args.set else _run_config(args)
    train_and_evaluate(config, run, resume=args.resume, logdir=args.logdir)
    print(f"run folder: {run} (eval.md, summary.json, plots/, export/)")


def _train_adapter(args: argparse.Namespace) -> None:
    from dpc_mjx.run.config import start_run  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.run.pipeline import run_events, train_adapter  # noqa: PLC0415 (handler)

    run = pathlib.Path(args.run)
    config = _run_config(args)
    start_run(config, run, resume=False)
    train_adapter(config, run, events=run_events(config, run, args.logdir))
    print(f"adapter saved in {run / 'adapter'}; continue with: dpc-mjx train --run {run} --resume")


def _transfer(args: argparse.Namespace) -> None:
    from dpc_mjx.run.pipeline import transfer_arm  # noqa: PLC0415 (subcommand handler)

    options = given(args, ("samples", "task", "seed"))
    transfer_arm(args.export, args.arm, **options, env=env_options(args))


def _eval(args: argparse.Namespace) -> None:
    from dpc_mjx.io import load  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.io.shipped import engine_of, shipped_for  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.physics import resolve_engine  # noqa: PLC0415
    from dpc_mjx.run.pipeline import evaluate_export  # noqa: PLC0415 (subcommand handler)

    env = _env_options(args)
    export = args.export or shipped_for(args.base)
    engine = env.get("engine") or engine_of(load(export))  # the export's, where it runs here
    prefix = "native-" if resolve_engine(engine) == "native" else ""
    evaluate_export(export, **_cells(args, prefix), **_eval_sizes(args), env=env)


def _eval_sizes(args: argparse.Namespace) -> dict:
    """Episodes (unless `--episodes`) and chunk length of the device's preset (`--device`)."""
    from dpc_mjx.run.config import DEVICE_PRESETS, RunConfig  # noqa: PLC0415 (handler)

    sized = RunConfig().replace(**DEVICE_PRESETS[_device(args)])
    return {"episodes": args.episodes or sized.eval_episodes, "chunk": sized.eval_chunk}


def _cells(args: argparse.Namespace, csv_prefix: str) -> dict:
    """The keyword arguments that `eval` and `sim2sim` share (`eval_options`), CSV defaulted."""
    names = ("arms", "controllers", "task", "steps", "seed", "out")
    return given(args, names) | {"csv": args.csv or _default_csv(args, csv_prefix)}


def _env_options(args: argparse.Namespace) -> dict:
    """`--env NAME=VALUE ...` with `--engine` (if given) as the engine."""
    env = env_options(args)
    if getattr(args, "engine", None):
        if env.get("engine", args.engine) != args.engine:
            raise DpcError(f"--engine {args.engine} and --env engine={env['engine']} disagree.")
        env["engine"] = args.engine
    return env


def _sim2sim(args: argparse.Namespace) -> None:
    from dpc_mjx.io.shipped import shipped_for  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.run.sim2sim import sim2sim  # noqa: PLC0415 (subcommand handler)

    export = args.export or shipped_for(args.base)
    cells = _cells(args, "sim2sim-") | given(args, ("episodes",))
    sim2sim(export, **cells, env=env_options(args))


def _sweep(args: argparse.Namespace) -> None:
    from dpc_mjx.run.sweep import sweep  # noqa: PLC0415 (subcommand handler)

    names = ("controllers", "task", "episodes", "steps", "seed", "out")
    sweep(
        args.export,
        upper_arm=args.upper_arm,
        gripper_mass=args.gripper_mass,
        env=env_options(args),
        **given(args, names),
    )


def _default_csv(args: argparse.Namespace, prefix: str = "") -> pathlib.Path:
    """Beside `--out` (same name, .csv), else runs/eval/<prefix><task>-seed<seed>.csv."""
    if args.out:
        return pathlib.Path(args.out).with_suffix(".csv")
    from dpc_mjx.envs.registry import DEFAULT_TASK  # noqa: PLC0415 (subcommand handler)

    name = f"{prefix}{(args.task or DEFAULT_TASK).replace('/', '-')}-seed{args.seed}.csv"
    return pathlib.Path("runs", "eval", name)


def _demo(args: argparse.Namespace) -> None:
    from dpc_mjx.run.demo import run_demo  # noqa: PLC0415 (subcommand handler)

    run_demo(quick=args.quick, engine=args.engine)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dpc-mjx", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    runs = parser.add_argument_group(
        "several processes (docs/scaling.md; before the command, the same in every process)"
    )
    runs.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address, or auto")
    runs.add_argument("--num-processes", type=int, metavar="N")
    runs.add_argument("--process-id", type=int, metavar="I", help="0 .. N-1, one per process")
    sub = parser.add_subparsers(dest="command", required=True)
    _training_commands(sub)
    _evaluation_commands(sub)
    tool_commands(sub)
    return parser


def _training_commands(sub) -> None:
    """demo, train, train-adapter, transfer."""
    p = sub.add_parser("demo", help="a small run, then MBC / observer / DPC (minutes)")
    p.add_argument("--quick", action="store_true", help="an even smaller budget (smoke run)")
    engine = "physics: native (MuJoCo C; the default on a CPU) or mjx (the default on a GPU)"
    p.add_argument("--engine", choices=("native", "mjx"), help=engine)
    p.set_defaults(handler=_demo)

    p = sub.add_parser("train", help="the whole pipeline into a run folder")
    _run_options(p, resume=True)
    p.set_defaults(handler=_train)

    p = sub.add_parser("train-adapter", help="only collect data and train the adapter")
    _run_options(p, resume=False)
    p.set_defaults(handler=_train_adapter)

    p = sub.add_parser("transfer", help="train a new arm's encoder against a frozen decoder")
    p.add_argument("--export", required=True, help="an export folder (run/export)")
    arm = "the new arm: a variant (so100), your arm's .urdf or MJCF .xml file, or a .json arm "
    p.add_argument("--arm", required=True, help=arm + "description (docs/own-arm.md)")
    p.add_argument("--samples", type=int, default=30_000)
    env = "env options over the export's, e.g. engine=native (collect in MuJoCo C)"
    add_episode_options(p, seed=0, env_help=env)
    p.set_defaults(handler=_transfer)


def _run_options(p: argparse.ArgumentParser, resume: bool) -> None:
    p.add_argument("--run", required=True, help="run folder (created)")
    p.add_argument("--arm", help="arm variant (default regular)")
    p.add_argument("--base", help=BASE_HELP)
    p.add_argument("--task", help=TASK_HELP)
    p.add_argument("--samples", type=int, help="adapter samples (default 100000)")
    p.add_argument(
        "--recipe",
        default="default",
        help="named settings the --set options change: default (the oracle regression), "
        "paper (SAC from a random actor, asymmetric critic)",
    )
    _device_option(p)
    p.add_argument("--set", nargs="*", action="extend", default=[], metavar="NAME=VALUE")
    p.add_argument("--logdir", help="TensorBoard events: LOGDIR/<run> (default RUN/tensorboard)")
    if resume:
        p.add_argument(
            "--timesteps", type=int, help="SAC env steps after the regression (default 0: none)"
        )
        p.add_argument("--episodes", type=int, help="evaluation episodes (default 64)")
        p.add_argument("--resume", action="store_true", help="continue a killed run")


def _device_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--device",
        choices=["auto", "cpu", "gpu"],
        default="auto",
        help="sizes for the accelerator: envs, episodes, chunk length (default auto: the one JAX "
        "runs on; run.config.DEVICE_PRESETS)",
    )


def _evaluation_commands(sub) -> None:
    """eval, sim2sim, sweep."""
    p = sub.add_parser("eval", help="MBC / observer / DPC / oracle, 95%% intervals")
    _eval_options(p)
    p.add_argument(
        "--engine",
        choices=["mjx", "native"],
        help="physics: native MuJoCo C (the default on a CPU: faster there, "
        "docs/benchmarks-cpu.md) or mjx (the default on an accelerator); the same results up "
        "to the engines' differences",
    )
    _device_option(p)
    p.set_defaults(handler=_eval)

    p = sub.add_parser("sim2sim", help="the eval cells in MJX and in native MuJoCo, side by side")
    _eval_options(p)
    p.set_defaults(handler=_sim2sim)

    p = sub.add_parser("sweep", help="every controller over a grid of arm lengths and masses")
    p.add_argument("--export", help="an export folder (default: the shipped one); its arm")
    p.add_argument("--upper-arm", default="0.10:0.30:8", help="upper-arm length, m, low:high:count")
    p.add_argument("--gripper-mass", default="0.1:0.6:8", help="gripper masses, kg, low:high:count")
    p.add_argument("--controllers", nargs="+", default=_CONTROLLERS, help=_CONTROLLERS_HELP)
    p.add_argument("--episodes", type=int, default=16, help="per grid point")
    p.add_argument("--steps", type=int, help="env steps per episode (default: the task's)")
    add_episode_options(p, seed=1000)
    p.add_argument("--out", default="runs/sweep", help="folder for the CSVs and heatmaps")
    p.set_defaults(handler=_sweep)


def _eval_options(p: argparse.ArgumentParser) -> None:
    shipped = "default: the shipped export of --base, artefacts/regular (a1), go2 or b1"
    p.add_argument("--export", help=f"an export folder ({shipped})")
    arms = "arms: encoder names, variants, arm files or descriptions (default: the policy's arm)"
    p.add_argument("--arms", nargs="+", help=arms)
    p.add_argument("--controllers", nargs="+", default=_CONTROLLERS, help=_CONTROLLERS_HELP)
    episodes = "per controller (default: 64 on a CPU, 1024 on a GPU: --device of eval)"
    p.add_argument("--episodes", type=int, help=episodes)
    p.add_argument(
        "--steps",
        type=int,
        help="env steps of 20 ms per episode (default: the task's episode length; "
        "reaching 1000 = 20 s, pushing 500, carrying 650, lifting 1000)",
    )
    p.add_argument("--out", help="also write the table to this markdown file")
    env = "env options over the export's, e.g. sensor_noise=0 sensor_delay=0 (exact sensors)"
    add_episode_options(p, seed=1000, env_help=env)
    csv = (
        "one row per episode (default: beside --out, else runs/eval/[native-]<task>-seed<seed>.csv)"
    )
    p.add_argument("--csv", help=csv)


def _join_processes(args: argparse.Namespace) -> None:
    """`jax.distributed` for a run of several processes (from the options, else the environment:
    JAX_COORDINATOR_ADDRESS, DPC_NUM_PROCESSES, DPC_PROCESS_ID), before any device is touched."""
    from dpc_mjx.devices import initialize  # noqa: PLC0415 (subcommand handler)

    initialize(args.coordinator, args.num_processes, args.process_id)


def _check_mujoco() -> None:
    """MuJoCo imports, else a DpcError with the repair: `pip install -U` of MuJoCo 4 (three wheels:
    mujoco-core, mujoco-studio, mujoco) over a 3.x install deletes the new core's files, and
    `import mujoco` says its core bindings ('mujoco-core') are missing (docs/commands.md,
    "Install, and the upgrade from MuJoCo 3")."""
    try:
        import mujoco  # noqa: F401, PLC0415 (the check itself, before any subcommand)
    except ImportError as e:
        if "mujoco-core" not in str(e):
            raise
        from importlib.metadata import version  # noqa: PLC0415 (only on this error)

        mj = version("mujoco")
        raise DpcError(
            f"MuJoCo {mj} is half-installed (pip upgraded a MuJoCo 3 in place, which deletes the "
            "files of mujoco-core); reinstall it: pip uninstall -y mujoco mujoco-core "
            f"mujoco-studio && pip install mujoco=={mj}"
        ) from None


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        _check_mujoco()
        compile_cache.enable()  # programs compiled once (dpc_mjx/compile_cache.py)
        _join_processes(args)
        args.handler(args)
    except DpcError as e:
        print(f"dpc-mjx: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dpc-mjx: interrupted (a run folder can be continued with --resume)", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
