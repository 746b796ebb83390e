"""Where the torque lag the refinement proposed on the friction-dominated joint came from
(docs/refinement.md, section 6, "A torque lag carried by the noise of the motion").

    python benchmarks/refine_lag_noise.py [SEED]        # default 4, about 6 minutes

The joint of ``tests/test_refine_quadrant_drift.py`` (``tests/test_friction_dominated.py``'s
values on the example plant, no undeclared effect) is simulated twice with the same seed:
with the plant's applied-torque noise and without it (``torque_noise_std_Nm = 0``); then once
with a 5 ms torque lag, with and without the noise. Printed:

* the share of the paper model's residual sum of squares the lag column dtau_hat/dt explains
  (after the projection on the declared columns) and its least-squares T_lag; the same for
  the column's noise part (the noisy run's column minus the noise-free twin's, evaluated on
  the noisy run's rows) and its noise-free part; the noise part's share of the column;
* that projection by distance of the rows to the quadrant band (in guards);
* T_lag by least squares on the column low-passed at 2, 5 and 10 Hz (:class:`ident.refine.
  _MotionPart`), with and without the lag in the plant;
* the refinement's step 1 (``max_steps=1``) on each plant;
* where it adds the lag, T_lag by instrumental variables on its final design (each column its
  own instrument but those named): the lag's column instrumented by its motion band
  (:class:`ident.refine._MotionPart` at 5 x the motion bandwidth), by dtau_hat/dt evaluated on
  the reference trajectory's states (q_ref, dq_ref, ddq_ref: free of the plant's noise), every
  column by its value on the reference's states (IDIM-IV's idea with the whole reference);
  and T_lag by least squares on the rows with |dq| above 10 % of its maximum.
"""

from __future__ import annotations

import re
import sys
import warnings
from dataclasses import replace
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_friction_dominated import friction_dominated  # noqa: E402

from ident.effects import TorqueLag, model_prediction, rigid_prediction  # noqa: E402
from ident.effects.torque_lag import time_derivative  # noqa: E402
from ident.estimate import fit_least_squares  # noqa: E402
from ident.fitting import fit_models  # noqa: E402
from ident.loaders import make_experiment  # noqa: E402
from ident.models import IdentModel  # noqa: E402
from ident.refine import _fit, _motion_band, _MotionPart, refine  # noqa: E402
from ident.terms import Term  # noqa: E402
from sim_drivers.offline import simulate  # noqa: E402

LAG = "\n[effects.torque_lag]\nenabled = true\ntime_constant_s = 0.005\n"


def fitted(seed: int, tmp: Path, noise: bool, lag: bool):
    """The paper model's report on the joint's three payload runs."""
    txt = (ROOT / "examples" / "plant_rx130l.toml").read_text()
    txt = txt.replace("enabled = true", "enabled = false")
    if not noise:
        txt = re.sub(r"^torque_noise_std_Nm = [0-9.]+", "torque_noise_std_Nm = 0.0", txt,
                     flags=re.M)
    plant, plan, gains = friction_dominated(txt + (LAG if lag else ""),
                                            tmp / f"plant_{noise}_{lag}.toml", "lag-noise")
    exps = []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=10 * seed + i)
        exps.append(make_experiment(f"p{i}.csv", r.t, r.q, r.tau_ref, payload_mass=p.mass_kg,
                                    payload_arm=p.arm_m))
    return fit_models(exps, ("paper",), table_iv=False), plan.reference


class _OnReference(Term):
    """``term``'s columns on the reference trajectory's states (q, dq, ddq of ``ref``
    interpolated at the samples' times; every run replays the same reference from t = 0)."""

    def __init__(self, term: Term, ref) -> None:
        self.term, self.ref = term, ref
        self.effect, self.variable = term.effect, term.variable

    def names(self) -> tuple[str, ...]:
        return tuple(n + "_ref" for n in self.term.names())

    def columns(self, s):
        return self.term.columns(replace(s, **{k: np.interp(s.t, self.ref.t, getattr(self.ref, k))
                                               for k in ("q", "dq", "ddq")}))


def instrumented(R, rep, ref) -> None:
    """T_lag of the refinement's final design by instrumental variables (module doc)."""
    d1 = R.final_design
    lag = next(t for t in d1.library.terms() if isinstance(t, TorqueLag))
    i = d1.names.index("T_lag")

    def show(label, Z, rows=slice(None)):
        res = fit_least_squares(d1.W[rows], d1.Y[rows], d1.names, eliminate=False,
                                Z=None if Z is None else Z[rows])
        j = list(res.names).index("T_lag")
        print(f"    {label}: T_lag {1e3 * res.chi[j]:.2f} +- {2e3 * res.std[j]:.2f} ms (2 sigma), "
              f"relative error {100 * res.rel_error:.3f} %")

    fc = _motion_band(rep.designs["paper"])
    Z = d1.W.copy()
    Z[:, i] = d1.with_term(_MotionPart(lag, fc), states_only=True).W[:, -1]
    show(f"IV, the lag's column instrumented by its motion band ({fc:.3g} Hz)", Z)
    Zr = d1.W.copy()
    for t in d1.library.terms():
        k = len(t.names())
        cols = d1.with_term(_OnReference(t, ref), states_only=True).W[:, -k:]
        for j, n in enumerate(t.names()):
            Zr[:, d1.names.index(n)] = cols[:, j]
    Z = d1.W.copy()
    Z[:, i] = Zr[:, i]
    show("IV, the lag's column instrumented by dtau_hat/dt on the reference", Z)
    show("IV, every column instrumented by its value on the reference", Zr)
    adq = np.abs(d1.signals.dq)
    show("least squares on the rows with |dq| > 10 % of its maximum", None, adq > 0.1 * adq.max())


class _Col(Term):
    effect = variable = "column"

    def __init__(self, f) -> None:
        self.f = f

    def names(self) -> tuple[str, ...]:
        return ("column",)

    def columns(self, s):
        return self.f(s)[:, None]


def analyse(rep, twin=None, ref=None) -> None:
    d = rep.designs["paper"]
    lib = rep.models["paper"].library
    m = _fit(lib, d, "paper")
    r = m.residual_
    W = d.W[:, [d.names.index(n) for n in m.names_]]
    pred = model_prediction(lib, m.coef_)

    def col(f):
        return d.with_term(_Col(f), states_only=True).W[:, -1]

    def proj(x):
        return x - W @ np.linalg.lstsq(W, x, rcond=None)[0]

    def show(label, x):
        xp = proj(x)
        print(f"  {label}: explains {100 * (r @ xp) ** 2 / (xp @ xp) / (r @ r):.1f} % of the "
              f"residual's sum of squares, T_lag {1e3 * (r @ xp) / (xp @ xp):.2f} ms")

    print(f"  paper model: relative error {100 * m.rel_error_:.3f} %")
    lag = col(lambda s: time_derivative(pred(s), s))
    show("dtau_hat/dt", lag)
    if twin is not None:
        dt_ = twin.designs["paper"]
        clean = []
        for b in dt_._blocks:
            s = b.full.states()
            clean.append((b.full.t, time_derivative(pred(s), s)))

        def clean_f(s):
            out = np.empty(len(s))
            for e in np.unique(s.experiment):
                k = s.experiment == e
                t, y = clean[int(e)]
                out[k] = np.interp(s.t[k], t, y)
            return out

        part = col(clean_f)
        show("its noise-free part (the twin's)", part)
        show("its noise part", lag - part)
        print(f"  noise part's share of the projected column: "
              f"{100 * np.sum(proj(lag - part) ** 2) / np.sum(proj(lag) ** 2):.0f} %")
        # by distance of the rows to the quadrant band (full-rate samples, in guards)
        band = next(float(n.split("< ")[1].split(" N")[0]) for n in rep.notes
                    if "quadrant band" in n)
        load = rigid_prediction(lib, m.coef_)
        dist = []
        for b in d._blocks:
            rows = b.index[b.mask]
            inb = np.flatnonzero(np.abs(load(b.full.states())) < band)
            j = np.clip(np.searchsorted(inb, rows), 1, max(inb.size - 1, 1))
            dist.append(np.minimum(np.abs(rows - inb[j - 1]), np.abs(inb[j] - rows))
                        if inb.size else np.full(rows.size, 10**9))
        dist = np.concatenate(dist) / d.guard
        c = r * proj(lag)
        far = dist > 10
        print(f"  rows more than 10 guards from the band: {100 * far.mean():.0f} % of the rows, "
              f"{100 * c[far].sum() / c.sum():.0f} % of the lag's projection on the residual")
    for fc in (2.0, 5.0, 10.0):
        x = proj(col(lambda s, fc=fc: _MotionPart(TorqueLag(pred), fc).columns(s)[:, 0]))
        sig2 = (r @ r - (r @ x) ** 2 / (x @ x)) / (len(r) - W.shape[1] - 1)
        share = 100 * (r @ x) ** 2 / (x @ x) / (r @ r)
        t_lag, t2 = 1e3 * (r @ x) / (x @ x), 2e3 * np.sqrt(sig2 / (x @ x))
        print(f"  column low-passed at {fc:g} Hz: explains {share:.1f} %, "
              f"T_lag {t_lag:.2f} +- {t2:.2f} ms")
    R = refine(d, IdentModel(lib, "paper"), max_steps=1)
    for st in R.steps:
        key = next((k for k in st.parameters if k.startswith("T_lag")), None)
        val = "" if key is None else (f": T_lag {1e3 * st.parameters[key]['value']:.2f} +- "
                                      f"{1e3 * st.parameters[key]['std2']:.2f} ms")
        print(f"  refinement adds {st.effect}{val} ({100 * st.rel_error_before:.2f} -> "
              f"{100 * st.rel_error_after:.2f} %)")
        if key is not None and ref is not None:
            instrumented(R, rep, ref)
    for rj in R.rejected:
        print(f"  refinement rejects {rj.effect}: {rj.reason}")


def main() -> None:
    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    warnings.filterwarnings("ignore")
    with TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (noisy, _), (clean, _) = fitted(seed, tmp, True, False), fitted(seed, tmp, False, False)
        print(f"seed {seed}, no undeclared effect, with the applied-torque noise:")
        analyse(noisy, clean)
        print("without the noise:")
        analyse(clean)
        for noise in (True, False):
            print(f"5 ms torque lag, {'with' if noise else 'without'} the noise:")
            rep, ref = fitted(seed, tmp, noise, True)
            analyse(rep, ref=ref)


if __name__ == "__main__":
    main()
