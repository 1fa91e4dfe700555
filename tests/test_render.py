"""Videos: `dpc-mjx render` writes a playable MP4 headless (OSMesa on a CPU-only machine)."""

import imageio_ffmpeg
import jax
import numpy as np
import pytest
from helpers import ENGINE, fast_jit
from PIL import Image

from dpc_mjx import DpcError
from dpc_mjx.run import cli
from dpc_mjx.run.render import FPS, gl_context, write_video

_SECONDS, _W, _H = 0.2, 160, 120


def test_render_writes_a_playable_mp4_of_the_episode(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(jax, "jit", fast_jit)  # compile-bound: a few steps of each program
    out = tmp_path / "clip.mp4"
    args = ["render", "--out", str(out), "--seconds", str(_SECONDS), "--width", str(_W)]
    args = [*args, "--height", str(_H), "--controller", "mbc", "--env", f"engine={ENGINE}"]
    assert cli.main(args) == 0
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    frames = np.stack([np.frombuffer(f, np.uint8).reshape(_H, _W, 3) for f in reader])
    assert meta["size"] == (_W, _H) and meta["fps"] == FPS
    assert len(frames) == round(_SECONDS * FPS) + 1  # the reset, then one frame per env step
    assert frames.std() > 10  # a picture (floor, sky, robot), not a blank frame
    robot = frames[:, _H // 3 :, _W // 4 : 3 * _W // 4]  # the camera follows the trunk
    assert np.abs(np.diff(robot.astype(float), axis=0)).mean() > 0.1  # it moves
    assert "render: " in capsys.readouterr().out


def test_gifs_and_bad_requests(tmp_path, monkeypatch):
    frames = np.random.default_rng(0).integers(0, 255, (10, 24, 32, 3), dtype=np.uint8)
    gif = Image.open(write_video(frames, tmp_path / "clip.gif"))
    assert gif.n_frames == 3 and gif.size == (32, 24)  # 12.5 frames per second from 50
    with pytest.raises(DpcError, match=r"as \.mp4 or \.gif"):
        write_video(frames, tmp_path / "clip.avi")
    assert cli.main(["render", "--out", str(tmp_path / "c.mov")]) == 2
    assert cli.main(["render", "--out", str(tmp_path / "c.mp4"), "--controller", "pid"]) == 2
    monkeypatch.setenv("MUJOCO_GL", "glfw")
    with pytest.raises(DpcError, match="cannot render without a screen; use one of"):
        gl_context(8, 8)
