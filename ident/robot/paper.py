"""The paper's load- and velocity-dependent friction on every joint of a robot (eq. 17-30).

For joint j (E_j = exp(-|dq_j| / q_s,j), eq. 29; P+_j, P-_j of eq. 27-28)::

    tau_j = P+_j (a_m + b_m E_j) tau_out,j + P-_j (a_g - b_g E_j) tau_out,j
          + P+_j (c_m + d_m E_j) sign(dq_j) + P-_j (c_g + d_g E_j) sign(dq_j)
          + F_V dq_j + tau_off                                                     (eq. 30)

    tau_out,j = W_j(q, dq, ddq) theta + p_j        (base rigid body + rotors; p_j: known payload)

exactly as the single-joint :mod:`ident.models` maps it (``LoadDependent`` on the rigid body and
payload, ``QuadrantCoulomb``, ``Viscous``, ``Offset``), with the per-joint parameters a_m{j}
b_m{j} a_g{j} b_g{j} c_m{j} d_m{j} c_g{j} d_g{j} FV{j} OFF{j} (ROBOT_FORMAT names).

Bilinear estimation
-------------------
The single-joint code identifies the products (a_m J, b_m J, ...) of eq. 42-43 as free linear
parameters. On n joints the rigid-body base parameters theta are shared by all joints, so the
model is bilinear in (theta, per-joint friction): the estimator here keeps that structure
(fewer parameters: p_b + 10 k instead of sum_j 4 p_j + 6) and solves it by Gauss-Newton,
started from the usual model's fit (a = 1, b = 0, c = F_C, d = 0), standard deviations from
the linearised model at the solution (eq. 15 with the Jacobian for W). With the quadrants
fixed, every Gauss-Newton step is a quadratic form in the moments
``sum P^s E^e v v^T`` (:mod:`ident.robot.moments`) accumulated in one pass, so the iterations
never touch the samples again.

Quadrants: ``quadrant="measured"`` uses the paper's proxy sign(P) = sign(tau dq) (eq. 26);
``quadrant="model"`` (default) decides sign(P_out) = sign(tau_out_hat dq), first with the usual
fit's theta, then with the current estimate, and repeats the pass until the assignment is
stable (what the simulator and the physics use; the proxy is wrong in the stiction band of
Fig. 2.b and "motor" everywhere on a joint whose friction exceeds its load).

The scale of theta against (a, b) is fixed by the known payload torques (p_j enters with the
coefficient a, not a free ratio) when they are not in the span of the base columns: without a
payload, or with one and the same payload in every experiment, only products are identifiable
and the estimator fixes a_m of the first joint to 1 (reported in ``fixed_``).

Products form
-------------
``RobotModel(model="paper", form="products")`` drops the rank-one constraint: eq. 42
generalised to every joint, linear in its parameters, no theta shared between the joints, no
gauge (:func:`products_coefficients`). Joint j's coefficient of each load column w_i -- its
base columns, then its payload torque p_j -- is alpha_i + E beta_i in the motor quadrant and
alpha_i - E beta_i in the generator one, all free; then c + E d of each quadrant on
sign(dq_j), FV_j on dq_j, OFF_j on 1: 4 (p_j + 1) + 6 parameters per joint
(:func:`products_names`: the single-joint ``LoadDependent`` names ``a_m_<column>`` ... with
the joint number appended, ``a_m_MX3_3``; the payload torque's products ``a_m{j}``, ...,
and ``c_m{j}`` ... ``OFF{j}``, as the bilinear form names them). On a one-joint robot this
is the single-joint ``new_model`` (tests/test_robot_fit.py, tests/test_robot_design.py).

Where the products are formed decides what "the single-joint model" means on filtered data.
By default the estimator weights the DECIMATED columns by P and E of the decimated samples;
the single-joint chain forms eq. 42's columns P+ w, P+ E w, P- w, -P- E w, P+- sign,
P+- E sign at FULL rate and then low-passes and decimates them, and filt(P E w) differs from
P filt(E) filt(w) wherever P or E varies within the filter's window (a quadrant change; E at
low velocity). :func:`ident.robot.design.products_columns` forms them at full rate on every
joint, as the single-joint chain does (``RobotColumns.products``); the products form then
reads these rows whole (:func:`rows_coefficients`, :class:`~ident.robot.moments.RowMoments`):
the same parameters and names, on a one-joint robot the single-joint paper fit to 1e-8.

The bilinear form reads them too on the columns chain with ``RobotModel(full_rate=True)``
(opt-in): its prediction is the products form's with the products of its own parameters
(a_m theta_i, ...; :func:`bilinear_rows_coefficients`), the products formed at full rate with
the quadrants of its own load prediction, so the measured torque and the model are filtered
alike (docs/refinement.md section 8.9).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import RobotIdentError
from .moments import IDQ, IP, ISG, N_EXTRA, ONE

__all__ = ["PAPER_BLOCK", "USUAL_BLOCK", "PRODUCT_PREFIXES", "paper_coefficients",
           "usual_coefficients", "products_coefficients", "products_names", "products_start",
           "rows_coefficients", "bilinear_rows_coefficients",
           "products_size", "paper_start", "batch_coefficients", "require_theta"]

#: Per-joint parameter prefixes of the paper model (ROBOT_FORMAT order).
PAPER_BLOCK = ("a_m", "b_m", "a_g", "b_g", "c_m", "d_m", "c_g", "d_g", "FV", "OFF")
#: Per-joint parameter prefixes of the usual model (eq. 5).
USUAL_BLOCK = ("FC", "FV", "OFF")
#: The products of each load column in the products form (eq. 42-43): motor, then generator.
PRODUCT_PREFIXES = (("a_m", "b_m"), ("a_g", "b_g"))
#: The products form's per-joint parameters after the load columns' products (eq. 42-44).
PRODUCTS_TAIL = ("c_m", "d_m", "c_g", "d_g", "FV", "OFF")


def usual_coefficients(theta: np.ndarray, blk: np.ndarray, s: int,
                       jacobian: bool = True) -> tuple[np.ndarray, ...]:
    """(c0, c1, D0, D1) of the usual model tau = W theta + p + FC sign + FV dq + OFF (eq. 8).

    ``theta``: the joint's base parameters (its non-zero columns), ``blk``: (FC, FV, OFF);
    quadrant ``s`` is irrelevant (same coefficients in both). ``jacobian=False``: (c0, c1)
    only (a cost evaluation)."""
    nt = theta.shape[0]
    nv = nt + N_EXTRA
    nx = nt + 3
    c0 = np.zeros(nv)
    c0[:nt] = theta
    c0[nt + IP] = 1.0
    c0[nt + ISG], c0[nt + IDQ], c0[nt + ONE] = blk
    if not jacobian:
        return c0, np.zeros(nv)
    D0 = np.zeros((nv, nx))
    D0[_diag(nt)] = 1.0
    D0[nt + ISG, nt] = D0[nt + IDQ, nt + 1] = D0[nt + ONE, nt + 2] = 1.0
    return c0, np.zeros(nv), D0, np.zeros((nv, nx))


def paper_coefficients(theta: np.ndarray, blk: np.ndarray, s: int,
                       jacobian: bool = True) -> tuple[np.ndarray, ...]:
    """(c0, c1, D0, D1) of eq. 30 in quadrant ``s`` (0: motor P+, 1: generator P-).

    ``blk`` = (a_m, b_m, a_g, b_g, c_m, d_m, c_g, d_g, FV, OFF). Prediction
    ``(c0 + E c1)^T v``; Jacobian row ``(D0 + E D1)^T v`` over (theta, blk).
    ``jacobian=False``: (c0, c1) only (a cost evaluation)."""
    nt = theta.shape[0]
    nv = nt + N_EXTRA
    nx = nt + len(PAPER_BLOCK)
    ia, ib, ic, idd = (0, 1, 4, 5) if s == 0 else (2, 3, 6, 7)
    a, b = blk[ia], blk[ib]
    sb = 1.0 if s == 0 else -1.0  # generator: a_g - b_g E (eq. 25, 30)
    c0 = np.zeros(nv)
    c1 = np.zeros(nv)
    c0[:nt] = a * theta
    c0[nt + IP] = a
    c0[nt + ISG] = blk[ic]
    c0[nt + IDQ] = blk[8]
    c0[nt + ONE] = blk[9]
    c1[:nt] = sb * b * theta
    c1[nt + IP] = sb * b
    c1[nt + ISG] = blk[idd]
    if not jacobian:
        return c0, c1
    D0 = np.zeros((nv, nx))
    D1 = np.zeros((nv, nx))
    diag = _diag(nt)
    D0[diag] = a
    D1[diag] = sb * b
    D0[:nt, nt + ia] = theta
    D0[nt + IP, nt + ia] = 1.0
    D1[:nt, nt + ib] = sb * theta
    D1[nt + IP, nt + ib] = sb
    D0[nt + ISG, nt + ic] = 1.0
    D1[nt + ISG, nt + idd] = 1.0
    D0[nt + IDQ, nt + 8] = 1.0
    D0[nt + ONE, nt + 9] = 1.0
    return c0, c1, D0, D1


def products_size(nt: int) -> int:
    """Parameters of one joint in the products form: 2 x 2 products of each of its ``nt``
    base columns and of its payload torque, then c_m, d_m, c_g, d_g, FV, OFF."""
    return 4 * (nt + 1) + len(PRODUCTS_TAIL)


def products_names(columns: list[str] | tuple[str, ...], number: int) -> tuple[str, ...]:
    """Names of one joint's products-form parameters, in :func:`products_coefficients`'s
    order: the single-joint ``LoadDependent`` names (``a_m_<column>``, ``b_m_<column>`` per
    load column, the payload torque's bare ``a_m``, ``b_m``; then the generator's a_g, b_g)
    with the robot's joint number appended (``_<number>`` after a column name, which
    carries digits of its own: ``a_m_MX3_3``; directly after a bare name: ``a_m3``), then
    ``c_m{n} d_m{n} c_g{n} d_g{n} FV{n} OFF{n}``."""
    suf = [f"_{c}_{number}" for c in columns] + [str(number)]
    out = [f"{p}{x}" for pre in PRODUCT_PREFIXES for x in suf for p in pre]
    return tuple(out) + tuple(f"{p}{number}" for p in PRODUCTS_TAIL)


def products_coefficients(theta: np.ndarray, blk: np.ndarray, s: int,
                          jacobian: bool = True) -> tuple[np.ndarray, ...]:
    """(c0, c1, D0, D1) of the products form (eq. 42-44 on joint j) in quadrant ``s``.

    ``theta``: empty (no shared parameter: every coefficient is one of the joint's);
    ``blk``: the joint's parameters in :func:`products_names`'s order, ``4 (nt + 1) + 6``
    values for ``nt`` base columns. In quadrant 0 (motor) the load column i (base columns,
    then the payload torque p) has the coefficient alpha_i + E beta_i (a_m_i, b_m_i), in
    quadrant 1 (generator) alpha_i - E beta_i (a_g_i, b_g_i, the single-joint column
    -P- E W); sign(dq) c + E d of the quadrant; FV on dq and OFF on 1 in both. Linear in
    the parameters: D0, D1 are constant."""
    nx = blk.shape[0]
    nt = (nx - len(PRODUCTS_TAIL)) // 4 - 1
    nl = nt + 1
    nv = nt + N_EXTRA
    vi = np.r_[np.arange(nt), nt + IP]  # the load columns' entries of v
    base = 0 if s == 0 else 2 * nl
    ia = base + 2 * np.arange(nl)
    tail = 4 * nl
    ic, idd = (tail, tail + 1) if s == 0 else (tail + 2, tail + 3)
    sb = 1.0 if s == 0 else -1.0
    c0 = np.zeros(nv)
    c1 = np.zeros(nv)
    c0[vi] = blk[ia]
    c1[vi] = sb * blk[ia + 1]
    c0[nt + ISG] = blk[ic]
    c1[nt + ISG] = blk[idd]
    c0[nt + IDQ] = blk[tail + 4]
    c0[nt + ONE] = blk[tail + 5]
    if not jacobian:
        return c0, c1
    D0 = np.zeros((nv, nx))
    D1 = np.zeros((nv, nx))
    D0[vi, ia] = 1.0
    D1[vi, ia + 1] = sb
    D0[nt + ISG, ic] = 1.0
    D1[nt + ISG, idd] = 1.0
    D0[nt + IDQ, tail + 4] = 1.0
    D0[nt + ONE, tail + 5] = 1.0
    return c0, c1, D0, D1


def rows_coefficients(theta: np.ndarray, blk: np.ndarray, s: int,
                      jacobian: bool = True) -> tuple[np.ndarray, ...]:
    """(c0, c1, D0, D1) of a linear model whose rows are given whole, v = [u, tau]
    (:class:`~ident.robot.moments.RowMoments`: the products form on the columns formed at full
    rate, u in :func:`products_names`'s order): c0 = (blk, 0), D0 the identity on u, c1 = D1
    = 0, the same in both slots ``s`` (only s = 0 holds rows). ``theta``: empty."""
    nx = blk.shape[0]
    c0 = np.zeros(nx + 1)
    c0[:nx] = blk
    c1 = np.zeros(nx + 1)
    if not jacobian:
        return c0, c1
    return c0, c1, np.eye(nx + 1, nx), np.zeros((nx + 1, nx))


def bilinear_rows_coefficients(theta: np.ndarray, blk: np.ndarray, s: int,
                               jacobian: bool = True) -> tuple[np.ndarray, ...]:
    """(c0, c1, D0, D1) of the BILINEAR paper model (eq. 30, theta times a, b) on rows given
    whole, v = [u, tau] with u the products formed at full rate in
    :func:`products_names`'s order (:meth:`~ident.robot.estimate.RobotModel._row_block`:
    per load column w_i -- the joint's base columns, then its known torque p -- filt(P+ w),
    filt(P+ E w), then filt(P- w), -filt(P- E w); filt(P+ sign), filt(P+ E sign), filt(P-
    sign), filt(P- E sign); dq; 1).

    The products form's coefficients are the products of the bilinear parameters (eq.
    42-43): a_m theta_i, b_m theta_i, a_g theta_i, b_g theta_i of each base column, a_m,
    b_m, a_g, b_g of p (its coefficient is 1), then c_m, d_m, c_g, d_g, FV, OFF. So c0 =
    those products (0 on tau), c1 = D1 = 0, and D0 their derivatives over (theta, blk),
    ``blk`` = (a_m, b_m, a_g, b_g, c_m, d_m, c_g, d_g, FV, OFF). The same in both slots
    ``s`` (only s = 0 holds rows: :class:`~ident.robot.moments.RowMoments`)."""
    nt = theta.shape[0]
    nl = nt + 1
    nu = 4 * nl + len(PRODUCTS_TAIL)
    load = np.r_[theta, 1.0]
    c0 = np.zeros(nu + 1)
    for q in range(4):  # a_m, b_m (motor), a_g, b_g (generator)
        c0[(q // 2) * 2 * nl + q % 2:(q // 2 + 1) * 2 * nl:2] = blk[q] * load
    c0[4 * nl:nu] = blk[4:]
    c1 = np.zeros(nu + 1)
    if not jacobian:
        return c0, c1
    D0 = np.zeros((nu + 1, nt + len(PAPER_BLOCK)))
    i = np.arange(nt)
    for q in range(4):
        rows = (q // 2) * 2 * nl + q % 2 + 2 * np.arange(nl)
        D0[rows[:nt], i] = blk[q]
        D0[rows, nt + q] = load
    D0[4 * nl + np.arange(len(PRODUCTS_TAIL)), nt + 4 + np.arange(len(PRODUCTS_TAIL))] = 1.0
    return c0, c1, D0, np.zeros_like(D0)


def products_start(theta: np.ndarray, usual_blk: np.ndarray) -> np.ndarray:
    """Products block of one joint from a usual fit (its base parameters ``theta`` and
    (FC, FV, OFF)): the paper start a = 1, b = 0, c = FC, d = 0 as products (alpha_i =
    theta_i, alpha_p = 1, beta = 0)."""
    fc, fv, off = usual_blk
    nl = theta.shape[0] + 1
    alpha = np.r_[theta, 1.0]
    out = np.zeros(products_size(theta.shape[0]))
    out[0:2 * nl:2] = alpha
    out[2 * nl:4 * nl:2] = alpha
    out[4 * nl:] = (fc, 0.0, fc, 0.0, fv, off)
    return out


def require_theta(model: Any, what: str) -> None:
    """Refuse, in one line, what needs a fitted model's base parameters when the model is
    the paper model's products form (``form="products"``: only their products with a, b are
    identified, eq. 42)."""
    if getattr(model, "form", "bilinear") == "products":
        raise RobotIdentError(f"{what}: needs the base parameters, and the paper model's "
                              "form='products' identifies only their products with a, b "
                              "(eq. 42); fit form='bilinear'")


def _diag(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the diagonal of the leading n x n block."""
    r = np.arange(n)
    return r, r


def paper_start(usual_blk: np.ndarray) -> np.ndarray:
    """Paper block from a usual fit (FC, FV, OFF): a = 1, b = 0, c = FC, d = 0."""
    fc, fv, off = usual_blk
    return np.array([1.0, 0.0, 1.0, 0.0, fc, 0.0, fc, 0.0, fv, off])


def batch_coefficients(model: str, theta: np.ndarray, blk: np.ndarray, s: int,
                       jacobian: bool = True) -> tuple[np.ndarray, ...]:
    """:func:`paper_coefficients` / :func:`usual_coefficients` of k joints at once, their
    rows padded to a common length: ``theta`` (k, m) (joint j's base parameters in its first
    entries, zeros after), ``blk`` (k, nb). Entry layout of v: the m padded base columns, then
    p, sign(dq), dq, 1, tau (nv = m + 5).

    Returns (c0, c1) (k, nv) and, with ``jacobian``, (gam0, gam1) (k,) and B (k, 2 nv, nb):
    the Jacobian of joint j on (theta, blk) is D = [gam0 I; 0; gam1 I; 0] on the theta
    columns (rows of v and of E v, ``JointMoments.normal``'s D0 over D1) and B on the block's.
    """
    k, m = theta.shape
    nv = m + N_EXTRA
    c0 = np.zeros((k, nv))
    c1 = np.zeros((k, nv))
    if model == "usual":
        c0[:, :m] = theta
        c0[:, m + IP] = 1.0
        c0[:, m + ISG], c0[:, m + IDQ], c0[:, m + ONE] = blk[:, 0], blk[:, 1], blk[:, 2]
        if not jacobian:
            return c0, c1
        B = np.zeros((k, 2 * nv, len(USUAL_BLOCK)))
        B[:, m + ISG, 0] = B[:, m + IDQ, 1] = B[:, m + ONE, 2] = 1.0
        return c0, c1, np.ones(k), np.zeros(k), B
    ia, ib, ic, idd = (0, 1, 4, 5) if s == 0 else (2, 3, 6, 7)
    a, b = blk[:, ia], blk[:, ib]
    sb = 1.0 if s == 0 else -1.0
    c0[:, :m] = a[:, None] * theta
    c0[:, m + IP] = a
    c0[:, m + ISG] = blk[:, ic]
    c0[:, m + IDQ] = blk[:, 8]
    c0[:, m + ONE] = blk[:, 9]
    c1[:, :m] = (sb * b)[:, None] * theta
    c1[:, m + IP] = sb * b
    c1[:, m + ISG] = blk[:, idd]
    if not jacobian:
        return c0, c1
    B = np.zeros((k, 2 * nv, len(PAPER_BLOCK)))
    B[:, :m, ia] = theta
    B[:, m + IP, ia] = 1.0
    B[:, nv:nv + m, ib] = sb * theta
    B[:, nv + m + IP, ib] = sb
    B[:, m + ISG, ic] = 1.0
    B[:, nv + m + ISG, idd] = 1.0
    B[:, m + IDQ, 8] = 1.0
    B[:, m + ONE, 9] = 1.0
    return c0, c1, a.copy(), sb * b, B
