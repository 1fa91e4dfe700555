"""The one table of `experiments/gpu_check.sh`, from the logs it left in a folder.

    python experiments/gpu_check_table.py OUT

One row per step: its wall time, exit status and what it measured (the bench's env steps/s, the
train's stages from its summary.json, the evaluation's episodes and cells, SAC's env steps/s),
under a line naming the versions and devices. A step that failed or was skipped says so.
"""

from __future__ import annotations

import json
import pathlib
import re
import sys

STEPS = {  # in the script's order
    "bench": "bench, 1 env step per call",
    "bench_mpc": "the env step, MPC against QP",
    "train_cold": "default train, cold cache",
    "train_warm": "default train, warm cache",
    "eval_cold": "eval 4 controllers, cold",
    "eval_warm": "eval 4 controllers, warm",
    "sac": "paper recipe, SAC stage",
    "bench_scan": "bench, 20 env steps per call",
    "bench_cmdbuf": "bench, 20 per call, GPU command buffers",
}
STAGES = ("data_seconds", "adapter_seconds", "sac_compile_seconds", "sac_train_seconds")


def measured(out: pathlib.Path, name: str, log: str) -> str:
    """What the step measured, read from its log and summary."""
    if name == "bench_mpc":  # | batch | compile QP / MPC | sps QP | MPC | ms QP | MPC | cost |
        rows = re.findall(
            r"^\| (\d+) \| ([\d.]+ / [\d.]+) \| ([\d,]+) \| ([\d,]+) \|.*\| ([\d.]+) \|$", log, re.M
        )
        return "; ".join(
            f"{b}: QP {q} env steps/s, MPC {m}, MPC / QP cost {r}x, compile {c} s"
            for b, c, q, m, r in rows
        )
    if name.startswith("bench"):
        rows = re.findall(r"^\| (\d+) \| ([\d,]+) \| ([\d,]+) \| ([\d.]+) \| ([\d.]+)", log, re.M)
        return "; ".join(
            f"{b}: env {e} steps/s, physics {p}, ratio {r}, compile {c} s" for b, e, p, r, c in rows
        )
    if name.startswith("eval"):
        cells = re.findall(r"^\| \S+ \| (\w+) \| ([\d.]+) \[", log, re.M)
        engine = re.search(r"^physics: (.*)$", log, re.M)
        falls = ", ".join(f"{c} fall rate {f}" for c, f in cells)
        return f"{engine.group(1) if engine else '?'}; {falls}"
    summary = out / f"summary_{name.rsplit('_', maxsplit=1)[-1]}.json"
    if not summary.exists():
        return "no summary.json"
    s = json.loads(summary.read_text())
    t = s["timings_seconds"]
    parts = [
        f"{k.removesuffix('_seconds')} {t[k]:.0f} s" for k in (*STAGES, "eval_seconds") if k in t
    ]
    if name == "sac" and t.get("sac_train_seconds"):
        parts.append(
            f"{s['sac_env_steps'] / t['sac_train_seconds']:,.0f} env steps/s, "
            f"{s['sac_grad_steps']:,} gradient steps"
        )
    episodes = s["eval"][0]["episodes"] if s.get("eval") else 0
    nll = re.search(r"held-out NLL ([\d.]+)", log)
    return (
        "; ".join(parts)
        + f"; eval {episodes} episodes each"
        + (f"; adapter held-out NLL {nll.group(1)}" if nll else "")
    )


def table(out: pathlib.Path) -> str:
    versions = (
        (out / "versions.txt").read_text().strip() if (out / "versions.txt").exists() else "?"
    )
    lines = [versions, "", "| step | wall (s) | rc | measured |", "|---|---|---|---|"]
    for name, label in STEPS.items():
        log_path = out / f"{name}.log"
        if not log_path.exists():
            lines.append(f"| {label} | | | not run |")
            continue
        log = log_path.read_text()
        rc = re.findall(r"^rc=(\d+)$", log, re.M)
        ms = out / f"{name}.ms"
        wall = f"{int(ms.read_text()) / 1000:.0f}" if ms.exists() else ""
        last = [line for line in log.splitlines() if line.strip()][-3:-1]  # before rc=
        what = measured(out, name, log) if rc == ["0"] else "failed: " + " / ".join(last)
        lines.append(f"| {label} | {wall} | {rc[0] if rc else '-'} | {what} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(pathlib.Path(sys.argv[1])))
