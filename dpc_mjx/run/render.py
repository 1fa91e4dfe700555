"""Videos of rollouts: an episode stepped in MJX, replayed frame by frame in MuJoCo's renderer.

Headless on any Linux machine: the OpenGL context is OSMesa (software; Debian's `libosmesa6`,
installed by `make render-deps`) or EGL (a GPU driver's), from `MUJOCO_GL` when set, else EGL
where JAX sees a GPU and OSMesa otherwise. Frames are taken once per env step (50 Hz), with a
camera that follows the trunk; end-effector pushes are drawn as red arrows (0.005 m per N) from
the end effector. `record_episode` runs the evaluation's episode (`run.eval`: episode i of seed s
starts from the i-th reset key and draws the i-th step keys); with the evaluation's batch
(`episodes`, `dpc-mjx render --episodes`) it is that episode to the last bit, with a smaller
batch (default i + 1 envs) XLA may round differently, and a fall can come some steps earlier or
later, or not at all.
"""

from __future__ import annotations

import importlib
import os
import pathlib

import jax
import mujoco
import numpy as np

from dpc_mjx import io
from dpc_mjx.controllers import Controller
from dpc_mjx.envs.registry import DEFAULT_TASK, make
from dpc_mjx.envs.rollout import Policy, record_episodes, zero_policy
from dpc_mjx.errors import DpcError
from dpc_mjx.io.shipped import SHIPPED, env_overrides
from dpc_mjx.robots import layout
from dpc_mjx.robots.arms import EE_SITE
from dpc_mjx.robots.arms.mount import arm_prefix
from dpc_mjx.robots.spec_json import arm_argument
from dpc_mjx.robots.variants import arm_name
from dpc_mjx.rotations import roll_pitch_yaw
from dpc_mjx.writer import is_writer

BACKENDS = {  # MUJOCO_GL value -> what to install when it is missing
    "osmesa": "Debian's libosmesa6 (`make render-deps`, or `apt-get install libosmesa6` as root)",
    "egl": "a GPU driver with EGL (libEGL), or use MUJOCO_GL=osmesa",
}
FPS = 50  # frames per second: one per env step of 20 ms
GIF_FPS = 12.5  # GIFs keep every 4th frame: a few MB for a clip of seconds
ARROW_M_PER_N = 0.005  # m of arrow per N of push
ARROW_RGBA = (0.9, 0.1, 0.1, 1.0)


def record_episode(
    env,
    seconds: float,
    seed: int,
    episode: int = 0,
    policy: Policy = zero_policy,
    episodes: int | None = None,
):
    """Episode `episode` of `seed` stepped in MJX for `seconds` in a batch of `episodes` envs
    (default episode + 1): (qpos (T + 1, nq), pushes (T + 1, n_arms, 3) N world, done (T + 1,)),
    T = seconds / 0.02, from the reset on."""
    episodes = episode + 1 if episodes is None else episodes
    if not 0 <= episode < episodes:
        raise DpcError(
            f"Episode {episode} is not one of the {episodes} episodes; 0 <= i < {episodes}."
        )
    steps = max(1, round(seconds * FPS))

    def record(before, after):
        del before

        def pushes(dist, time, qpos):
            return env.sampler.pushes(dist, time, roll_pitch_yaw(qpos[3:7])[2])

        state = after.pipeline_state
        return state.qpos, jax.vmap(pushes)(after.info["dist"], state.time, state.qpos), after.done

    qpos, push, done = record_episodes(env, episodes, steps, seed, record, policy)
    return qpos[:, episode], push[:, episode], done[:, episode]


class FrameRenderer:
    """Offscreen frames of a model (width x height pixels) with a camera following the trunk."""

    def __init__(self, model: mujoco.MjModel, width: int = 480, height: int = 360):
        self.model = model.__copy__()
        self.model.vis.global_.offwidth = max(width, self.model.vis.global_.offwidth)
        self.model.vis.global_.offheight = max(height, self.model.vis.global_.offheight)
        self.data = mujoco.MjData(self.model)
        self.viewport = mujoco.MjrRect(0, 0, width, height)
        self._context = gl_context(width, height)
        self._context.make_current()
        self.con = mujoco.MjrContext(self.model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.con)
        self.scene = mujoco.MjvScene(self.model, maxgeom=4000)
        self.option = mujoco.MjvOption()
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.camera.trackbodyid = layout(self.model).trunk
        self.camera.distance, self.camera.azimuth, self.camera.elevation = 1.4, 135.0, -20.0
        self._ee_sites = []
        i = 0
        while mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, arm_prefix(i) + EE_SITE) >= 0:
            self._ee_sites.append(self.model.site(arm_prefix(i) + EE_SITE).id)
            i += 1

    def frame(self, qpos: np.ndarray, pushes: np.ndarray | None = None, text: str = ""):
        """(height, width, 3) uint8: the model at `qpos`, arrows for `pushes` (n_arms, 3) N."""
        self._context.make_current()
        self.data.qpos[:] = qpos
        mujoco.mj_forward(self.model, self.data)
        mujoco.mjv_updateScene(
            self.model, self.data, self.option, None, self.camera, mujoco.mjtCatBit.mjCAT_ALL,
            self.scene,
        )  # fmt: skip
        for site, force in zip(self._ee_sites, [] if pushes is None else pushes, strict=False):
            if np.linalg.norm(force) > 1e-6 and self.scene.ngeom < self.scene.maxgeom:
                start = self.data.site_xpos[site]
                geom = self.scene.geoms[self.scene.ngeom]
                mujoco.mjv_initGeom(
                    geom, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), np.zeros(3), np.eye(3).ravel(),
                    np.asarray(ARROW_RGBA, np.float32),
                )  # fmt: skip
                end = start + ARROW_M_PER_N * np.asarray(force)
                mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_ARROW, 0.012, start, end)
                self.scene.ngeom += 1
        mujoco.mjr_render(self.viewport, self.scene, self.con)
        if text:
            mujoco.mjr_overlay(
                mujoco.mjtFont.mjFONT_NORMAL, mujoco.mjtGridPos.mjGRID_TOPLEFT, self.viewport, text,
                "", self.con,
            )  # fmt: skip
        rgb = np.zeros((self.viewport.height, self.viewport.width, 3), np.uint8)
        mujoco.mjr_readPixels(rgb, None, self.viewport, self.con)
        return np.flipud(rgb)

    def close(self) -> None:
        """Free the GL resources (also done when the renderer is garbage collected)."""
        if self._context is not None:
            self.con.free()
            self._context.free()
            self._context = None


def gl_context(width: int, height: int):
    """A headless OpenGL context of the backend `MUJOCO_GL` names (else EGL with a GPU, OSMesa
    without); `DpcError` saying what to install if it cannot be made."""
    backend = os.environ.get("MUJOCO_GL", "").lower()
    if not backend:
        backend = "egl" if jax.default_backend() == "gpu" else "osmesa"
    if backend not in BACKENDS:
        raise DpcError(
            f"MUJOCO_GL={backend!r} cannot render without a screen; use one of {list(BACKENDS)}."
        )
    try:
        return importlib.import_module(f"mujoco.{backend}").GLContext(width, height)
    except Exception as e:  # noqa: BLE001 (a missing library shows as several error types)
        raise DpcError(
            f"Headless rendering with MUJOCO_GL={backend} failed ({type(e).__name__}: {e}); "
            f"install {BACKENDS[backend]}."
        ) from e


def write_video(frames: np.ndarray, path: str | pathlib.Path, fps: int = FPS) -> pathlib.Path:
    """Frames (T, H, W, 3) uint8 as an MP4 (H.264, through imageio-ffmpeg) or a GIF (Pillow, at
    most `GIF_FPS` frames per second), by the file's suffix."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        from PIL import Image  # noqa: PLC0415 (optional: Pillow, only for GIFs)

        step = max(1, round(fps / GIF_FPS))
        images = [Image.fromarray(f) for f in frames[::step]]
        images[0].save(
            path, save_all=True, append_images=images[1:], duration=1000 * step / fps, loop=0
        )
    elif path.suffix.lower() == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: PLC0415 (optional dependency: the render extra)
        except ImportError as e:
            raise DpcError(
                "Writing MP4 needs imageio-ffmpeg: `pip install -e .[render]` (make install does)."
            ) from e
        h, w = frames.shape[1:3]
        writer = imageio_ffmpeg.write_frames(  # an ffmpeg subprocess (JAX warns of the fork)
            str(path), (w, h), fps=fps, codec="libx264", pix_fmt_out="yuv420p", macro_block_size=8
        )
        writer.send(None)
        for f in frames:
            writer.send(np.ascontiguousarray(f))
        writer.close()
    else:
        raise DpcError(f"{path}: write videos as .mp4 or .gif, not {path.suffix or 'no suffix'}.")
    return path


def render_rollout(
    out: str | pathlib.Path,
    *,
    task: str = DEFAULT_TASK,
    arm: str = "regular",
    controllers: tuple[str, ...] = (Controller.MBC,),
    export: str | pathlib.Path | None = None,
    seconds: float = 2.0,
    seed: int = 0,
    episode: int = 0,
    episodes: int | None = None,
    width: int = 480,
    height: int = 360,
    env: dict | None = None,
) -> dict[str, int | None]:
    """Render episode `episode` of `seed` (of a batch of `episodes`, see `record_episode`) on
    `task` under each controller ('mbc', 'observer', 'oracle', 'dpc': the export's policy and the
    arm's encoder), side by side and labelled, into
    `out` (.mp4 or .gif). Every controller runs under the export's env options (its policy frame
    and sensor model; its disturbances on the task it was trained on), as `dpc-mjx eval` does,
    with `env` over them (e.g. `{"engine": "native"}`). Returns the env step of each
    controller's fall (None if it did not fall)."""
    if not controllers:
        raise DpcError(f"Render which controllers? Got none; use {[c.value for c in Controller]}.")
    controllers = [c.value for c in Controller.parse_all(controllers)]  # plain names, labels
    if pathlib.Path(out).suffix.lower() not in (".mp4", ".gif"):
        raise DpcError(f"{out}: write videos as .mp4 or .gif.")
    art = io.load(export or SHIPPED)
    arm_spec = arm_argument(arm) if isinstance(arm, str) else arm
    columns, falls, renderer = [], {}, None
    options = {**env_overrides(art, task), **(env or {})}
    for controller in controllers:
        task_env = make(task, arm=arm_spec, controller=controller, **options)
        dpc = controller == Controller.DPC
        policy = art.dpc_policy(arm_name(arm_spec)) if dpc else zero_policy
        print(f"render: {controller}, {seconds} s of episode {episode} (seed {seed})", flush=True)
        qpos, pushes, done = record_episode(task_env, seconds, seed, episode, policy, episodes)
        fell = int(np.argmax(done)) if done.any() else None
        falls[controller] = fell
        renderer = renderer or FrameRenderer(task_env.model, width, height)
        frames = []
        for t, (q, push) in enumerate(zip(qpos, pushes, strict=True)):
            text = f"{controller.upper()}  {t / FPS:.2f} s"
            if fell is not None and t >= fell:
                text += f"  fell at {fell / FPS:.2f} s"
            frames.append(renderer.frame(q, push, text))
        columns.append(np.stack(frames))
    renderer.close()
    if is_writer():  # process 0 of a run of several
        path = write_video(np.concatenate(columns, axis=2), out)
        print(f"render: {path} ({len(columns[0])} frames, {path.stat().st_size / 1e6:.1f} MB)")
    return falls
