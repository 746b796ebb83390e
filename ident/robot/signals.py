"""Multi-axis signals of a robot run: the input of every n-dof estimator (ROBOT_FORMAT)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectories.robot.payload import RobotPayloadData

from . import RobotIdentError


@dataclass(frozen=True)
class RobotColumns:
    """Regressor columns filtered and decimated in parallel with the torque (the single-joint
    chain, :func:`ident.robot.design.design_runs`), n decimated samples of k joints.

    Attributes
    ----------
    W : ndarray, shape (k, p, n)
        Standard rigid-body regressor (``RobotRegressor.rigid_kpn`` layout: joint, standard
        parameter, sample) computed at full rate on the filtered states, then decimated.
    p : ndarray, shape (n, k)
        Known torque of the sample's experiment [N m]: the payload's, plus the known rotors'
        Ia_j ddq_j with ``RobotRegressor(known_rotor_inertia=True)``; computed and decimated
        alike.
    sign : ndarray, shape (n, k)
        sign(dq) computed at full rate, decimated (the Coulomb column, eq. 5).
    keep : ndarray of bool, shape (n, k)
        Rows of joint j outside the stiction area (|dq_j| >= dq_min at full rate, dilated by
        the guard) and away from the experiment's edges.
    Wz, pz : ndarray or None
        The same with the reference trajectory's acceleration (IDIM-IV instruments).
    """

    W: np.ndarray
    p: np.ndarray
    sign: np.ndarray
    keep: np.ndarray
    Wz: np.ndarray | None = None
    pz: np.ndarray | None = None

    def check(self, n: int, k: int, source: str) -> None:
        """Raise :class:`RobotIdentError` unless the shapes fit n samples of k joints."""
        shapes = {"p": (n, k), "sign": (n, k), "keep": (n, k)}
        if self.pz is not None:
            shapes["pz"] = (n, k)
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise RobotIdentError(f"{source}: columns.{name} has shape "
                                      f"{np.shape(getattr(self, name))}, expected {shape}")
        for name in ("W", "Wz"):
            a = getattr(self, name)
            if a is not None and (np.ndim(a) != 3 or np.shape(a)[0] != k
                                  or np.shape(a)[2] != n):
                raise RobotIdentError(f"{source}: columns.{name} has shape {np.shape(a)}, "
                                      f"expected ({k}, p, {n})")


@dataclass(frozen=True)
class RobotSignals:
    """Joint-side signals of the k moving joints of a robot, n samples.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time [s], increasing within each experiment.
    q, dq, ddq : ndarray, shape (n, k)
        Position [rad or m], velocity [rad/s], acceleration [rad/s^2] (filtered).
    tau : ndarray, shape (n, k)
        Joint-side torque [N m] (force [N] for a prismatic joint).
    joints : tuple of str
        Names of the k moving joints, in column order (the robot file's names).
    experiment : ndarray of int, shape (n,)
        Index of the experiment (run) of each sample, into ``payloads``.
    payloads : tuple of RobotPayloadData
        Known payload of each experiment (empty payload = none).
    q_ref : ndarray, shape (n, k), optional
        Reference trajectory (IV instruments), or None.
    source : str
        Where the signals come from (file names), for messages.
    columns : RobotColumns or None
        Regressor columns filtered and decimated in parallel with the torque (the
        single-joint chain); None: the estimators build the regressor from q, dq, ddq.
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray
    joints: tuple[str, ...]
    experiment: np.ndarray | None = None
    payloads: tuple[RobotPayloadData, ...] = ()
    q_ref: np.ndarray | None = None
    source: str = ""
    columns: RobotColumns | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).reshape(-1)
        n, k = t.size, len(self.joints)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "joints", tuple(self.joints))
        for name in ("q", "dq", "ddq", "tau") + (("q_ref",) if self.q_ref is not None else ()):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.ndim == 1 and k == 1:
                a = a[:, None]
            if a.shape != (n, k):
                raise RobotIdentError(f"{self.source or 'RobotSignals'}: {name} has shape "
                                      f"{a.shape}, expected ({n}, {k}) for joints {self.joints}")
            object.__setattr__(self, name, a)
        e = np.zeros(n, dtype=int) if self.experiment is None else np.asarray(
            self.experiment, dtype=int).reshape(-1)
        if e.shape != (n,):
            raise RobotIdentError(f"{self.source or 'RobotSignals'}: experiment has shape "
                                  f"{e.shape}, expected ({n},)")
        object.__setattr__(self, "experiment", e)
        pays = tuple(self.payloads) or (RobotPayloadData(),) * (int(e.max()) + 1 if n else 1)
        if n and int(e.max()) >= len(pays):
            raise RobotIdentError(f"{self.source or 'RobotSignals'}: experiment index "
                                  f"{int(e.max())} has no payload (got {len(pays)})")
        object.__setattr__(self, "payloads", pays)
        if self.columns is not None:
            self.columns.check(n, k, self.source or "RobotSignals")

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def k(self) -> int:
        """Number of moving joints."""
        return len(self.joints)
