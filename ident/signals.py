"""The sampled signals every regressor term reads (pure data, no I/O)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from . import OutputLeakError

G = 9.81  # [m/s^2] gravity, as in the paper (section IV.A)


class _HiddenOutput:
    """Stands for the measured torque in :meth:`Signals.states`: any use raises
    :class:`~ident.OutputLeakError` (arithmetic, numpy ufuncs and conversions alike)."""

    def _leak(self, *_a, **_k):
        raise OutputLeakError(
            "a candidate read the measured torque tau: candidate terms, variables and bases "
            "must be functions of the states and of the model's own prediction")

    __array_ufunc__ = __array_function__ = _leak  # numpy ufuncs and functions
    __array__ = __getitem__ = __len__ = __iter__ = __float__ = __bool__ = _leak
    __add__ = __radd__ = __sub__ = __rsub__ = __mul__ = __rmul__ = _leak
    __truediv__ = __rtruediv__ = __pow__ = __neg__ = __abs__ = _leak
    __lt__ = __le__ = __gt__ = __ge__ = _leak

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        self._leak()

    def __repr__(self) -> str:
        return "<measured torque hidden>"


#: The placeholder of the measured torque in a states-only view (:meth:`Signals.states`).
HIDDEN_OUTPUT = _HiddenOutput()


@dataclass(frozen=True)
class Signals:
    """Aligned samples of one or more concatenated experiments (paper eq. 36-37).

    All arrays have shape ``(n,)``. Positions, velocities and torques are joint-side SI.

    Attributes
    ----------
    t : ndarray
        Time since the start of the sample's own run [s] (restarts for each experiment).
    q, dq, ddq : ndarray
        Position [rad or m], velocity [rad/s or m/s], acceleration [rad/s^2 or m/s^2].
    tau : ndarray
        Motor torque from the current reference, tau = g_f v_f (eq. 7) [N m or N].
    payload_mass : ndarray
        Weighed additional mass M_aw of the sample's experiment [kg] (0 without payload).
    payload_arm : ndarray
        Lever arm L_a of the additional mass [m].
    experiment : ndarray of int
        Index of the experiment (input file / payload run) each sample comes from.
    revolute : bool
        Revolute joints have gravity terms g cos q, g sin q; prismatic joints have none.
    dtau : ndarray or None
        Time derivative of ``tau`` [N m/s], when a term needs it (torque lag).
    extra : dict of str to ndarray, or None
        Other continuous variables of the same samples, by name, e.g. the other joints'
        positions and velocities of a robot (``q2``, ``dq2``: :mod:`ident.robot.refine_joint`).
        They follow every row selection (:meth:`take`, :func:`ident.preprocess.build_design`)
        and the refinement's library search may build a term in them
        (:class:`ident.library_search.LibraryTerm`, docs/refinement.md "Cross-joint effects").
    quadrant : ndarray or None
        sign(P_out) decided by a model of the load, sign(τ̂_out q̇) (set by
        :func:`ident.preprocess.build_design` when it is given a ``load_model``); None: the
        paper's proxy sign(τ q̇) of eq. 26 (:attr:`sign_power`).
    sign : ndarray or None
        sign(q̇) formed at full rate and decimated with the torque, values in [-1, 1]
        (fractional over a few samples at a reversal, where the decimated torque's dry
        friction is the low-pass of a step): the direction of samples that were decimated
        already, e.g. a robot fit's rows (``RobotSignals.sign``, carried by
        :mod:`ident.robot.refine_joint`). None: sign(q̇) of these samples, right at full
        rate (:attr:`direction`).
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray
    payload_mass: np.ndarray
    payload_arm: np.ndarray
    experiment: np.ndarray
    revolute: bool = True
    dtau: np.ndarray | None = field(default=None)
    extra: dict[str, np.ndarray] | None = field(default=None)
    quadrant: np.ndarray | None = field(default=None)
    sign: np.ndarray | None = field(default=None)

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def take(self, index: np.ndarray) -> Signals:
        """Samples selected by a boolean mask or an index array."""
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, dict):
                kw[f.name] = {k: x[index] for k, x in v.items()}
            else:
                kw[f.name] = v[index] if isinstance(v, np.ndarray) else v
        return replace(self, **kw)

    def states(self) -> Signals:
        """The same samples without the measured torque: ``tau`` (and ``dtau``) are
        :data:`HIDDEN_OUTPUT`, whose every use raises :class:`~ident.OutputLeakError`.

        The refinement gives only this view to its candidates (terms, diagnosis variables,
        library bases), so that none can be built from the output it is fitted to.
        """
        return replace(self, tau=HIDDEN_OUTPUT, dtau=None)

    @property
    def has_output(self) -> bool:
        """False on a :meth:`states` view."""
        return self.tau is not HIDDEN_OUTPUT

    @property
    def direction(self) -> np.ndarray:
        """The dry friction's direction column [-]: :attr:`sign` when the samples carry it
        (decimated samples: sign(q̇) formed at full rate, low-passed with the torque), else
        sign(q̇) of the samples. The sign of a decimated q̇ is a step at a reversal where the
        torque's Coulomb part is a ramp, which biased the Coulomb and Stribeck estimates of
        the robot's states chain (docs/robot-identification.md)."""
        if self.sign is not None:
            return self.sign
        return np.sign(self.dq)

    @property
    def sign_power(self) -> np.ndarray:
        """sign(P): the model quadrant :attr:`quadrant` when a load model decided it, else
        sign(tau * dq), the paper's proxy for sign(P_out) (eq. 26)."""
        if self.quadrant is not None:
            return self.quadrant
        return np.sign(self.tau * self.dq)
