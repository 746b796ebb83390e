"""The base parameters of a robot with one moving joint as today's single-joint model
(eq. 31: :func:`single_joint_map`), and a single-joint log's lever-arm payload placed on that
robot (:func:`lever_arm_payload`, :func:`placed_payload`).

The base-parameter rule itself (``base_parameters``, ``qr_rule``, ``payload_base``, ...) is the
robot model's, :mod:`trajectories.robot.base`, re-exported here for the callers that import it
from :mod:`ident.robot.base`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectories import RobotError
from trajectories.robot.base import (  # noqa: F401 (re-exported)
    DEFAULT_RTOL,
    PAYLOAD_NAMES,
    BaseParameters,
    PayloadBase,
    _format,
    base_parameters,
    independent_columns,
    payload_base,
    qr_rule,
    random_states,
)
from trajectories.robot.payload import RobotPayloadData
from trajectories.robot.regressor import RobotRegressor

from ..signals import G
from . import RobotIdentError

__all__ = ["BaseParameters", "base_parameters", "qr_rule", "SingleJointMap", "single_joint_map",
           "lever_arm_payload", "placed_payload", "PayloadBase", "payload_base",
           "PAYLOAD_NAMES", "DEFAULT_RTOL"]


# --------------------------------------------------------------------------- 1-dof mapping
@dataclass(frozen=True, eq=False)
class SingleJointMap:
    """Base parameters of a one-joint robot -> today's single-joint model (eq. 31).

    Attributes
    ----------
    names : tuple of str
        ``("J", "MX", "MY")`` (revolute) or ``("J",)`` (prismatic), then ``("F_C", "F_V",
        "tau_off")`` when the base parameters include friction.
    matrix : ndarray, shape (len(names), p_b)
        chi_single = matrix @ chi_b.
    expressions : tuple of str
        e.g. ``"J = ZZ3R"``, ``"MX = -MY3"``.
    residual : float
        Largest relative residual of ``W_b = W_single matrix`` at random states (same
        column space when ~1e-12).
    """

    names: tuple[str, ...]
    matrix: np.ndarray
    expressions: tuple[str, ...]
    residual: float

    def values(self, base_values: np.ndarray) -> dict[str, float]:
        """Single-joint parameter values from base parameter values (p_b,)."""
        v = self.matrix @ np.asarray(base_values, dtype=float)
        return dict(zip(self.names, (float(x) for x in v), strict=True))


def single_joint_map(base: BaseParameters, regressor: RobotRegressor,
                     seed: int = 0) -> SingleJointMap:
    """Express the base parameters of a robot with one moving joint as the single-joint
    model of :mod:`ident.models` (eq. 31, ``RigidBody``: J ddq + MX g cos q + MY g sin q,
    g = 9.81; usual friction F_C, F_V, tau_off).

    The gravity columns of the robot rotate with the locked joints; the map is the least
    squares fit ``W_b = W_single T`` at random states (exact when the column spaces agree,
    see ``residual``), e.g. RX130L joint 3: ``J = ZZ3R`` (ZZ3 + Ia3), ``MX = -MY3``.

    Raises
    ------
    RobotIdentError
        More than one moving joint, or the column spaces differ (gravity not of magnitude
        9.81 m/s^2, or a base parameter the single-joint model lacks).
    """
    if regressor.k != 1:
        raise RobotIdentError(f"single_joint_map: expected one moving joint, got "
                              f"{regressor.joints}")
    rev = regressor.revolute[0]
    q, dq, ddq = random_states(regressor, None, max(60, 6 * base.p_b), seed)
    W = regressor.rigid(q, dq, ddq)[:, 0, :]
    friction = len(base.standard_names) > regressor.p
    if friction:
        W = np.concatenate([W, regressor.friction(dq)[:, 0, :]], axis=-1)
    Wb = base.reduce(W)
    cols = [ddq[:, 0]] + ([G * np.cos(q[:, 0]), G * np.sin(q[:, 0])] if rev else [])
    names = ["J"] + (["MX", "MY"] if rev else [])
    if friction:
        cols += [np.sign(dq[:, 0]), dq[:, 0], np.ones_like(dq[:, 0])]
        names += ["F_C", "F_V", "tau_off"]
    S = np.column_stack(cols)
    T, *_ = np.linalg.lstsq(S, Wb, rcond=None)  # Wb = S T
    res = float(np.abs(S @ T - Wb).max() / max(np.abs(Wb).max(), 1e-300))
    if res > 1e-8:
        raise RobotIdentError(f"single_joint_map: the base regressor of {regressor.joints} "
                              f"is not in the span of the single-joint columns {names} "
                              f"(relative residual {res:.2g})")
    T[np.abs(T) < 1e-10] = 0.0
    exprs = []
    for i, nm in enumerate(names):
        terms = []
        for b in np.flatnonzero(T[i]):
            c = T[i, b]
            sign = "-" if c < 0 else "+"
            mag = "" if abs(abs(c) - 1) < 1e-9 else f"{_format(abs(c))}*"
            terms.append(f"{sign} {mag}{base.names[b]}")
        if terms:
            terms[0] = terms[0].removeprefix("+ ").replace("- ", "-", 1)
        text = " ".join(terms) if terms else "0"
        exprs.append(f"{nm} = {text}")
    return SingleJointMap(tuple(names), T, tuple(exprs), res)


def lever_arm_payload(payload: RobotPayloadData, regressor: RobotRegressor,
                      base: BaseParameters, smap: SingleJointMap | None = None
                      ) -> RobotPayloadData:
    """Place a single-joint log's payload (mass M_a at lever arm L_a, eq. 34-35) on a robot
    with one moving revolute joint: the point mass in the flange frame whose base parameters
    add ``M_a L_a^2`` to J, ``M_a L_a`` to MX and nothing to MY of :func:`single_joint_map`.

    Parameters
    ----------
    payload : RobotPayloadData
        Returned unchanged when ``payload.arm_m`` is None.
    regressor, base
        The one-joint robot and its base parameters.
    smap : SingleJointMap, optional
        ``single_joint_map(base, regressor)`` (computed when not given).

    Returns
    -------
    RobotPayloadData
        Same mass, ``com`` [m] in the flange frame, no inertia about the CoM, ``arm_m`` None.

    Raises
    ------
    RobotIdentError
        More than one moving joint (the arm has no direction there), a prismatic joint, or no
        point mass gives the single-joint payload columns.
    """
    if payload.arm_m is None:
        return payload
    if regressor.k != 1:
        raise RobotIdentError(f"payload of {payload.mass} kg with a single-joint lever arm "
                              f"(arm_m = {payload.arm_m} m): on {regressor.k} moving joints "
                              "the arm has no direction; give the payload's CoM in the flange "
                              "frame (metadata payload.com_m)")
    smap = single_joint_map(base, regressor) if smap is None else smap
    if smap.names[:3] != ("J", "MX", "MY"):
        raise RobotIdentError(f"payload lever arm (arm_m = {payload.arm_m} m): joint "
                              f"{regressor.joints[0]} is not revolute")
    m, arm = payload.mass, payload.arm_m
    if m == 0.0:
        return RobotPayloadData()
    n_std = len(base.standard_names)

    def single(c: np.ndarray) -> np.ndarray:
        chi = np.zeros(n_std)  # the one moving link's XX..M come first
        chi[:10] = regressor.payload_parameters(RobotPayloadData(m, c))
        return smap.matrix[:3] @ base.values(chi)  # (J, MX, MY) of the point mass at c

    f0 = single(np.zeros(3))
    A = np.column_stack([single(e)[1:] - f0[1:] for e in np.eye(3)])
    com, *_ = np.linalg.lstsq(A, np.array([m * arm, 0.0]) - f0[1:], rcond=None)
    got = single(com)
    want = np.array([m * arm**2, m * arm, 0.0])
    if not np.allclose(got, want, rtol=1e-9, atol=1e-9 * max(1.0, float(np.abs(want).max()))):
        raise RobotIdentError(f"payload lever arm (arm_m = {arm} m): no point mass on the "
                              f"flange of {regressor.joints[0]} adds (J, MX, MY) = "
                              f"{tuple(want)}")
    return RobotPayloadData(m, com)


def placed_payload(payload: RobotPayloadData, regressor: RobotRegressor,
                   base: BaseParameters | None, source: str,
                   cache: dict[tuple[float, float], RobotPayloadData]) -> RobotPayloadData:
    """``payload`` placed by :func:`lever_arm_payload` when it is a single-joint log's lever
    arm (else unchanged), cached in ``cache`` by (mass, lever arm); ``base`` None:
    ``base_parameters(regressor)``, computed only then. Errors name ``source``."""
    if payload.arm_m is None:
        return payload
    key = (payload.mass, payload.arm_m)
    if key not in cache:
        try:
            cache[key] = lever_arm_payload(payload, regressor, base if base is not None
                                           else base_parameters(regressor))
        except (RobotIdentError, RobotError) as err:
            raise RobotIdentError(f"{source}: {err}") from None
    return cache[key]
