"""Run an exported DPC policy with numpy only, e.g. on the robot's own computer.

This file imports nothing but the Python standard library, numpy and msgpack (no jax, no flax, no
other dpc_mjx module), so it can be copied alone next to an export folder written by
`dpc_mjx.io.export`:

    policy = NumpyPolicy("export/", arm="regular")
    u = policy.u(obs, yaw)   # obs = [s_body, s_arm (2 n), p_arm (n_act), u_obs (6)], the raw
                             # env observation; yaw (rad) the heading; u in the world frame
    u = policy.u(obs)        # u in the policy's frame (action_scaling.frame), as the ONNX
                             # graph of `dpc-mjx onnx` gives it

    z = tanh(E((obs[:input_size] - mean_E) / std_E))                     latent (latent_size,)
    x = [s_body, z] or [s_body, z, u_obs]                                policy.inputs
    a = tanh(pi((x - mean_pi) / std_pi)[:action_size])                    action in [-1, 1]^6
    u = u_scale * a: [f_a (N), tau_a (N m)], per component, about the COM, in the frame
        action_scaling.frame: 'yaw' (heading-aligned; `u(obs, yaw)` turns it to the world
        frame, `u(obs)` leaves it in the yaw frame) or 'world'
    u = u_obs + u_scale * a where action_scaling.base is 'observer' (yaw frame; the policy is
        a residual of the observer's estimate). The env adds the estimate of every 4 ms tick to
        the policy's u of the last 20 ms step: between policy steps, pass the observation with
        the tick's u_obs (its last 6 entries), or add the tick's estimate to `residual(obs)`
    u = u_gravity + u_scale * a where action_scaling.base is 'gravity': u_gravity the arms'
        weight and its torque about the base's COM at their present pose (from the arm's masses
        and kinematics; the robot computes it), in the policy's frame: `u(obs, yaw, u_gravity)`
    u = u_model + u_scale * a where action_scaling.base is 'model': u_model the arms' model
        wrench of the tick (world; `dpc_mjx.control.arm_estimate`), computed by arm_dynamics.py
        (copy it next to this file) from `arm_model_<arm>.json` and the tick's inputs:
        `u(obs, yaw, measured={...})`, `model_wrench(measured)` (`arm_dynamics.MEASURED`). An
        export written before that file: `u(obs, yaw, u_model=)`, u_model in the policy's frame

Every size and the layout come from the sidecar: s_body = obs[start:stop] with
`observation.s_body` {start, stop, names} (a sidecar written before that key existed has s_body
first, policy.observation_size - latent_size long); u_obs = obs[input_size:input_size + 6], the
disturbance observer's estimate (yaw frame); a policy whose inputs lack u_obs also takes obs
without it (input_size long).

E and pi are ReLU MLPs (Dense layers `hidden_0 .. hidden_k`, then `out` for E; the last
`hidden_k` is pi's output). The msgpack files use flax's format: a dict tree whose arrays are
msgpack ExtType 1 with payload msgpack((shape, dtype name, raw C-order bytes)), decoded here.
Computation is in float64. Any problem with the files or the input raises `ValueError`.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import pathlib
import sys

import msgpack
import numpy as np

FORMAT_VERSION = 1  # the export format read here; equal to dpc_mjx.io.FORMAT_VERSION
SIDECAR = "dpc.json"  # equal to dpc_mjx.io.SIDECAR
_NDARRAY_EXT = 1  # flax's msgpack ExtType code of an ndarray
_U_OBS_SIZE = 6  # u_obs, the last block of a raw env observation (dpc_mjx.envs.observations)


def _ext_hook(code: int, data: bytes) -> np.ndarray:
    if code != _NDARRAY_EXT:
        raise ValueError(f"unsupported msgpack extension type {code}")
    shape, dtype, buffer = msgpack.unpackb(data, raw=False)
    return np.frombuffer(buffer, dtype=np.dtype(dtype)).reshape(shape)


def read_tree(path: str | pathlib.Path, sha256: str | None = None) -> dict:
    """The dict of numpy arrays in a flax msgpack file; `ValueError` if missing or corrupt, or if
    its sha256 differs from `sha256`."""
    path = pathlib.Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ValueError(f"Cannot read {path} ({e}); copy the whole export folder.") from e
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise ValueError(
            f"{path} is not the file recorded in {SIDECAR} (sha256 differs): it is truncated, "
            "corrupt or from another export; copy the export folder again."
        )
    try:
        tree = msgpack.unpackb(data, ext_hook=_ext_hook, raw=False)
    except Exception as e:  # msgpack raises several types for corrupt input
        raise ValueError(f"{path} is truncated or corrupt ({e}); copy the export again.") from e
    if not isinstance(tree, dict):
        raise ValueError(f"{path} does not hold a dict of arrays; copy the export again.")
    return tree


def _get(tree: dict, keys: tuple[str, ...], path: pathlib.Path) -> np.ndarray | dict:
    node = tree
    for k in keys:
        if not isinstance(node, dict) or k not in node:
            raise ValueError(f"{path} lacks {'.'.join(keys)}; re-export with dpc_mjx.io.export.")
        node = node[k]
    return node


def _mlp(layers: dict, names: list[str], path: pathlib.Path) -> list[tuple[np.ndarray, ...]]:
    """[(kernel (n_in, n_out), bias (n_out,))] in float64, in the order `names`."""
    out = []
    for name in names:
        k, b = (np.asarray(_get(layers, (name, p), path), np.float64) for p in ("kernel", "bias"))
        if k.ndim != 2 or b.shape != (k.shape[1],) or (out and out[-1][0].shape[1] != k.shape[0]):
            raise ValueError(
                f"{path}: layer {name} has kernel {k.shape}, bias {b.shape}, which "
                "do not chain; re-export with dpc_mjx.io.export."
            )
        out.append((k, b))
    return out


def _forward(layers: list[tuple[np.ndarray, ...]], x: np.ndarray) -> np.ndarray:
    for i, (k, b) in enumerate(layers):
        x = x @ k + b
        if i < len(layers) - 1:
            x = np.maximum(x, 0.0)
    return x


def _norm(tree: dict, key: str, n: int, path: pathlib.Path) -> tuple[np.ndarray, np.ndarray]:
    mean, std = (np.asarray(_get(tree, (key, s), path), np.float64) for s in ("mean", "std"))
    if mean.shape != (n,) or std.shape != (n,):
        raise ValueError(
            f"{path}: {key} has shape {mean.shape}/{std.shape}, {SIDECAR} says ({n},);"
            " re-export with dpc_mjx.io.export."
        )
    return mean, std


def _s_body(meta: dict, size: int) -> slice:
    """Where s_body sits in the observation: the sidecar's observation.s_body, or for a sidecar
    written before it was recorded, the first `size` entries."""
    if "observation" not in meta:
        return slice(0, size)
    s = meta["observation"]["s_body"]
    start, stop = int(s["start"]), int(s["stop"])
    if not 0 <= start < stop or len(s["names"]) != stop - start:
        raise ValueError(f"observation.s_body {s!r} is not a slice [start, stop) with its names")
    return slice(start, stop)


def _file(directory: pathlib.Path, name: str) -> pathlib.Path:
    if not isinstance(name, str) or pathlib.PurePath(name).name != name or name in ("", ".", ".."):
        raise ValueError(f"file {name!r} is not a file name in the export folder")
    return directory / name


class NumpyPolicy:
    """The exported encoder of `arm` and the policy, as numpy arrays (see the module docstring).

    Each method takes one observation (input_size,) or a batch (B, input_size) and returns (k,)
    or (B, k). Attributes: `meta` (the sidecar), `arm`, `input_size`, `latent_size`,
    `action_size`, `s_body` (its slice of the observation), `scale` (6,) (u = scale * a; N for
    f_a, N·m for tau_a).
    """

    def __init__(self, directory: str | pathlib.Path, arm: str) -> None:
        d = pathlib.Path(directory)
        try:
            meta = json.loads((d / SIDECAR).read_text())
            version = meta["format_version"]
            latent = int(meta["adapter_config"]["latent_size"])
            n_hidden = len(meta["adapter_config"]["hidden"])
            pol, scaling, encoders = meta["policy"], meta["action_scaling"], meta["encoders"]
            hidden, action_size = [int(h) for h in pol["hidden"]], int(pol["action_size"])
            u_scale = [float(v) for v in scaling["u_scale"]]  # (6,) N, N·m per unit action
            obs_size = int(pol["observation_size"])  # the policy's observation
            inputs = list(pol.get("inputs", ["s_body", "z"]))  # older sidecars: [s_body, z]
            n_obs = _U_OBS_SIZE if "u_obs" in inputs else 0
            frame = str(scaling.get("frame", "world"))  # older sidecars: world
            base = str(scaling.get("base", "zero"))  # older sidecars: zero
            s_body = _s_body(meta, obs_size - latent - n_obs)
            enc = encoders.get(arm)
            if enc is not None:
                input_size = int(enc["input_size"])  # [s_body, s_arm, p_arm] of this arm
                enc_path, pol_path = _file(d, enc["file"]), _file(d, pol["file"])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
            raise ValueError(
                f"{d / SIDECAR} is missing or invalid ({e!r}); point at an export folder written "
                "by dpc_mjx.io.export."
            ) from e
        if version != FORMAT_VERSION:
            raise ValueError(
                f"{d / SIDECAR} has format_version {version!r}; this file reads {FORMAT_VERSION}. "
                "Copy inference.py from the dpc_mjx that wrote the export."
            )
        if enc is None:
            raise ValueError(
                f"The export has no encoder for arm {arm!r}; it has {sorted(encoders)}."
            )
        self.meta, self.arm, self.input_size = meta, arm, input_size
        self.latent_size, self.action_size = latent, action_size
        self.inputs, self.frame, self.base = inputs, frame, base
        self.s_body = s_body  # of the observation
        n_body = s_body.stop - s_body.start
        known = inputs in (["s_body", "z"], ["s_body", "z", "u_obs"]) and frame in ("yaw", "world")
        known = known and (base in ("zero", *_ADDED) or (base == "observer" and frame == "yaw"))
        if not known or n_body + latent + n_obs != obs_size or s_body.stop > input_size:
            raise ValueError(
                f"{d / SIDECAR}: s_body = obs[{s_body.start}:{s_body.stop}], latent_size "
                f"{latent}, policy.inputs {inputs} and action_scaling.frame {frame!r} (base "
                f"{base!r}) do not fit policy.observation_size {obs_size} and the encoder's input "
                f"size {input_size}; re-export the artefacts."
            )
        if len(u_scale) != action_size:
            raise ValueError(
                f"{d / SIDECAR}: action_scaling.u_scale has {len(u_scale)} entries, the policy "
                f"{action_size} actions; re-export the artefacts."
            )
        self.scale = np.array(u_scale)  # N (f_a), N·m (tau_a)
        self.arm_model, self._no_model = _arm_model(meta, d, arm, input_size, n_body)

        tree = read_tree(enc_path, enc.get("sha256"))
        mlp = _get(tree, ("params", "params", "mlp"), enc_path)
        self._enc = _mlp(mlp, [f"hidden_{i}" for i in range(n_hidden)] + ["out"], enc_path)
        self._enc_norm = _norm(tree, "input_norm", input_size, enc_path)
        self._check(self._enc, input_size, latent, enc_path)

        tree = read_tree(pol_path, pol.get("sha256"))
        layers = _get(tree, ("params", "params"), pol_path)
        self._pi = _mlp(layers, [f"hidden_{i}" for i in range(len(hidden) + 1)], pol_path)
        self._pi_norm = _norm(tree, "obs_norm", obs_size, pol_path)
        self._check(self._pi, obs_size, 2 * action_size, pol_path)
        if [k.shape[1] for k, _ in self._pi[:-1]] != hidden:
            raise ValueError(
                f"{pol_path}: hidden sizes differ from {SIDECAR}'s {hidden}; re-export."
            )

    @staticmethod
    def _check(layers: list, n_in: int, n_out: int, path: pathlib.Path) -> None:
        found = (layers[0][0].shape[0], layers[-1][0].shape[1])
        if found != (n_in, n_out):
            raise ValueError(
                f"{path} maps {found[0]} -> {found[1]} entries, {SIDECAR} says "
                f"{n_in} -> {n_out}; re-export with dpc_mjx.io.export."
            )

    def _obs(self, obs) -> np.ndarray:
        x = np.asarray(obs, np.float64)
        sizes = [self.input_size + _U_OBS_SIZE]
        if "u_obs" not in self.inputs and self.base != "observer":
            sizes.append(self.input_size)
        if x.ndim not in (1, 2) or x.shape[-1] not in sizes:
            raise ValueError(
                f"Observation of shape {x.shape}: arm {self.arm!r}'s raw env observation "
                f"[s_body, s_arm, p_arm, u_obs] has {sizes[0]} entries per row (the encoder reads "
                f"the first {self.input_size}); pass that arm's raw observation, (n,) or (B, n)."
            )
        bad = ~np.isfinite(x)
        if bad.any():
            raise ValueError(
                f"Observation has {int(bad.sum())} NaN/inf entries (first at index "
                f"{tuple(int(i) for i in np.argwhere(bad)[0])}); check the robot's state estimate."
            )
        return x

    def _latent(self, x: np.ndarray) -> np.ndarray:
        mean, std = self._enc_norm
        return np.tanh(_forward(self._enc, (x[..., : self.input_size] - mean) / std))

    def latent(self, obs) -> np.ndarray:
        """z (..., latent_size) in (-1, 1)."""
        return self._latent(self._obs(obs))

    def action(self, obs) -> np.ndarray:
        """Deterministic action a (..., action_size) in [-1, 1]: the actor's mode."""
        return self._action(self._obs(obs))

    def _action(self, x: np.ndarray) -> np.ndarray:
        """`action` of an observation `_obs` has checked."""
        blocks = {
            "s_body": x[..., self.s_body],
            "z": self._latent(x),
            "u_obs": x[..., self.input_size : self.input_size + _U_OBS_SIZE],
        }
        pi_in = np.concatenate([blocks[k] for k in self.inputs], axis=-1)
        mean, std = self._pi_norm
        return np.tanh(_forward(self._pi, (pi_in - mean) / std)[..., : self.action_size])

    def residual(self, obs) -> np.ndarray:
        """The policy's own u_scale * a (..., 6) in its frame: u itself where `base` is 'zero',
        what is added to the observer's estimate (or the arms' gravity wrench) where it is
        'observer' (or 'gravity')."""
        return self._residual(self._obs(obs))

    def _residual(self, x: np.ndarray) -> np.ndarray:
        if self.action_size != 6:
            raise ValueError(
                f"u needs a 6-D action [f_a, tau_a], this policy has {self.action_size}."
            )
        return self._action(x) * self.scale

    def u(self, obs, yaw=None, u_gravity=None, u_model=None, measured=None) -> np.ndarray:
        """u = [f_a (3, N), tau_a (3, N·m)] (..., 6) about the base's COM: `residual(obs)`, plus
        the observation's u_obs where `base` is 'observer', `u_gravity` (..., 6; the arms'
        weight at their pose) where it is 'gravity', where it is 'model' the arms' model wrench:
        from `measured` (`model_wrench`) where the export has the arm's model, else `u_model`
        (..., 6); given wrenches in the policy's frame. Without `yaw`, in the policy's frame
        (`frame`; a computed u_model turned by measured's heading); with the heading `yaw` (rad;
        () or (B,)), world: a yaw-frame policy's u turned, [R_z(yaw) f, R_z(yaw) tau]."""
        x = self._obs(obs)
        u = self._residual(x)
        if self.base == "observer":  # x holds u_obs (`_obs` checked its size)
            u = u + x[..., self.input_size : self.input_size + _U_OBS_SIZE]
        computes = self.arm_model is not None
        given = {"gravity": u_gravity, "model": u_model}
        for base, wrench in given.items():
            if base == self.base and computes == (wrench is not None):
                fix = f"pass u_{base} (..., 6), N and N·m about the base's COM, policy's frame."
                fix = "pass measured=, not u_model: its arm model gives it." if computes else fix
                raise ValueError(
                    f"This policy's u is added to {_ADDED[base]} (action_scaling.base "
                    f"{base!r}): {fix}{self._no_model or ''}"
                )
            if base != self.base and wrench is not None:
                raise ValueError(
                    f"u_{base} is added only to a policy on {_ADDED[base]}; this policy's base "
                    f"is {self.base!r}: leave u_{base} out."
                )
        if self.base in given and not computes:
            u = u + np.broadcast_to(np.asarray(given[self.base], np.float64), u.shape)
        world, heading = 0.0, None  # the computed u_model (world) and the heading it is at
        if computes or measured is not None:
            world, heading = self._model_wrench(measured, x)
        if self.frame == "yaw" and yaw is None and heading is not None:
            world = _turn(world, -heading)  # to the policy's frame
        return u + world if self.frame == "world" or yaw is None else _turn(u, yaw) + world

    def model_wrench(self, measured, obs=None) -> np.ndarray:
        """u_model (..., 6), world frame, N and N·m about the base's COM: the arms' model
        wrench of the tick (`arm_dynamics.tick_wrench`) from `measured`, a dict of the tick's
        inputs (`arm_dynamics.MEASURED`; leading batch axes allowed), q and qd where absent
        the raw observation `obs`'s s_arm. `ValueError` naming what is missing."""
        return self._model_wrench(measured, None if obs is None else self._obs(obs))[0]

    def _model_wrench(self, measured, x) -> tuple[np.ndarray, np.ndarray]:
        """(u_model (..., 6) world, the heading (...) rad of measured's rot)."""
        if self.arm_model is None:
            raise ValueError(
                "measured is read only by an export on the arms' model wrench that records the "
                f"arm's model.{self._no_model or f' This policy is on {self.base!r}.'}"
            )
        n, start = self.arm_model.n, self.s_body.stop
        s_arm = [] if x is None else np.split(x[..., start : start + 2 * n], 2, axis=-1)
        inputs = _dynamics().tick_inputs(
            self.arm_model, {**dict(zip(("q", "qd"), s_arm)), **(measured or {})}
        )
        heading = np.arctan2(inputs["rot"][..., 1, 0], inputs["rot"][..., 0, 0])
        return _dynamics().tick_wrench(self.arm_model, inputs), heading


def _turn(u: np.ndarray, yaw) -> np.ndarray:
    """[R_z(yaw) f, R_z(yaw) tau] of u (..., 6)."""
    c, s = np.cos(np.asarray(yaw, np.float64)), np.sin(np.asarray(yaw, np.float64))
    out = np.array(u, np.float64)
    for i in (0, 3):  # force, then torque
        out[..., i] = c * u[..., i] - s * u[..., i + 1]
        out[..., i + 1] = s * u[..., i] + c * u[..., i + 1]
    return out


@functools.cache
def _dynamics():
    """`arm_dynamics.py`: the package's, or the copy next to this file (a robot's computer)."""
    if __package__:  # dpc_mjx.io
        return importlib.import_module(f"{__package__}.arm_dynamics")
    path = pathlib.Path(__file__).with_name("arm_dynamics.py")
    if not path.is_file():
        raise ValueError(
            f"An export on the arms' model wrench needs {path.name} next to {__file__}: copy "
            "dpc_mjx/io/arm_dynamics.py there (numpy only, like this file)."
        )
    spec = importlib.util.spec_from_file_location("dpc_arm_dynamics", path)
    module = sys.modules["dpc_arm_dynamics"] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _arm_model(meta: dict, d: pathlib.Path, arm: str, n_in: int, n_body: int):
    """(the arm's model, None) of a 'model' export, or (None, why u_model must be given)."""
    if meta["action_scaling"].get("base") != "model":
        return None, None
    if "arm_model" not in meta["encoders"][arm]:
        return None, (
            f" This export was written before the arms' model was recorded (no encoders.{arm}."
            "arm_model in its sidecar); dpc_mjx.io.add_arm_models(DIR) records it."
        )
    return _dynamics().from_export(meta, d, arm, n_in, n_body)


# The wrenches a robot computes and passes to `NumpyPolicy.u`, by action_scaling.base
_ADDED = {
    "gravity": "the arms' gravity wrench (their weight and its torque at their pose)",
    "model": "the arms' model wrench (their inverse dynamics from the measured states)",
}

__all__ = ["FORMAT_VERSION", "NumpyPolicy", "read_tree"]
