"""Quadruped bases, any of them, from their URDF or MJCF file: read and checked into a `BaseSpec`
(`bases.file`: trunk, legs found from the tree and placed by geometry, feet, torque limits, masses,
home pose; through `bases.urdf_tree`, `bases.mjcf_tree`, `bases.fuse`, `bases.geometry` and
`bases.measure`), described for the user to correct (`bases.describe`), and built as a MuJoCo spec
with the names the library gives every base's parts (`bases.model`). `bases.a1` keeps the A1's
numbers, the reference the other bases are scaled from. Nothing here knows an arm:
`dpc_mjx.robots.assemble` puts arms on a base.

    from dpc_mjx.robots.bases import read_base
    spec = read_base("go2")   # or "path/to/my_dog.urdf"
"""

from dpc_mjx.robots.bases.file import LEGS, NAMED_BASES, BaseSpec, read_base

__all__ = ["LEGS", "NAMED_BASES", "BaseSpec", "read_base"]
