"""A pinocchio stand-in for ``ident.robot.regressor.RobotRegressor`` and
``ident.robot.base.base_parameters`` (ROBOT_FORMAT interface), for the estimator tests.

``PinRegressor(model)``: pinocchio's joint-torque regressor, columns reordered to ROBOT_FORMAT
(XX XY XZ YY YZ ZZ MX MY MZ M per link, then Ia per joint); ``PinBase``: numerical base
parameters by pivoted QR of the regressor on random states (Gautier 1991).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import scipy.linalg

# pinocchio order [m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] -> XX XY XZ YY YZ ZZ MX MY MZ M
_PIN_TO_STD = [4, 5, 7, 6, 8, 9, 1, 2, 3, 0]
_STD = ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M")


class PinRegressor:
    """Rigid body + rotor regressor of a serial pinocchio model (all joints moving)."""

    def __init__(self, model: pin.Model, gravity=None, numbers=None) -> None:
        self.model = pin.Model(model)
        self.model.armature = np.zeros(self.model.nv)
        if gravity is not None:
            self.model.gravity = pin.Motion(np.asarray(gravity, float), np.zeros(3))
        self.data = self.model.createData()
        k = self.model.nv
        self.joints = tuple(self.model.names[1:])
        self.numbers = tuple(numbers) if numbers is not None else tuple(range(1, k + 1))
        self.standard_names = tuple(f"{n}{j}" for j in self.numbers for n in _STD) + tuple(
            f"Ia{j}" for j in self.numbers)
        idx = []
        for j in range(k):
            idx += [10 * j + c for c in _PIN_TO_STD]
        self._order = np.array(idx)

    def rigid(self, q, dq, ddq) -> np.ndarray:
        q, dq, ddq = (np.atleast_2d(np.asarray(a, float)) for a in (q, dq, ddq))
        n, k = q.shape
        out = np.zeros((n, k, 11 * k))
        m, d = self.model, self.data
        for i in range(n):
            Y = pin.computeJointTorqueRegressor(m, d, q[i], dq[i], ddq[i])
            out[i, :, :10 * k] = Y[:, self._order]
        for j in range(k):
            out[:, j, 10 * k + j] = ddq[:, j]
        return out

    def payload_torque(self, q, dq, ddq, payload) -> np.ndarray:
        q, dq, ddq = (np.atleast_2d(np.asarray(a, float)) for a in (q, dq, ddq))
        n, k = q.shape
        xx, xy, xz, yy, yz, zz = payload.inertia
        inertia = pin.Inertia(payload.mass, np.asarray(payload.com, float),
                              np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
        dyn = inertia.toDynamicParameters()
        out = np.empty((n, k))
        m, d = self.model, self.data
        for i in range(n):
            Y = pin.computeJointTorqueRegressor(m, d, q[i], dq[i], ddq[i])
            out[i] = Y[:, 10 * (k - 1):] @ dyn
        return out


class PinBase:
    """Base parameters: ``names``, ``columns``, ``beta`` (p_b x p), ``reduce(W)``."""

    def __init__(self, reg: PinRegressor, seed: int = 0, n: int = 200) -> None:
        rng = np.random.default_rng(seed)
        k = len(reg.joints)
        W = reg.rigid(rng.uniform(-np.pi, np.pi, (n, k)), rng.normal(size=(n, k)),
                      rng.normal(size=(n, k))).reshape(n * k, -1)
        norms = np.linalg.norm(W, axis=0)
        nz = np.flatnonzero(norms > 1e-10 * norms.max())
        Ws = W[:, nz] / norms[nz]
        _, R, piv = scipy.linalg.qr(Ws, mode="economic", pivoting=True)
        dR = np.abs(np.diag(R))
        r = int(np.sum(dR > 1e-8 * dR[0]))
        cols = np.sort(nz[piv[:r]])
        others = np.setdiff1d(np.arange(W.shape[1]), cols)
        K = np.linalg.lstsq(W[:, cols], W[:, others], rcond=None)[0]
        K[np.abs(K) < 1e-10] = 0.0
        beta = np.zeros((r, W.shape[1]))
        beta[:, cols] = np.eye(r)
        beta[:, others] = K
        self.columns = cols
        self.beta = beta
        names = []
        for i, c in enumerate(cols):
            regrouped = np.any(K[i] != 0)
            names.append(reg.standard_names[c] + ("R" if regrouped else ""))
        self.names = tuple(names)

    def reduce(self, W: np.ndarray) -> np.ndarray:
        return W[..., self.columns]
