"""The controllers the library compares, one name each: `Controller`, a `StrEnum`.

Each picks the u (the arm's wrench on the base, [f (N), tau (N·m)] about its COM) that the
low-level controller compensates for (`DpcEnv.controller_u`, `run.eval`, `deploy`, the CLI):

    mbc                  u = 0: the model-based controller alone
    observer             u = the momentum observer's estimate (`control/observer.py`; no
                         training, no sensor)
    feedforward          u = the arms' model wrench: their inverse dynamics from their file and
                         the measured joint and trunk states (`control/arm_estimate.py`)
    feedforward_observer u = the arms' model wrench + the observer's estimate of what the
                         model leaves (pushes, payload, model error)
    dpc                  u from the trained policy acting on [s_body, z] (the env's action,
                         scaled), added to `EnvConfig.u_base`
    oracle               u = the measured arm-mount wrench (simulation only: no robot has the
                         sensor)

Members are strings (`Controller.DPC == "dpc"`), so plain strings work wherever a controller is
asked for; `Controller.parse` (and `Controller(...)`) also takes 'policy', the env's name for
'dpc' before this enum existed (the `env_config.controller` of exports written before it).
"""

from __future__ import annotations

import enum
from collections.abc import Iterable

from dpc_mjx.errors import DpcError


class Controller(enum.StrEnum):
    """A controller by name; iteration order is the tables' (MBC, the classical ones, DPC,
    the oracle)."""

    MBC = "mbc"
    OBSERVER = "observer"
    FEEDFORWARD = "feedforward"
    FEEDFORWARD_OBSERVER = "feedforward_observer"
    DPC = "dpc"
    ORACLE = "oracle"

    @classmethod
    def _missing_(cls, value: object) -> Controller | None:
        return ALIASES.get(value) if isinstance(value, str) else None

    @classmethod
    def parse(cls, value: str | Controller) -> Controller:
        """The member named `value` (a member, its string, or an alias in `ALIASES`); a
        `DpcError` naming the valid names otherwise."""
        try:
            return cls(value)
        except ValueError:
            raise DpcError(
                f"Unknown controller {value!r}; choose one of {[c.value for c in cls]} "
                f"(or {sorted(ALIASES)} for 'dpc')."
            ) from None

    @property
    def index(self) -> int:
        """Its place in the tables' order (0 MBC .. 5 oracle): the per-env controller of a mixed
        batch (`envs.controller_batch`) as an integer a compiled program can select by."""
        return list(Controller).index(self)

    def adds(self, u_base: str = "zero") -> tuple[bool, bool]:
        """(the observer's estimate, the arms' model wrench): what the low-level controller adds
        to this controller's u (`LowLevelController.step`); DPC's by its `u_base` ('observer',
        'model'; 'zero' and 'gravity' add nothing there)."""
        if self is Controller.DPC:
            return u_base == "observer", u_base == "model"
        return _ADDS.get(self, (False, False))

    @classmethod
    def parse_all(cls, values: Iterable[str | Controller]) -> tuple[Controller, ...]:
        """`parse` of each of `values`, in their order."""
        return tuple(cls.parse(v) for v in values)


_ADDS = {  # (adds the observer's estimate, adds the arms' model wrench), as `Controller.adds`
    Controller.OBSERVER: (True, False),
    Controller.FEEDFORWARD: (False, True),
    Controller.FEEDFORWARD_OBSERVER: (True, True),
}

# Older names of a controller: 'policy' is what `EnvConfig.controller` called DPC
ALIASES: dict[str, Controller] = {"policy": Controller.DPC}
