"""Exports: a trained DPC policy as data, msgpack files plus a JSON sidecar, never pickle (a pickle
runs code when it is loaded and ties the files to this library's classes).

An export is a folder:

    dpc.json                 the sidecar: format and library version, the observation layout,
                             sizes, action scaling, configs, per file its sha256 (`sidecar.py`)
    policy.msgpack           `PolicyState` (actor params, observation statistics)
    decoder.msgpack          `DecoderState`
    encoder_<arm>.msgpack    `EncoderState`, one per arm
    arm_model_<arm>.json     the arm's rigid-body model, one per arm, where the policy's u is
                             added to the arms' model wrench (action_scaling.base 'model')

The modules, by role:

    export.py         export, add_encoder, add_arm_models: the networks checked against each
                      other, then written; the arms' models
    load.py           load -> Artefacts: the sidecar checked against itself and every size it
                      declares against its file, then the networks restored; stale, truncated or
                      mismatched files fail with a message saying what to do
    sidecar.py        the sidecar's keys: building them, reading them
    sidecar_checks.py the sidecar's fields checked against each other and this library
    shipped.py        the shipped exports; an export's env options and evaluation cells
    serialization.py  old path of `dpc_mjx.serialization` (checked, atomic msgpack and JSON)
    inference.py      NumpyPolicy: runs an export with numpy + msgpack only (copy the file alone to
                      a robot's computer; it imports nothing else, not even this package)
    arm_dynamics.py   the arms' model wrench with numpy alone, from arm_model_<arm>.json (copy it
                      next to inference.py for an export on the arms' model wrench)
    onnx_graph.py     an export's encoder and policy as one ONNX graph (`dpc-mjx onnx`); onnx
                      imported only when a graph is built
    onnx_arm.py       the arms' model wrench as nodes of that graph, from measured inputs
"""

from dpc_mjx.envs.observations import S_BODY_NAMES
from dpc_mjx.io import serialization
from dpc_mjx.io.export import add_arm_models, add_encoder, export
from dpc_mjx.io.load import Artefacts, load
from dpc_mjx.io.sidecar import DECODER_FILE, FORMAT_VERSION, POLICY_FILE, REEXPORT, SIDECAR

__all__ = [
    "DECODER_FILE",
    "FORMAT_VERSION",
    "POLICY_FILE",
    "REEXPORT",
    "S_BODY_NAMES",
    "SIDECAR",
    "Artefacts",
    "add_arm_models",
    "add_encoder",
    "export",
    "load",
    "serialization",
]
