"""The paper's figure of the arms: every arm variant on the A1, standing in its home pose.

    python experiments/figure_arms.py [--variants regular longer ...] [--out docs/figures/arms.png]

Rendered headless with `dpc_mjx.run.render.FrameRenderer` (OSMesa or EGL), one tile per variant
(named in its corner), in a grid of four columns.
"""

from __future__ import annotations

import argparse
import pathlib

import mujoco
import numpy as np
from PIL import Image

from dpc_mjx.robots import VARIANTS, build
from dpc_mjx.run.render import FrameRenderer

COLUMNS = 4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", nargs="+", default=[v for v in VARIANTS if v != "none"])
    ap.add_argument("--out", default="docs/figures/arms.png")
    ap.add_argument("--size", type=int, nargs=2, default=(360, 300), help="tile width height")
    args = ap.parse_args()

    tiles = []
    for name in args.variants:
        model = build(name)
        renderer = FrameRenderer(model, *args.size)
        renderer.camera.distance, renderer.camera.azimuth = 1.4, 150.0
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        tiles.append(renderer.frame(data.qpos, text=name))
        renderer.close()
    while len(tiles) % COLUMNS:
        tiles.append(np.full_like(tiles[0], 255))
    rows = [np.concatenate(tiles[i : i + COLUMNS], 1) for i in range(0, len(tiles), COLUMNS)]
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate(rows, 0)).save(out)
    print(f"figure: {out}")


if __name__ == "__main__":
    main()
