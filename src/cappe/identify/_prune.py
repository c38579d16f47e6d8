"""Model pruning (thesis 4.7): from a high-order black-box fit to the physical poles, zeros and modes.

High-order ARX/ARMA fits (order 40 in the thesis) describe a structure's resonances very precisely but carry many
"phantom" roots with no physical counterpart. :func:`prune` maps the roots of one input-output transfer function
to continuous time and removes them by rules:

(a) ``"cutoff"``: natural frequency above the anti-alias cut-off (default 0.8 x Nyquist, the usable band of an
    analyzer sampling at 2.56 x its bandwidth); delays (roots at z = 0) and roots on the negative real axis
    (which map to the Nyquist frequency) fall here too.
(a') ``"unstable"``: poles with a positive real part (negative damping); a passive structure has none, so they are
    artefacts of the fit (typically at the edge of the excited band, where the input is not persistently exciting).
    Zeros may lie in the right half-plane (non-collocated FRFs) and are kept.
(b) ``"cancellation"``: a pole and a zero closer than ``cancel_tol * |pole|`` cancel; pairs are matched one to
    one by least total distance.
(c) ``"damping"``: complex roots with ``|zeta| > max_damping`` (default 0.3: structural modes of machine tools
    and test rigs have damping ratios of a few per cent, joint-dominated ones up to about 0.1, so 0.3 leaves a
    threefold margin, while roots that only shape the noise are typically damped 0.4 and more).
(d) ``"real"``: real (non-oscillatory) poles and zeros, unless ``keep_real=True`` (keep them for velocity or
    acceleration outputs, whose zeros at s = 0 are real).
(e) ``"n_modes"``: keep the ``n_modes`` most significant complex pole pairs; ``"min_peak"``: drop pairs whose
    significance is below ``min_peak`` times the largest. The significance of a mode is its modal peak
    ``|r| / |Re(lambda)|`` (``r`` the residue of the continuous partial-fraction term ``r / (s - lambda)``, the
    peak height of that term's magnitude at resonance), computed from the unpruned model.

A zero whose nearest pole (relative distance) was removed leaves with it (rule ``"with_pole"``), and zeros beyond
the number of kept poles are dropped from the highest frequency down (``"properness"``).

Poles map exactly, ``lambda = log(z) / dt`` (the zero-order-hold map of poles); zeros are mapped the same way
(matched-z), which is accurate well below the Nyquist frequency; the sampling zeros that the ZOH adds lie near
z = -1 and fall to rule (a). The kept roots define ``G(s) = k prod(s - z_j) / prod(s - p_j)``; the real gain k
is fitted in least squares to the unpruned discrete model's frequency response over the band (relative errors,
``sum |H - k G|^2 / |H|^2``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from cappe.exceptions import DataError
from cappe.identify._polynomial import (
    DiscreteTransferFunction,
    ModalParameters,
    PolynomialModel,
    modal_parameters_from_poles,
)
from cappe.systems.transfer import TransferFunctionModel

__all__ = ["PrunedModel", "PrunedRoot", "prune"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

_REAL_TOL = 1e-9
_GRID = 2000  # frequency points for the gain fit and the fit error


@dataclass(frozen=True)
class PrunedRoot:
    """One continuous root (a complex pair is listed once, by its upper-half-plane member).

    Attributes
    ----------
    value : complex
        The root in rad/s.
    kind : str
        ``"pole"`` or ``"zero"``.
    rule : str
        ``""`` when kept, else the rule that removed it (see :func:`prune`).
    significance : float
        Modal peak ``|r| / |Re(lambda)|`` (poles only, output units per input unit; nan for zeros).
    partner : complex or None
        The root it cancelled with or left with (rules ``"cancellation"`` and ``"with_pole"``).

    Examples
    --------
    >>> root = PrunedRoot(complex(-3.0, 4.0), "pole", "damping")
    >>> root.damping, root.to_dict()["rule"]
    (0.6, 'damping')
    """

    value: complex
    kind: str
    rule: str = ""
    significance: float = float("nan")
    partner: complex | None = None

    @property
    def frequency(self) -> float:
        """Natural frequency ``|value| / 2 pi`` in Hz."""
        return float(abs(self.value) / (2 * np.pi))

    @property
    def damping(self) -> float:
        """Damping ratio ``-Re(value) / |value|`` (1 for a real stable root)."""
        return float(-self.value.real / abs(self.value)) if self.value != 0 else 0.0

    @property
    def is_real(self) -> bool:
        return abs(self.value.imag) <= _REAL_TOL * max(abs(self.value), 1e-300)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "kind": self.kind,
            "re": float(self.value.real),
            "im": float(self.value.imag),
            "frequency": self.frequency if np.isfinite(self.frequency) else None,
            "damping": self.damping if np.isfinite(self.damping) else None,
        }
        if self.rule:
            out["rule"] = self.rule
        if self.kind == "pole" and np.isfinite(self.significance):
            out["significance"] = float(self.significance)
        if self.partner is not None:
            out["partner"] = [float(self.partner.real), float(self.partner.imag)]
        return out


@dataclass(frozen=True)
class PrunedModel:
    """Result of :func:`prune`.

    Attributes
    ----------
    transfer_function : TransferFunctionModel
        Continuous model from the kept roots, gain fitted to the unpruned response over ``band``.
    poles, zeros : tuple of PrunedRoot
        Kept roots (pairs listed once).
    removed_poles, removed_zeros : tuple of PrunedRoot
        Removed roots with the rule that removed each.
    gain : float
        The fitted gain k.
    modes : ModalParameters
        Frequencies (Hz) and damping ratios of the kept complex pole pairs.
    band : tuple of float
        Frequency band (Hz) of the gain fit and of ``fit_error``.
    cutoff : float
        Cut-off frequency of rule (a), Hz.
    fit_error : float
        Relative RMS difference ``|H - G| / |H|`` between the unpruned and the pruned response over the band.
    settings : dict
        The rule settings used.

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.identify._polynomial import DiscreteTransferFunction
    >>> num, den, _ = sig.cont2discrete(([1.0], [1.0, 2.0, 1e4]), 1e-3, method="zoh")
    >>> res = prune(DiscreteTransferFunction(tuple(num.ravel()), tuple(den), 1e-3, "u", "y"))
    >>> res.n_modes, [r.rule for r in res.removed_zeros]
    (1, ['cutoff'])
    """

    transfer_function: TransferFunctionModel
    poles: tuple[PrunedRoot, ...]
    zeros: tuple[PrunedRoot, ...]
    removed_poles: tuple[PrunedRoot, ...]
    removed_zeros: tuple[PrunedRoot, ...]
    gain: float
    modes: ModalParameters
    band: tuple[float, float]
    cutoff: float
    fit_error: float
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def n_modes(self) -> int:
        return self.modes.n_modes

    def removed_by(self, rule: str) -> tuple[PrunedRoot, ...]:
        """Removed poles and zeros attributed to one rule.

        Parameters
        ----------
        rule : str
            ``"cutoff"``, ``"unstable"``, ``"cancellation"``, ``"damping"``, ``"real"``, ``"n_modes"``,
            ``"min_peak"``, ``"with_pole"`` or ``"properness"`` (see :func:`prune`).

        Returns
        -------
        tuple of PrunedRoot
            Poles first, then zeros.
        """
        return tuple(r for r in self.removed_poles + self.removed_zeros if r.rule == rule)

    def to_dict(self) -> dict[str, Any]:
        counts: dict[str, int] = {}
        for r in self.removed_poles + self.removed_zeros:
            counts[r.rule] = counts.get(r.rule, 0) + 1
        return {
            "transfer_function": self.transfer_function.to_dict(),
            "gain": self.gain,
            "modes": self.modes.to_dict()["modes"],
            "poles": [r.to_dict() for r in self.poles],
            "zeros": [r.to_dict() for r in self.zeros],
            "removed_poles": [r.to_dict() for r in self.removed_poles],
            "removed_zeros": [r.to_dict() for r in self.removed_zeros],
            "removed_counts": counts,
            "band": list(self.band),
            "cutoff": self.cutoff,
            "fit_error": self.fit_error,
            "settings": dict(self.settings),
        }


def _representatives(z: CArray) -> CArray:
    """Upper-half-plane members of complex pairs and the real roots (conjugate duplicates dropped)."""
    tol = _REAL_TOL * np.maximum(np.abs(z), 1e-300)
    real = np.abs(z.imag) <= tol
    return np.concatenate([z[real].real.astype(complex), z[~real & (z.imag > 0)]])


def _to_s(z: CArray, dt: float) -> CArray:
    """``log(z) / dt``; a root at z = 0 becomes -inf (removed by the cut-off rule)."""
    out = np.full(z.shape, -np.inf + 0j, dtype=complex)
    nz = np.abs(z) > 0
    out[nz] = np.log(z[nz]) / dt
    return out


def _expand(roots: list[complex]) -> CArray:
    full: list[complex] = []
    for r in roots:
        if abs(r.imag) <= _REAL_TOL * max(abs(r), 1e-300):
            full.append(complex(r.real))
        else:
            full += [r, r.conjugate()]
    return np.asarray(full, dtype=complex)


def prune(
    model: PolynomialModel | DiscreteTransferFunction,
    *,
    input: str | None = None,  # noqa: A002
    cutoff: float | None = None,
    cancel_tol: float = 0.01,
    max_damping: float = 0.3,
    keep_real: bool = False,
    n_modes: int | None = None,
    min_peak: float | None = None,
    band: tuple[float, float] | None = None,
) -> PrunedModel:
    """Prune a high-order discrete model to its physical roots by the rules of thesis 4.7 (see the module notes).

    Parameters
    ----------
    model : PolynomialModel or DiscreteTransferFunction
        A fitted model (e.g. ``ARX(40, 40)``) or one of its discrete transfer functions.
    input : str, optional
        Which input's transfer function to prune (required for a multi-input model).
    cutoff : float, optional
        Anti-alias cut-off in Hz (rule a); default 0.8 x Nyquist.
    cancel_tol : float
        Pole-zero cancellation distance relative to ``|pole|`` (rule b); 0 disables the rule.
    max_damping : float
        Highest credible damping ratio (rule c).
    keep_real : bool
        Keep real poles and zeros (rule d).
    n_modes : int, optional
        Physical number of modes: keep that many complex pole pairs, the most significant (rule e).
    min_peak : float, optional
        Drop pole pairs whose modal peak is below this fraction of the largest one.
    band : (float, float), optional
        Band in Hz for the gain fit and the fit error; default ``(0, cutoff)``.

    Returns
    -------
    PrunedModel

    Examples
    --------
    >>> import numpy as np, scipy.signal as sig
    >>> from cappe.identify._polynomial import DiscreteTransferFunction
    >>> dt = 1e-3   # one lightly damped mode at 50 Hz, zeta = 0.02, sampled at 1 kHz (ZOH)
    >>> w, zeta = 2 * np.pi * 50, 0.02
    >>> num, den, _ = sig.cont2discrete(([w**2], [1, 2 * zeta * w, w**2]), dt, method="zoh")
    >>> res = prune(DiscreteTransferFunction(tuple(num.ravel()), tuple(den), dt, "u", "y"))
    >>> np.round(res.modes.frequency, 6), np.round(res.modes.damping, 6)
    (array([50.]), array([0.02]))
    """
    tf = _discrete_tf(model, input)
    dt = tf.dt
    nyquist = 0.5 / dt
    cut = 0.8 * nyquist if cutoff is None else _positive(cutoff, "cutoff")
    if cut > nyquist:
        msg = f"cutoff must not exceed the Nyquist frequency {nyquist:g} Hz; got {cut:g} Hz"
        raise DataError(msg)
    if not (np.isfinite(cancel_tol) and cancel_tol >= 0):
        msg = f"cancel_tol must be a finite number >= 0; got {cancel_tol!r}"
        raise DataError(msg)
    _positive(max_damping, "max_damping")
    if n_modes is not None and (isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) or n_modes < 1):
        msg = f"n_modes must be an integer >= 1 or None; got {n_modes!r}"
        raise DataError(msg)
    if min_peak is not None and not (0 < min_peak < 1):
        msg = f"min_peak must be a fraction in (0, 1) or None; got {min_peak!r}"
        raise DataError(msg)
    f_lo, f_hi = (0.0, cut) if band is None else _band(band, nyquist)

    num = np.asarray(tf.numerator, dtype=float)
    den = np.asarray(tf.denominator, dtype=float)
    zd_poles = np.asarray(np.roots(den), dtype=complex)
    num_trim = np.trim_zeros(num, "f")
    zd_zeros = np.roots(num_trim) if num_trim.size > 1 else np.zeros(0, complex)
    if zd_poles.size == 0:
        msg = f"the transfer function from {tf.input!r} has no poles; nothing to prune"
        raise DataError(msg)

    p_rep = _representatives(zd_poles)
    z_rep = _representatives(np.asarray(zd_zeros, dtype=complex))
    poles_s = _to_s(p_rep, dt)
    zeros_s = _to_s(z_rep, dt)
    p_sig = _significance(num, zd_poles, p_rep, dt)
    p_real = np.abs(p_rep.imag) <= _REAL_TOL * np.maximum(np.abs(p_rep), 1e-300)
    z_real = np.abs(z_rep.imag) <= _REAL_TOL * np.maximum(np.abs(z_rep), 1e-300)
    # negative real discrete roots map onto the Nyquist frequency: not physical roots of a sampled system
    p_nyq = p_real & (p_rep.real <= 0)
    z_nyq = z_real & (z_rep.real <= 0)

    p_rule = [""] * p_rep.size
    z_rule = [""] * z_rep.size
    p_partner: list[complex | None] = [None] * p_rep.size
    z_partner: list[complex | None] = [None] * z_rep.size

    def freq(s: complex) -> float:
        return float(abs(s) / (2 * np.pi))

    # (a) cut-off
    for j, s in enumerate(poles_s):
        if p_nyq[j] or not np.isfinite(s) or freq(s) > cut:
            p_rule[j] = "cutoff"
    for j, s in enumerate(zeros_s):
        if z_nyq[j] or not np.isfinite(s) or freq(s) > cut:
            z_rule[j] = "cutoff"
    # (a') unstable poles: not physical for a passive structure
    for j, s in enumerate(poles_s):
        if not p_rule[j] and s.real > 0:
            p_rule[j] = "unstable"
    # (b) cancellation: one-to-one matching of the remaining poles and zeros by relative distance
    if cancel_tol > 0:
        pi = [j for j in range(p_rep.size) if not p_rule[j]]
        zi = [j for j in range(z_rep.size) if not z_rule[j]]
        if pi and zi:
            dist = np.abs(poles_s[pi][:, None] - zeros_s[zi][None, :]) / np.abs(poles_s[pi])[:, None]
            rows, cols = linear_sum_assignment(np.where(dist < cancel_tol, dist, 1e6))
            for r, c in zip(rows, cols, strict=True):
                if dist[r, c] < cancel_tol:
                    p_rule[pi[r]] = z_rule[zi[c]] = "cancellation"
                    p_partner[pi[r]], z_partner[zi[c]] = complex(zeros_s[zi[c]]), complex(poles_s[pi[r]])
    # (c) damping and (d) real roots
    for rules, roots, real in ((p_rule, poles_s, p_real), (z_rule, zeros_s, z_real)):
        for j, s in enumerate(roots):
            if rules[j]:
                continue
            if real[j]:
                if not keep_real:
                    rules[j] = "real"
            elif abs(s.real) / abs(s) > max_damping:
                rules[j] = "damping"
    # (e) significance: min_peak, then n_modes among the remaining complex pairs
    pairs = [j for j in range(p_rep.size) if not p_rule[j] and not p_real[j]]
    if min_peak is not None and pairs:
        top = max(p_sig[j] for j in pairs)
        for j in pairs:
            if not p_sig[j] >= min_peak * top:
                p_rule[j] = "min_peak"
        pairs = [j for j in pairs if not p_rule[j]]
    if n_modes is not None and len(pairs) > n_modes:
        ranked = sorted(pairs, key=lambda j: -np.nan_to_num(p_sig[j], nan=-1.0))
        for j in ranked[n_modes:]:
            p_rule[j] = "n_modes"
    # zeros leave with their nearest pole when it was removed
    finite_p = np.isfinite(poles_s)
    for j, s in enumerate(zeros_s):
        if z_rule[j] or not finite_p.any():
            continue
        rel = np.where(finite_p, np.abs(poles_s - s) / np.where(finite_p, np.abs(poles_s), 1.0), np.inf)
        near = int(np.argmin(rel))
        if p_rule[near]:
            z_rule[j] = "with_pole"
            z_partner[j] = complex(poles_s[near])
    # properness: no more zeros than poles
    n_p = sum(1 if p_real[j] else 2 for j in range(p_rep.size) if not p_rule[j])
    kept_z = sorted((j for j in range(z_rep.size) if not z_rule[j]), key=lambda j: abs(zeros_s[j]))
    n_z = sum(1 if z_real[j] else 2 for j in kept_z)
    while n_z > n_p and kept_z:
        j = kept_z.pop()
        z_rule[j] = "properness"
        n_z -= 1 if z_real[j] else 2

    def listing(kind: str, values: CArray, rules: list[str], partners: list[complex | None]) -> list[PrunedRoot]:
        out = []
        for j, s in enumerate(values):
            sig_j = float(p_sig[j]) if kind == "pole" else float("nan")
            out.append(PrunedRoot(complex(s), kind, rules[j], sig_j, partners[j]))
        return sorted(out, key=lambda r: abs(r.value) if np.isfinite(abs(r.value)) else np.inf)

    all_p = listing("pole", poles_s, p_rule, p_partner)
    all_z = listing("zero", zeros_s, z_rule, z_partner)
    kept_p = [r for r in all_p if not r.rule]
    kept_zr = [r for r in all_z if not r.rule]
    if not kept_p:
        msg = "every pole was removed by the pruning rules; relax cutoff, max_damping or keep_real"
        raise DataError(msg)
    p_full = _expand([r.value for r in kept_p])
    z_full = _expand([r.value for r in kept_zr])

    # gain by least squares (relative errors) against the unpruned response over the band; the pruned model is
    # compared through its own ZOH discretization, so the half-sample lag of the hold does not bias the gain
    f = np.linspace(f_lo, f_hi, _GRID + 1)[1:] if f_lo == 0 else np.linspace(f_lo, f_hi, _GRID)
    h = tf.evaluate(f)
    g0 = _zoh_response(z_full, p_full, dt, f)
    gain = float(np.sum(np.real(np.conj(g0) * h)) / np.sum(np.abs(g0) ** 2))
    fit_error = float(np.linalg.norm(h - gain * g0) / np.linalg.norm(h))
    numerator = np.real(gain * np.poly(z_full)) if z_full.size else np.array([gain])
    denominator = np.real(np.poly(p_full))
    tfm = TransferFunctionModel(
        tuple(float(x) for x in numerator), tuple(float(x) for x in denominator), tf.input, tf.output, "float"
    )
    settings = {
        "cutoff": cut,
        "cancel_tol": cancel_tol,
        "max_damping": max_damping,
        "keep_real": keep_real,
        "n_modes": n_modes,
        "min_peak": min_peak,
    }
    return PrunedModel(
        tfm,
        tuple(kept_p),
        tuple(kept_zr),
        tuple(r for r in all_p if r.rule),
        tuple(r for r in all_z if r.rule),
        gain,
        modal_parameters_from_poles(p_full),
        (float(f_lo), float(f_hi)),
        float(cut),
        fit_error,
        settings,
    )


def _significance(num: Array, poles: CArray, reps: CArray, dt: float) -> Array:
    """Modal peak ``|r| / |Re lambda|`` of each representative discrete pole (nan at z = 0).

    The discrete residue ``r_d = N(p) / prod(p - p_k)`` of ``r_d / (z - p)`` is the ZOH image of the continuous
    term ``r / (s - lambda)`` with ``r = r_d lambda / (p - 1)``, ``p = exp(lambda dt)``.
    """
    out = np.full(reps.size, np.nan)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for j, p in enumerate(reps):
            if p == 0:
                continue
            others = np.delete(poles, int(np.argmin(np.abs(poles - p))))
            r_d = np.polyval(num, p) / np.prod(p - others)
            lam = np.log(complex(p)) / dt
            r_c = r_d * lam / (p - 1.0) if p != 1 else r_d / dt
            out[j] = abs(r_c) / abs(lam.real) if lam.real != 0 else np.inf
    return out


def _zoh_response(zeros: CArray, poles: CArray, dt: float, freq: Array) -> CArray:
    """Response at ``z = exp(2j pi f dt)`` of the ZOH discretization of ``prod(s - zeros) / prod(s - poles)``.

    Term by term from the partial fractions ``d + sum r_j / (s - p_j)``: the hold maps ``r / (s - p)`` to
    ``r (exp(p dt) - 1) / p / (z - exp(p dt))`` (``r dt / (z - 1)`` for p = 0). Distinct poles assumed.
    """
    z = np.exp(2j * np.pi * freq * dt)
    out = np.full(z.shape, 1.0 + 0j) if zeros.size == poles.size else np.zeros(z.shape, dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for j, p in enumerate(poles):
            r = np.prod(p - zeros) / np.prod(p - np.delete(poles, j))
            pd = np.exp(p * dt)
            rd = r * (pd - 1.0) / p if p != 0 else r * dt
            out += rd / (z - pd)
    return out


def _discrete_tf(model: PolynomialModel | DiscreteTransferFunction, input: str | None) -> DiscreteTransferFunction:  # noqa: A002
    if isinstance(model, DiscreteTransferFunction):
        return model
    if isinstance(model, PolynomialModel):
        return model.to_discrete_tf(input)
    msg = f"prune takes a fitted PolynomialModel or a DiscreteTransferFunction; got {type(model).__name__}"
    raise DataError(msg)


def _positive(value: float, name: str) -> float:
    if not (isinstance(value, (int, float, np.floating)) and np.isfinite(value) and value > 0):
        msg = f"{name} must be a positive finite number; got {value!r}"
        raise DataError(msg)
    return float(value)


def _band(band: tuple[float, float], nyquist: float) -> tuple[float, float]:
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        msg = f"band must be a pair (f_low, f_high) in Hz; got {band!r}"
        raise DataError(msg) from exc
    if not (0 <= lo < hi <= nyquist):
        msg = f"band must satisfy 0 <= f_low < f_high <= Nyquist ({nyquist:g} Hz); got ({lo:g}, {hi:g})"
        raise DataError(msg)
    return lo, hi
