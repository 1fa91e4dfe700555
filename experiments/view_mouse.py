"""`dpc-mjx view` driven by a synthetic mouse on a virtual display: does a pull move the robot?

Starts a virtual X display (Xvfb), runs `dpc-mjx view` on it (the shipped export, MuJoCo's
passive viewer, the native engine), hides the viewer's side panels (Tab, Shift+Tab: the 3-D view
fills the window, the camera follows the trunk, so the trunk is at the window's centre), then
does what the view's help line tells a user: double-click the body at the centre to select it,
Ctrl + right drag to the right, hold, let go. The view's own log says which body the pull
caught, how long, how hard and how far it moved (`view.MousePulls`). Prints that as a table and
exits 0 only if a body of the robot was pulled and moved at least `--min-moved` m.

Needs the X tools `Xvfb` and `xdotool` (Debian/Ubuntu: `apt-get install xvfb xdotool`), not
part of the project; the viewer renders with whatever OpenGL the display offers (Xvfb: Mesa's
software renderer, slower than real time on 2 cores, which the view's log says).

    python experiments/view_mouse.py --controller mbc --out /tmp/view_mouse

`--out` keeps screenshots (PNG) of the view before and during the pull, and the view's log.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

TOOLS = ("Xvfb", "xdotool")
SCREEN = "1280x800x24"
DRAG_PX, DRAG_MOVES, MOVE_S, HOLD_S = 160, 20, 0.1, 2.0  # the drag: px right, in moves of s
LET_GO = re.compile(
    r"pull on '(?P<body>[^']+)' let go after (?P<s>[\d.]+) s, peak (?P<f>\d+) N and "
    r"(?P<tau>[\d.]+) N·m; the body moved (?P<m>[\d.]+) m"
)


class ViewProcess:
    """`dpc-mjx view` on `display`, its output echoed and kept in `lines`."""

    def __init__(self, display: str, controller: str, seconds: float):
        command = [sys.executable, "-m", "dpc_mjx.run.cli", "view", "--controller", controller]
        env = os.environ | {"DISPLAY": display}
        self.proc = subprocess.Popen(
            [*command, "--seconds", str(seconds)],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())
            print(f"  | {line.rstrip()}", flush=True)

    def wait_for(self, pattern: str, timeout: float) -> re.Match | None:
        """The first line matching `pattern`, looked for every 0.5 s for about `timeout` s;
        None if none came or the view ended."""
        for _ in range(round(timeout / 0.5)):
            if self.proc.poll() is not None:
                break
            for line in self.lines:
                if match := re.search(pattern, line):
                    return match
            time.sleep(0.5)
        return None


def xdo(display: str, *args: str) -> str:
    out = subprocess.run(
        ["xdotool", *args],
        check=True,
        env=os.environ | {"DISPLAY": display},
        capture_output=True,
        text=True,
    )
    return out.stdout.strip()


def screenshot(display: str, out: Path | None, name: str) -> None:
    if out is not None:
        from PIL import ImageGrab  # noqa: PLC0415 (Pillow comes with the render extra)

        ImageGrab.grab(xdisplay=display).save(out / f"{name}.png")


def pull(display: str, out: Path | None) -> None:
    """Select the body at the 3-D view's centre and drag it right with Ctrl + right button."""
    window = xdo(display, "search", "--sync", "--name", "MuJoCo").splitlines()[0]
    xdo(display, "key", "--window", window, "Tab", "shift+Tab")  # hide both panels
    time.sleep(3.0)
    geometry = xdo(display, "getwindowgeometry", window)
    w, h = map(int, re.search(r"Geometry: (\d+)x(\d+)", geometry).groups())
    x, y = w // 2, h // 2
    screenshot(display, out, "before")
    xdo(display, "mousemove", "--window", window, str(x), str(y))
    xdo(display, "click", "--repeat", "2", "--delay", "80", "1")  # double-click: select
    time.sleep(1.5)
    xdo(display, "keydown", "ctrl")
    xdo(display, "mousedown", "3")
    for i in range(1, DRAG_MOVES + 1):
        dx = x + DRAG_PX * i // DRAG_MOVES
        xdo(display, "mousemove", "--window", window, str(dx), str(y))
        time.sleep(MOVE_S)
    screenshot(display, out, "pulling")
    time.sleep(HOLD_S)
    xdo(display, "mouseup", "3")
    xdo(display, "keyup", "ctrl")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--controller", default="mbc", help="mbc, observer, dpc or oracle")
    p.add_argument("--display", default=":97", help="the virtual display Xvfb opens")
    p.add_argument("--min-moved", type=float, default=0.05, help="m the pulled body must move")
    p.add_argument("--out", type=Path, help="folder for screenshots and the view's log")
    args = p.parse_args()
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    if missing:
        print(f"view_mouse: needs {', '.join(missing)} (apt-get install xvfb xdotool)")
        return 2
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
    xvfb = subprocess.Popen(["Xvfb", args.display, "-screen", "0", SCREEN, "-nolisten", "tcp"])
    view = None
    try:
        time.sleep(2.0)
        view = ViewProcess(args.display, args.controller, seconds=600.0)
        if view.wait_for(r"^view: real time", timeout=600.0) is None:
            print("view_mouse: the view did not start (its log is above)")
            return 1
        pull(args.display, args.out)
        caught = view.wait_for(LET_GO.pattern, timeout=120.0)
    finally:
        if view is not None:
            view.proc.terminate()
            view.proc.wait(timeout=30)
            if args.out:
                (args.out / "view.log").write_text("\n".join(view.lines) + "\n")
        xvfb.terminate()
    return report(caught, args.min_moved)


def report(caught: re.Match | None, min_moved: float) -> int:
    if caught is None:
        print("view_mouse: no pull reached the env (the view logged none)")
        return 1
    print("\n| body | pulled (s, simulated) | peak force (N) | peak torque (N·m) | moved (m) |")
    print("|---|---|---|---|---|")
    print(f"| {caught['body']} | {caught['s']} | {caught['f']} | {caught['tau']} | {caught['m']} |")
    moved = float(caught["m"]) >= min_moved and caught["body"] != "world"
    print(f"\nview_mouse: {'PASS' if moved else 'FAIL'} (a robot body moved >= {min_moved} m)")
    return 0 if moved else 1


if __name__ == "__main__":
    sys.exit(main())
