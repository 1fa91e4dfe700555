"""Low-level control: the balance QP (`balance`) and a small dense QP solver (`qp`)."""

from dpc_mjx.control.balance import (
    BalanceParams,
    BalanceQP,
    build_balance_qp,
    default_params,
    solve_balance,
)
from dpc_mjx.control.qp import QPResult, QPSettings, solve

__all__ = [
    "BalanceParams",
    "BalanceQP",
    "QPResult",
    "QPSettings",
    "build_balance_qp",
    "default_params",
    "solve",
    "solve_balance",
]
