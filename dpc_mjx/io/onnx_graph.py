"""An export's encoder and policy as one ONNX graph (`onnx_model`, `write_onnx`; `dpc-mjx onnx`),
for the stacks that run ONNX (onnxruntime, TensorRT, C++ and ROS 2 nodes). It computes what
`NumpyPolicy(export, arm).u(obs)` returns, u in the policy's frame:

    input  'obs'  float32 (batch, input_size + 6): the raw env observation of the arm,
                  [s_body, s_arm, p_arm, u_obs], input_size = encoders.<arm>.input_size
    output 'u'    float32 (batch, 6): [f_a (N), tau_a (N m)] about the base's COM, in the frame
                  action_scaling.frame ('yaw': heading-aligned, turn f and tau by R_z(yaw) for
                  the world frame; 'world')

    z = tanh(E((obs[:, :input_size] - mean_E) / std_E))                latent (batch, latent_size)
    x = concat of policy.inputs: s_body = obs[:, s_body], z, u_obs = obs[:, input_size:+6]
    u = u_scale * tanh(pi((x - mean_pi) / std_pi)[:, :action_size])   (+ u_obs where
        action_scaling.base is 'observer'; where it is 'gravity' the robot adds its arms'
        weight and its torque at their pose, u_gravity, as `NumpyPolicy.u(obs, u_gravity=)`)

Where action_scaling.base is 'model' and the export records the arm's model
(encoders.<arm>.arm_model, `arm_model_<arm>.json`), the graph computes the arms' model wrench
u_model itself (`onnx_arm.model_wrench`, the numbers of `arm_dynamics.servo_motion`) from q, qd
(the observation's s_arm) and five more inputs, each required, so a runtime refuses to run
without them (`onnx_arm.MEASURED`; float32, batch-first):

    'targets' (batch, n) rad (m), 'rot' (batch, 3, 3) trunk -> world, 'ang_vel' (batch, 3) rad/s
    world, 'desired' (batch, 6) [COM m/s^2, angular rad/s^2] world, 'com' (batch, 3) m world
    output 'u'        u_model + u_scale * a in the policy's frame (a 'yaw' policy: u_model
                      turned by R_z(-heading of rot)), `NumpyPolicy.u(obs, measured=...)`
    output 'u_world'  (the output's name + '_world') the same in the world frame: the residual
                      turned by R_z(heading of rot) plus u_model, `u(obs, heading, measured=...)`

A 'model' export without the arm's model (written before it was recorded), or whose u_model
reads another estimator, gives the policy's part, `NumpyPolicy.residual(obs)`, and the robot adds
u_model (policy frame), as `NumpyPolicy.u(obs, u_model=)`; its metadata says so (`u_model`).

E and pi are Gemm (x @ kernel + bias) layers with Relu between, the flax/brax MLPs. Every size,
the layout and the scaling come from the sidecar (checked by `load`), the weights and the
normalisers from the msgpack files, in float32 as stored. The opset and the tensor names are the
sidecar's `onnx` entry (`sidecar.ONNX` for an export written before it was recorded); the
model's metadata_props name the export, the arm, the frame, the inputs and the files' sha256.

The graph is built with the `onnx` package's helpers, imported only here, when a graph is built:
`import dpc_mjx` needs no onnx (`pip install 'dpc-mjx[onnx]'` installs it, and onnxruntime).
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
from typing import Any

import numpy as np

from dpc_mjx._version import __version__
from dpc_mjx.envs.observations import U_OBS_SIZE
from dpc_mjx.errors import DpcError
from dpc_mjx.io import arm_dynamics, onnx_arm, sidecar, sidecar_checks
from dpc_mjx.io.load import Artefacts, load
from dpc_mjx.serialization import write_bytes

INSTALL = "pip install 'dpc-mjx[onnx]'"
_MIN_OPSET = 13  # Slice, Gemm, Concat, element-wise ops; onnx_arm's axes and pads as inputs
_FRAMES = ("yaw", "world")
_U_NAMES = ("f_x", "f_y", "f_z", "tau_x", "tau_y", "tau_z")  # u: N, then N·m


@dataclasses.dataclass(frozen=True)
class _Layers:
    """What the graph computes, from one export and arm (float32 arrays)."""

    input_size: int  # the encoder's input [s_body, s_arm, p_arm]; the graph takes + U_OBS_SIZE
    s_body: slice  # of the observation
    inputs: tuple[str, ...]  # the policy's observation blocks, in order
    encoder: list[tuple[np.ndarray, np.ndarray]]  # [(kernel (n_in, n_out), bias (n_out,))]
    encoder_norm: tuple[np.ndarray, np.ndarray]  # (mean, std) (input_size,)
    policy: list[tuple[np.ndarray, np.ndarray]]
    policy_norm: tuple[np.ndarray, np.ndarray]  # (mean, std) (observation_size,)
    action_size: int
    scale: np.ndarray  # (action_size,) N for f_a, N·m for tau_a per unit action
    frame: str  # of u: 'yaw' or 'world'
    base: str  # u_scale * a added to: 'zero', 'observer' (u_obs, yaw frame), 'gravity', 'model'
    arm_model: arm_dynamics.ArmModel | None  # base 'model': the graph computes u_model from it
    u_model: str  # how u_model reaches u (the metadata's `u_model`); '' unless base 'model'


def import_onnx() -> Any:
    """The `onnx` module; `DpcError` saying how to install it when it is missing."""
    try:
        import onnx  # noqa: PLC0415 (optional dependency: the onnx extra)
    except ImportError as e:
        raise DpcError(
            f"Writing an ONNX graph needs the onnx package ({e}); install it with {INSTALL} "
            "(onnx and onnxruntime)."
        ) from e
    return onnx


def onnx_names(meta: dict, path: pathlib.Path) -> dict:
    """{opset, input, output} of the graph: the sidecar's `onnx` entry, or `sidecar.ONNX` when
    the export was written before it was recorded; `DpcError` if the entry is malformed."""
    entry = meta.get("onnx", sidecar.ONNX)
    ok = isinstance(entry, dict) and all(k in entry for k in sidecar.ONNX)
    names = {k: entry[k] for k in sidecar.ONNX} if ok else {}
    ok = (
        ok
        and type(names["opset"]) is int
        and names["opset"] >= _MIN_OPSET
        and all(isinstance(names[k], str) and names[k] for k in ("input", "output"))
        and names["input"] != names["output"]
    )
    if not ok:
        raise DpcError(
            f"{path}: onnx must be {{opset (int >= {_MIN_OPSET}), input, output (two names)}}, "
            f"got {json.dumps(entry)}; {sidecar.REEXPORT}."
        )
    return names


def _layers(art: Artefacts, arm: str, path: pathlib.Path) -> _Layers:
    """The export's networks for `arm` as float32 arrays, the sizes from the sidecar."""
    d = sidecar_checks.check(art.meta, path)
    encoder = art.encoder(arm)
    scaling = art.meta["action_scaling"]
    frame = str(scaling.get("frame", "world"))  # older sidecars: world
    if frame not in _FRAMES or d.action_size != len(_U_NAMES):
        raise DpcError(
            f"{path}: an ONNX graph gives u = [f_a, tau_a] (6,) in the frame 'yaw' or 'world'; "
            f"this policy has {d.action_size} actions and action_scaling.frame {frame!r}; "
            f"{sidecar.REEXPORT}."
        )
    base = str(scaling.get("base", "zero"))  # checked by `sidecar_checks.check`
    arm_model, u_model = _arm_model(art.meta, arm, path, d) if base == "model" else (None, "")
    mlp = encoder.params["params"]["mlp"]
    enc_names = [*(f"hidden_{i}" for i in range(len(d.config.hidden))), "out"]
    pol_names = [f"hidden_{i}" for i in range(len(d.policy_hidden) + 1)]
    return _Layers(
        input_size=d.input_sizes[arm],
        s_body=d.s_body,
        inputs=d.policy_inputs,
        encoder=[_dense(mlp[n]) for n in enc_names],
        encoder_norm=_pair(encoder.input_norm),
        policy=[_dense(art.policy.params["params"][n]) for n in pol_names],
        policy_norm=_pair(art.policy.obs_norm),
        action_size=d.action_size,
        scale=np.asarray(scaling["u_scale"], np.float32),
        frame=frame,
        base=base,
        arm_model=arm_model,
        u_model=u_model,
    )


def _arm_model(meta: dict, arm: str, path: pathlib.Path, d: sidecar_checks.Declared):
    """(the `ArmModel` the graph computes u_model from, how) of a 'model' export, or (None, why
    the robot adds u_model) where it records no arm model or one of another estimator."""
    if "arm_model" not in meta["encoders"][arm]:
        return None, (
            "added by the robot (policy frame): the export records no arm model "
            f"(encoders.{arm}.arm_model; dpc_mjx.io.add_arm_models records it)"
        )
    n_body = d.s_body.stop - d.s_body.start
    try:
        model, why = arm_dynamics.from_export(meta, path.parent, arm, d.input_sizes[arm], n_body)
    except ValueError as e:
        raise DpcError(f"{e} (the arm model of {arm!r}); {sidecar.REEXPORT}.") from e
    if model is None:
        return None, f"added by the robot (policy frame):{why}"
    inputs = ", ".join(onnx_arm.MEASURED)
    return model, f"computed in the graph from obs's s_arm and the inputs {inputs}"


def _dense(layer) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(layer["kernel"], np.float32), np.asarray(layer["bias"], np.float32)


def _pair(norm) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(norm.mean, np.float32), np.asarray(norm.std, np.float32)


class _Graph:
    """Nodes and initializers of a graph under construction, each tensor named `<hint>_<n>`."""

    def __init__(self, onnx: Any) -> None:
        self.onnx, self.nodes, self.initializers = onnx, [], []

    def name(self, hint: str) -> str:
        return f"{hint}_{len(self.nodes) + len(self.initializers)}"

    def const(self, hint: str, array: np.ndarray) -> str:
        name = self.name(hint)
        self.initializers.append(self.onnx.numpy_helper.from_array(np.asarray(array), name))
        return name

    def op(self, op: str, *inputs: str, out: str | None = None, **attrs) -> str:
        out = out or self.name(op.lower())
        self.nodes.append(self.onnx.helper.make_node(op, list(inputs), [out], **attrs))
        return out

    def columns(self, x: str, start: int, stop: int) -> str:
        """x[:, start:stop]."""
        bounds = {"start": start, "stop": stop, "axis": 1}
        ints = [self.const(f"slice_{k}", np.array([v], np.int64)) for k, v in bounds.items()]
        return self.op("Slice", x, *ints)

    def standardise(self, x: str, norm: tuple[np.ndarray, np.ndarray], hint: str) -> str:
        """(x - mean) / std, as `Normalizer` computes it."""
        centred = self.op("Sub", x, self.const(f"{hint}_mean", norm[0]))
        return self.op("Div", centred, self.const(f"{hint}_std", norm[1]))

    def mlp(self, x: str, layers: list[tuple[np.ndarray, np.ndarray]], hint: str) -> str:
        """x @ kernel + bias per layer, Relu between (not after the last)."""
        for i, (kernel, bias) in enumerate(layers):
            w, b = self.const(f"{hint}{i}_kernel", kernel), self.const(f"{hint}{i}_bias", bias)
            x = self.op("Gemm", x, w, b)
            if i < len(layers) - 1:
                x = self.op("Relu", x)
        return x


def _nodes(g: _Graph, net: _Layers, obs: str, u: str) -> None:
    """The graph from the observation `obs` (batch, input_size + 6) (and where it computes
    u_model, `onnx_arm.MEASURED`'s inputs) to `u` (batch, 6) (and `u`_world)."""
    n = net.input_size
    e_in = g.standardise(g.columns(obs, 0, n), net.encoder_norm, "encoder_norm")
    blocks = {
        "s_body": lambda: g.columns(obs, net.s_body.start, net.s_body.stop),
        "z": lambda: g.op("Tanh", g.mlp(e_in, net.encoder, "encoder")),
        "u_obs": lambda: g.columns(obs, n, n + U_OBS_SIZE),
    }
    x = g.op("Concat", *(blocks[k]() for k in net.inputs), axis=1)
    logits = g.mlp(g.standardise(x, net.policy_norm, "policy_norm"), net.policy, "policy")
    action = g.op("Tanh", g.columns(logits, 0, net.action_size))
    if net.base == "observer":  # u = u_obs + u_scale * a
        residual = g.op("Mul", action, g.const("u_scale", net.scale))
        g.op("Add", blocks["u_obs"](), residual, out=u)
    elif net.arm_model is not None:  # u = u_model + u_scale * a
        _with_model(g, net, obs, g.op("Mul", action, g.const("u_scale", net.scale)), u)
    else:  # 'zero', or the robot adds its arms' wrench to u
        g.op("Mul", action, g.const("u_scale", net.scale), out=u)


def _with_model(g: _Graph, net: _Layers, obs: str, residual: str, u: str) -> None:
    """`u` = residual + u_model in the policy's frame and `u`_world = the same in the world's,
    u_model (world) from q, qd = obs's s_arm and the inputs `onnx_arm.MEASURED`."""
    n, start = net.arm_model.n, net.s_body.stop
    q, qd = g.columns(obs, start, start + n), g.columns(obs, start + n, start + 2 * n)
    world = onnx_arm.model_wrench(g, net.arm_model, q, qd, {k: k for k in onnx_arm.MEASURED})
    if net.frame == "world":
        g.op("Add", residual, world, out=u)
        g.op("Identity", u, out=f"{u}_world")
    else:  # 'yaw': turned by the heading of rot
        g.op("Add", residual, onnx_arm.heading_turn(g, "rot", world, to_world=False), out=u)
        turned = onnx_arm.heading_turn(g, "rot", residual, to_world=True)
        g.op("Add", turned, world, out=f"{u}_world")


def onnx_model(export_dir: str | pathlib.Path, arm: str, artefacts: Artefacts | None = None) -> Any:
    """The `onnx.ModelProto` of the export's encoder of `arm` and its policy (module docstring),
    checked by `onnx.checker` with shape inference; `artefacts`: the export already loaded from
    `export_dir` (`load`), to build several arms' graphs with one read. `DpcError` when onnx is
    missing, the export does not load or has no encoder for `arm`."""
    onnx = import_onnx()
    out = pathlib.Path(export_dir)
    art = artefacts if artefacts is not None else load(out)
    path = out / sidecar.SIDECAR
    names = onnx_names(art.meta, path)
    if names["opset"] > onnx.defs.onnx_opset_version():
        raise DpcError(
            f"{path}: onnx.opset is {names['opset']}, onnx {onnx.__version__} knows up to "
            f"{onnx.defs.onnx_opset_version()}; upgrade onnx or set it to {sidecar.ONNX['opset']}."
        )
    net = _layers(art, arm, path)
    inputs, outputs = _signature(net, names, path)
    g = _Graph(onnx)
    _nodes(g, net, names["input"], names["output"])
    f32 = onnx.TensorProto.FLOAT
    n_obs = net.input_size + U_OBS_SIZE
    graph = onnx.helper.make_graph(
        g.nodes,
        f"dpc_{arm}",
        [onnx.helper.make_tensor_value_info(k, f32, ["batch", *s]) for k, s in inputs.items()],
        [onnx.helper.make_tensor_value_info(k, f32, ["batch", *s]) for k, s in outputs.items()],
        g.initializers,
    )
    opset = [onnx.helper.make_opsetid("", names["opset"])]
    measured = f" and the tick's {', '.join(onnx_arm.MEASURED)}" if net.arm_model else ""
    model = onnx.helper.make_model(
        graph,
        opset_imports=opset,
        ir_version=onnx.helper.find_min_ir_version_for(opset),
        producer_name="dpc_mjx",
        producer_version=__version__,
        doc_string=f"u ({net.frame} frame) of arm {arm!r} from its raw env observation "
        f"[s_body, s_arm, p_arm, u_obs] ({n_obs}){measured}; dpc_mjx.io.onnx_graph",
    )
    onnx.helper.set_model_props(model, _props(art.meta, arm, net, inputs, outputs))
    onnx.checker.check_model(model, full_check=True)
    return model


def _signature(net: _Layers, names: dict, path: pathlib.Path) -> tuple[dict, dict]:
    """({input name: shape after the batch axis}, {output name: shape}) of the graph; `DpcError`
    where the sidecar's names take one of the arm model's inputs."""
    inputs = {names["input"]: [net.input_size + U_OBS_SIZE]}
    outputs = {names["output"]: [net.action_size]}
    if net.arm_model is None:
        return inputs, outputs
    measured = {
        k: [net.arm_model.n if x == "n" else x for x in shape]
        for k, (shape, _) in onnx_arm.MEASURED.items()
    }
    world = f"{names['output']}_world"
    outputs[world] = [net.action_size]
    if (set(measured) | {world}) & {names["input"], names["output"]}:
        raise DpcError(
            f"{path}: onnx.input and onnx.output {names['input']!r}, {names['output']!r} take "
            f"a name of the arm model's inputs {list(measured)} (or its output "
            f"'{names['output']}_world'); rename them in the sidecar's onnx entry."
        )
    return inputs | measured, outputs


def _props(meta: dict, arm: str, net: _Layers, inputs: dict, outputs: dict) -> dict[str, str]:
    """The model's metadata_props: which export and arm, and how to read u."""
    words = {k: s for k, (_, s) in onnx_arm.MEASURED.items()}
    words[next(iter(inputs))] = "the raw env observation [s_body, s_arm, p_arm, u_obs]"
    extra = {"u_model": net.u_model} if net.base == "model" else {}
    return {
        **extra,
        "inputs": json.dumps({k: [s, words.get(k, "")] for k, s in inputs.items()}),
        "outputs": json.dumps(outputs),
        "arm": arm,
        "frame": net.frame,
        "base": net.base,
        "u_scale": json.dumps(net.scale.tolist()),
        "u": json.dumps(list(_U_NAMES)),
        "input_size": str(net.input_size + U_OBS_SIZE),
        "policy_inputs": json.dumps(list(net.inputs)),
        "export_library_version": str(meta.get("library_version")),
        "encoder_sha256": str(meta["encoders"][arm].get("sha256")),
        "policy_sha256": str(meta["policy"].get("sha256")),
    }


def write_onnx(export_dir: str | pathlib.Path, arm: str, out: str | pathlib.Path) -> pathlib.Path:
    """Write `onnx_model(export_dir, arm)` to the file `out` (atomically); returns its path."""
    model = onnx_model(export_dir, arm)
    out = pathlib.Path(out)
    write_bytes(out, model.SerializeToString())
    return out


__all__ = ["INSTALL", "import_onnx", "onnx_model", "onnx_names", "write_onnx"]
