"""Random-motion data for the latent dynamic adapter (paper §III-B, "random movement of both the
robot and the arm"): samples (s_body_t, s_arm_t, p_arm_t) -> s_drp_{t+1}.

The data come from a DPC env (normally the reaching task) batched with `wrap_for_training`: the
body follows random velocity commands, the arm random reaching targets, under random end-effector
pushes and payloads (the env's `EnvConfig` distributions), with the env's low-level controller.
For the adapter the env should be built with `controller="mbc"` (u = 0), so the data show the
arm's effect on the body the policy will later correct; `collect` warns of nothing and takes any
env whose observation is `[s_body, s_arm, p_arm, u_obs]`. Each row also keeps, for the policy's
regression (`policy.regression`), the observer's estimate u_obs, the oracle's u (privileged), the
arms' gravity wrench, what the arms' model cannot know (`unmodelled_u`: privileged, one extra
forward pass per env step), the part of it that is the payloads' weight (`payload_u`:
privileged), what the mount feels beyond the arms' servo motion (`felt_u`: privileged, same pass)
and the heading (to turn u into the yaw frame).

s_drp = (roll rate, pitch rate): the trunk's angular velocity about its own x and y axes (rad/s,
trunk frame, what an IMU's gyro reads), i.e. s_body[2:4] one env step (20 ms) later.

A transition whose next state is the first of a new episode (fall, NaN reset or episode end) is
dropped: its "next" state is not a successor. `collect` runs batched steps until exactly
`samples` transitions are kept and reports how many env steps that took. On several devices the
env batch is sharded over them (`dpc_mjx.devices`; the same rows as on one device).
"""

from __future__ import annotations

import dataclasses
import pathlib
import time

import jax
import jax.numpy as jp
import numpy as np
from mujoco import mjx

from dpc_mjx import devices
from dpc_mjx.control.arm_model import exact_inputs, model_wrench, servo_motion
from dpc_mjx.control.state import gravity_u, oracle_u
from dpc_mjx.envs import rollout
from dpc_mjx.envs.base import DpcEnv
from dpc_mjx.envs.observations import PRIVILEGED, S_BODY_DRP
from dpc_mjx.envs.wrappers import wrap_for_training
from dpc_mjx.errors import DpcError
from dpc_mjx.progress import bar
from dpc_mjx.rotations import roll_pitch_yaw, wrench_to_world, wrench_to_yaw_frame

DRP = S_BODY_DRP  # roll and pitch rate (rad/s, trunk frame) inside s_body
# The per-row columns of a `Dataset` (s_body first)
_ROWS = (
    "s_body",
    "s_arm",
    "p_arm",
    "s_drp_next",
    "env_id",
    "u_oracle",
    "u_obs",
    "yaw",
    "u_gravity",
    "u_unmodelled",
    "u_payload",
    "u_felt",
)


@dataclasses.dataclass(frozen=True)
class Dataset:
    """N transitions; arrays are float32 numpy, rows in collection order (time, then env)."""

    s_body: np.ndarray  # (N, 11) see `observations.s_body`
    s_arm: np.ndarray  # (N, 2 n) arm joint positions, velocities
    p_arm: np.ndarray  # (N, n_act) arm servo targets
    s_drp_next: np.ndarray  # (N, 2) rad/s, roll and pitch rate one env step later
    env_id: np.ndarray | None = None  # (N,) which of the batched envs a row came from
    # (N, 6) privileged, never an input of the adapter or the policy: the oracle's u at t, the
    # measured mount wrench [f_a (N), tau_a (N·m)] about the base's COM (`state.oracle_u`),
    # world frame
    u_oracle: np.ndarray | None = None
    u_obs: np.ndarray | None = None  # (N, 6) the observer's estimate at t, yaw frame (obs block)
    yaw: np.ndarray | None = None  # (N,) rad, the trunk's heading at t (world frame <-> yaw frame)
    # (N, 6) the arms' gravity wrench at t from their file's masses (`DpcEnv.arm_gravity`), world
    u_gravity: np.ndarray | None = None
    # (N, 6) privileged: what the arms' model cannot know at t (the pushes and the payload as the
    # mount feels them, and model error), the measured mount wrench minus the arms' model
    # wrench on the simulator's exact state and accelerations, both of one forward pass
    # (`unmodelled_u`), world
    u_unmodelled: np.ndarray | None = None
    # (N, 6) privileged: the part of u_unmodelled that the payloads' weight is, a force m g at
    # each gripper and its moment about the base's COM (`payload_u`), world; the target of DPC
    # on the model with `RunConfig.model_target` 'payload' (`policy.regression`)
    u_payload: np.ndarray | None = None
    # (N, 6) privileged: what the mount feels beyond the arms' model of their servos' motion, the
    # oracle's u minus `servo_motion`'s wrench on the exact state and base acceleration (`felt_u`),
    # world; the target of DPC on the model with `RunConfig.model_target` 'felt'
    u_felt: np.ndarray | None = None
    env_steps: int = 0  # env steps run to collect them (kept + dropped)
    seconds: float = 0.0  # wall time of the collection

    def __post_init__(self):
        n = len(self.s_body)
        for name in _ROWS[1:]:
            if getattr(self, name) is not None and len(getattr(self, name)) != n:
                raise DpcError(f"Dataset.{name} has {len(getattr(self, name))} rows, s_body {n}.")

    def __len__(self) -> int:
        return len(self.s_body)

    @property
    def encoder_input(self) -> np.ndarray:
        """(N, n_in) the encoder's raw input [s_body, s_arm, p_arm] (an env observation)."""
        return np.concatenate([self.s_body, self.s_arm, self.p_arm], axis=1)

    @property
    def observation(self) -> np.ndarray:
        """(N, n_in + 6) the raw env observation [s_body, s_arm, p_arm, u_obs]."""
        if self.u_obs is None:
            raise DpcError(
                "This dataset has no u_obs column (collected before it existed); collect it again."
            )
        return np.concatenate([self.encoder_input, self.u_obs], axis=1)

    def u_oracle_in(self, frame: str) -> np.ndarray:
        """(N, 6) the oracle's u in `frame` ('world', or 'yaw': turned by the heading `yaw`)."""
        return self._world_wrench_in("u_oracle", frame)

    def u_gravity_in(self, frame: str) -> np.ndarray:
        """(N, 6) the arms' gravity wrench in `frame` ('world', or 'yaw': turned by `yaw`)."""
        return self._world_wrench_in("u_gravity", frame)

    def u_unmodelled_in(self, frame: str) -> np.ndarray:
        """(N, 6) what the arms' model cannot know in `frame` ('world', or 'yaw': turned by
        `yaw`)."""
        return self._world_wrench_in("u_unmodelled", frame)

    def u_payload_in(self, frame: str) -> np.ndarray:
        """(N, 6) the payloads' weight wrench in `frame` ('world', or 'yaw': turned by `yaw`)."""
        return self._world_wrench_in("u_payload", frame)

    def u_felt_in(self, frame: str) -> np.ndarray:
        """(N, 6) what the mount feels beyond the servos' motion in `frame` (as `u_oracle_in`)."""
        return self._world_wrench_in("u_felt", frame)

    def _world_wrench_in(self, name: str, frame: str) -> np.ndarray:
        """(N, 6) the world-frame wrench column `name` in `frame` ('world' or 'yaw')."""
        column = getattr(self, name)
        if column is None or (frame == "yaw" and self.yaw is None):
            raise DpcError(f"This dataset has no {name} (or yaw) column; collect it again.")
        if frame == "world":
            return column
        return np.asarray(wrench_to_yaw_frame(column, self.yaw), np.float32)

    def u_obs_in(self, frame: str) -> np.ndarray:
        """(N, 6) the observer's estimate in `frame` ('yaw', as observed, or 'world': turned
        back by the heading `yaw`)."""
        if self.u_obs is None or (frame == "world" and self.yaw is None):
            raise DpcError("This dataset has no u_obs (or yaw) column; collect it again.")
        if frame == "yaw":
            return self.u_obs
        return np.asarray(wrench_to_world(self.u_obs, self.yaw), np.float32)

    def take(self, rows: slice | np.ndarray) -> Dataset:
        columns = {k: getattr(self, k) for k in _ROWS}
        return dataclasses.replace(
            self, **{k: None if v is None else v[rows] for k, v in columns.items()}
        )

    def save(self, path: str | pathlib.Path) -> None:
        """As a numpy .npz (arrays only; read back with `Dataset.load`, never pickle)."""
        arrays = {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if isinstance(getattr(self, f.name), np.ndarray)
        }
        counters = np.array([self.env_steps, self.seconds], np.float64)
        path = pathlib.Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, counters=counters, **arrays)

    @classmethod
    def load(cls, path: str | pathlib.Path) -> Dataset:
        """A dataset written by `save`; `DpcError` if missing or not one."""
        try:
            with np.load(path, allow_pickle=False) as f:
                arrays = {k: f[k] for k in f.files}
        except (OSError, ValueError) as e:
            raise DpcError(f"Cannot read the dataset {path} ({e}); collect it again.") from e
        names = {f.name for f in dataclasses.fields(cls)}
        if not {"s_body", "s_arm", "p_arm", "s_drp_next", "counters"} <= set(arrays):
            raise DpcError(f"{path} is not a dataset written by Dataset.save; collect it again.")
        env_steps, seconds = arrays.pop("counters")
        fields = {k: v for k, v in arrays.items() if k in names}
        return cls(**fields, env_steps=int(env_steps), seconds=float(seconds))

    @classmethod
    def concatenate(cls, parts: list[Dataset]) -> Dataset:
        """The rows of `parts` in order (columns missing from any part are dropped; env_id is
        kept as it is, so it names envs of several collections)."""
        columns = {}
        for name in _ROWS:
            values = [getattr(p, name) for p in parts]
            columns[name] = None if any(v is None for v in values) else np.concatenate(values)
        return cls(
            **columns,
            env_steps=sum(p.env_steps for p in parts),
            seconds=sum(p.seconds for p in parts),
        )

    @classmethod
    def interleave(cls, parts: list[Dataset]) -> Dataset:
        """The rows of collections from several arms as one: each part's rows keep their order
        and are spread evenly over the whole (row i of a part of n rows at (i + 0.5) / n, ties
        in part order), so that `split` holds out the latest rows of every part; env ids are
        offset so that part k's envs follow part k-1's."""
        offset, shifted, position = 0, [], []
        for part in parts:
            if part.env_id is None:
                raise DpcError("interleave needs the env_id of every part (from `collect`).")
            shifted.append(dataclasses.replace(part, env_id=part.env_id + offset))
            offset += int(part.env_id.max()) + 1
            position.append((np.arange(len(part)) + 0.5) / len(part))
        order = np.argsort(np.concatenate(position), kind="stable")
        return cls.concatenate(shifted).take(order)

    def previous_rows(self) -> np.ndarray:
        """(N,) int: the row of the same env one env step earlier in the same episode, -1 where
        there is none (an episode's first kept row, a row after a dropped transition, a row of
        another collection). Read from the rows themselves: row j follows row i when both have
        one env_id, i comes first, and j's roll and pitch rates are exactly i's `s_drp_next`
        (the same observation: `collect` records both from it)."""
        if self.env_id is None:
            raise DpcError("previous_rows needs the env_id column (a dataset from `collect`).")
        previous = np.full(len(self), -1, np.int64)
        last: dict[int, int] = {}  # env id -> its latest row so far
        for j, env in enumerate(self.env_id.tolist()):
            i = last.get(env)
            if i is not None and np.array_equal(self.s_drp_next[i], self.s_body[j, DRP]):
                previous[j] = i
            last[env] = j
        return previous

    def split(self, val_fraction: float) -> tuple[Dataset, Dataset]:
        """(train, validation): the last `val_fraction` of the rows are held out (later in time,
        so validation episodes are mostly not seen in training)."""
        n_val = max(1, round(len(self) * val_fraction))
        if n_val >= len(self):
            raise DpcError(f"{len(self)} samples are too few to hold out {val_fraction:.0%}.")
        return self.take(slice(0, len(self) - n_val)), self.take(slice(len(self) - n_val, None))


def exact_wrenches(env: DpcEnv, d) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(the arms' model wrench on the exact state and accelerations, the oracle's u, the model
    wrench of the servos' motion on the exact state and base acceleration toward the servos'
    targets `d.ctrl`) of one env's data `d`, each (6,) N and N·m about the base's COM, world,
    from one `mjx.forward` of `d` (privileged: `arm_model.exact_inputs`, `servo_motion`). Zeros
    for a base without arms."""
    if env.arm_model is None:
        return jp.zeros(6), jp.zeros(6), jp.zeros(6)
    d = mjx.forward(env.mx, d)
    offset = jp.asarray(env.controller.idx.com_offset, jp.float32)  # trunk frame, m
    gravity = jp.asarray(env.model.opt.gravity, jp.float32)
    base, (q, qd, qdd) = exact_inputs(env.lay, offset, gravity, d)
    oracle = oracle_u(env.lay, d, d.xpos[env.lay.trunk] + base.com)
    servo, _ = servo_motion(env.arm_model, base, q, qd, d.ctrl[env.lay.arm_act])
    return model_wrench(env.arm_model, base, q, qd, qdd), oracle, servo


def unmodelled_u(env: DpcEnv, d) -> jax.Array:
    """(6,) what the arms' model cannot know in one env's data `d`: the oracle's u minus the
    model wrench on the exact state, one forward pass (`exact_wrenches`; privileged), world."""
    model, oracle, _ = exact_wrenches(env, d)
    return oracle - model


def felt_u(env: DpcEnv, d) -> jax.Array:
    """(6,) what the mount feels beyond the arms' servo motion in one env's data `d`: the oracle's
    u minus the model wrench of the motion the servos cause (`arm_model.servo_motion`) on the
    exact state and base acceleration (`exact_wrenches`; privileged), world. A push on a
    yielding arm moves it faster than its servos would; the model wrench a controller computes
    from the servos' law leaves that part out, and this is what remains of the push at the mount
    (a stiff arm passes all of it: then `unmodelled_u`)."""
    _, oracle, servo = exact_wrenches(env, d)
    return oracle - servo


def payload_u(env: DpcEnv, d, payload: jax.Array) -> jax.Array:
    """(6,) the payloads' weight in one env's data `d`: `payload` (k,) kg, one per arm, each a
    force m g at its arm's end-effector site, and that force's moment about the base's COM,
    world (`control.state.gravity_u`; privileged: no robot knows its load). The slow part of
    `unmodelled_u` (equal to it with no push)."""
    if not env.lay.arms:
        return jp.zeros(6)
    gravity = jp.asarray(env.model.opt.gravity, jp.float32)
    return gravity_u(payload, gravity, d.site_xpos[env.ee_sites], env.com_pos(d))


def _wrench_labels(env: DpcEnv, before) -> tuple[jax.Array, ...]:
    """(u_gravity, u_unmodelled, u_payload, u_felt), each (B, 6) world, of a batch's state
    `before` (one forward pass per env for the exact wrenches)."""
    d, payload = before.pipeline_state, before.info["dist"].payload  # payload (B, k) kg
    u_gravity = jax.vmap(env.arm_gravity)(d)
    model, oracle, servo = jax.vmap(lambda x: exact_wrenches(env, x))(d)
    u_payload = jax.vmap(lambda x, m: payload_u(env, x, m))(d, payload)
    return u_gravity, oracle - model, u_payload, oracle - servo


def _staggered(state, episode_length: int, burn_in: int, seed: int):
    """`state` (a `wrap_for_training` batch just reset) with env i's episode step counter set so
    that its first episode ends after k_i ~ U{1 .. min(burn_in, episode_length)} steps."""
    n = state.info["steps"].shape[0]
    key = jax.random.fold_in(jax.random.PRNGKey(seed), 7)  # apart from the envs' own keys
    k = jax.random.randint(key, (n,), 1, min(burn_in, episode_length) + 1)
    steps = (episode_length - k).astype(state.info["steps"].dtype)
    return state.replace(info={**state.info, "steps": steps})


def collect(
    env: DpcEnv,
    samples: int,
    n_envs: int = 64,
    seed: int = 0,
    chunk: int = 50,
    progress: bool = True,
    policy: rollout.Policy = rollout.zero_policy,
    burn_in: int = 0,
) -> Dataset:
    """Exactly `samples` random-motion transitions from `n_envs` envs stepped in jitted chunks of
    `chunk` env steps, with actions from `policy` (default 0: u = 0 for a 'policy' env, ignored
    by 'mbc'; a trained policy on a 'policy' env gives the student's own states, for DAgger).

    `burn_in` > 0 staggers the starts: each env's first episode is cut short after a random
    number of steps, uniform in 1 .. burn_in, and the rows of the first burn_in steps (rounded
    up to whole chunks) are dropped; with burn_in = the episode length the kept rows' episode
    ages are spread evenly, as a few envs' long trajectories are, however many envs there are
    (`RunConfig.data_burn_in`; many envs would otherwise give only each episode's first steps)."""
    if not isinstance(samples, int) or samples < 1:
        raise DpcError(f"samples must be a positive int, got {samples!r}.")
    if not isinstance(n_envs, int) or n_envs < 1:
        raise DpcError(f"n_envs must be a positive int, got {n_envs!r}.")
    layout = env.unwrapped.obs_layout
    batched = wrap_for_training(env)

    def record(before, after):  # the obs, its oracle u, heading and the next roll/pitch rates
        u_oracle = before.info["privileged"][:, PRIVILEGED["u_oracle"]]
        yaw = roll_pitch_yaw(before.pipeline_state.qpos[:, 3:7])[:, 2]  # (B,) rad
        keep = after.done == 0.0  # the next obs is a successor of obs
        drp = after.obs[:, layout.s_body][:, DRP]
        return before.obs, u_oracle, yaw, drp, keep, *_wrench_labels(env.unwrapped, before)

    t0 = time.perf_counter()
    key = jax.random.PRNGKey(seed)  # the chunks' keys reach only the policy
    # several devices: the batch sharded over them, padded with copies of the first envs (their
    # rows dropped below), so the data are those of one device
    size = devices.padded(n_envs)
    keys = devices.shard(devices.pad(jax.random.split(key, n_envs), size), size)
    state = jax.jit(lambda k: devices.constrain(batched.reset(k), size))(keys)
    if burn_in:
        state = _staggered(state, env.unwrapped.config.episode_length, burn_in, seed)
    run_chunk = rollout.make_chunk(batched.step, policy, chunk, record)
    carry = (state, devices.shard(rollout.Tally.zeros(size), size))
    ids = np.tile(np.arange(n_envs, dtype=np.int32), chunk)  # row order: (time, env)
    parts, kept, steps = [], 0, 0
    burn_chunks = -(-burn_in // chunk)  # the burn-in's chunks, their rows dropped
    with bar(samples, "collect", "sample", progress) as pbar:
        for i, (_, out) in enumerate(rollout.chunks(run_chunk, carry, key)):
            steps += chunk * n_envs
            if i < burn_chunks:  # staggered starts: these rows are dropped
                pbar.set_postfix_str(f"burn-in {(i + 1) * chunk}/{burn_chunks * chunk} steps")
                continue
            obs, u, yaw, drp, keep, *labels = (x[:, :n_envs].reshape(-1, *x.shape[2:]) for x in out)
            columns = (obs, drp, ids, u, yaw, *labels)
            parts.append(tuple(x[keep] for x in columns))
            kept += int(keep.sum())
            pbar.update(min(int(keep.sum()), samples - pbar.n))
            if kept >= samples:
                break
    columns = (np.concatenate([p[k] for p in parts])[:samples] for k in range(len(parts[0])))
    obs, drp, env_id, u_oracle, yaw, u_gravity, u_unmodelled, u_payload, u_felt = columns
    return Dataset(
        s_body=obs[:, layout.s_body],
        s_arm=obs[:, layout.s_arm],
        p_arm=obs[:, layout.p_arm],
        s_drp_next=drp,
        env_id=env_id,
        u_oracle=u_oracle,
        u_obs=obs[:, layout.u_obs],
        yaw=yaw,
        u_gravity=u_gravity,
        u_unmodelled=u_unmodelled,
        u_payload=u_payload,
        u_felt=u_felt,
        env_steps=steps,
        seconds=time.perf_counter() - t0,
    )
