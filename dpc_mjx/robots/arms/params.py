"""Continuous arm parameters on a batched `mjx.Model`: one compile covers a grid of arms.

Structure (number and kind of arms) is fixed by `dpc_mjx.robots.build`; continuous values of a
parametric `ArmSpec` arm (upper-arm length, gripper/payload mass) are written into the fields of
an `mjx.Model` here, batched along a leading axis, with the `in_axes` tree that tells `jax.vmap`
which fields carry that axis:

    mx, in_axes = batch_arm_params(mjx.put_model(model), model, upper_arm_length=[0.14, 0.28],
                                   gripper_mass=[0.1, 0.5])
    step = jax.jit(jax.vmap(mjx.step, in_axes=(in_axes, 0)))

Not updated: the compile-time constants `body_invweight0`/`dof_invweight0` (constraint
regularisation scales), which change by well under 1% for these parameters.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import mjx

from dpc_mjx.errors import DpcError
from dpc_mjx.robots.arms.mount import arm_prefix
from dpc_mjx.robots.arms.parametric import rod_inertia


@dataclasses.dataclass(frozen=True)
class ArmParamIndex:
    """Ids of the fields a parametric arm's continuous parameters live in."""

    upper_arm: int  # body id; link along its +z, COM at L/2
    forearm: int  # body id, placed at (0, 0, L) in the upper arm
    gripper: int  # palm body id
    finger: int  # finger body id
    upper_arm_geom: int  # capsule from (0,0,0) to (0,0,L)
    palm_chain: np.ndarray  # (nbody,) 1.0 for the palm and its ancestors, else 0.0
    finger_chain: np.ndarray  # (nbody,) same for the finger


def arm_param_index(model: mujoco.MjModel, arm: int = 0) -> ArmParamIndex:
    """Field ids of parametric arm number `arm` of a compiled variant."""
    p = arm_prefix(arm)
    try:
        ids = {n: model.body(p + n).id for n in ("upper_arm", "forearm", "gripper", "finger")}
        geom = model.geom(p + "upper_arm").id
    except KeyError as e:
        raise DpcError(
            f"Arm {arm} of this model is not a parametric ArmSpec arm (missing {e}); "
            "continuous parameters exist only for ArmSpec arms, e.g. variants regular/longer/"
            "heavier/double."
        ) from e
    return ArmParamIndex(
        upper_arm=ids["upper_arm"],
        forearm=ids["forearm"],
        gripper=ids["gripper"],
        finger=ids["finger"],
        upper_arm_geom=geom,
        palm_chain=_chain(model, ids["gripper"]),
        finger_chain=_chain(model, ids["finger"]),
    )


def _chain(model: mujoco.MjModel, body: int) -> np.ndarray:
    mask = np.zeros(model.nbody)
    while True:
        mask[body] = 1.0
        if body == 0:
            return mask
        body = int(model.body_parentid[body])


def arm_param_fields(
    mx: mjx.Model, idx: ArmParamIndex, upper_arm_length: jax.Array, gripper_mass: jax.Array
) -> dict[str, jax.Array]:
    """Model fields (unbatched) of one arm with upper-arm length (m) and gripper mass (kg).

    The gripper mass is split between palm and finger in the compiled ratio, each inertia scaled
    with its mass; the upper arm keeps its mass and radius, its inertia follows the rod formula the
    model was compiled with (`arms.rod_inertia`).
    """
    length = jp.asarray(upper_arm_length, jp.float32)
    mass = jp.asarray(gripper_mass, jp.float32)
    ua, g = idx.upper_arm, idx.upper_arm_geom
    radius = mx.geom_size[g, 0]

    body_pos = mx.body_pos.at[idx.forearm].set(jp.array([0.0, 0.0, 1.0]) * length)
    body_ipos = mx.body_ipos.at[ua].set(jp.array([0.0, 0.0, 0.5]) * length)
    body_inertia = mx.body_inertia.at[ua].set(
        jp.stack(rod_inertia(mx.body_mass[ua], length, radius, 2))
    )
    geom_pos = mx.geom_pos.at[g].set(jp.array([0.0, 0.0, 0.5]) * length)
    geom_size = mx.geom_size.at[g, 1].set(0.5 * length)
    geom_rbound = mx.geom_rbound.at[g].set(0.5 * length + radius)

    old = mx.body_mass[idx.gripper] + mx.body_mass[idx.finger]
    scale = mass / old
    new_palm, new_finger = mx.body_mass[idx.gripper] * scale, mx.body_mass[idx.finger] * scale
    body_mass = mx.body_mass.at[idx.gripper].set(new_palm).at[idx.finger].set(new_finger)
    body_inertia = body_inertia.at[idx.gripper].multiply(scale).at[idx.finger].multiply(scale)
    subtree = (
        mx.body_subtreemass
        + (new_palm - mx.body_mass[idx.gripper]) * idx.palm_chain
        + (new_finger - mx.body_mass[idx.finger]) * idx.finger_chain
    )
    return {
        "body_pos": body_pos,
        "body_ipos": body_ipos,
        "body_inertia": body_inertia,
        "body_mass": body_mass,
        "body_subtreemass": subtree,
        "geom_pos": geom_pos,
        "geom_size": geom_size,
        "geom_rbound": geom_rbound,
    }


def batch_arm_params(
    mx: mjx.Model,
    model: mujoco.MjModel,
    *,
    upper_arm_length,
    gripper_mass,
    arm: int = 0,
) -> tuple[mjx.Model, mjx.Model]:
    """A batched model over (B,) upper-arm lengths (m) and gripper masses (kg), and its in_axes.

    Both arrays must have the same length B; repeat a value to keep it fixed.
    """
    lengths = np.asarray(upper_arm_length, np.float32).reshape(-1)
    masses = np.asarray(gripper_mass, np.float32).reshape(-1)
    if lengths.shape != masses.shape:
        raise DpcError(
            f"upper_arm_length has {lengths.size} values and gripper_mass {masses.size}; "
            "give one value of each per batch element."
        )
    for name, v in (("upper_arm_length", lengths), ("gripper_mass", masses)):
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise DpcError(f"{name} must be positive and finite, got {v}.")
    idx = arm_param_index(model, arm)
    fields = jax.vmap(lambda L, m: arm_param_fields(mx, idx, L, m))(lengths, masses)
    batched = mx.tree_replace(fields)
    in_axes = jax.tree.map(lambda _: None, mx).tree_replace({k: 0 for k in fields})
    return batched, in_axes
