"""Preprocessing: from raw experiments to the decimated, selected system Y = W chi + rho.

(Past 600 lines: the steps below run in this order on the same arrays and are documented
together with the paper's section IV.B; each step is its own function.)

Per experiment (paper section IV.B and the EMPS reference script):

0. alignment (optional, ``torque_delay``): when the torque reference of sample k is computed
   from the position of sample k and held by the drive over the following cycle
   [t_k, t_k + dt] (jointid's runner and simulators), the motion it explains is the one of
   the cycle's middle, and q is interpolated to t_k + dt/2 (cubic Lagrange, exact for
   polynomials up to degree 3) before anything else. Without it dq and ddq lag the torque
   by dt/2, which biases F_V and the inertia terms by a few 0.1 % (simulated joint: F_V
   -0.2 % at 3.5 sigma, gone with the shift). Off by default: files of unknown timing are
   processed like the MATLAB reference scripts (on EMPS the shift moves F_V by +2 %);
1. zero-phase Butterworth low-pass of q (order 4), central differences for dq and ddq;
   tau is low-pass filtered the same way *only* to compute sign(P) = sign(tau dq) (eq. 26);
2. the regressor columns W are computed at full rate on these filtered signals;
3. edge trimming (``trim`` full-rate samples at both ends of each experiment);
4. parallel filtering and decimation of Y (the raw tau) and of every column of W, as
   MATLAB's ``decimate`` does (Chebyshev I order 8, 0.05 dB ripple, cut-off 0.8 f_s/(2 r),
   zero phase, keeping the last sample);
5. one selection mask (stiction area |dq| < ``dq_min``, small torques |tau| < ``tau_min``)
   applied identically to Y and every column;
6. optionally the instruments Z of the IDIM-IV estimator (:func:`ident.estimate.fit_instrumental`):
   the same columns with the measured acceleration replaced by the reference trajectory's
   (``reference``: the planned position, processed exactly as q), filtered, decimated and
   selected like W.

Pure numerics: no file access.

Length (~680 lines): the filters, the decimation and the :class:`Design` they build are one
chain whose settings (cut-off, decimation, delay, guard, instruments) every step reads;
``Design.with_term`` must rebuild a column exactly as :func:`build_design` did.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.signal

from . import DataError
from .loaders import uniform_grid
from .signals import Signals
from .terms import Library, Term
from .timing import shift

__all__ = [
    "Design",
    "build_design",
    "diffcent",
    "lowpass",
    "decimate",
    "choose_cutoff",
    "split_experiments",
    "shift",
    "TORQUE_DELAY",
    "CUTOFF_FLOOR_IV",
    "decimation_index",
    "default_rates",
    "default_torque_delay",
    "guarded_keep",
]

BUTTER_ORDER = 4
#: Delay of the torque reference's effective instant after its position sample, in samples,
#: for jointid's logs: a command computed from the position of cycle k and held over the
#: cycle acts on the motion of the cycle's middle (zero-order hold: the runner with the
#: simulated drive, the offline simulator). ``build_design`` defaults to 0 (unknown timing).
TORQUE_DELAY = 0.5
#: Lower bound of the default cut-off, as a fraction of f_s, when instruments are built.
#: The columns are nonlinear in the filtered signals (E_xp ddq, sign(P)): a narrow band
#: smears the breakaway and reversal transients, a bias no estimator removes (simulated
#: joint, true position and applied torque: b_m_J -139 % at f_s/20, +5 % at f_s/10). A
#: wider band lets more quantisation and torque noise into W, which biases OLS but not IV.
#: Measured with IV on five noise seeds of the simulated campaign (largest |z| over the new
#: model's parameters; relative error; low-velocity error new/usual): 0.1 f_s: 2.2-4.7
#: (b_g_J -30 to -70 %), 0.75 %, 0.31; 0.125 f_s: 1.2-2.9, 1.1 %, 0.43; 0.15 f_s: 0.8-2.4,
#: 1.4 %, 0.52. The residual grows with the band because W then holds more of the encoder
#: quantisation (amplified twice by differentiation), which OLS would absorb as bias.
CUTOFF_FLOOR_IV = 0.125


def diffcent(y: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along axis 0, one-sided at both ends (MATLAB ``diffcent``).

    Parameters
    ----------
    y : ndarray, shape (n, ...)
        Samples with period ``dt`` [s].
    dt : float
        Sampling period [s].

    Returns
    -------
    ndarray, shape (n, ...)
        dy/dt.
    """
    y = np.asarray(y, dtype=float)
    out = np.empty_like(y)
    out[1:-1] = (y[2:] - y[:-2]) / (2.0 * dt)
    out[0] = (y[1] - y[0]) / dt
    out[-1] = (y[-1] - y[-2]) / dt
    return out


def lowpass(x: np.ndarray, cutoff_hz: float, fs: float, order: int = BUTTER_ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass (MATLAB ``filtfilt(butter(order, fc/fnyq), x)``)."""
    wn = cutoff_hz / (fs / 2.0)
    if not 0 < wn < 1:
        raise DataError(
            f"cut-off {cutoff_hz:g} Hz must lie between 0 and the Nyquist frequency {fs / 2:g} Hz"
        )
    sos = scipy.signal.butter(order, wn, output="sos")
    return scipy.signal.sosfiltfilt(sos, x, axis=0)


def _factors(r: int) -> list[int]:
    out, rest = [], r
    while rest > 13:
        for f in range(13, 1, -1):
            if rest % f == 0:
                out.append(f)
                rest //= f
                break
        else:
            break
    out.append(rest)
    return [f for f in out if f > 1]


@functools.lru_cache(maxsize=32)
def _antialias(f: int) -> np.ndarray:
    """Anti-alias filter of one decimation stage by ``f``, second-order sections.

    MATLAB's Chebyshev type I design (order 8, 0.05 dB ripple, cut-off 0.8 (f_s/2)/f)
    normalised to unit gain at DC: an even-order Chebyshev I filter has its DC gain at the
    bottom of the pass-band ripple (10^(-0.05/20) = 0.99426), so the raw design, applied
    forward and backward, would scale slowly varying signals by 0.9886 per stage (0.977 for
    two stages). The pass band then lies between 1 and 10^(0.05/20) per pass.
    """
    sos = scipy.signal.cheby1(8, 0.05, 0.8 / f, output="sos")
    dc = float(np.prod(sos[:, :3].sum(axis=1) / sos[:, 3:].sum(axis=1)))
    sos[0, :3] /= dc
    return sos


def decimate(x: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """Anti-alias filter and downsample by ``r`` along axis 0 (MATLAB ``decimate``).

    Chebyshev type I, order 8, 0.05 dB ripple, cut-off 0.8 (f_s/2)/r, applied forward and
    backward (zero phase); factors above 13 are done in stages. Like MATLAB, the kept
    samples end on the last one. Unlike MATLAB's and scipy's design, each stage is
    normalised to unit DC gain (see :func:`_antialias`): constants and slow signals
    (positions, velocities) come out unscaled, so nonlinear functions of the decimated
    signals (sin(2 pi q / P), exp(-|dq| / q_s)) are right. Y and every column of W share
    the filter, so least-squares estimates do not depend on this gain.

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, k)
        Samples (columns filtered independently).
    r : int
        Decimation factor.

    Returns
    -------
    y : ndarray, shape (~n/r,) or (~n/r, k)
        Decimated samples.
    index : ndarray of int
        Indices of the kept samples in ``x``.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        y, index = _decimate_rows(x[None, :], r)
        return y[0], index
    y, index = _decimate_rows(np.ascontiguousarray(x.T), r)
    return y.T, index


def decimation_index(n: int, r: int) -> np.ndarray:
    """Indices of the samples :func:`decimate` keeps of n by r (each stage keeps every f-th
    sample ending on the last one)."""
    index = np.arange(n)
    if r > 1:
        for f in _factors(r):
            index = index[(index.size - 1) % f::f]
    return index


def _decimate_rows(x: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`decimate` along the last axis of a C-contiguous (k, n) array (2x faster
    than filtering along a strided axis 0)."""
    index = decimation_index(x.shape[-1], r)
    if r <= 1:
        return x, index
    y = x
    for f in _factors(r):
        sos = _antialias(f).copy()
        padlen = min(3 * 2 * len(sos), y.shape[-1] - 1)
        y = _sosfiltfilt(sos, _antialias_zi(f), y, padlen)
        y = np.ascontiguousarray(y[:, (y.shape[-1] - 1) % f::f])
    return y, index


@functools.lru_cache(maxsize=32)
def _antialias_zi(f: int) -> np.ndarray:
    """``scipy.signal.sosfilt_zi`` of :func:`_antialias` (f), shape (sections, 2)."""
    zi = scipy.signal.sosfilt_zi(_antialias(f))
    zi.flags.writeable = False
    return zi


def _sosfiltfilt(sos: np.ndarray, zi: np.ndarray, x: np.ndarray, padlen: int) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x, axis=-1, padlen=padlen)`` (odd padding) of a 2-D
    ``x`` with the steady-state ``zi = sosfilt_zi(sos)`` given: the same operations, so the
    same floats, without computing ``zi`` again at every call (a fifth of the time on the
    columns of one q_s of a scan)."""
    n = sos.shape[0]
    ext = scipy.signal._arraytools.odd_ext(x, padlen, axis=-1) if padlen > 0 else x
    z = zi.reshape(n, 1, 2)
    y, _ = scipy.signal.sosfilt(sos, ext, axis=-1, zi=z * ext[:, :1])
    y, _ = scipy.signal.sosfilt(sos, y[:, ::-1], axis=-1, zi=z * y[:, -1:])
    y = y[:, ::-1]
    return y[:, padlen:-padlen] if padlen > 0 else y


def choose_cutoff(q: np.ndarray, dt: float, min_fraction: float = 0.05,
                  t: np.ndarray | None = None, source: str = "") -> float:
    """Low-pass cut-off [Hz] chosen from the bandwidth of the measured motion.

    The velocity spectrum (differences of q) is compared with its noise floor (median power
    in the upper half of the band); the motion bandwidth f_b holds 99.5 % of the energy
    above the floor, and the cut-off is 5 f_b (the paper's practice: about 5 times the
    bandwidth of the dynamics), but never below f_s/20: stiction, reversals and the
    position loop put content well above the trajectory's own bandwidth (the EMPS
    reference script uses 100 Hz at 1 kHz for its 20 Hz position loop; pass it
    explicitly). At most 0.4 f_s. ``min_fraction`` is that lower bound as a fraction of f_s
    (:func:`build_design` raises it to :data:`CUTOFF_FLOOR_IV` with instruments).

    ``t`` (the samples' time stamps [s], optional): irregular stamps are first put on a
    uniform grid by :func:`ident.loaders.uniform_grid` (the loaders' one resampling: values
    interpolated at their stamps, or taken as uniformly sampled under jittered stamps,
    whichever leaves less noise above f_s/4): differences of q over jittered instants taken
    as uniform are broadband noise. When the rule above reaches 0.4 f_s (its floor, a
    median over the upper half of the band, is below the top of a noise spectrum that rises
    with f, as differenced white position noise does), the floor is taken again in the
    position spectrum, where such noise is flat, from the band's complement of the motion
    (above f_s/4), and differenced. A choice at a bound is warned about, with the reason
    (``source`` names the data in the message).
    """
    fs = 1.0 / dt
    q = np.asarray(q, dtype=float)
    if t is not None and q.size >= 2:
        tu, grid, note = uniform_grid(t, {"q": q}, warn=False)
        if note is not None:
            q = grid["q"]
            dt = float((tu[-1] - tu[0]) / (tu.size - 1))
    lo, hi = min_fraction * fs, max(min_fraction, 0.4) * fs
    v = np.diff(q) / dt
    v = v - v.mean()
    n = v.size
    if n < 16:
        return lo
    win = np.hanning(n)
    p = np.abs(np.fft.rfft(v * win)) ** 2
    f = np.fft.rfftfreq(n, dt)
    upper = f > fs / 4
    floor = float(np.median(p[upper])) if np.any(upper) else 0.0
    e = np.clip(p - floor, 0, None)
    c = np.cumsum(e)
    if c[-1] <= 0:
        return lo
    fb = float(f[int(np.searchsorted(c, 0.995 * c[-1]))])
    why = "no motion above the noise floor of the velocity spectrum"
    if 5.0 * fb >= hi and np.any(upper):
        # white position noise: |1 - exp(-i w dt)|^2 / dt^2 times a flat floor of q
        x = q[1:] - q[1:].mean()
        pq = np.abs(np.fft.rfft(x * win)) ** 2
        gain = (2.0 * np.sin(np.pi * f * dt)) ** 2 / dt**2
        e2 = np.clip(p - float(np.median(pq[upper])) * gain, 0, None)
        c2 = np.cumsum(e2)
        if c2[-1] > 0:
            fb = float(f[int(np.searchsorted(c2, 0.995 * c2[-1]))])
        why = ("the velocity spectrum stays above its noise floor up to the Nyquist frequency "
               "(broadband noise, e.g. jittered time stamps taken as uniform)")
    cut = float(f"{np.clip(5.0 * fb, lo, hi):.6g}")
    where = f"{source}: " if source else ""
    if 5.0 * fb >= hi:
        warnings.warn(f"{where}cut-off {cut:g} Hz is the upper bound 0.4 f_s: {why}; "
                      "give --cutoff", stacklevel=2)
    elif 5.0 * fb < lo and 5.0 * fb < 0.5 * lo:
        warnings.warn(f"{where}cut-off {cut:g} Hz is the lower bound {min_fraction:g} f_s "
                      f"(5 x the motion bandwidth is {5.0 * fb:.3g} Hz); give --cutoff to "
                      "filter more", stacklevel=2)
    return cut


def split_experiments(s: Signals) -> list[slice]:
    """Contiguous blocks of equal ``experiment`` index, as slices."""
    e = np.asarray(s.experiment)
    if e.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(e) != 0) + 1
    bounds = np.concatenate([[0], cuts, [e.size]])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _dt(t: np.ndarray) -> float:
    d = np.diff(t)
    if d.size == 0 or not np.all(d > 0):
        raise DataError("time must be strictly increasing within each experiment")
    return float(np.median(d))


@dataclass
class _Block:
    """One experiment: full-rate filtered signals, decimated rows, selection."""

    sub: Signals  # raw samples after edge trim
    full: Signals  # filtered q, dq, ddq; tau low-passed (for sign P); after edge trim
    index: np.ndarray  # indices kept by decimation (into full)
    dec: np.ndarray  # decimated rows (4 + b, m): tau, q, dq, ddq, then the design's columns
    mask: np.ndarray  # selection on the decimated samples
    zfull: Signals | None = None  # ``full`` with the reference acceleration (instruments)
    zdec: np.ndarray | None = None  # decimated instrument rows (b, m), same order as columns


def _assemble(blocks: list[_Block], n_par: int, revolute: bool) -> tuple:
    """Y, W, decimated signals, Z (or None) from the blocks' decimated rows and masks."""
    ys, ws, zs, sigs = [], [], [], []
    for b in blocks:
        m = b.mask
        y = b.dec[0, m]
        ys.append(y)
        ws.append(b.dec[4:, m].T)
        if b.zdec is not None:
            zs.append(b.zdec[:, m].T)
        picked = b.sub.take(b.index[m])
        sigs.append(replace(picked, q=b.dec[1, m], dq=b.dec[2, m], ddq=b.dec[3, m], tau=y))
    Y = np.concatenate(ys)
    if Y.size <= n_par:
        raise DataError(
            f"{Y.size} samples left after selection for {n_par} parameters; "
            "lower dq_min/tau_min or the decimation"
        )
    dsig = Signals(
        t=np.concatenate([s.t for s in sigs]),
        q=np.concatenate([s.q for s in sigs]),
        dq=np.concatenate([s.dq for s in sigs]),
        ddq=np.concatenate([s.ddq for s in sigs]),
        tau=Y,
        payload_mass=np.concatenate([s.payload_mass for s in sigs]),
        payload_arm=np.concatenate([s.payload_arm for s in sigs]),
        experiment=np.concatenate([s.experiment for s in sigs]),
        revolute=revolute,
        # other variables (other joints' states) are picked at the kept instants, not
        # anti-alias filtered: slow signals, see Signals.extra
        extra=None if sigs[0].extra is None else {
            k: np.concatenate([s.extra[k] for s in sigs]) for k in sigs[0].extra},
    )
    Z = np.concatenate(zs, axis=0) if zs else None
    return Y, np.concatenate(ws, axis=0), dsig, Z


@dataclass
class Design:
    """The decimated, selected system Y = W chi + rho (eq. 11, 36).

    Attributes
    ----------
    Y : ndarray, shape (m,)
        Decimated motor torque [N m].
    W : ndarray, shape (m, b)
        Decimated regressor columns, in the order of ``names``.
    names : tuple[str, ...]
        Parameter name of each column.
    library : Library
        The terms that built the columns.
    signals : Signals
        Decimated and selected signals (q, dq, ddq from the filtered position, tau = Y, t,
        payload, experiment) for diagnosis and velocity bands.
    cutoff_hz, decimation, trim, dq_min, tau_min, guard, torque_delay
        The preprocessing settings used.
    Z : ndarray, shape (m, b) or None
        Instruments of the IDIM-IV estimator, column for column with ``W`` (built with the
        reference trajectory's acceleration), or None when no reference was given.
    """

    Y: np.ndarray
    W: np.ndarray
    names: tuple[str, ...]
    library: Library
    signals: Signals
    cutoff_hz: float
    decimation: int
    trim: int
    dq_min: float | None
    tau_min: float | None
    guard: int = 0
    torque_delay: float = 0.0
    Z: np.ndarray | None = field(default=None, repr=False)
    _blocks: list[_Block] = field(default_factory=list, repr=False)

    def __len__(self) -> int:
        return int(self.Y.shape[0])

    def settings(self) -> dict[str, float | int | None]:
        """The preprocessing settings, for reports."""
        return {
            "cutoff_hz": self.cutoff_hz,
            "decimation": self.decimation,
            "trim": self.trim,
            "dq_min": self.dq_min,
            "tau_min": self.tau_min,
            "guard": self.guard,
            "torque_delay": self.torque_delay,
            "instruments": "reference" if self.Z is not None else None,
            "samples": len(self),
        }

    def with_term(self, term: Term, *, states_only: bool = False) -> Design:
        """A new design with ``term``'s columns appended.

        The columns are computed on the same full-rate filtered signals, filtered,
        decimated and selected exactly as the existing ones. With ``states_only`` (every
        refinement candidate) the term sees :meth:`Signals.states` views: its columns cannot
        read the measured torque (:class:`~ident.OutputLeakError` if it tries).
        """
        new = tuple(term.names())
        clash = set(new) & set(self.names)
        if clash:
            raise DataError(f"parameters {sorted(clash)} are already in the design")
        blocks, cols, zcols = [], [], []
        for b in self._blocks:
            full = b.full.states() if states_only else b.full
            rows, _ = _decimate_rows(np.ascontiguousarray(term.columns(full).T), self.decimation)
            zdec = None
            if b.zfull is not None and b.zdec is not None:
                zrows = rows.copy()
                zfull = b.zfull.states() if states_only else b.zfull
                diff = _instrument_rows(term.columns(zfull).T, term.columns(full).T, 0)
                if diff:
                    zd, _ = _decimate_rows(np.stack([r for _, r in diff]), self.decimation)
                    for k, (i, _) in enumerate(diff):
                        zrows[i] = zd[k]
                zdec = np.concatenate([b.zdec, zrows], axis=0)
                zcols.append(zrows[:, b.mask].T)
            blocks.append(replace(b, dec=np.concatenate([b.dec, rows], axis=0), zdec=zdec))
            cols.append(rows[:, b.mask].T)
        Z = None
        if self.Z is not None and zcols:
            Z = np.concatenate([self.Z, np.concatenate(zcols, axis=0)], axis=1)
        return replace(
            self,
            W=np.concatenate([self.W, np.concatenate(cols, axis=0)], axis=1),
            Z=Z,
            names=self.names + new,
            library=Library(*self.library.terms(), term),
            _blocks=blocks,
        )

    def without(self, names: Iterable[str]) -> Design:
        """A new design without the given parameter columns.

        Terms that lose any of their columns leave ``library`` (their remaining columns
        stay in ``W``/``names``).
        """
        drop = set(names)
        unknown = drop - set(self.names)
        if unknown:
            raise DataError(f"parameters {sorted(unknown)} are not in the design")
        keep = [i for i, n in enumerate(self.names) if n not in drop]
        rows = [0, 1, 2, 3] + [4 + i for i in keep]
        terms = [t for t in self.library.terms() if not (set(t.names()) & drop)]
        return replace(
            self,
            W=self.W[:, keep],
            Z=self.Z[:, keep] if self.Z is not None else None,
            names=tuple(self.names[i] for i in keep),
            library=Library(*terms),
            _blocks=[
                replace(b, dec=b.dec[rows], zdec=b.zdec[keep] if b.zdec is not None else None)
                for b in self._blocks
            ],
        )

    def select(
        self,
        *,
        dq_min: float | None = None,
        tau_min: float | None = None,
        load_model: tuple[Term, np.ndarray] | None = None,
    ) -> Design:
        """The same design with another sample selection (see :func:`build_design`),
        without recomputing or re-filtering any column."""
        blocks = [
            replace(b, mask=_selection(b.full, b.index, dq_min, tau_min, self.guard, load_model))
            for b in self._blocks
        ]
        Y, W, dsig, Z = _assemble(blocks, len(self.names), self.signals.revolute)
        return replace(
            self, Y=Y, W=W, Z=Z, signals=dsig, dq_min=dq_min, tau_min=tau_min, _blocks=blocks
        )


def _instrument_rows(zcols: np.ndarray, wcols: np.ndarray, offset: int) -> list:
    """``(offset + i, row)`` for the instrument rows that differ from the regressor's (those
    with the acceleration); the others are shared and decimated once."""
    return [
        (offset + i, np.ascontiguousarray(z))
        for i, (z, w) in enumerate(zip(zcols, wcols, strict=True))
        if not np.array_equal(z, w)
    ]


def _dilate(bad: np.ndarray, k: int) -> np.ndarray:
    """True within k samples of a True sample."""
    if k <= 0 or not bad.any():
        return bad
    c = np.concatenate([[0], np.cumsum(bad, dtype=np.int64)])
    n = bad.size
    i = np.arange(n)
    hi = np.minimum(i + k + 1, n)
    lo = np.maximum(i - k, 0)
    return (c[hi] - c[lo]) > 0


def guarded_keep(bad: np.ndarray, guard: int, index: np.ndarray) -> np.ndarray:
    """Kept decimated samples ``index`` of one experiment: not within ``guard`` full-rate
    samples of a ``bad`` one (shape (n,)) nor of the experiment's edges (transients of the
    decimation filter); see ``guard`` of :func:`build_design`."""
    bad = bad.copy()
    if guard > 0:
        bad[:guard] = True
        bad[-guard:] = True
    return ~_dilate(bad, guard)[index]


def default_rates(fs: float, cutoff_hz: float, decimation: int | None = None,
                  trim: int | None = None, guard: int | None = None) -> tuple[int, int, int]:
    """(decimation, trim, guard) with the defaults of :func:`build_design` for the None ones:
    r = round(f_s / cut-off) (at least 1), trim = max(ceil(3 f_s / cut-off), 2 r), guard = 3 r.
    Given values are returned as int, unchecked."""
    r = max(1, int(round(fs / cutoff_hz))) if decimation is None else int(decimation)
    trim = max(int(np.ceil(3 * fs / cutoff_hz)), 2 * r) if trim is None else int(trim)
    return r, trim, 3 * r if guard is None else int(guard)


def default_torque_delay(sources: Iterable[str]) -> float:
    """:data:`TORQUE_DELAY` when every source is a jointid MCAP log (commands held over the
    next cycle), else 0 (files of unknown timing, processed like the MATLAB scripts)."""
    names = [str(x) for x in sources]
    return TORQUE_DELAY if names and all(x.lower().endswith(".mcap") for x in names) else 0.0


def _selection(
    full: Signals,
    index: np.ndarray,
    dq_min: float | None,
    tau_min: float | None,
    guard: int,
    load_model: tuple[Term, np.ndarray] | None,
) -> np.ndarray:
    """Mask over the decimated samples ``index`` of one experiment (see build_design)."""
    bad = np.zeros(len(full), dtype=bool)
    if dq_min is not None:
        bad |= np.abs(full.dq) < dq_min
    if tau_min is not None:
        bad |= np.abs(full.tau) < tau_min
    if load_model is not None:
        bad |= np.sign(full.tau) != np.sign(_load_torque(full, load_model))
    return guarded_keep(bad, guard, index)


def _load_torque(full: Signals, load_model: tuple[Term, np.ndarray]) -> np.ndarray:
    """τ̂_out = W_out χ_out of a load model [N m], shape (n,)."""
    term, chi = load_model
    return term.columns(full) @ np.asarray(chi, dtype=float)


def build_design(
    library: Term,
    signals: Signals,
    *,
    decimation: int | None = None,
    cutoff_hz: float | None = None,
    tau_min: float | None = None,
    dq_min: float | None = None,
    trim: int | None = None,
    guard: int | None = None,
    load_model: tuple[Term, np.ndarray] | None = None,
    dq_min_rel: float | None = None,
    torque_delay: float = 0.0,
    reference: np.ndarray | None = None,
) -> Design:
    """Filter, differentiate, build W, decimate in parallel and select (see module doc).

    Parameters
    ----------
    library : Term
        Regressor terms (a :class:`~ident.terms.Library` or one term).
    signals : Signals
        Raw concatenated experiments (``dq``/``ddq`` are recomputed; see
        :func:`ident.loaders.concat`). All experiments share one sampling period.
    decimation : int or None
        Decimation factor r; default round(f_s / cut-off) (the EMPS script's rule:
        ``round(0.8 f_nyq / (2 f_dyn))`` with cut-off 5 f_dyn).
    cutoff_hz : float or None
        Butterworth cut-off on q [Hz]; default :func:`choose_cutoff` of the first experiment,
        at least f_s/20, or :data:`CUTOFF_FLOOR_IV` f_s with a ``reference``.
    tau_min : float or None
        Drop decimated samples with |tau| below it [N m] (sign of P unreliable, eq. 26).
    dq_min : float or None
        Drop decimated samples with |dq| below it [rad/s] (stiction area, eq. 26).
    trim : int or None
        Full-rate samples cut at both ends of each experiment (filter edge effects);
        default ceil(3 f_s / cut-off), at least 2 r.
    guard : int or None
        The stiction and small-torque criteria are evaluated at full rate on the filtered
        dq and tau, and every sample within ``guard`` full-rate samples of a rejected one is
        rejected too, so that no kept decimated sample is smeared by the anti-alias filter
        with samples of the stiction area; default 3 r. The first and last ``guard``
        samples of each experiment (edge transients of the decimation filter) are dropped
        too.
    dq_min_rel : float or None
        Set ``dq_min`` to this fraction of the largest |dq| (filtered, full rate, all
        experiments); the resolved value is stored in ``Design.dq_min``.
    load_model : (Term, array) or None
        A model of the load torque, tau_out_hat = W_out chi_out (e.g. the rigid body and
        payload terms with the values of a first fit of the usual model). Samples where
        sign(tau) differs from sign(tau_out_hat) are dropped (with the guard): there the
        proxy sign(P) = sign(tau dq) of eq. 26 is not sign(P_out) (the friction exceeds
        the load, the paper's "stiction area" rectangle of Fig. 2.b).
    torque_delay : float
        Instant the torque of sample k refers to, after the position sample, in samples
        (0 <= d < 1); q is interpolated there (step 0 of the module doc). 0 (default)
        leaves q as sampled; :data:`TORQUE_DELAY` for zero-order-held commands.
    reference : ndarray, shape (n,), or None
        Reference (planned) position of every sample [rad or m], concatenated like
        ``signals``. When given, the design carries the instruments ``Z`` of the IDIM-IV
        estimator: the same columns computed with the measured q and dq (sign(P) from the
        measured tau) and the acceleration of the reference, which is free of the
        applied-torque noise that the closed loop puts into the measured motion but not
        into the logged torque reference.

    Returns
    -------
    Design

    Raises
    ------
    DataError
        Too few samples left, bad settings.
    """
    lib = library if isinstance(library, Library) else Library(library)
    slices = split_experiments(signals)
    if not slices:
        raise DataError("no samples to identify from")
    dts = [_dt(signals.t[sl]) for sl in slices]
    dt = dts[0]
    if max(abs(d - dt) for d in dts) > 0.01 * dt:
        raise DataError("experiments have different sampling periods; resample them first")
    fs = 1.0 / dt
    if cutoff_hz is None:
        floor = CUTOFF_FLOOR_IV if reference is not None else 0.05
        cutoff_hz = choose_cutoff(signals.q[slices[0]], dt, floor)
    cutoff_hz = float(cutoff_hz)
    if decimation is not None and int(decimation) < 1:
        raise DataError(f"decimation must be a positive integer, got {int(decimation)}")
    decimation, trim, guard = default_rates(fs, cutoff_hz, decimation, trim, guard)
    if trim < 0:
        raise DataError(f"trim must be >= 0, got {trim}")
    torque_delay = float(torque_delay)
    if reference is not None:
        reference = np.asarray(reference, dtype=float).ravel()
        if reference.shape != signals.q.shape:
            raise DataError(
                f"reference has {reference.size} samples, expected {signals.q.size} (one per "
                "position sample)"
            )
        if not np.all(np.isfinite(reference)):
            raise DataError(
                f"reference has {int(np.sum(~np.isfinite(reference)))} NaN/inf values "
                "(the log lacks setpoints for some cycles)"
            )
    for k, v in (signals.extra or {}).items():
        if np.shape(v) != signals.q.shape or not np.all(np.isfinite(v)):
            raise DataError(f"signals.extra[{k!r}]: expected {signals.q.size} finite values "
                            "(one per position sample)")
    fulls: list[tuple[Signals, Signals, Signals | None]] = []
    for sl in slices:
        n = sl.stop - sl.start
        if n - 2 * trim < max(4 * decimation, 10):
            raise DataError(
                f"experiment {int(signals.experiment[sl.start])}: {n} samples, too few "
                f"after trimming {trim} at each end and decimating by {decimation}"
            )
        qf = lowpass(shift(signals.q[sl], torque_delay), cutoff_hz, fs)
        dq = diffcent(qf, dt)
        ddq = diffcent(dq, dt)
        tauf = lowpass(signals.tau[sl], cutoff_hz, fs)
        keep = slice(trim, n - trim if trim else n)
        sub = signals.take(np.arange(sl.start, sl.stop)[keep])
        full = replace(sub, q=qf[keep], dq=dq[keep], ddq=ddq[keep], tau=tauf[keep])
        if load_model is not None:
            # the quadrant of eq. 27-28 from the model of the load, not from the measured
            # torque: the columns read no output (equal to eq. 26's proxy on the kept rows)
            full = replace(full, quadrant=np.sign(_load_torque(full, load_model) * full.dq))
        zfull = None
        if reference is not None:
            qr = lowpass(shift(reference[sl], torque_delay), cutoff_hz, fs)
            zfull = replace(full, ddq=diffcent(diffcent(qr, dt), dt)[keep])
        fulls.append((sub, full, zfull))
    if dq_min_rel is not None:
        vmax = max(float(np.max(np.abs(f.dq))) for _, f, _ in fulls)
        dq_min = dq_min_rel * vmax

    blocks: list[_Block] = []
    b = len(lib.names())
    for sub, full, zfull in fulls:
        stack = np.empty((4 + b, len(full)))
        stack[0], stack[1], stack[2], stack[3] = sub.tau, full.q, full.dq, full.ddq
        zrows: list[tuple[int, np.ndarray]] = []
        for term, sl in lib.slices():
            cols = term.columns(full).T
            stack[4 + sl.start : 4 + sl.stop] = cols
            if zfull is not None:
                zrows += _instrument_rows(term.columns(zfull).T, cols, sl.start)
        if zrows:
            stack = np.concatenate([stack, np.stack([r for _, r in zrows])])
        dec, index = _decimate_rows(stack, decimation)
        del stack
        zdec = None
        if zfull is not None:
            zdec = dec[4 : 4 + b].copy()
            for k, (i, _) in enumerate(zrows):
                zdec[i] = dec[4 + b + k]
            dec = np.ascontiguousarray(dec[: 4 + b])
        mask = _selection(full, index, dq_min, tau_min, guard, load_model)
        blocks.append(
            _Block(sub=sub, full=full, index=index, dec=dec, mask=mask, zfull=zfull, zdec=zdec)
        )
    Y, W, dsig, Z = _assemble(blocks, b, signals.revolute)
    return Design(
        Y=Y,
        W=W,
        names=tuple(lib.names()),
        library=lib,
        signals=dsig,
        cutoff_hz=cutoff_hz,
        decimation=decimation,
        trim=trim,
        dq_min=dq_min,
        tau_min=tau_min,
        guard=guard,
        torque_delay=torque_delay,
        Z=Z,
        _blocks=blocks,
    )
