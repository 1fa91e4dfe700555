"""The hyperparameters of a SAC run (`SacConfig`) and their checks (`SacConfig.validate`).

Most are the options of brax's SAC (`brax.training.agents.sac.train`): batch size, gradient steps
per actor step, learning rate, discount, reward scaling, Polyak rate `tau`, replay sizes, the
observation normalisation, the paper's 2 x 128 networks (`hidden`). Ours, for our loop
(`sac.train`): a separate actor learning rate, the initial entropy temperature, the critic
warm-up (`actor_warmup_steps`), an asymmetric critic (`critic_privileged`), the epoch length
(one jitted call, one log row, one checkpoint) and the periodic deterministic evaluation with
best-policy selection (`eval_*`, `keep_best`).
The env's own options live in its `EnvConfig`.
"""

from __future__ import annotations

import dataclasses
import math

from dpc_mjx.errors import DpcError
from dpc_mjx.sac.networks import HIDDEN


@dataclasses.dataclass(frozen=True)
class SacConfig:
    """SAC hyperparameters (the env's own options live in its `EnvConfig`)."""

    # env steps in all (rounded up to whole epochs); 0: no SAC, the result is the starting actor
    # (`train`'s actor_init, e.g. the oracle regression)
    num_timesteps: int = 500_000
    num_envs: int = 64  # envs stepped together; one actor step = num_envs env steps
    batch_size: int = 256  # transitions per gradient step
    grad_updates_per_step: int = 16  # gradient steps per actor step (update-to-data 1/4)
    learning_rate: float = 3e-4  # Adam, critics (and the actor unless actor_learning_rate)
    actor_learning_rate: float | None = None  # Adam, actor; None: learning_rate
    discounting: float = 0.99
    # Per-step rewards are <= 0.34 and a fall costs -1000 (`EnvConfig.fall_penalty`); scaled by
    # 0.1 the critics' targets stay within about [-100, 3.4].
    reward_scaling: float = 0.1
    tau: float = 0.005  # Polyak rate of the target critics
    init_alpha: float = 1.0  # initial entropy temperature (brax: 1), tuned towards -action/2
    actor_warmup_steps: int = 0  # gradient steps that train the critics only
    # Env steps collected (with the initial policy) before the first gradient step; they are
    # part of the first epoch(s), whose gradient steps are skipped until then.
    min_replay_size: int = 8192
    max_replay_size: int = 200_000  # bounded explicitly (brax defaults it to num_timesteps)
    hidden: tuple[int, ...] = HIDDEN
    normalize_observations: bool = True
    # Asymmetric actor-critic: the critics also see the privileged values [u_oracle, payload,
    # ee push force] (yaw frame, `sac.env.PrivilegedCriticWrapper`); the actor never does
    critic_privileged: bool = False
    epoch_steps: int = 16_384  # env steps per jitted epoch: one log row and one checkpoint
    # Every `eval_every` epochs (0: never) the deterministic policy runs `eval_envs` episodes of
    # the env's episode length from fixed seeds (the same ones each time, so checkpoints are
    # compared on equal terms); with `keep_best`, the result is the best policy so evaluated.
    eval_every: int = 2
    eval_envs: int = 32
    keep_best: bool = True
    seed: int = 0  # the networks' initialisation and exploration; in a run, `RunConfig.seed`

    def validate(self) -> None:
        for name in ("eval_every", "actor_warmup_steps", "num_timesteps"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise DpcError(f"SacConfig.{name} must be an int >= 0, got {v!r}.")
        for name in (
            "eval_envs",
            "num_envs",
            "batch_size",
            "grad_updates_per_step",
            "max_replay_size",
            "epoch_steps",
        ):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise DpcError(f"SacConfig.{name} must be an int >= 1, got {v!r}.")
        if self.num_timesteps and not 0 <= self.min_replay_size < self.num_timesteps:
            raise DpcError(
                f"SacConfig.min_replay_size={self.min_replay_size} must be >= 0 and below "
                f"num_timesteps={self.num_timesteps}, or no learning happens."
            )
        if self.max_replay_size < max(self.min_replay_size, self.batch_size):
            raise DpcError(
                f"SacConfig.max_replay_size={self.max_replay_size} must hold at least "
                f"min_replay_size={self.min_replay_size} and batch_size={self.batch_size}."
            )
        for name in ("normalize_observations", "critic_privileged", "keep_best"):
            if not isinstance(getattr(self, name), bool):
                raise DpcError(
                    f"SacConfig.{name} must be true or false, got {getattr(self, name)!r}."
                )
        for name in ("learning_rate", "reward_scaling", "tau", "init_alpha"):
            if not getattr(self, name) > 0:
                raise DpcError(f"SacConfig.{name} must be > 0, got {getattr(self, name)}.")
        lr = self.actor_learning_rate
        if lr is not None and not lr > 0:
            raise DpcError(f"SacConfig.actor_learning_rate must be > 0 or None, got {lr}.")
        if not 0.0 <= self.discounting < 1.0:
            raise DpcError(f"SacConfig.discounting must be in [0, 1), got {self.discounting}.")

    @property
    def actor_steps_per_epoch(self) -> int:
        return max(1, self.epoch_steps // self.num_envs)

    @property
    def env_steps_per_epoch(self) -> int:
        return self.actor_steps_per_epoch * self.num_envs

    @property
    def epochs(self) -> int:
        """Epochs to reach `num_timesteps` env steps (0 for none)."""
        return math.ceil(self.num_timesteps / self.env_steps_per_epoch)


__all__ = ["SacConfig"]
