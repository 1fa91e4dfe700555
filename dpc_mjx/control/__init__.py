"""Low-level control (paper §III-D), one module per role:

  controller.py   the low-level controller: one tick from state, command and disturbance u
  gait.py         which feet are in stance, and each swing's progress
  state.py        the body state read from MJX data
  balance.py      the balance QP of the stance forces (model, cost, friction constraints)
  static_balance.py  can the A1 hold an arm up: standing still, with the QP's constraints
  observer.py     the momentum disturbance observer: u estimated without training or force sensor
  qp/             the batched interior-point QP solver (its __init__ lists its parts)
  swing.py        footholds, swing trajectories and the swing-foot PD
  closed_loop.py  the controller alone on MJX physics, with locomotion metrics

Rotations (yaw, rotation vectors, skew matrices) are in `dpc_mjx.rotations`.
docs/decisions-controller.md explains the choices.
"""

from dpc_mjx.control import closed_loop, observer
from dpc_mjx.control.balance import (
    BalanceParams,
    BalanceQP,
    build_balance_qp,
    default_params,
    solve_balance,
)
from dpc_mjx.control.controller import ControllerState, LowLevelController, make_controller
from dpc_mjx.control.gait import stand, trot
from dpc_mjx.control.observer import ObserverConfig
from dpc_mjx.control.qp import QPResult, QPSettings, solve
from dpc_mjx.control.state import has_fallen, oracle_u

__all__ = [
    "BalanceParams",
    "BalanceQP",
    "ControllerState",
    "LowLevelController",
    "ObserverConfig",
    "QPResult",
    "QPSettings",
    "build_balance_qp",
    "closed_loop",
    "default_params",
    "has_fallen",
    "make_controller",
    "observer",
    "oracle_u",
    "solve",
    "solve_balance",
    "stand",
    "trot",
]
