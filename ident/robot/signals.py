"""Multi-axis signals of a robot run: the input of every n-dof estimator (ROBOT_FORMAT)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from trajectories.robot.payload import RobotPayloadData

from . import RobotIdentError


@dataclass(frozen=True)
class FullRateProducts:
    """The paper model's eq. 42 columns of every joint formed at FULL rate, then low-passed and
    decimated with the torque (:func:`ident.robot.design.products_columns`), n decimated
    samples of k joints: what the single-joint chain's ``LoadDependent`` and
    ``QuadrantCoulomb`` columns are (:mod:`ident.models`). P+_j, P-_j: the model quadrant
    (1 + sign(tau_out_hat_j dq_j)) / 2 and its complement (eq. 27-28, 44), E_j =
    exp(-|dq_j| / q_s,j) (eq. 29), all at full rate.

    Attributes
    ----------
    loads : tuple of ndarray, one per joint, shape (4, l_j + 1, n)
        Joint j's load columns w -- the standard regressor columns ``cols[j]``, then its
        known torque p_j (payload and known rotors) -- times P+, P+ E, P-, -P- E (the
        families of a_m, b_m, a_g, b_g, eq. 42-43) [N m per parameter unit].
    coulomb : ndarray, shape (4, n, k)
        P+ sign(dq), P+ E sign(dq), P- sign(dq), P- E sign(dq) (c_m, d_m, c_g, d_g).
    pplus : ndarray, shape (n, k)
        P+ itself, low-passed and decimated: 1 or 0 away from a quadrant change, fractional
        where the low-pass blends both quadrants (a row's quadrant: P+ > 1/2 motor).
    cols : tuple of ndarray of int
        Per joint, the standard columns (``RobotRegressor.standard_names`` indices) of its
        load columns: the base parameters' (``BaseParameters.columns``) not structurally
        zero in its row.
    q_s : ndarray, shape (k,)
        The q_s of E [rad/s] per joint.
    loads_z : tuple of ndarray or None
        The IDIM-IV instruments of ``loads`` (same shapes): the load columns with the
        reference trajectory's acceleration, times the same P and E; None: not formed.
    """

    loads: tuple[np.ndarray, ...]
    coulomb: np.ndarray
    pplus: np.ndarray
    cols: tuple[np.ndarray, ...]
    q_s: np.ndarray
    loads_z: tuple[np.ndarray, ...] | None = None

    def check(self, n: int, k: int, source: str) -> None:
        """Raise :class:`RobotIdentError` unless the shapes fit n samples of k joints."""
        shapes = {"coulomb": (4, n, k), "pplus": (n, k), "q_s": (k,)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise RobotIdentError(f"{source}: columns.products.{name} has shape "
                                      f"{np.shape(getattr(self, name))}, expected {shape}")
        if len(self.loads) != k or len(self.cols) != k:
            raise RobotIdentError(f"{source}: columns.products has {len(self.loads)} load "
                                  f"blocks and {len(self.cols)} column lists, expected {k}")
        for name in ("loads", "loads_z"):
            blocks = getattr(self, name)
            if blocks is None:
                continue
            if len(blocks) != k:
                raise RobotIdentError(f"{source}: columns.products.{name} has {len(blocks)} "
                                      f"blocks, expected {k}")
            for j, (a, c) in enumerate(zip(blocks, self.cols, strict=True)):
                if np.shape(a) != (4, len(c) + 1, n):
                    raise RobotIdentError(f"{source}: columns.products.{name}[{j}] has "
                                          f"shape {np.shape(a)}, expected "
                                          f"(4, {len(c) + 1}, {n})")

    def take(self, rows: slice | np.ndarray) -> FullRateProducts:
        """The decimated samples ``rows`` (a chunk)."""
        return FullRateProducts(tuple(a[:, :, rows] for a in self.loads),
                                self.coulomb[:, rows], self.pplus[rows], self.cols, self.q_s,
                                None if self.loads_z is None else
                                tuple(a[:, :, rows] for a in self.loads_z))


class ProductsTooLarge(RobotIdentError):
    """The full-rate products of a run need more than ``ident.robot.design.MAX_BYTES``
    (:func:`ident.robot.design.products_columns`): the bilinear paper fit then reads the
    decimated columns (``RobotModel(full_rate=True)``, one warning)."""


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
    products : FullRateProducts or None
        The paper model's quadrant and E products formed at full rate
        (:func:`ident.robot.design.products_columns`), read by
        ``RobotModel(model="paper", form="products")``; None: that form weights the
        decimated columns by P and E of the decimated samples.
    full : tuple of ident.chain.FullRate, or None
        The chain's full-rate signals of each run (filtered q, dq, ddq, low-passed tau,
        reference), kept when :func:`ident.robot.design.design_runs` is asked to
        (``keep_full``): the sign check, the full-rate products and another model's design
        on the same samples (:func:`ident.preprocess.design_on_full_rate`) then read them
        instead of filtering the runs again. Memory: about 7 n_f k floats per run.
    full_columns : ident.robot.design.FullRateColumns or None
        With ``full``: per run, the full-rate regressor and known torque the chain
        evaluated, kept within a memory bound, so that the load prediction and the full-rate
        products do not evaluate them again.
    source : ident.robot.design.FullRateSource or None
        The runs and settings that built these columns (:func:`ident.robot.design.
        design_runs`): the bilinear paper model forms its products at full rate from them,
        at its own q_s and quadrants (``RobotModel(full_rate=True)``).
    """

    W: np.ndarray
    p: np.ndarray
    sign: np.ndarray
    keep: np.ndarray
    Wz: np.ndarray | None = None
    pz: np.ndarray | None = None
    products: FullRateProducts | None = None
    full: tuple | None = None
    full_columns: Any = None
    source: Any = None

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
        if self.products is not None:
            self.products.check(n, k, source)


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
    sign : ndarray, shape (n, k), optional
        sign(dq) computed at full rate and decimated with the torque (the Coulomb column, as
        ``RobotColumns.sign``; the states chain forms it): the estimators' Coulomb column
        when they build the regressor from the states. None: sign of the decimated dq,
        which near a reversal is a step where the decimated torque's Coulomb part is the
        low-pass of one (a bias on the Coulomb parameter, docs/robot-data.md).
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
    sign: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).reshape(-1)
        n, k = t.size, len(self.joints)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "joints", tuple(self.joints))
        for name in ("q", "dq", "ddq", "tau") + tuple(
                o for o in ("q_ref", "sign") if getattr(self, o) is not None):
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
