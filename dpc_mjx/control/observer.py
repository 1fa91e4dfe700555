"""A generalized-momentum disturbance observer of the floating base: the classical estimate of the
arm's wrench u = [f_a, tau_a], with no training and no force sensor.

What it reads (what a robot measures, plus the controller's own command and nominal model):
the body state the controller reads (`state.BodyState`: COM velocity, trunk orientation and
angular velocity, foot positions), the stance ground-reaction forces the balance QP asked for at
the previous tick (`ControllerState.forces`, the QP's f; the feet have no force sensor) and the
nominal rigid-body model of the balance QP (`BalanceParams.mass` m and trunk-frame inertia I_B
about the base's COM). Same convention and reference point as `state.oracle_u`: force on
the base (trunk + legs; N) and torque about the base's COM (N·m), world frame.

Momentum (centroidal, the rigid base at its home pose; world frame)::

    p = [m v_com, I_w omega],   I_w = R I_B R^T   (kg·m/s, kg·m²/s; R trunk -> world, full R)

Newton-Euler of the floating base, with the known and the unknown wrench::

    dp/dt = F_known + F_ext
    F_known = [sum_i f_i + m g_vec,  sum_i (c_i - com) x f_i]     g_vec = (0, 0, -9.81) m/s²

f_i the ground's force on foot i (the QP's, swing feet 0), c_i its contact point (foot centre
minus the foot radius in z, the QP's lever). No gyroscopic term: for a rigid body the angular
momentum about the COM, L = I_w omega with the full (not yaw-only) I_w, obeys dL/dt = sum of
torques exactly (I_w domega/dt + omega x I_w omega = tau is the same equation), so the
omega x I_w omega term of Euler's equation belongs to d(I_w omega)/dt, not to F_known.

First-order momentum observer, discrete at the controller tick dt (4 ms), K = diag(k_force I3,
k_torque I3) in rad/s::

    r_k = K (p_k - p_0 - sum_{j=0}^{k-1} (F_known_j + r_j) dt),    r_0 = 0

kept as `predicted_k = p_0 + sum(...)` (the momentum that the known wrench and the estimate
predict; it stays near p, so float32 does not lose the sum over a long episode). F_known_j is
the wrench of the forces commanded at tick j, which act over [t_j, t_j + dt], with the lever
arms read at tick j + 1 (MJX data after a step hold the kinematics the step integrated from). In
continuous time r obeys dr/dt = K (F_ext - r): r is F_ext through a first-order low-pass of
bandwidth K, time constant 1/K (25 ms at the default 40 rad/s; 95 % of a step after
3/K = 75 ms, 99 % after 5/K = 0.125 s), with no differentiation of a velocity. The discrete
filter has the pole 1 - K dt (0.84 at the default): a monotone lag for K dt < 1, i.e.
K < 250 rad/s at the 4 ms tick.

Gain (`ObserverConfig`, default 40 rad/s on every axis). The arm's wrench is slow (a reaching
move lasts ~1 s, a push 0.2-1 s); what is not the arm is fast (touch-down and lift-off of the
trot, every 0.15 s, swing-leg reactions) and passes into r in proportion to K: on the bare A1
trotting at 0.3 m/s the estimate's ripple (std of f_z) measured 4.6, 11, 21, 34 N at K = 10,
25, 50, 100 rad/s, while its mean did not change. 40 rad/s keeps the lag (25 ms, 6 ticks) a
fortieth of a reaching move and an eighth of the shortest push, at a ripple the balance QP
tolerates when it feeds r back as u: it fell least in the 512-episode table of
docs/results-heavy-arms.md (against 20 rad/s, the default until 0.2: -0.041 [-0.068, -0.014]
falls on `z1`, -0.023 [-0.052, +0.005] on `regular`).

Delay (`ObserverConfig.delay`, ticks). With a measurement-to-torque delay of D ticks
(`EnvConfig.sensor_delay`) the forces commanded at tick j act over [t_{j+D}, t_{j+D+1}], so the
wrench that moved the momentum between ticks k-1 and k is that of the forces commanded at tick
k-1-D. An observer aligned to the delay (`delay=D`, `EnvConfig.observer_aligned`) keeps the D
forces commanded but not yet acting (`ObserverState.pending`) and integrates the one that acted;
`delay=0` integrates the forces of the previous tick whatever the env's delay (the observer
before this option: the delay is then one of the errors it sees).

Where it fails. It estimates ALL of the wrench on the base (trunk + legs) that the nominal model
does not explain, not the arm's alone, and cannot separate them: the arm's wrench, plus the model
error of the legs (their weight, which tau = J^T f does not carry: the feet push harder than asked;
their mass and inertia moving away from the home pose; swing-leg reactions), plus the difference
between the commanded and the actual foot forces (torque saturation, slipping, a foot that
touches down or lifts off off schedule, impacts), plus any other push on the body. Measured on
the bare A1 (no arm: the true u is 0), the estimate at rest is r ~ (-5, 0, +10.5 N; 0, 1.4,
0 N·m), which is the legs' weight term J^-T g_leg(q) of the stance feet to 0.1 N and 0.2 N·m;
trotting at 0.3 m/s its mean is ~ (-10, 0, +21 N; 0, 2.4, 0 N·m). With an arm, r = the arm's
wrench + this, so r's f_z is ~10 N above the oracle's standing (the legs' term is about the
arm's weight, with the opposite sign) and ~20 N above it trotting. It lags a sudden push by
~1/K. As a controller (u = r) it therefore compensates the legs' model error too, like integral
action on the balance QP's errors, which `mbc` and `oracle` do not.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from dpc_mjx.control.balance import GRAVITY, BalanceParams
from dpc_mjx.control.state import BodyState
from dpc_mjx.errors import DpcError


@struct.dataclass
class ObserverConfig:
    """Observer gains, rad/s (the bandwidth K of the estimate's first-order lag; see the module
    docstring for the choice): a number for the three axes, or an (x, y, z) tuple."""

    k_force: float | tuple[float, float, float] = 40.0  # rad/s, on [m v_com]
    k_torque: float | tuple[float, float, float] = 40.0  # rad/s, on [I_w omega]
    # ticks from a force's command to its action (see the module docstring; static: it sizes
    # `ObserverState.pending`)
    delay: int = struct.field(pytree_node=False, default=0)

    def gains(self) -> jax.Array:
        """(6,) rad/s, K's diagonal [force x, y, z, torque x, y, z]."""
        k_f = jp.broadcast_to(jp.asarray(self.k_force, jp.float32), (3,))
        k_t = jp.broadcast_to(jp.asarray(self.k_torque, jp.float32), (3,))
        return jp.concatenate([k_f, k_t])

    def validate(self, dt: float) -> None:
        """Raise `DpcError` unless every gain is in (0, 1/dt) rad/s (a stable, monotone lag) and
        the delay a whole number of ticks in [0, 10]."""
        if not (isinstance(self.delay, int) and 0 <= self.delay <= 10):
            raise DpcError(
                f"ObserverConfig.delay={self.delay!r}: use a whole number of {dt:g} s ticks in "
                "[0, 10], the env's sensor_delay to align the observer to it."
            )
        for name in ("k_force", "k_torque"):
            value = getattr(self, name)
            values = value if isinstance(value, tuple) else (value,)
            ok = (not isinstance(value, tuple) or len(value) == 3) and all(
                isinstance(v, (int, float)) and 0.0 < v < 1.0 / dt for v in values
            )
            if not ok:
                raise DpcError(
                    f"ObserverConfig.{name}={value!r}: use a number or an (x, y, z) tuple of "
                    f"gains in (0, {1.0 / dt:g}) rad/s (below 1/dt of the {dt:g} s tick; "
                    "20-50 rad/s is the useful range)."
                )


@struct.dataclass
class ObserverState:
    """One env's observer (unbatched; world frame, about the base's COM)."""

    predicted: jax.Array  # (6,) p_0 + sum_{j<k} (F_known_j + r_j) dt: [kg·m/s (3), kg·m²/s (3)]
    estimate: jax.Array  # (6,) r_k = [f (N), tau (N·m)], the estimated external wrench
    elapsed: jax.Array  # () s since the last update (0 at init: the first tick reads init's data)
    pending: jax.Array  # (delay, 4, 3) N, world: forces commanded but not yet acting, oldest first


def momentum(model: BalanceParams, s: BodyState) -> jax.Array:
    """(6,) [m v_com (kg·m/s), I_w omega (kg·m²/s)], I_w = R I_B R^T, world frame."""
    inertia_w = s.rot @ model.inertia @ s.rot.T  # (3, 3) kg·m², world, about the base's COM
    return jp.concatenate([model.mass * s.com_vel, inertia_w @ s.ang_vel])


def known_wrench(
    model: BalanceParams, s: BodyState, forces: jax.Array, foot_radius: float
) -> jax.Array:
    """(6,) [sum f_i + m g_vec (N), sum (c_i - com) x f_i (N·m)]: the modelled wrench on the base
    for ground forces `forces` (4, 3) (N, world, on the feet) at the contact points of `s`, a
    foot's sphere centre `foot_radius` (m) above its contact point."""
    contact_points = s.foot_pos.at[:, 2].add(-foot_radius)  # (4, 3) m, as the balance QP's
    weight = jp.array([0.0, 0.0, -GRAVITY]) * model.mass  # (3,) N
    force = jp.sum(forces, axis=0) + weight
    torque = jp.sum(jp.cross(contact_points - s.com_pos, forces), axis=0)
    return jp.concatenate([force, torque])


def init(config: ObserverConfig, model: BalanceParams, s: BodyState) -> ObserverState:
    """The observer at rest on the state `s`: r = 0, predicted = the measured momentum, no force
    pending (the home controls of a reset command no leg torque)."""
    return ObserverState(
        predicted=momentum(model, s),
        estimate=jp.zeros(6),
        elapsed=jp.zeros(()),
        pending=jp.zeros((config.delay, 4, 3)),
    )


def update(
    config: ObserverConfig,
    model: BalanceParams,
    ob: ObserverState,
    s: BodyState,
    forces: jax.Array,
    dt: float,
    foot_radius: float,
    also_known: jax.Array | float = 0.0,
) -> ObserverState:
    """One tick: `s` the body state read now, `forces` (4, 3) the ground forces commanded at
    the previous tick (N, world), `dt` (s) the tick, `foot_radius` (m) the base's feet's,
    `also_known` (6,) a wrench on the base the estimate leaves out (N, N·m, world, about the
    base's COM: the arms' model wrench for `feedforward_observer`; 0: none).
    r_k = K (p_k - predicted_k), see module doc; with `config.delay` D the known wrench is that
    of the forces commanded D ticks before `forces`."""
    acting, pending = forces, ob.pending
    if config.delay:  # the oldest pending forces acted over the tick just past
        acting, pending = ob.pending[0], jp.concatenate([ob.pending[1:], forces[None]])
    wrench = known_wrench(model, s, acting, foot_radius) + also_known
    predicted = ob.predicted + (wrench + ob.estimate) * ob.elapsed
    estimate = config.gains() * (momentum(model, s) - predicted)
    return ObserverState(
        predicted=predicted,
        estimate=estimate,
        elapsed=jp.full((), dt, jp.float32),
        pending=pending,
    )


__all__ = ["ObserverConfig", "ObserverState", "init", "known_wrench", "momentum", "update"]
