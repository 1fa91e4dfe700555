"""The `dpc-mjx` tool subcommands (export, onnx, bench, render, view, variants, mjcf, base) and the
option parsing every subcommand shares (`--set` / `--env NAME=VALUE` lists, given options);
`dpc_mjx.run.cli` builds the whole command line from these."""

from __future__ import annotations

import argparse
import json
import warnings

from dpc_mjx.controllers import Controller
from dpc_mjx.errors import DpcError

CONTROLLER_NAMES = " ".join(c.value for c in Controller)  # mbc observer ... oracle
TASK_HELP = "a task (`dpc_mjx.envs.known_tasks()`; default: reaching, `envs.DEFAULT_TASK`)"


def parse_sets(items: list[str]) -> dict:
    """`NAME=VALUE` strings -> {name: value}, values read as JSON where they parse (lists as
    tuples), else kept as strings."""
    out = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise DpcError(f"Options take name=value, got {item!r} (e.g. sac.num_envs=32).")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = text
        out[name] = tuple(value) if isinstance(value, list) else value
    return out


BASE_HELP = "the quadruped: a1 (default), go1, go2, b1, b1-z1, or your .urdf/.xml/.json file"


def add_env_options(p: argparse.ArgumentParser, help_text: str | None = None) -> None:
    """`--env NAME=VALUE ...` and `--base`, read back by `env_options`."""
    p.add_argument(
        "--env", nargs="*", action="extend", default=[], metavar="NAME=VALUE", help=help_text
    )
    p.add_argument("--base", help=BASE_HELP)


def add_episode_options(
    p: argparse.ArgumentParser,
    *,
    seed: int | None,
    seed_help: str | None = None,
    env_help: str | None = None,
) -> None:
    """What an episode is drawn from: `--task`, `--seed` (default `seed`; None: no such option)
    and the env options (`add_env_options`)."""
    p.add_argument("--task", help=TASK_HELP)
    if seed is not None:
        p.add_argument("--seed", type=int, default=seed, help=seed_help)
    add_env_options(p, env_help)


def env_options(args: argparse.Namespace) -> dict:
    """The env options of `--env` and `--base` (the same as `--env base=...`)."""
    options = parse_sets(args.env)
    return options | ({"base": args.base} if args.base else {})


def given(args: argparse.Namespace, names: tuple[str, ...]) -> dict:
    """The options `names` that have a value (None: the library's default, e.g. the task)."""
    return {k: getattr(args, k) for k in names if getattr(args, k) is not None}


def _render(args: argparse.Namespace) -> None:
    from dpc_mjx.run.render import render_rollout  # noqa: PLC0415 (subcommand handler)

    render_rollout(
        args.out,
        **given(args, ("task",)),
        arm=args.arm,
        controllers=tuple(args.compare or [args.controller]),
        export=args.export,
        seconds=args.seconds,
        seed=args.seed,
        episode=args.episode,
        episodes=args.episodes,
        width=args.width,
        height=args.height,
        env=env_options(args),
    )


def _view(args: argparse.Namespace) -> None:
    from dpc_mjx.run.view import view  # noqa: PLC0415 (subcommand handler)

    names = ("controller", "arm", "task", "export", "seconds")
    view(**given(args, names), env=env_options(args))


def _export(args: argparse.Namespace) -> None:
    from dpc_mjx.run.pipeline import export_run  # noqa: PLC0415 (subcommand handler)

    print(f"exported to {export_run(args.run, args.out)}")


def _onnx(args: argparse.Namespace) -> None:
    from dpc_mjx.io.onnx_graph import write_onnx  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.io.shipped import SHIPPED  # noqa: PLC0415 (subcommand handler)

    print(f"wrote {write_onnx(args.export or SHIPPED, args.arm, args.out)}")


def _bench(args: argparse.Namespace) -> None:
    from dpc_mjx.run.bench import print_table  # noqa: PLC0415 (subcommand handler)

    print_table(args.arm, args.batches, args.calls, args.chunk)


def _variants(args: argparse.Namespace) -> None:
    from dpc_mjx.robots import VARIANTS  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.run.demo import run_variants  # noqa: PLC0415 (subcommand handler)

    run_variants(args.variants or tuple(VARIANTS), batch=args.batch, seconds=args.seconds)


def _mjcf(args: argparse.Namespace) -> None:
    from dpc_mjx.robots.mjcf import write_mjcf  # noqa: PLC0415 (subcommand handler)

    for path in write_mjcf(args.out_dir):
        print(path)


def _base(args: argparse.Namespace) -> None:
    from dpc_mjx.robots.bases.describe import describe, description  # noqa: PLC0415 (handler)
    from dpc_mjx.robots.bases.file import read_base  # noqa: PLC0415 (subcommand handler)
    from dpc_mjx.serialization import write_json  # noqa: PLC0415 (subcommand handler)

    with warnings.catch_warnings():  # a fusion's warning: describe prints it among the facts
        warnings.simplefilter("ignore", UserWarning)
        spec = read_base(args.file)
    print(describe(spec))
    if args.out:
        write_json(args.out, description(spec, args.out))
        print(f"wrote {args.out}; correct it there, then check it: dpc-mjx base {args.out}")


def tool_commands(sub) -> None:
    """export, bench, render, view, variants, mjcf, base."""
    p = sub.add_parser("export", help="export a run's adapter and policy")
    p.add_argument("--run", required=True)
    p.add_argument("--out", help="export folder (default: run/export)")
    p.set_defaults(handler=_export)

    p = sub.add_parser("onnx", help="an export's encoder and policy as one ONNX graph")
    p.add_argument("--export", help="the export folder (default: the shipped export)")
    p.add_argument("--arm", default="regular", help="the arm whose encoder the graph holds")
    p.add_argument("--out", required=True, help="the file to write, e.g. policy.onnx")
    p.set_defaults(handler=_onnx)

    p = sub.add_parser("bench", help="env steps/s, full env vs physics only")
    p.add_argument("--arm", default="regular")
    p.add_argument("--batches", type=int, nargs="+", default=[1, 64, 256])
    p.add_argument("--calls", type=int, default=20)
    p.add_argument("--chunk", type=int, default=1, help="env steps per env call (lax.scan)")
    p.set_defaults(handler=_bench)

    p = sub.add_parser("render", help="a video (MP4 or GIF) of an episode, headless")
    p.add_argument("--out", required=True, help="clip.mp4 or clip.gif")
    p.add_argument("--arm", default="regular", help="a variant, an arm file or description")
    p.add_argument("--controller", default=Controller.MBC.value, help=f"one of {CONTROLLER_NAMES}")
    p.add_argument("--compare", nargs="+", help="several controllers side by side, same episode")
    p.add_argument("--export", help="for dpc and the env options (default: the shipped export)")
    p.add_argument("--seconds", type=float, default=2.0)
    p.add_argument("--episode", type=int, default=0, help="episode index within the seed")
    p.add_argument(
        "--episodes",
        type=int,
        help="the evaluation's episode count: replays its batch, so its episode to the last bit "
        "(default: episode + 1 envs, which may round differently)",
    )
    p.add_argument("--width", type=int, default=480)
    p.add_argument("--height", type=int, default=360)
    env = "env options over the export's (engine=native: MuJoCo C)"
    add_episode_options(p, seed=0, seed_help="as dpc-mjx eval --seed", env_help=env)
    p.set_defaults(handler=_render)

    p = sub.add_parser("view", help="MuJoCo's viewer: a controller live, pushed with the mouse")
    p.add_argument("--controller", default=Controller.DPC.value, help=f"one of {CONTROLLER_NAMES}")
    p.add_argument("--arm", help="a variant, an arm file or description (default: the export's)")
    p.add_argument("--export", help="for dpc and the env options (default: the shipped export)")
    p.add_argument("--seconds", type=float, help="stop after this simulated time (default: never)")
    env = "env options over the export's (push_force=[0,30]: random pushes too; engine=mjx)"
    add_episode_options(p, seed=None, env_help=env)
    p.set_defaults(handler=_view)

    p = sub.add_parser("variants", help="build every arm variant and stand a batch of each")
    p.add_argument("--variants", nargs="*", help="variant names (default: all)")
    p.add_argument("--batch", type=int, default=16, help="envs per variant (default 16)")
    p.add_argument("--seconds", type=float, default=1.0, help="simulated time (default 1)")
    p.set_defaults(handler=_variants)

    p = sub.add_parser("mjcf", help="write every variant's robot and scene MJCF")
    p.add_argument("out_dir", nargs="?", default="mjcf")
    p.set_defaults(handler=_mjcf)
    _base_command(sub)


def _base_command(sub) -> None:
    """base (issue 27): a quadruped base's file as read, and its JSON to correct."""
    p = sub.add_parser("base", help="what is inferred of a quadruped base's file, as a JSON")
    what = "a named base (a1 go1 go2 b1 b1-z1), a .urdf, an MJCF .xml or a base .json"
    p.add_argument("file", help=what)
    p.add_argument("--out", help="write the JSON that reproduces it here, e.g. my_dog.json")
    p.set_defaults(handler=_base)
