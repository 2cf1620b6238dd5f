"""Name the effect a nominal model is missing: greedy forward selection over a library of
candidate effects, judged by time-blocked cross-validation, an information criterion that
does not count autocorrelated samples as independent, and a noise floor estimated from the
data.

The nominal description (geometry and inertial parameters) is taken as correct; its
prediction ``tau_nom = Y(q, qd, qdd) @ (P @ parameter_vector(model))`` is subtracted from the
measured torque and the residual ``r = tau - tau_nom`` is what candidate effects must explain.
Every candidate is a set of regressor columns, linear in its parameters, fitted *for all
joints at once* (per-joint parameters, one candidate = one block of columns):

=============================  ==========================  =====================================
candidate                      parameters                  torque on joint i
=============================  ==========================  =====================================
``viscous_friction``           ``fv1..fvn``                ``fv_i qd_i``
``coulomb_friction``           ``fc1..fcn``                ``fc_i sign(qd_i)`` (``tanh(qd/eps)``)
``torque_offset``              ``f01..f0n``                ``f0_i``
``armature``                   ``Ia1..Ian``                ``Ia_i qdd_i``
``payload``                    ``payload_m .. payload_Izz``  the last 10 columns of ``Y @ P``
                                                           (a body on the flange; its 10
                                                           barycentric values add to the last
                                                           link's)
``base_tilt``                  ``dgx, dgy, dgz``           gravity torques of the nominal
                                                           parameters under ``g_nom + dg``
                                                           (exactly linear in ``g``)
``stribeck_friction``          ``fs1..fsn`` (+ ``vs``)     ``fs_i exp(-(qd_i/vs)^2) sign(qd_i)``,
                                                           ``vs`` from :data:`STRIBECK_VS`
``position_ripple``            ``rs1.., rc1..``            ``rs_i sin(k q_i) + rc_i cos(k q_i)``
``load_dependent_friction``    ``fl1..fln``                ``fl_i |tau_nom_i| sign(qd_i)``
=============================  ==========================  =====================================

Judgement (constants below; each rule says why):

* **Held-out error**: K contiguous time blocks (``folds``), fit on K-1, predict the held-out
  block; out-of-fold predictions give a held-out RMS per joint.  Contiguous blocks because
  filtered, autocorrelated samples next to a training sample are not independent test data.
* **Criterion**: ``BIC_eff = N_eff log(RSS / rows) + rank log(N_eff)`` with the effective
  sample size per joint ``N_eff = N / (1 + 2 sum_k rho_k)`` (autocorrelation of the
  residual of the larger model, summed up to the first non-positive lag), summed over joints.
  Both models of a comparison use the same ``N_eff``.
* **Noise floor** per joint: ``1.4826 median|d2 r| / sqrt(6)``, the robust (MAD) scale of
  the second difference of the residual within each segment (white noise of std s gives
  ``d2`` of std ``sqrt(6) s``; smooth effects contribute ``(omega dt)^2`` of their amplitude,
  sparse jumps such as Coulomb reversals are ignored by the median).  Torques low-passed
  before logging have correlated noise whose second difference is small: the floor is then
  an underestimate and the stop falls to the cross-validation rule.
* **Acceptance** of the best remaining candidate (the one with the lowest held-out MSE when
  fitted together with the already chosen ones): (a) held-out MSE (summed over joints) falls
  by at least :data:`MIN_RELATIVE_IMPROVEMENT`; (b) ``BIC_eff`` falls by at least
  :data:`BIC_MARGIN` (strong evidence on the Kass-Raftery scale); (c) its block of
  parameters is non-zero: the Wald statistic ``dRSS / s^2 * N_eff / rows`` exceeds the
  chi-square quantile :data:`WALD_P` of its rank.  Stop when no candidate passes, or when every
  joint's held-out RMS is within :data:`NOISE_STOP` times its noise floor, or the residual is
  at rounding level (:data:`ROUNDING`).
* **Indistinguishable**: another candidate is indistinguishable from the best when the
  fold-wise difference of their held-out MSE is within :data:`AMBIGUITY_SE` standard errors
  of zero, or within ``(AMBIGUITY_NOISE * floor)^2``.  Then nothing is *named*: the best
  member's columns stay in the fit (so the remaining residual keeps shrinking and
  ``rms_after`` is honest), the group goes to ``indistinguishable`` with a motion that would
  separate it (:func:`separating_motion`), and ``effects`` does not list it.  The principal
  angle between the two column spaces is reported with it.

Example (runs in seconds; ``segments`` are :class:`kindyngen.measured.logs.Segment`):

>>> from kindyngen.robot import load_robot                          # doctest: +SKIP
>>> d = discover(load_robot("robots/lwr4.yaml"), segments)          # doctest: +SKIP
>>> d.effects, d.indistinguishable                                  # doctest: +SKIP
(('viscous_friction',), ())
>>> d.values["fv2"], d.rms_after                                    # doctest: +SKIP
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
from scipy.stats import chi2

from ..inertial_parameters import NAMES as BARYCENTRIC_NAMES
from ..inertial_parameters import parameter_vector
from ..robot import RobotModel
from .effects import effect_columns, effect_names
from .logs import Segment, concatenate_rows
from .regressor_rows import description_torques, torque_regressor

CANDIDATES = ("viscous_friction", "coulomb_friction", "torque_offset", "armature", "payload",
              "base_tilt", "stribeck_friction", "position_ripple", "load_dependent_friction")

#: Stribeck velocities tried (rad/s): at every step each is fitted with the chosen effects
#: and the one of lowest held-out error stands for the candidate (the choice counts as one
#: extra parameter in the criterion).
STRIBECK_VS = (0.02, 0.05, 0.1, 0.2, 0.5)
#: Ripple periods per radian of joint angle (``sin(k q)``, ``cos(k q)``).
RIPPLE_K = 6.0

#: (a) held-out MSE must fall by this fraction: below it a gain is within what re-fitting on
#: other folds varies by.
MIN_RELATIVE_IMPROVEMENT = 0.02
#: (b) BIC_eff must fall by this much (strong evidence).
BIC_MARGIN = 10.0
#: (c) right-tail probability of the chi-square test of the candidate's block (several
#: candidates are tested at each step: a small level keeps false positives rare).
WALD_P = 1e-4
#: stop once every joint's held-out RMS is within this factor of its noise floor.
NOISE_STOP = 1.2
#: residual RMS below this times the torque RMS is rounding, not an effect.
ROUNDING = 1e-9
#: ambiguity: held-out MSE gap within this many fold standard errors ...
AMBIGUITY_SE = 2.0
#: ... or a gap below (this fraction of the noise floor)^2 per joint, summed.
AMBIGUITY_NOISE = 0.1
#: eigenvalues of the column-scaled normal matrix below this times the largest are dropped
#: (minimum-norm solution: the payload's columns are rank-deficient among themselves).
RCOND = 1e-11

NOISE_METHOD = ("robust scale of the second difference of the residual within each segment: "
                "1.4826 median|d2 r| / sqrt(6)")

_SEPARATE = {
    frozenset({"payload", "base_tilt"}): "rotate the wrist (joints 5-7) through large angles at a few "
    "arm poses: a payload's gravity torque follows the flange orientation, a tilt's does not",
    frozenset({"payload", "torque_offset"}): "visit several poses far apart (joint 2 and 4 over most "
    "of their range): gravity torques of a payload change with the pose, an offset does not",
    frozenset({"base_tilt", "torque_offset"}): "swing joint 1 through a large angle: a tilted base's "
    "gravity torques vary with joint 1, an offset does not",
    frozenset({"coulomb_friction", "viscous_friction"}): "run the joints at several constant speeds "
    "(or a multisine with varied amplitudes): Coulomb friction does not grow with speed",
    frozenset({"coulomb_friction", "stribeck_friction"}): "include slow constant-speed sweeps (below "
    "and above the Stribeck velocity)",
    frozenset({"coulomb_friction", "load_dependent_friction"}): "move the same joint at the same speeds "
    "under very different loads (poses or accelerations)",
    frozenset({"position_ripple", "torque_offset"}): "move each joint over several ripple periods",
    frozenset({"armature", "payload"}): "accelerate the wrist joints hard at different poses",
}


def separating_motion(a: str, b: str) -> str:
    """What motion would tell candidate ``a`` from ``b`` (a sentence)."""
    return _SEPARATE.get(frozenset({a, b}), "a motion that excites the two candidates' columns differently "
                         "(larger range, several speeds, several poses)")


# ---------------------------------------------------------------------------------------------
# results

@dataclass(frozen=True, eq=False)
class Step:
    """One accepted (or ambiguous) step of the forward selection.

    ``effect``: the candidate fitted at this step; ``alternatives``: candidates that explain
    the residual about equally well (empty when the effect is named); ``parameter_names``,
    ``values``, ``std`` (std inflated by ``sqrt(rows / N_eff)``); ``rms_before``/``rms_after``:
    held-out RMS per joint (N m) before/after adding it; ``criterion_before``/``_after``:
    BIC_eff of the two models (same N_eff); ``improvement``: relative fall of the held-out
    MSE; ``wald``: the block statistic and its threshold; ``note``."""

    effect: str
    alternatives: tuple[str, ...]
    parameter_names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    rms_before: np.ndarray
    rms_after: np.ndarray
    criterion_before: float
    criterion_after: float
    improvement: float
    wald: tuple[float, float]
    note: str


@dataclass(frozen=True, eq=False)
class Discovery:
    """The outcome of :func:`discover`.

    ``effects``: the named effects in order (``()`` when none); ``fitted``: every candidate
    whose columns are in the final fit (the named ones plus one representative of each
    indistinguishable group); ``steps``; ``rms_before``/``rms_after``: held-out RMS per joint
    (N m) of the nominal model and of nominal + fitted effects; ``noise_floor`` per joint and
    ``noise_method``; ``indistinguishable``: tuple of ``(names, reason)``; ``notes``;
    ``values``/``std``: every fitted parameter by name (fv1.., fc1.., f01.., Ia1.. as in the
    description; payload_m, payload_mx, ... the barycentric values to add to the last link;
    dgx, dgy, dgz the gravity change); ``payload``: the 10 barycentric values (minimum norm
    where not identifiable) or None; ``payload_mass``: the payload mass when identifiable;
    ``gravity``: the fitted gravity vector (base_tilt) or None; ``tilt_deg``: (roll about x,
    pitch about y, total) in degrees, or None; ``n_eff``: effective samples per joint of the
    final residual; ``samples``; ``folds``."""

    effects: tuple[str, ...]
    fitted: tuple[str, ...]
    steps: tuple[Step, ...]
    rms_before: np.ndarray
    rms_after: np.ndarray
    noise_floor: np.ndarray
    noise_method: str
    indistinguishable: tuple[tuple[tuple[str, ...], str], ...]
    notes: tuple[str, ...]
    values: dict
    std: dict
    payload: np.ndarray | None
    payload_mass: float | None
    gravity: np.ndarray | None
    tilt_deg: tuple[float, float, float] | None
    n_eff: np.ndarray
    samples: int
    folds: int
    stribeck_vs: float | None = None    # the grid velocity chosen for stribeck_friction, if fitted
    ripple_k: float = RIPPLE_K
    eps: float | None = None


def predict_effects(discovery: Discovery, model: RobotModel, q, qd, qdd, effects=None) -> np.ndarray:
    """Torques (N, n) of the fitted ``effects`` (default: every fitted one) with the values
    of ``discovery``, along new motion: what the discovered model adds to the nominal one."""
    effects = discovery.fitted if effects is None else tuple(effects)
    q, qd, qdd = (np.asarray(a, float) for a in (q, qd, qdd))
    tau_nom = nominal_torques(model, q, qd, qdd)
    out = np.zeros_like(q)
    for name in effects:
        if name not in discovery.fitted:
            raise ValueError(f"{name} was not fitted (fitted: {', '.join(discovery.fitted) or 'none'})")
        columns, names, _ = _columns(name, model, q, qd, qdd, tau_nom, discovery.eps, discovery.ripple_k,
                                     discovery.stribeck_vs)
        out += columns @ np.array([discovery.values[k] for k in names])
    return out


# ---------------------------------------------------------------------------------------------
# columns

def nominal_torques(model: RobotModel, q, qd, qdd) -> np.ndarray:
    """The description's rigid-body torques ``Y @ (P @ parameter_vector(model))``, (N, n)."""
    return description_torques(model, q, qd, qdd, effects=False)


def _gravity_columns(model: RobotModel, q) -> np.ndarray:
    """(N, n, 3): gravity torques of the nominal parameters under unit gravity along base x,
    y, z.  Each model is built with its own gravity (a tilted model's base map differs)."""
    full = parameter_vector(model)
    zero = np.zeros_like(q)
    out = []
    for g in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
        R = torque_regressor(replace(model, gravity=g))
        out.append(R(q, zero, zero) @ (R.base_map @ full))
    return np.stack(out, axis=2)


def _columns(name, model, q, qd, qdd, tau_nom, eps, ripple_k, stribeck_vs):
    """(columns (N, n, k), parameter names, detail text) of one candidate."""
    n = model.n
    if name in ("viscous_friction", "coulomb_friction", "torque_offset", "armature"):
        return effect_columns(name, qd, qdd, eps), effect_names(name, n), ""
    rows = np.arange(n)
    if name == "payload":
        R = torque_regressor(model)
        Yb = R(q, qd, qdd)
        P = R.base_map[:, -10:]               # the last link's 10 barycentric columns
        return Yb @ P, tuple(f"payload_{k}" for k in BARYCENTRIC_NAMES), ""
    if name == "base_tilt":
        return _gravity_columns(model, q), ("dgx", "dgy", "dgz"), ""
    if name in ("stribeck_friction", "position_ripple", "load_dependent_friction"):
        if name == "stribeck_friction":
            values = [np.exp(-(qd / stribeck_vs) ** 2) * np.sign(qd)]
            names, detail = [f"fs{i + 1}" for i in range(n)], f"vs = {stribeck_vs:g} rad/s"
        elif name == "position_ripple":
            values = [np.sin(ripple_k * q), np.cos(ripple_k * q)]
            names = [f"rs{i + 1}" for i in range(n)] + [f"rc{i + 1}" for i in range(n)]
            detail = f"k = {ripple_k:g} periods per rad"
        else:
            values, names, detail = [np.abs(tau_nom) * np.sign(qd)], [f"fl{i + 1}" for i in range(n)], ""
        out = np.zeros((len(q), n, n * len(values)))
        for k, v in enumerate(values):
            out[:, rows, k * n + rows] = v
        return out, tuple(names), detail
    raise ValueError(f"unknown candidate {name!r} (known: {', '.join(CANDIDATES)})")


# ---------------------------------------------------------------------------------------------
# statistics

def noise_floor(residual: np.ndarray, lengths: Sequence[int]) -> np.ndarray:
    """Per joint, the white-noise level of ``residual`` (N, n) from the robust scale of its
    second difference inside each segment (``lengths`` samples each, never across a seam).

    >>> rng = np.random.default_rng(0)
    >>> x = 0.1 * rng.standard_normal((20000, 1)) + np.sin(np.linspace(0, 20, 20000))[:, None]
    >>> round(float(noise_floor(x, [20000])[0]), 2)
    0.1
    """
    parts, start = [], 0
    for length in lengths:
        seg = residual[start:start + length]
        start += length
        if len(seg) >= 3:
            parts.append(np.diff(seg, 2, axis=0))
    d2 = np.concatenate(parts, axis=0)
    return 1.4826 * np.median(np.abs(d2), axis=0) / math.sqrt(6.0)


def effective_samples(residual: np.ndarray) -> np.ndarray:
    """Per joint, ``N / (1 + 2 sum rho_k)`` with the residual's autocorrelation summed up to
    the first non-positive lag (at least 1, at most N).

    >>> rng = np.random.default_rng(1)
    >>> white = rng.standard_normal((4000, 1))
    >>> bool(3000 < effective_samples(white)[0] <= 4000)
    True
    >>> smooth = np.convolve(white[:, 0], np.ones(20) / 20, "same")[:, None]
    >>> bool(effective_samples(smooth)[0] < 400)
    True
    """
    N, n = residual.shape
    out = np.empty(n)
    size = 1 << int(np.ceil(np.log2(2 * N)))
    for j in range(n):
        x = residual[:, j] - residual[:, j].mean()
        f = np.fft.rfft(x, size)
        acf = np.fft.irfft(f * np.conj(f), size)[:N]
        if acf[0] <= 0:
            out[j] = N
            continue
        rho = acf[1:] / acf[0]
        stop = np.flatnonzero(rho <= 0)
        s = rho[:stop[0]].sum() if len(stop) else rho.sum()
        out[j] = min(N, max(1.0, N / (1.0 + 2.0 * s)))
    return out


class _Problem:
    """All candidate columns stacked once; fits of any subset via Gram matrices."""

    def __init__(self, blocks, r, folds):
        self.N, self.n = r.shape
        self.r = r
        self.blocks = blocks                     # name -> slice into the stacked columns
        A = np.concatenate([b[0] for b in blocks.values()], axis=2) if blocks else np.zeros((self.N, self.n, 0))
        self.slices, start = {}, 0
        for name, (cols, _, _) in blocks.items():
            self.slices[name] = np.arange(start, start + cols.shape[2])
            start += cols.shape[2]
        scale = np.sqrt(np.sum(A ** 2, axis=(0, 1)))
        self.scale = np.where(scale > 0, 1.0 / np.where(scale > 0, scale, 1), 0.0)
        self.A = A * self.scale                  # unit columns (zero columns stay zero)
        edges = np.linspace(0, self.N, folds + 1).astype(int)
        self.folds = [(edges[k], edges[k + 1]) for k in range(folds)]
        A2 = self.A.reshape(self.N * self.n, -1)
        r2 = r.reshape(-1)
        self.G = A2.T @ A2
        self.b = A2.T @ r2
        self.Gf, self.bf = [], []
        for lo, hi in self.folds:
            Af = A2[lo * self.n:hi * self.n]
            self.Gf.append(Af.T @ Af)
            self.bf.append(Af.T @ r2[lo * self.n:hi * self.n])

    def columns(self, names):
        return np.concatenate([self.slices[c] for c in names]) if names else np.zeros(0, int)

    @staticmethod
    def _solve(G, b):
        """Minimum-norm solution and pseudo-inverse of the normal equations; rank."""
        if len(b) == 0:
            return np.zeros(0), np.zeros((0, 0)), 0
        w, V = np.linalg.eigh(G)
        keep = w > RCOND * max(w.max(), 1e-300)
        inv = (V[:, keep] / w[keep]) @ V[:, keep].T
        return inv @ b, inv, int(keep.sum())

    def fit(self, names):
        """Full-data fit and out-of-fold residuals of the candidates ``names``."""
        idx = self.columns(names)
        theta, inv, rank = self._solve(self.G[np.ix_(idx, idx)], self.b[idx])
        residual = self.r - self.A[:, :, idx] @ theta
        oof = np.empty_like(self.r)
        for (lo, hi), Gf, bf in zip(self.folds, self.Gf, self.bf):
            th, _, _ = self._solve((self.G - Gf)[np.ix_(idx, idx)], (self.b - bf)[idx])
            oof[lo:hi] = self.r[lo:hi] - self.A[lo:hi][:, :, idx] @ th
        fold_mse = np.array([np.sum(np.mean(oof[lo:hi] ** 2, axis=0)) for lo, hi in self.folds])
        return dict(names=tuple(names), idx=idx, theta=theta, inv=inv, rank=rank, residual=residual,
                    rss=float(np.sum(residual ** 2)), oof=oof, fold_mse=fold_mse,
                    heldout=np.sqrt(np.mean(oof ** 2, axis=0)), mse=float(np.sum(np.mean(oof ** 2, axis=0))))

    def criterion(self, fit, n_eff_total):
        rows = self.N * self.n
        return float(n_eff_total * math.log(max(fit["rss"], 1e-300) / rows) + fit["rank"] * math.log(n_eff_total))


def _principal_cosine(A, B) -> float:
    """Cosine of the smallest principal angle between the column spaces of A and B (rows x k)."""
    def basis(M):
        if M.shape[1] == 0:
            return M
        U, s, _ = np.linalg.svd(M, full_matrices=False)
        return U[:, s > 1e-8 * max(s.max(), 1e-300)]
    Qa, Qb = basis(A), basis(B)
    if Qa.shape[1] == 0 or Qb.shape[1] == 0:
        return 0.0
    return float(np.linalg.svd(Qa.T @ Qb, compute_uv=False).max())


# ---------------------------------------------------------------------------------------------
# the search

def residual_diagnostics(model: RobotModel, segments: Sequence[Segment]) -> dict:
    """Arrays for residual plots: ``t`` (one time axis through the segments), ``q``, ``qd``,
    ``qdd``, ``tau`` (N, n), ``nominal`` (the description's rigid-body torques) and
    ``residual = tau - nominal``; ``noise_floor`` per joint."""
    q, qd, qdd, tau = concatenate_rows(segments)
    nominal = nominal_torques(model, q, qd, qdd)
    t, start = [], 0.0
    for s in segments:
        t.append(s.t - s.t[0] + start)
        start = t[-1][-1] + s.dt
    residual = tau - nominal
    return dict(t=np.concatenate(t), q=q, qd=qd, qdd=qdd, tau=tau, nominal=nominal, residual=residual,
                noise_floor=noise_floor(residual, [len(s.t) for s in segments]))


def discover(model: RobotModel, segments: Sequence[Segment], candidates: Sequence[str] = CANDIDATES,
             folds: int = 5, progress: Callable[[str], None] | None = None, eps: float | None = None,
             *, ripple_k: float = RIPPLE_K, stribeck_vs: Sequence[float] = STRIBECK_VS) -> Discovery:
    """Which of ``candidates`` does the nominal ``model`` miss on ``segments``?  See the module
    text for the rules.  ``eps``: Coulomb smoothing (rad/s) of the Coulomb candidate (None:
    ``sign``); the description's own declared effects are assumed absent (a note says so
    when it declares some)."""
    progress = progress or (lambda text: None)
    candidates = tuple(dict.fromkeys(candidates))
    for c in candidates:
        if c not in CANDIDATES:
            raise ValueError(f"unknown candidate {c!r} (known: {', '.join(CANDIDATES)})")
    segments = tuple(segments)
    if folds < 2:
        raise ValueError("folds must be at least 2")
    notes = []
    if model.effects:
        notes.append(f"the description declares {', '.join(model.effects)}: ignored here (rigid bodies only "
                     f"are the nominal prediction)")
    q, qd, qdd, tau = concatenate_rows(segments)
    N, n = q.shape
    if N < 10 * folds:
        raise ValueError(f"{N} samples are too few for {folds} folds")
    progress("nominal prediction")
    tau_nom = nominal_torques(model, q, qd, qdd)
    r = tau - tau_nom
    floor = noise_floor(r, [len(s.t) for s in segments])
    scale = float(np.sqrt(np.mean(tau ** 2))) or 1.0
    progress("candidate columns")
    # one block of columns per candidate; the Stribeck candidate has one per velocity of the
    # grid, and at every step the velocity with the lowest held-out error stands for it
    blocks, variants, public = {}, {}, {}
    for c in candidates:
        for vs in (tuple(stribeck_vs) if c == "stribeck_friction" else (None,)):
            key = c if vs is None else f"{c}@{vs:g}"
            blocks[key] = _columns(c, model, q, qd, qdd, tau_nom, eps, ripple_k, vs)
            variants.setdefault(c, []).append(key)
            public[key] = c
    details = {key: b[2] for key, b in blocks.items()}
    problem = _Problem(blocks, r, folds)
    extra_k = {"stribeck_friction": 1 if len(stribeck_vs) > 1 else 0}

    current = problem.fit(())
    rms_before = current["heldout"].copy()
    chosen, named, steps, groups = [], [], [], []          # chosen: block keys; named: candidates
    remaining = [c for c in candidates if any(np.any(problem.A[:, :, problem.slices[k]]) for k in variants[c])]
    for c in candidates:
        if c not in remaining:
            notes.append(f"{c}: its columns vanish on this motion (not tried)")

    def at_floor(fit) -> str | None:
        if np.all(np.sqrt(np.mean(fit["residual"] ** 2, axis=0)) <= ROUNDING * scale):
            return "the residual is at rounding level"
        if np.all(fit["heldout"] <= NOISE_STOP * floor):
            return f"every joint's held-out RMS is within {NOISE_STOP}x its noise floor"
        return None

    while remaining:
        reason = at_floor(current)
        if reason:
            notes.append(f"stopped: {reason}")
            break
        progress(f"step {len(steps) + 1}: trying {', '.join(remaining)}")
        trials, key_of = {}, {}
        for c in remaining:
            fits = [(problem.fit(chosen + [k]), k) for k in variants[c]]
            trials[c], key_of[c] = min(fits, key=lambda f: f[0]["mse"])
        best = min(remaining, key=lambda c: trials[c]["mse"])
        best_key = key_of[best]
        fit = trials[best]
        n_eff = effective_samples(fit["residual"])
        n_eff_total = float(n_eff.sum())
        rows = N * n
        k_extra = extra_k.get(best, 0)
        crit_before = problem.criterion(current, n_eff_total)
        crit_after = problem.criterion(fit, n_eff_total) + k_extra * math.log(n_eff_total)
        improvement = 1.0 - fit["mse"] / current["mse"] if current["mse"] > 0 else 0.0
        dof = max(rows - fit["rank"], 1)
        s2 = fit["rss"] / dof
        wald = (current["rss"] - fit["rss"]) / max(s2, 1e-300) * n_eff_total / rows
        r_block = max(fit["rank"] - current["rank"], 1)
        wald_threshold = float(chi2.isf(WALD_P, r_block))
        failed = []
        if improvement < MIN_RELATIVE_IMPROVEMENT:
            failed.append(f"held-out MSE falls by {100 * improvement:.3g} % < {100 * MIN_RELATIVE_IMPROVEMENT:g} %")
        if crit_after > crit_before - BIC_MARGIN:
            failed.append(f"BIC_eff changes by {crit_after - crit_before:.4g} (needs < -{BIC_MARGIN:g})")
        if wald < wald_threshold:
            failed.append(f"Wald {wald:.4g} < {wald_threshold:.4g}")
        if failed:
            notes.append(f"stopped: best remaining candidate {best} rejected ({'; '.join(failed)})")
            break
        # indistinguishable candidates: held-out error about as low as the best's
        alternatives, reasons = [], []
        rows_idx = problem.columns([best_key])
        base_idx = problem.columns(chosen)
        A2 = problem.A.reshape(rows, -1)
        for c in remaining:
            if c == best:
                continue
            d = trials[c]["fold_mse"] - fit["fold_mse"]
            gap, se = float(d.mean()), float(d.std(ddof=1) / math.sqrt(len(d)))
            small = float(np.sum((AMBIGUITY_NOISE * floor) ** 2))
            if gap <= AMBIGUITY_SE * se or gap <= small:
                # principal angle between the two blocks after removing the chosen columns
                B = A2[:, base_idx]
                def proj_out(M):
                    if B.shape[1] == 0:
                        return M
                    coef, *_ = np.linalg.lstsq(B, M, rcond=None)
                    return M - B @ coef
                cos = _principal_cosine(proj_out(A2[:, rows_idx]), proj_out(A2[:, problem.columns([key_of[c]])]))
                alternatives.append(c)
                reasons.append(f"{c}: held-out MSE {trials[c]['mse']:.4g} vs {fit['mse']:.4g} "
                               f"(gap {gap:.3g} +- {se:.3g}, fold standard error), smallest principal angle "
                               f"{math.degrees(math.acos(min(1.0, cos))):.3g} deg; to separate: "
                               f"{separating_motion(best, c)}")
        idx = fit["idx"]
        cov_scale = s2 * rows / n_eff_total
        values = fit["theta"] * problem.scale[idx]
        std = np.sqrt(np.maximum(np.diag(fit["inv"]), 0) * cov_scale) * problem.scale[idx]
        own = np.isin(idx, problem.slices[best_key])
        note = details.get(best_key, "")
        if alternatives:
            group = (best,) + tuple(alternatives)
            groups.append((group, "explain the residual about equally well: " + "; ".join(reasons)))
            note = (note + "; " if note else "") + f"indistinguishable from {', '.join(alternatives)}: not named"
        else:
            named.append(best)
        steps.append(Step(effect=best, alternatives=tuple(alternatives),
                          parameter_names=blocks[best_key][1], values=values[own], std=std[own],
                          rms_before=current["heldout"], rms_after=fit["heldout"],
                          criterion_before=crit_before, criterion_after=crit_after, improvement=improvement,
                          wald=(float(wald), wald_threshold), note=note))
        chosen.append(best_key)
        remaining.remove(best)
        current = fit

    # final values of every fitted candidate
    idx = current["idx"]
    rows = N * n
    n_eff = effective_samples(current["residual"])
    s2 = current["rss"] / max(rows - current["rank"], 1)
    values = current["theta"] * problem.scale[idx] if len(idx) else np.zeros(0)
    std = (np.sqrt(np.maximum(np.diag(current["inv"]), 0) * s2 * rows / n_eff.sum()) * problem.scale[idx]
           if len(idx) else np.zeros(0))
    names = [name for c in chosen for name in blocks[c][1]]
    value_of = dict(zip(names, map(float, values)))
    std_of = dict(zip(names, map(float, std)))
    payload = payload_mass = gravity = tilt = None
    fitted = tuple(public[k] for k in chosen)
    for k in chosen:
        if details[k]:
            notes.append(f"{public[k]}: {details[k]}")
    if "payload" in fitted:
        payload = np.array([value_of[f"payload_{k}"] for k in BARYCENTRIC_NAMES])
        # the mass is identifiable when its direction has no part in the fit's null space
        G = problem.G[np.ix_(idx, idx)]
        w, V = np.linalg.eigh(G)
        null = V[:, w <= RCOND * w.max()]
        e = (idx == problem.slices["payload"][0]).astype(float)
        if null.shape[1] == 0 or np.linalg.norm(null.T @ e) < 1e-6:
            payload_mass = float(payload[0])
        else:
            notes.append("payload mass not identifiable on this motion (only combinations of the flange "
                         "body's parameters are)")
    if "base_tilt" in fitted:
        g0 = np.array([float(v) for v in model.gravity])
        gravity = g0 + np.array([value_of["dgx"], value_of["dgy"], value_of["dgz"]])
        total = math.degrees(math.acos(np.clip(g0 @ gravity / (np.linalg.norm(g0) * np.linalg.norm(gravity)), -1, 1)))
        # roll about base x and pitch about base y of a base whose level gravity is -z
        roll = math.degrees(math.atan2(-gravity[1], -gravity[2]))
        pitch = math.degrees(math.atan2(gravity[0], -gravity[2]))
        tilt = (roll, pitch, total)
    return Discovery(effects=tuple(named), fitted=fitted, steps=tuple(steps), rms_before=rms_before,
                     rms_after=current["heldout"], noise_floor=floor, noise_method=NOISE_METHOD,
                     indistinguishable=tuple(groups), notes=tuple(notes), values=value_of, std=std_of,
                     payload=payload, payload_mass=payload_mass, gravity=gravity, tilt_deg=tilt, n_eff=n_eff,
                     samples=N, folds=folds, ripple_k=ripple_k, eps=eps,
                     stribeck_vs=next((float(k.split("@")[1]) for k in chosen if k.startswith("stribeck")), None))
