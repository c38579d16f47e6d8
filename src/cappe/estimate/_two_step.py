"""The "two-step" methods (thesis 3.6.2): an experimental transfer function first, then the physical parameters whose
model transfer function matches it.

**Step 1 - experimental transfer functions.** ``fit(data)`` takes

* :class:`TimeData` with force channels named as model inputs and response channels named as model outputs: for
  each output an output-error model ``OE`` of the physical order (``nf = 2 n_dof`` per input, every excited input
  at once, ``nk = 0`` for accelerations) is fitted and converted to continuous time by the exact inverse of the
  zero-order hold (``identification="oe"``, the default; of the first-order hold for ``intersample="foh"``; for a
  band-limited input, ``intersample="bl"``, see below); or the thesis's route, a high-order ``ARX`` pruned to the
  ``n_dof`` most significant modes (``identification="arx"``, :func:`cappe.identify.prune` without its pole-zero
  cancellation rule, which would remove the weakly coupled mode of the two-mass rig's G22; zeros are mapped by
  matched-z, which is approximate, ~1e-6 relative at 2 kHz for the rig);
* :class:`FRFData`: one rational fit with a common denominator of the physical order (:func:`fit_rational`);
* :class:`TransferFunctionModel` / :class:`ZeroPoleGainModel` objects (or a sequence of them, a
  :class:`RationalFit` or :class:`PrunedModel`), used as given.

**Step 1 for a band-limited input** (``intersample="bl"``, what a DAQ with an anti-alias filter records). A
band-limited input has no finite-order discrete equivalent: any discrete model converted by a hold's inverse is
biased (the first-order hold's gain error is about ``(omega dt)^2 / 12``, 1.2 % at the rig's 119 Hz mode at 2 kHz,
which left m1, k11 and c11 2.5 % low and failed the chi-square test below on every DAQ record). The samples of a
band-limited input determine it between the samples, so the response of a continuous model to it is determined
too: :func:`cappe.systems.statespace.band_limited_modal_response` computes it (the one-step method's simulation).
Step 1 therefore fits, per output, a continuous output-error model ``y = sum_i G_i(s) u_i + offset + free
response`` with the physical order's complex pole pairs shared by the inputs (:class:`_BandLimitedOE`) by
separable least squares: the residues, feed-throughs, offset and initial state are linear and solved at every
pole vector, which a trust region searches from the first-order-hold model's poles. Its Gauss-Newton covariance is
in the continuous model's own parameters, carried to the coefficients by the same delta method as the OE route
(:func:`_linearized`). Against the rig's true transfer functions on a noise-free 64x DAQ record: 3e-5 relative
at 10-400 Hz (the first-order-hold stand-in: 1.2 % at 119 Hz, 12 % at 400 Hz). A time-domain fit rather than a
frequency-domain one on the record's DFT lines (Pintelon and Schoukens): it is exact at every sample of a record
that starts at rest or whose initial state the free response takes, needs no leakage term and no band selection,
and its output errors go to the same residual tests as the OE route. A delay between force and response is not
modelled (estimated per output it trades with the numerators' high coefficients): the residual tests and the
chi-square test below have to catch it.

**Step 1 for held or linear inputs** (``zoh`` or ``foh``). The OE model has one denominator per input, the physics
one for all: where an input excites a mode weakly, its path may place that mode elsewhere (on ``lsim`` records with
F1 + F2 and 5 % noise, d2's F2 path lost the rig's 181 Hz mode, and the second step FAILED its chi-square test on 8
of 10 records); and with one input its search stops in local minima (F1 only, 5 % noise: d1's lightly damped 99.5 Hz
mode misplaced, a loss 1.2-1.5 x the continuous model's from the same poles, the chi-square test FAILED on 4-5 of 10
records). Step 1 then fits the same continuous model with shared poles (its residues solved at every pole
vector), simulated with the held or linear input
(the exact step of each mode, :func:`cappe.systems.statespace.hold_weights`; no feed-through where a held input
reaches a displacement or velocity one sample late), from each input's OE poles, the lowest cost kept. Natural
frequencies are bounded by the Nyquist frequency (above it a mode is an alias of one below at the samples).

**Step 2 - matching.** The model's transfer functions at a parameter vector come from the exact polynomial form
``G(s) = S adj(Z(s)) B / det(Z(s))``, ``Z(s) = M s^2 + (C + G) s + K``: both polynomials are sampled on a circle of
radius ``rho`` (the geometric mean natural frequency at the start) and their coefficients recovered by an FFT, which
is exact for polynomials and perfectly conditioned in the scaled variable ``s / rho``. The derivatives with respect to
the unknowns come the same way from ``d det Z = det Z tr(Z^-1 dZ)`` and ``d Z^-1 = -Z^-1 dZ Z^-1`` with the exact
``dM, dC, dK`` of the affine model, so the Gauss-Newton Jacobian is exact.

* :class:`TwoStepTFEstimator` compares coefficients by the normalized-square index of thesis eqs 3.98/3.99: the
  residuals are ``(a_model(p) - a_exp) / a_exp`` for every denominator coefficient below the leading one (monic
  denominators) and every numerator coefficient of every pair. Coefficients that vanish in the model for all values
  of the unknowns (structural zeros, e.g. the ``s`` term of ``d2/F1`` when ``c12 = 0`` is known, or terms above the
  model's numerator degree) are not compared: the identified value there is noise. Identical experimental
  denominators (a common-denominator fit) are compared once.
* :class:`TwoStepZPKEstimator` compares poles, zeros and gains (thesis eq. 3.103). Model and experimental roots are
  paired by the Hungarian assignment on their relative distance ``|l_m - l_e| / |l_e|``; extra experimental roots (far
  sampling or noise zeros) stay unpaired and are listed in the diagnostics. Each paired root gives the relative
  errors of its natural frequency ``|l|`` and damping ratio ``-Re(l) / |l|`` (``roots="frequency-damping"``) or
  the real and imaginary parts of ``(l_m - l_e) / l_e`` (``roots="complex"``); each member of a complex pair is
  weighted by ``1 / sqrt(2)`` so that a pair counts once. The gain is the low-frequency asymptote ``b_k / a_j``
  (lowest non-zero numerator and denominator coefficients; the static gain for displacement outputs), robust to
  far-away spurious zeros that change the leading coefficient a lot.

Every residual can be scaled per pair (``weights={"F1->d1": 2.0}``); by default all weights are 1, so the cost is
the thesis's normalized-square index. The search runs in log coordinates inside the bounds from the start and
``n_starts - 1`` scrambled Sobol points (seeded by ``rng``); the lowest cost wins.

**Identifiability.** With one input and the outputs d1, d2 of the two-mass rig (thesis eqs 5.7-5.12), the eight
compared coefficients of G11 and G21 determine the seven parameters only through a term of a few per cent (``k12``
enters ``a0`` as ``k12^2 / (m1 m2)`` next to ``(k11 + k12)(k12 + k22) / (m1 m2)``), so noise in ``a0`` is amplified
about 40 times into ``k12`` and ``m2`` (condition number ~460; with 1 % output noise m2, k12, k22 and c22 came out
up to 23 % off, all together along that direction). Exciting F2 as well adds G22, whose numerator
``s^2 / m2 + ...`` fixes m2 directly, and G12 = G21 (reciprocity) a second estimate of ``k12 / (m1 m2)``
(condition number ~8): excite both inputs. With G11 alone m2 is not determined at all (only ratios such as
``k12^2 / m2``); the estimate then reports it non-identifiable.

**Weighting by step 1's covariance (minimum distance, ``weighting="auto"`` default for time data).** The
normalized-square index weighs every coefficient alike although step 1 determines them with very different
precision, so small errors of the poorly determined ones become large errors of the parameters (issue 21: m2 off
by up to 80 % with F1 only, 1 % noise). The OE fit of step 1 has a parameter covariance ``cov(theta)``; its first-order
propagation through the inverse hold map (:func:`_propagate`: central differences of the map at steps of 1e-3
standard errors) gives the covariance ``S`` of the continuous coefficients, every pair of one output correlated
through their shared OE parameters, outputs independent. The second step then minimizes
``(c_model(p) - c_exp)^T S^+ (c_model(p) - c_exp)`` (Markov / minimum-distance estimation) over *every* identified
coefficient, those of the model's structural zeros compared against 0 (their noise informs the others through the
correlations). ``S^+`` is the pseudo-inverse on the eigen-directions of the correlation matrix above 1e-10 of its
largest eigenvalue (exact duplicates such as the members of a complex pair fall below). The zero-pole variant
compares the same information in its own coordinates: each paired root's relative frequency and damping (or complex
error), the low-frequency gain, and, for the experimental roots the model does not have (its roots at infinity),
the coefficients of ``prod (1 - s / root)`` in ``s / rho`` against 0; their covariance is propagated from ``S`` by
the exact root derivatives ``d root / d c_i = -root^i / P'(root)``. Both variants then reach the one-step method's
accuracy on the issue's repro (max error 0.33 % over 10 seeds, one-step 0.31 %). Transfer functions given directly,
fitted to FRFs or pruned from an ARX model have no covariance: the index above is used and the diagnostics say why.

**Uncertainty.** Weighted: ``cov(p) = (J^T S^+ J)^-1`` and the chi-square test of the fit, ``chi2 = r^T S^+ r`` on
``rank(S) - n_unknowns`` degrees of freedom (``diagnostics["second_step_test"]``): p below 1 % means the physical
model does not reproduce step 1's transfer functions within their uncertainty (wrong structure, or step 1 biased
by a wrong intersample assumption or a delay); the fit is then FAILED (``success`` False) with a warning line, and
the covariance is scaled by ``chi2 / dof`` (which widens the intervals but cannot cover a bias). Unweighted: the
standard errors come from the Jacobian of the normalized residuals with their variance estimated from the residuals
themselves (:func:`jacobian_uncertainty`); the identified coefficients or roots do not have equal relative
precision, so these are a scale, not calibrated intervals (over repeated 1 % noise runs of the rig they were within
a factor of about 3 of the observed scatter, either way).
"""

from __future__ import annotations

import warnings
from abc import abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2 as chi2_distribution
from scipy.stats import qmc

from cappe._rng import RandomLike
from cappe.estimate._base import (
    _EXACT_FIT_RMS,
    Estimator,
    Fitted,
    least_squares_fit,
    with_noise_variance,
    with_residual_tests,
)
from cappe.estimate._space import ParameterSpace
from cappe.estimate._uncertainty import jacobian_uncertainty
from cappe.exceptions import DataError, IllConditionedWarning, ModelError
from cappe.model import NumericModel, Structure
from cappe.systems.frf import FRFData
from cappe.systems.mechanical import DERIVATIVE_ORDER
from cappe.systems.statespace import StateSpaceModel, check_intersample
from cappe.systems.timedata import TimeData
from cappe.systems.transfer import TransferFunctionModel
from cappe.systems.zpk import ZeroPoleGainModel

__all__ = ["TwoStepTFEstimator", "TwoStepZPKEstimator", "model_transfer_functions"]

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

#: A scaled coefficient below this fraction of the largest sample of its polynomial is a structural zero when it is
#: one at three generic parameter vectors (FFT round-off is ~1e-15 of the samples).
_STRUCTURAL_RTOL = 1e-9
_IDENTIFICATIONS = ("oe", "arx")
_WEIGHTINGS = ("auto", "covariance", "none")
#: Eigenvalues of the correlation matrix of the compared quantities below this fraction of the largest are dropped
#: from the weighting (pseudo-inverse): exact duplicates (the two members of a complex pair, one denominator compared
#: twice) and combinations known to better than the arithmetic that propagated the covariance (~1e-5 relative).
_WHITEN_RTOL = 1e-10
#: Level of the second step's chi-square test (as the residual tests of step 1: 1 %).
_CHI2_LEVEL = 0.01
_ROOT_FORMS = ("frequency-damping", "complex")


# ---------------------------------------------------------------------------------------------------------------
# model transfer-function coefficients


@dataclass(frozen=True)
class _Pair:
    input: str
    output: str
    column: int  # model input index
    row: int  # model output index
    order: int  # time-derivative order of the output

    @property
    def label(self) -> str:
        return f"{self.input}->{self.output}"


class _ModelTF:
    """Numerator and denominator coefficients of the model's transfer functions and their derivatives."""

    def __init__(
        self, model: NumericModel, space: ParameterSpace, pairs: Sequence[_Pair], position: Mapping[str, float] | None
    ) -> None:
        self.model = model
        self.space = space
        self.pairs = tuple(pairs)
        self.position = position
        n = model.n_dof
        self.n = n
        self.degree = 2 * n
        self.n_points = 4 * n + 4
        mats = model.matrices(space.full(space.start), position)
        if np.any(mats["H"]):
            msg = (
                f"model '{model.structure.name}' has hysteretic damping (H != 0): its transfer functions are not "
                f"rational in s; the two-step methods need viscous damping"
            )
            raise ModelError(msg)
        try:
            lam = np.linalg.eigvals(np.linalg.solve(mats["M"], mats["K"])).real
        except np.linalg.LinAlgError as exc:
            msg = f"model '{model.structure.name}' has a singular mass matrix at the start values"
            raise ModelError(msg) from exc
        positive = lam[lam > 0]
        self.rho = float(np.exp(np.mean(np.log(np.sqrt(positive))))) if positive.size else 1.0
        j = np.arange(self.n_points)
        self.x = np.exp(1j * np.pi * (2 * j + 1) / self.n_points)  # unit circle, off the real and imaginary axes
        self.s = self.rho * self.x
        self.shift = np.exp(-1j * np.pi * np.arange(self.n_points) / self.n_points)
        self.analytic = self._io_constant()
        self.num_mask, self.den_mask = self._structure()

    def _io_constant(self) -> bool:
        lo, hi = self.space.internal_bounds()
        u = self.space.to_internal(self.space.start)
        u2 = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi), u + 0.1)
        b1, s1 = self.model.io_matrices(self.space.full(self.space.start), self.position)
        b2, s2 = self.model.io_matrices(self.space.full(self.space.from_internal(u2)), self.position)
        return bool(np.array_equal(b1, b2) and np.array_equal(s1, s2))

    def _coefficients(self, values: CArray) -> CArray:
        """Scaled coefficients (..., degree + 1), ascending powers of s / rho, of polynomials sampled at ``self.s``."""
        c = np.fft.fft(values, axis=-1) / self.n_points * self.shift
        return np.asarray(c[..., : self.degree + 1], dtype=complex)

    def raw(self, p: Array, derivatives: bool = False) -> tuple[Array, Array, Array | None, Array | None, Array, Array]:
        """Scaled, un-normalized coefficients: num (n_pairs, d+1), den (d+1,), their derivatives (..., n_unknowns),
        and the magnitude of the samples of each polynomial (for the structural-zero test)."""
        full = self.space.full(np.asarray(p, dtype=float))
        mats = self.model.matrices(full, self.position, names=("M", "C", "G", "K"))
        m, d, k = mats["M"], mats["C"] + mats["G"], mats["K"]
        b_mat, s_mat = self.model.io_matrices(full, self.position)
        s = self.s
        z = m[None] * (s**2)[:, None, None] + d[None] * s[:, None, None] + k[None]
        zinv = np.linalg.inv(z)
        det = np.linalg.det(z)
        cols = np.array([pr.column for pr in self.pairs])
        rows = np.array([pr.row for pr in self.pairs])
        orders = np.array([pr.order for pr in self.pairs])
        u = np.einsum("fab,bp->fap", zinv, b_mat[:, cols])  # Z^-1 b per pair (n_f, n, n_pairs)
        w = np.einsum("pa,fab->fpb", s_mat[rows], zinv)  # s^T Z^-1 per pair (n_f, n_pairs, n)
        powers = s[:, None] ** orders[None, :]
        g = np.einsum("pa,fap->fp", s_mat[rows], u) * powers  # s^T Z^-1 b s^order (n_f, n_pairs)
        num_samples = (det[:, None] * g).T  # (n_pairs, n_f)
        num = self._coefficients(num_samples).real
        den = self._coefficients(det).real
        num_scale = np.abs(num_samples).max(axis=1)
        den_scale = np.array([np.abs(det).max()])
        if not derivatives:
            return num, den, None, None, num_scale, den_scale
        der = self.model.matrix_derivatives(full, self.position, names=("M", "C", "G", "K"))
        c_idx = self.space.columns
        dm, dd, dk = der["M"][c_idx], der["C"][c_idx] + der["G"][c_idx], der["K"][c_idx]
        dz = (
            dm[None] * (s**2)[:, None, None, None] + dd[None] * s[:, None, None, None] + dk[None]
        )  # (n_f, n_u, n, n)
        ddet = det[:, None] * np.einsum("fab,fjba->fj", zinv, dz)  # (n_f, n_u)
        dg = -np.einsum("fpa,fjab,fbp->fpj", w, dz, u) * powers[:, :, None]  # (n_f, n_pairs, n_u)
        dnum_samples = ddet[:, None, :] * g[:, :, None] + det[:, None, None] * dg
        dnum = self._coefficients(np.moveaxis(dnum_samples, 0, -1)).real  # (n_pairs, n_u, d+1)
        dden = self._coefficients(ddet.T).real  # (n_u, d+1)
        return num, den, np.moveaxis(dnum, 1, 2), dden.T, num_scale, den_scale

    def _structure(self) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """Coefficients that are non-zero for generic values of the unknowns (checked at three vectors)."""
        sp = self.space
        lo, hi = sp.internal_bounds()
        u0 = sp.to_internal(sp.start)
        num_mask = np.zeros((len(self.pairs), self.degree + 1), dtype=bool)
        den_mask = np.zeros(self.degree + 1, dtype=bool)
        for shift in (0.0, 0.618034, 0.381966):
            frac = np.mod(shift + 0.7548777 * np.arange(1, sp.n + 1), 1.0)
            u = np.where(np.isfinite(lo) & np.isfinite(hi), lo + frac * (hi - lo), u0 * (1 + 0.1 * frac))
            p = sp.start if shift == 0.0 else sp.from_internal(u)
            num, den, _, _, n_scale, d_scale = self.raw(p)
            num_mask |= np.abs(num) > _STRUCTURAL_RTOL * n_scale[:, None]
            den_mask |= np.abs(den) > _STRUCTURAL_RTOL * d_scale
        if not den_mask[-1]:
            msg = f"model '{self.model.structure.name}' has a singular mass matrix; its transfer functions are improper"
            raise ModelError(msg)
        return num_mask, den_mask

    def evaluate(self, p: Array, derivatives: bool = False) -> tuple[Array, Array, Array | None, Array | None]:
        """Coefficients in SI (ascending powers of s, monic denominator) and their derivatives (..., n_unknowns)."""
        num, den, dnum, dden, _, _ = self.raw(p, derivatives)
        unscale = self.rho ** -np.arange(self.degree + 1, dtype=float)
        num_u, den_u = num * unscale, den * unscale
        lead = den_u[-1]
        num_si, den_si = num_u / lead, den_u / lead
        if dnum is None or dden is None:
            return num_si, den_si, None, None
        dnum_u, dden_u = dnum * unscale[None, :, None], dden * unscale[:, None]
        dlead = dden_u[-1]
        dnum_si = dnum_u / lead - num_u[:, :, None] * dlead / lead**2
        dden_si = dden_u / lead - den_u[:, None] * dlead / lead**2
        return num_si, den_si, dnum_si, dden_si


def model_transfer_functions(
    model: NumericModel | Structure,
    pairs: Sequence[tuple[str, str]],
    params: Mapping[str, float] | None = None,
    *,
    unknowns: Sequence[str] | None = None,
    position: Mapping[str, float] | None = None,
) -> tuple[TransferFunctionModel, ...]:
    """Transfer functions of a model from the exact polynomial form ``S adj(Z) B / det(Z)`` (no pole-zero cancellation).

    Structural zeros (coefficients that vanish for all values of ``unknowns``, by default the parameters marked
    unknown in the model) are exact zeros; leading ones are dropped.

    Parameters
    ----------
    model : NumericModel or Structure
    pairs : sequence of (input, output)
        Model input and output names.
    params : mapping, optional
        Parameter overrides (SI).
    unknowns : sequence of str, optional
        The parameters that may vary (for the structural zeros).
    position : mapping, optional
        Axis positions.

    Returns
    -------
    tuple of TransferFunctionModel
        One per pair, monic denominator of degree ``2 n_dof``.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> (g11,) = model_transfer_functions(load_model("builtin:two-mass-rig"), [("F1", "d1")])
    >>> [round(c, 6) for c in g11.numerator]     # 1/m1, c22/(m1 m2), (k12 + k22)/(m1 m2): eq. 5.8 with b2 = 1/m1
    [0.719424, 0.310211, 237608.078675]
    """
    nm = model if isinstance(model, NumericModel) else NumericModel(model)
    space = ParameterSpace.from_model(nm, unknowns, values=params)
    resolved = _pairs(nm, pairs)
    engine = _ModelTF(nm, space, resolved, position)
    num, den, _, _ = engine.evaluate(space.start)
    out = []
    for k, pair in enumerate(resolved):
        coef = np.where(engine.num_mask[k], num[k], 0.0)
        top = int(np.flatnonzero(engine.num_mask[k]).max()) if engine.num_mask[k].any() else 0
        d_coef = np.where(engine.den_mask, den, 0.0)
        out.append(
            TransferFunctionModel(
                tuple(float(c) for c in coef[: top + 1][::-1]), tuple(float(c) for c in d_coef[::-1]), pair.input,
                pair.output,
            )
        )
    return tuple(out)


def _pairs(model: NumericModel, pairs: Sequence[Any]) -> list[_Pair]:
    out = []
    for item in pairs:
        if not (isinstance(item, (tuple, list)) and len(item) == 2):
            msg = f"each pair must be (input, output); got {item!r}"
            raise DataError(msg)
        inp, outp = item
        if inp not in model.input_names:
            msg = f"pair {inp}->{outp}: {inp!r} is not an input of model '{model.structure.name}'; its inputs are " \
                  f"{list(model.input_names)}"
            raise DataError(msg)
        if outp not in model.output_names:
            msg = f"pair {inp}->{outp}: {outp!r} is not an output of model '{model.structure.name}'; its outputs " \
                  f"are {list(model.output_names)}"
            raise DataError(msg)
        row = model.output_names.index(outp)
        order = DERIVATIVE_ORDER.get(model.output_quantities[row])
        if order is None:
            msg = f"pair {inp}->{outp}: output quantity {model.output_quantities[row]!r} has no transfer function"
            raise DataError(msg)
        out.append(_Pair(inp, outp, model.input_names.index(inp), row, order))
    labels = [p.label for p in out]
    repeated = sorted({x for x in labels if labels.count(x) > 1})
    if repeated:
        msg = f"pairs must be listed once each; repeated: {repeated}"
        raise DataError(msg)
    if not out:
        msg = "no input/output pairs to compare"
        raise DataError(msg)
    return out


# ---------------------------------------------------------------------------------------------------------------
# step 1: experimental transfer functions


def _coefficients_of(tf: TransferFunctionModel) -> tuple[Array, Array]:
    """Ascending, monic float coefficients."""
    num, den = tf.float_coefficients()
    den = np.trim_zeros(den, "f")
    if den.size == 0 or not np.all(np.isfinite(num)) or not np.all(np.isfinite(den)):
        msg = f"transfer function {tf.input}->{tf.output} has no denominator or non-finite coefficients"
        raise DataError(msg)
    return num[::-1] / den[0], den[::-1] / den[0]


def _as_tf(item: Any) -> TransferFunctionModel:
    if isinstance(item, TransferFunctionModel):
        return item
    if isinstance(item, ZeroPoleGainModel):
        num = np.real_if_close(item.gain * np.poly(item.zeros)) if item.zeros.size else np.array([item.gain])
        den = np.real_if_close(np.poly(item.poles))
        return TransferFunctionModel(
            tuple(float(np.real(c)) for c in np.atleast_1d(num)), tuple(float(np.real(c)) for c in den), item.input,
            item.output,
        )
    msg = f"expected TransferFunctionModel or ZeroPoleGainModel; got {type(item).__name__}"
    raise DataError(msg)


def _given_tfs(data: Any) -> list[TransferFunctionModel] | None:
    """Transfer functions handed over directly (None when ``data`` is something else)."""
    from cappe.identify._prune import PrunedModel
    from cappe.identify._rational import RationalFit

    if isinstance(data, (TransferFunctionModel, ZeroPoleGainModel)):
        return [_as_tf(data)]
    if isinstance(data, RationalFit):
        return list(data.transfer_functions)
    if isinstance(data, PrunedModel):
        return [data.transfer_function]
    if isinstance(data, (list, tuple)) and data and all(
        isinstance(x, (TransferFunctionModel, ZeroPoleGainModel, PrunedModel)) for x in data
    ):
        return [x.transfer_function if isinstance(x, PrunedModel) else _as_tf(x) for x in data]
    return None


@dataclass(frozen=True)
class _Step1:
    """What step 1 found: the experimental transfer functions of the pairs and, where step 1 has them, its output
    errors (for the residual tests) and the covariance of its continuous coefficients (for the weighting)."""

    pairs: list[_Pair]
    tfs: list[TransferFunctionModel]
    source: str
    #: (errors (n_samples, n_out), inputs (n_samples, n_in), output names, input names) of an OE step 1
    errors: tuple[Array, Array, list[str], list[str]] | None = None
    #: per pair: numerator (degree + 1) then denominator below its leading 1 (degree), ascending powers of s (SI)
    coefficients: Array | None = None
    #: covariance of ``coefficients`` (first-order propagation of step 1's parameter covariance)
    covariance: Array | None = None
    #: why there is no covariance (when there is none)
    no_covariance: str = ""
    #: what the user must read about step 1 (a WARNING line)
    warning: str = ""


def _experimental(est: _TwoStep, model: NumericModel, data: Any) -> _Step1:
    """Step 1: experimental transfer functions of the chosen pairs, and how they were obtained."""
    given = _given_tfs(data)
    if given is not None:
        available = [(tf.input, tf.output) for tf in given]
        wanted = list(est.pairs) if est.pairs is not None else available
        pairs = _pairs(model, list(wanted))
        by_label = {f"{tf.input}->{tf.output}": tf for tf in given}
        missing = [p.label for p in pairs if p.label not in by_label]
        if missing:
            msg = f"no experimental transfer function given for pair(s) {missing}; given: {sorted(by_label)}"
            raise DataError(msg)
        return _Step1(pairs, [by_label[p.label] for p in pairs], "given",
                      no_covariance="transfer functions given without their covariance")
    if isinstance(data, FRFData):
        return _from_frf(est, model, data)
    if isinstance(data, TimeData):
        return _from_time(est, model, data)
    msg = (
        f"two-step estimation takes TimeData, FRFData or transfer functions (TransferFunctionModel / "
        f"ZeroPoleGainModel, a sequence of them, a RationalFit or PrunedModel); got {type(data).__name__}"
    )
    raise DataError(msg)


def _default_pairs(est: _TwoStep, model: NumericModel, inputs: Sequence[str], outputs: Sequence[str],
                   where: str) -> list[_Pair]:
    ins = [i for i in model.input_names if i in inputs]
    outs = [o for o in model.output_names if o in outputs]
    if not ins:
        msg = f"{where} has no channel named after a model input {list(model.input_names)}; channels: {list(inputs)}"
        raise DataError(msg)
    if not outs:
        msg = (
            f"{where} has no channel named after a model output {list(model.output_names)}; channels: "
            f"{list(outputs)}"
        )
        raise DataError(msg)
    wanted = list(est.pairs) if est.pairs is not None else [(i, o) for o in outs for i in ins]
    pairs = _pairs(model, list(wanted))
    for p in pairs:
        lacking = [c for c in (p.input, p.output) if c not in (*inputs, *outputs)]
        if lacking:
            msg = (
                f"pair {p.label} needs channel(s) {lacking}, which {where} lacks; channels: "
                f"{sorted({*inputs, *outputs})}"
            )
            raise DataError(msg)
    return pairs


def _from_time(est: _TwoStep, model: NumericModel, data: TimeData) -> _Step1:
    from cappe.identify._polynomial import ARX, OE
    from cappe.identify._prune import prune

    pairs = _default_pairs(est, model, data.channels, data.channels, "the time data")
    inputs = [i for i in model.input_names if i in data.channels]  # every excited input enters each output's model
    n = 2 * model.n_dof
    tfs: dict[str, TransferFunctionModel] = {}
    errors: dict[str, Any] = {}
    propagated: dict[str, tuple[Array, Array] | str] = {}
    fallback: list[str] = []
    for output in dict.fromkeys(p.output for p in pairs):
        order = next(p.order for p in pairs if p.output == output)
        # a held input reaches a displacement or velocity one sample late; a linear one within the sample
        nk = 0 if order == 2 or est.intersample != "zoh" else 1
        if est.identification == "oe":
            nb = n + 1 if nk == 0 else n
            oe = OE(nb=[nb] * len(inputs), nf=[n] * len(inputs), nk=[nk] * len(inputs)).fit(
                data, inputs=inputs, output=output
            )
            y = data.channel(output)
            hold = "zoh" if est.intersample == "zoh" else "foh"
            names = [p.input for p in pairs if p.output == output]
            # a band-limited input has no finite-order discrete equivalent, the OE model's denominators of
            # several inputs are not shared, and the discrete OE search itself stops in local minima (one input,
            # 5 % noise: d1's lightly damped 99.5 Hz mode misplaced on 4 of 10 lsim records, a cost 1.2-1.5 x
            # the continuous model's from the same poles): the continuous model with the physical poles shared
            # by the inputs, its residues solved at every pole vector, simulated as the input behaves between the
            # samples, from each input's OE poles (the lowest cost; band-limited: from the first input's, as
            # measured in the README's tables)
            bl: _BandLimitedOE | str = "no start"
            for name in inputs if est.intersample != "bl" else inputs[:1]:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", IllConditionedWarning)
                    start = oe.continuous_poles(name)
                trial = _fit_continuous_oe(data, inputs, output, start, est.intersample, feedthrough=nk == 0)
                if isinstance(bl, str) or (not isinstance(trial, str) and trial.errors @ trial.errors
                                           < bl.errors @ bl.errors):
                    bl = trial
            if not isinstance(bl, str):
                errors[output] = bl.errors
                coef = bl.coefficients(bl.parameters_, names)
                for k, name in enumerate(names):
                    block = coef[k * (2 * n + 1): (k + 1) * (2 * n + 1)]
                    tfs[f"{name}->{output}"] = TransferFunctionModel(
                        tuple(float(c) for c in block[: n + 1][::-1]),
                        (1.0, *(float(c) for c in block[n + 1:][::-1])), name, output)
                propagated[output] = (bl.no_covariance if bl.covariance_ is None else _linearized(
                    partial(bl.coefficients, inputs=names), bl.parameters_, bl.covariance_))
                continue
            fallback.append(f"{output}: {bl}")
            errors[output] = oe.residuals(data) / max(float(np.sqrt(np.mean((y - y.mean()) ** 2))), 1e-300)
            for p in pairs:
                if p.output == output:
                    tfs[p.label] = oe.to_transfer_function(p.input, negative_real="reflect", intersample=hold)
            propagated[output] = _propagate(oe, names, hold, n, strictly_proper=nk == 1)
        else:
            na = int(est.arx_order)
            arx = ARX(na, [na] * len(inputs), [nk] * len(inputs)).fit(data, inputs=inputs, output=output)
            for p in pairs:
                if p.output == output:
                    pruned = prune(arx, input=p.input, n_modes=model.n_dof, keep_real=order > 0, cancel_tol=0.0)
                    tfs[p.label] = pruned.transfer_function
    # step 1's output errors, for the residual tests of its fit (OE: the simulated output's errors)
    tested = ((np.column_stack(list(errors.values())), np.column_stack([data.channel(i) for i in inputs]),
               list(errors), inputs) if errors else None)
    source = f"{est.identification} (time data)"
    if est.intersample == "bl" and est.identification == "oe":
        source = ("continuous output-error model simulated with a band-limited input (time data)" if not fallback else
                  f"oe (time data), the first-order hold standing in for a band-limited input ({'; '.join(fallback)})")
    elif est.identification == "oe":
        shared = " with poles shared by the inputs" if len(inputs) > 1 else ""
        source = (f"continuous output-error model{shared}, simulated with a "
                  f"{'held' if est.intersample == 'zoh' else 'linear'} input (time data)" if not fallback else
                  f"oe (time data){', one denominator per input' if len(inputs) > 1 else ''} ({'; '.join(fallback)})")
    tf_list = [tfs[p.label] for p in pairs]
    warning = ""
    if fallback and est.intersample == "bl":
        warning = (f"step 1 fell back to the first-order hold's inverse for a band-limited input, which is biased "
                   f"(gain error ~(omega dt)^2 / 12): {'; '.join(fallback)}")
    elif fallback and len(inputs) > 1:
        warning = (f"step 1 fell back to one output-error denominator per input, which need not share the poles: "
                   f"{'; '.join(fallback)}")
    elif fallback:
        warning = (f"step 1 fell back to the discrete output-error model, whose search may stop in a local minimum: "
                   f"{'; '.join(fallback)}")
    if est.identification != "oe":
        return _Step1(pairs, tf_list, source, tested,
                      no_covariance="the pruned ARX model (identification 'arx') has no covariance of its modes")
    exact = [o for o, e in errors.items() if not float(np.sqrt(np.mean(e**2))) > _EXACT_FIT_RMS]
    if exact:
        return _Step1(pairs, tf_list, source, tested, no_covariance=(
            f"step 1 fits {exact} exactly (output errors below {_EXACT_FIT_RMS:g} of the outputs): its covariance is "
            f"round-off"), warning=warning)
    failed = [f"{o}: {why}" for o, why in propagated.items() if isinstance(why, str)]
    if failed:
        return _Step1(pairs, tf_list, source, tested, no_covariance="; ".join(failed), warning=warning)
    coef, cov = _stack_pairs(pairs, {o: v for o, v in propagated.items() if not isinstance(v, str)}, n)
    return _Step1(pairs, tf_list, source, tested, coef, cov, warning=warning)


def _continuous_coefficients(ss: StateSpaceModel) -> tuple[Array, Array]:
    """Numerator (n + 1) and monic denominator (n + 1) coefficients, ascending powers of s, of a SISO continuous
    state-space model of order n: ``det(sI - A) (C (sI - A)^-1 B + D)`` and ``det(sI - A)`` sampled on a circle
    of radius the geometric mean of the poles' magnitudes and recovered by an FFT (exact for polynomials, smooth in
    the matrices, unlike roots that come and go at infinity)."""
    a, b, c, d = ss.A, ss.B[:, 0], ss.C[0], float(ss.D[0, 0])
    n = a.shape[0]
    poles = np.linalg.eigvals(a)
    mags = np.abs(poles[np.abs(poles) > 0])
    rho = float(np.exp(np.mean(np.log(mags)))) if mags.size else 1.0
    m = 2 * (n + 1)
    k = np.arange(m)
    s = rho * np.exp(1j * np.pi * (2 * k + 1) / m)
    den_s = np.prod(s[:, None] - poles[None, :], axis=1)
    g = np.array([c @ np.linalg.solve(sk * np.eye(n) - a, b) for sk in s]) + d
    shift = np.exp(-1j * np.pi * k / m) / m
    unscale = rho ** -np.arange(n + 1, dtype=float)
    num = (np.fft.fft(den_s * g) * shift)[: n + 1].real * unscale
    den = (np.fft.fft(den_s) * shift)[: n + 1].real * unscale
    return num / den[-1], den / den[-1]


def _propagate(oe: Any, inputs: Sequence[str], hold: str, degree: int, *, strictly_proper: bool = False) -> tuple[
        Array, Array] | str:
    """The continuous coefficients of an OE model's transfer functions from ``inputs`` (per input: numerator
    ``degree + 1``, then the denominator below its leading 1) and their covariance, ``G cov(theta) G^T``: the
    first-order (delta-method) propagation of the OE parameter covariance through the inverse hold map
    (:meth:`PolynomialModel.to_state_space`). ``G`` is the central difference of the map with steps of 1e-3 of each
    parameter's standard error: a linearization over the scale the covariance describes (its truncation error is
    ~1e-6 of the propagated standard errors; 1e-2 and 1e-4 steps agree to that). With a delay of one sample
    (``strictly_proper``: a held input reaching a displacement or velocity) the continuous equivalent has no
    ``s^degree`` numerator term: that coefficient is round-off and is set to exactly 0 with no variance (it is then
    not compared). Returns why not where the covariance is not finite."""
    theta = np.asarray(oe.parameters_, dtype=float)
    cov = np.asarray(oe.covariance_, dtype=float)
    std = np.sqrt(np.diag(cov))
    if not (np.all(np.isfinite(cov)) and np.all(std > 0)):
        return "the output-error model's parameter covariance is not finite (its parameters are not all identifiable)"

    def coefficients(t: Array) -> Array:
        model = oe.with_parameters(t)
        parts = []
        for name in inputs:
            num, den = _continuous_coefficients(
                model.to_state_space(name, negative_real="reflect", intersample=hold))
            if num.size != degree + 1:
                msg = f"internal error: a continuous equivalent of order {num.size - 1}, expected {degree}"
                raise RuntimeError(msg)
            if strictly_proper:
                num[degree] = 0.0
            parts += [num, den[:degree]]
        return np.concatenate(parts)

    with warnings.catch_warnings():  # a perturbed model's negative real poles were reported for the fitted one
        warnings.simplefilter("ignore", IllConditionedWarning)
        return _linearized(coefficients, theta, cov)


def _linearized(coefficients: Callable[[Array], Array], theta: Array, cov: Array) -> tuple[Array, Array]:
    """``coefficients(theta)`` and its covariance ``G cov G^T`` (delta method), ``G`` by central differences with
    steps of 1e-3 of each parameter's standard error (parameters without variance do not move)."""
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    centre = coefficients(theta)
    jac = np.zeros((centre.size, theta.size))
    for j in np.flatnonzero(std > 0):
        step = np.zeros_like(theta)
        step[j] = 1e-3 * std[j]
        jac[:, j] = (coefficients(theta + step) - coefficients(theta - step)) / (2 * step[j])
    return centre, jac @ cov @ jac.T


# ---------------------------------------------------------------------------------------------------------------
# step 1 for a band-limited input: a continuous-time output-error model simulated as the DAQ recorded the input

@dataclass(frozen=True)
class _BandLimitedOE:
    """A continuous-time output-error model of one output, ``y = sum_i G_i(s) u_i + offset + free response``,
    fitted with the band-limited simulation of :func:`band_limited_modal_response` (exact at the samples of a
    band-limited input, as a DAQ with an anti-alias filter records it).

    ``G_i(s) = D_i + sum_r R_ri / (s - lam_r) + conj`` shares the ``n_modes`` complex pole pairs of the output (a
    common denominator of degree ``2 n_modes``, numerators of that degree). Parameters ``theta``: per mode
    ``log |lam|``, then per mode ``log zeta`` (stable, underdamped), then the linear ones: per input, ``2 Re R`` and
    ``-2 Im R`` per mode and ``D``; the offset; per mode the weights of ``Re e^{lam t}`` and ``Im e^{lam t}`` (the
    record's initial state: Pintelon and Schoukens' transient term in the time domain); all for the output divided
    by ``scale``."""

    inputs: tuple[str, ...]
    n_modes: int
    dt: float
    scale: float
    parameters_: Array
    covariance_: Array | None  # None where the record does not determine every parameter (``no_covariance``)
    errors: Array  # output errors divided by ``scale`` (n_samples,)
    no_covariance: str = ""

    def coefficients(self, theta: Array, inputs: Sequence[str]) -> Array:
        """Per input of ``inputs``: the numerator (``2 n_modes + 1``) and the monic denominator below its leading 1,
        ascending powers of s, SI."""
        m = self.n_modes
        lam = _bl_poles(theta[: 2 * m])
        roots = np.concatenate([lam, lam.conj()])
        den: Array = np.asarray(np.poly(roots).real, dtype=float)  # descending, monic
        lin = theta[2 * m:]
        parts: list[Array] = []
        for name in inputs:
            i = self.inputs.index(name)
            block = lin[i * (2 * m + 1): (i + 1) * (2 * m + 1)]
            residue = 0.5 * (block[:m] - 1j * block[m: 2 * m])
            num = block[2 * m] * np.poly(roots).astype(complex)
            for r in range(m):
                others = np.delete(roots, r)
                partner = np.delete(roots, m + r)
                num[1:] += residue[r] * np.poly(others) + residue[r].conj() * np.poly(partner)
            parts += [self.scale * num.real[::-1], den[::-1][:-1]]
        return np.concatenate(parts)


def _bl_poles(u: Array) -> CArray:
    """Upper members of the complex pole pairs from ``[log |lam|, log zeta]`` per mode."""
    m = u.size // 2
    om, ze = np.exp(u[:m]), np.exp(u[m:])
    return np.asarray(om * (-ze + 1j * np.sqrt(np.clip(1.0 - ze**2, 0.0, None))), dtype=complex)


def _bl_basis(u_in: Array, u_nl: Array, dt: float, intersample: str = "bl") -> Array:
    """Columns of the linear parameters of :class:`_BandLimitedOE` at the poles ``u_nl``: each mode's response to
    each input simulated with the input's behaviour between the samples (band-limited: the DFT response of
    :func:`band_limited_modal_response`; held or linear: the exact step of :func:`hold_weights`, the record
    starting at rest, any other start being a free response)."""
    from scipy.signal import lfilter

    from cappe.systems.statespace import band_limited_modal_response, hold_weights

    m = u_nl.size // 2
    lam = _bl_poles(u_nl)
    eye = np.eye(m)
    cm = np.vstack([eye, -1j * eye])  # Re z_r, Im z_r
    if intersample == "bl":
        cols = [band_limited_modal_response(lam, np.ones((m, 1)), cm, np.zeros((2 * m, 1)), u_in[:, i: i + 1], dt)
                for i in range(u_in.shape[1])]
    else:  # z[k] = e^{lam dt} z[k - 1] + w_now u[k - 1] + w_next u[k], per mode
        w_now, w_next = hold_weights(lam, dt, intersample)
        mu = np.exp(lam * dt)
        cols = []
        for i in range(u_in.shape[1]):
            z = np.column_stack([lfilter([w_next[r], w_now[r]], [1.0, -mu[r]], u_in[:, i].astype(complex))
                                 for r in range(m)])
            cols.append(np.hstack([z.real, z.imag]))
    free = np.exp(np.outer(np.arange(u_in.shape[0]) * dt, lam))
    feed = [u_in[:, i: i + 1] for i in range(u_in.shape[1])]
    per_input = [block for pair in zip(cols, feed, strict=True) for block in pair]
    return np.hstack([*per_input, np.ones((u_in.shape[0], 1)), free.real, free.imag])


def _fit_continuous_oe(data: TimeData, inputs: Sequence[str], output: str, start: CArray,
                       intersample: str = "bl", *, feedthrough: bool = True) -> _BandLimitedOE | str:
    """Step 1's continuous output-error model (every intersample behaviour; the name of :class:`_BandLimitedOE`
    recalls the input it was first written for): fitted by separable least squares (the linear parameters
    solved at every poles-and-delay vector, which scipy's trust region searches from ``start``: the poles of the
    first-order-hold stand-in, ~1 % off), with its Gauss-Newton covariance ``s^2 (J^T J)^-1`` over every parameter
    (:func:`jacobian_uncertainty`; the Jacobian of the poles by central differences); no covariance, and why, where
    the record leaves a combination of the parameters undetermined. Returns why not where the start has no complex
    pole pairs. The same model simulated with a held or linear input (``intersample``) is step 1 of several inputs:
    their poles shared; ``feedthrough=False`` holds the feed-throughs at 0 (a held input reaching a displacement or
    velocity one sample late: the continuous model is strictly proper), with no variance."""
    from scipy.optimize import least_squares

    upper = start[start.imag > 0]
    if upper.size == 0 or upper.size * 2 != start.size or np.any(upper.real >= 0):
        return (f"the {'first-order-hold stand-in' if intersample == 'bl' else 'output-error model'} has real or "
                f"unstable poles: no start for the {'band-limited ' if intersample == 'bl' else 'continuous '}step 1")
    upper = np.sort_complex(upper)
    om = np.abs(upper)
    ze = np.clip(-upper.real / om, 1e-6, 0.99)
    m = upper.size
    lo = np.full(2 * m, -np.inf)
    # natural frequencies below the Nyquist frequency: a mode above it is an alias of one below at the samples (an
    # lsim record, F1 + F2, 5 % noise: d2's 181 Hz mode went to 1819 Hz, chi2 2e8 in the second step)
    hi = np.concatenate([np.full(m, np.log(np.pi / data.dt)), np.full(m, np.log(0.999))])
    u0 = np.minimum(np.concatenate([np.log(om), np.log(ze)]), hi - 1e-9)
    y = data.channel(output)
    scale = max(float(np.sqrt(np.mean((y - y.mean()) ** 2))), 1e-300)
    yn = y / scale
    u_in = np.column_stack([data.channel(i) for i in inputs])
    dt = data.dt
    keep = np.ones(len(inputs) * (2 * m + 1) + 1 + 2 * m, dtype=bool)  # the linear parameters solved for
    if not feedthrough:
        keep[[i * (2 * m + 1) + 2 * m for i in range(len(inputs))]] = False

    def solve(u_nl: Array) -> tuple[Array, Array]:
        phi = _bl_basis(u_in, u_nl, dt, intersample)
        norm = np.sqrt(np.sum(phi[:, keep] ** 2, axis=0))
        norm[norm == 0] = 1.0
        c = np.zeros(keep.size)
        c[keep] = np.linalg.lstsq(phi[:, keep] / norm, yn, rcond=None)[0] / norm
        return phi, c

    def residuals(u_nl: Array) -> Array:
        phi, c = solve(u_nl)
        return np.asarray(phi @ c - yn)

    found = least_squares(residuals, u0, bounds=(lo, hi), x_scale=np.full(2 * m, 1e-3), xtol=1e-12, ftol=1e-12,
                          gtol=1e-12, max_nfev=200)
    u_nl = found.x
    phi, c = solve(u_nl)
    errors = phi @ c - yn
    jac_nl = np.zeros((yn.size, u_nl.size))
    for j in range(u_nl.size):
        h = 1e-6 * max(1.0, abs(u_nl[j]))
        step = np.zeros_like(u_nl)
        step[j] = h
        jac_nl[:, j] = (_bl_basis(u_in, u_nl + step, dt, intersample) @ c
                        - _bl_basis(u_in, u_nl - step, dt, intersample) @ c) / (2 * h)
    jac = np.hstack([jac_nl, phi[:, keep]])
    norm = np.sqrt(np.sum(jac**2, axis=0))
    norm[norm == 0] = 1.0
    theta = np.concatenate([u_nl, c])
    solved = np.concatenate([np.ones(u_nl.size, dtype=bool), keep])
    # the one home of the Gauss-Newton covariance, with unit-norm columns for the rank decision: the linear
    # parameters (residues, offset, initial state) may lie near 0, where relative scaling would invent a null space
    unc = jacobian_uncertainty(names=[n for n, k in zip(_bl_names(inputs, m), solved, strict=True) if k],
                               values=theta[solved], jacobian=jac, residuals=errors, scale=1.0 / norm)
    if not np.all(unc.identifiable) or not np.all(np.isfinite(unc.covariance)):
        # a pseudo-inverse would give the undetermined direction no variance, and the weighted second step would
        # read it as known exactly: the coefficients are kept, the weighting is refused with the combination
        return _BandLimitedOE(tuple(inputs), m, dt, scale, theta, None, errors, no_covariance=(
            f"the {'band-limited ' if intersample == 'bl' else ''}step 1 does not determine "
            f"{'; '.join(unc.combinations) or 'all its parameters'}"))
    cov = np.zeros((theta.size, theta.size))
    cov[np.ix_(solved, solved)] = unc.covariance
    return _BandLimitedOE(tuple(inputs), m, dt, scale, theta, cov, errors)


def _bl_names(inputs: Sequence[str], m: int) -> list[str]:
    """Names of :class:`_BandLimitedOE`'s parameters, in its order (for the undetermined combinations)."""
    modes = range(1, m + 1)
    per_input = [f"{i}:{part}{r}" for i in inputs for part, rs in (("ReR", modes), ("ImR", modes), ("D", [""]))
                 for r in rs]
    return [*(f"log|lam{r}|" for r in modes), *(f"log zeta{r}" for r in modes), *per_input, "offset",
            *(f"x0re{r}" for r in modes), *(f"x0im{r}" for r in modes)]


def _stack_pairs(pairs: Sequence[_Pair], propagated: Mapping[str, tuple[Array, Array]], degree: int) -> tuple[
        Array, Array]:
    """Coefficients and covariance in pair order from the per-output blocks of :func:`_propagate` (outputs are fitted
    separately, so their blocks are uncorrelated; the pairs of one output share its OE parameters)."""
    size = 2 * degree + 1
    index: list[NDArray[np.intp]] = []
    coef = np.zeros(len(pairs) * size)
    cov = np.zeros((coef.size, coef.size))
    for k, pair in enumerate(pairs):
        position = [p.input for p in pairs if p.output == pair.output].index(pair.input)
        index.append(np.arange(position * size, (position + 1) * size))
        coef[k * size:(k + 1) * size] = propagated[pair.output][0][index[-1]]
    for k, pk in enumerate(pairs):
        for j, pj in enumerate(pairs):
            if pk.output == pj.output:
                block = propagated[pk.output][1]
                cov[k * size:(k + 1) * size, j * size:(j + 1) * size] = block[np.ix_(index[k], index[j])]
    return coef, cov


def _from_frf(est: _TwoStep, model: NumericModel, frf: FRFData) -> _Step1:
    from cappe.identify._rational import fit_rational

    pairs = _default_pairs(est, model, frf.input_names, frf.output_names, "the FRF data")
    ins = list(dict.fromkeys(p.input for p in pairs))
    outs = list(dict.fromkeys(p.output for p in pairs))
    h = frf.H[[frf.output_names.index(o) for o in outs]][:, [frf.input_names.index(i) for i in ins]]
    keep = np.all(np.isfinite(h), axis=(0, 1)) & (frf.freq > 0)
    if est.band is not None:
        keep &= (frf.freq >= est.band[0]) & (frf.freq <= est.band[1])
    sub = FRFData(frf.freq[keep], h[..., keep], tuple(ins), tuple(outs))
    n = 2 * model.n_dof
    n_num = min(n, n - 2 + max(p.order for p in pairs))
    fit = fit_rational(sub, order=(n_num, n))
    return _Step1(pairs, [fit.transfer_function(p.output, p.input) for p in pairs], "fit_rational (FRF data)",
                  no_covariance="the rational fit of FRFs has no coefficient covariance")


# ---------------------------------------------------------------------------------------------------------------
# estimators


class _TwoStep(Estimator):
    """Shared settings and step 1 of the two-step estimators."""

    method: ClassVar[str] = ""

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        pairs: Sequence[tuple[str, str]] | None = None,
        position: Mapping[str, float] | None = None,
        identification: str = "oe",
        arx_order: int = 40,
        band: tuple[float, float] | None = None,
        weights: Mapping[str, float] | None = None,
        n_starts: int = 16,
        intersample: str = "zoh",
        weighting: str = "auto",
    ) -> None:
        super().__init__(model, unknowns, bounds=bounds, start=start, values=values, rng=rng)
        self.pairs = pairs
        self.position = position
        self.identification = identification
        self.arx_order = arx_order
        self.band = band
        self.weights = weights
        self.n_starts = n_starts
        self.intersample = intersample
        self.weighting = weighting

    def _check_settings(self) -> None:
        check_intersample(self.intersample)
        if self.intersample != "zoh" and self.identification == "arx":
            msg = (f"identification 'arx' (pruned, matched-z zeros) assumes a held input; got intersample "
                   f"{self.intersample!r} (use identification 'oe')")
            raise DataError(msg)
        if self.weighting not in _WEIGHTINGS:
            msg = f"weighting must be 'auto', 'covariance' or 'none'; got {self.weighting!r}"
            raise DataError(msg)
        if self.weighting == "covariance" and self.weights is not None:
            msg = ("weights scale the unweighted comparison (weighting 'none'); with weighting 'covariance' step 1's "
                   f"covariance sets every weight; got weights {dict(self.weights)!r}")
            raise DataError(msg)
        if self.identification not in _IDENTIFICATIONS:
            msg = f"identification must be 'oe' or 'arx'; got {self.identification!r}"
            raise DataError(msg)
        for name, value, low in (("n_starts", self.n_starts, 1), ("arx_order", self.arx_order, 1)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                msg = f"{name} must be an integer >= {low}; got {value!r}"
                raise DataError(msg)
        if self.band is not None and not (len(self.band) == 2 and 0 <= self.band[0] < self.band[1]):
            msg = f"band must be (f_lo, f_hi) in Hz with 0 <= f_lo < f_hi; got {self.band!r}"
            raise DataError(msg)

    def _pair_weights(self, pairs: Sequence[_Pair]) -> Array:
        given = dict(self.weights or {})
        labels = [p.label for p in pairs]
        extra = sorted(set(given) - set(labels))
        if extra:
            msg = f"weights given for {extra}, which are not among the compared pairs {labels}"
            raise DataError(msg)
        out = np.array([float(given.get(label, 1.0)) for label in labels])
        bad = [label for label, w in zip(labels, out, strict=True) if not (np.isfinite(w) and w > 0)]
        if bad:
            msg = f"weights must be finite and > 0; got {[given[b] for b in bad]} for {bad}"
            raise DataError(msg)
        return out

    def _fit(
        self, model: NumericModel, space: ParameterSpace, data: Any, rng: np.random.Generator
    ) -> Fitted:
        self._check_settings()
        step1 = _experimental(self, model, data)
        pairs, tfs = step1.pairs, step1.tfs
        self.transfer_functions_ = tuple(tfs)
        weights = self._pair_weights(pairs)
        engine = _ModelTF(model, space, pairs, self.position)
        weighted = self._weighted(step1)
        if weighted:
            residuals, jacobian, info = self._weighted_residuals(engine, step1)
        else:
            residuals, jacobian, info = self._residuals(engine, tfs, weights)
        starts = _sobol_starts(space, int(self.n_starts), rng)
        diagnostics = {
            "identification": step1.source,
            "pairs": [p.label for p in pairs],
            "transfer_functions": [tf.to_dict() for tf in tfs],
            "second_step_weighting": ("covariance of step 1 (minimum distance)" if weighted else
                          "none (normalized-square index)" + (f": {step1.no_covariance}" if step1.no_covariance
                                                              and self.weighting == "auto" else "")),
            **({} if weighted else {"weights": dict(zip([p.label for p in pairs], weights.tolist(), strict=True))}),
            **info,
        }
        # whitened residuals have unit variance when the model is right: the covariance is (J^T W J)^-1
        fitted = least_squares_fit(
            self.method, space, residuals, jacobian if engine.analytic else None, starts=starts,
            diagnostics=diagnostics, noise_variance=1.0 if weighted else None,
        )
        if step1.warning:
            warnings.warn(step1.warning, IllConditionedWarning, stacklevel=2)
            said = {**fitted.estimate.diagnostics}
            said["warnings"] = [*said.get("warnings", []), step1.warning]
            fitted = fitted.with_estimate(replace(fitted.estimate, diagnostics=said))
        if step1.errors is not None:
            # step 1 must explain the data: its output errors are tested as MATLAB's resid would test them
            errors, inputs, out_names, in_names = step1.errors
            estimate = with_residual_tests(fitted.estimate, [errors], [inputs], out_names, in_names)
            if estimate.diagnostics.get("fit_test") == "failed":
                estimate = replace(estimate, message="step 1 (output-error model) " + estimate.message)
            fitted = fitted.with_estimate(estimate)
        # step 2 must explain step 1
        return _second_step_test(fitted, int(info["residuals"]), space.n) if weighted else fitted

    def _weighted(self, step1: _Step1) -> bool:
        """Whether the second step is weighted by step 1's covariance (see ``weighting``)."""
        if self.weighting == "none" or (self.weighting == "auto" and self.weights is not None):
            return False
        if step1.covariance is None:
            if self.weighting == "covariance":
                msg = f"weighting 'covariance' needs the covariance of step 1; {step1.no_covariance}"
                raise DataError(msg)
            return False
        return True

    @abstractmethod
    def _residuals(
        self, engine: _ModelTF, tfs: Sequence[TransferFunctionModel], weights: Array
    ) -> tuple[Callable[[Array], Array], Callable[[Array], Array], dict[str, Any]]:
        """Residuals, their Jacobian and diagnostics of the variant's comparison."""

    @abstractmethod
    def _weighted_residuals(
        self, engine: _ModelTF, step1: _Step1
    ) -> tuple[Callable[[Array], Array], Callable[[Array], Array], dict[str, Any]]:
        """Residuals whitened by step 1's covariance (unit variance at the truth), their Jacobian and diagnostics;
        ``info["residuals"]`` is the number of whitened residuals."""


def _whitening(cov: Array) -> tuple[Array, int]:
    """``T`` with ``T cov T^T = I`` on the range of ``cov`` (rows: its kept eigen-directions), and how many directions
    were dropped. The covariance is scaled to a correlation matrix first (its entries span many decades); eigenvalues
    below :data:`_WHITEN_RTOL` of the largest are dropped (pseudo-inverse), as are entries without variance."""
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    live = np.isfinite(d) & (d > 0)
    corr = cov[np.ix_(live, live)] / np.outer(d[live], d[live])
    w, v = np.linalg.eigh(corr)
    keep = w > _WHITEN_RTOL * w.max()
    t = np.zeros((int(keep.sum()), cov.shape[0]))
    t[:, live] = (v[:, keep] / np.sqrt(w[keep])).T / d[live][None, :]
    return t, int((~keep).sum() + (~live).sum())


def _second_step_test(fitted: Fitted, n_compared: int, n_unknowns: int) -> Fitted:
    """The chi-square test of the weighted second step: at the optimum the whitened residuals' sum of squares is
    chi-square with ``n_compared - n_unknowns`` degrees of freedom when the physical model reproduces step 1's
    transfer functions up to step 1's uncertainty. A failed test (p below :data:`_CHI2_LEVEL`) warns, marks the fit
    failed (``success`` False, ``fit_test`` "failed": the text output says FAILED) and scales the covariance by
    ``chi2 / dof`` (the spread the fit actually shows)."""
    estimate = fitted.estimate
    if fitted.cost is None:
        return fitted
    chi2 = float(estimate.cost)
    dof = n_compared - n_unknowns
    diagnostics = dict(estimate.diagnostics)
    if dof < 1:
        diagnostics["second_step_test"] = {"chi2": chi2, "dof": dof, "p_value": None, "passed": None,
                                           "note": "as many compared quantities as unknowns: no test"}
        return fitted.with_estimate(replace(estimate, diagnostics=diagnostics))
    p_value = float(chi2_distribution.sf(chi2, dof))
    passed = p_value >= _CHI2_LEVEL
    diagnostics["second_step_test"] = {"chi2": chi2, "dof": dof, "p_value": p_value, "level": _CHI2_LEVEL,
                                       "passed": passed}
    if passed:
        return fitted.with_estimate(replace(estimate, diagnostics=diagnostics))
    factor = chi2 / dof
    diagnostics["second_step_test"]["covariance_scale"] = factor
    diagnostics["fit_test"] = "failed"
    diagnostics["warnings"] = [*diagnostics.get("warnings", []), (
        f"second step FAILED its chi-square test: the physical model does not reproduce step 1's transfer functions "
        f"within their uncertainty (chi2 {chi2:.4g} on {dof} dof, p = {p_value:.2g} < {_CHI2_LEVEL:g}); a wrong model "
        f"structure or a biased step 1 (intersample, delay); standard errors scaled by sqrt(chi2/dof) = "
        f"{np.sqrt(factor):.3g}, but a bias is not covered by scaling")]
    message = "step 2 does not reproduce step 1 within its uncertainty (chi-square test)"
    if estimate.diagnostics.get("fit_test") == "failed":  # step 1's own failure is the cause: it comes first
        message = f"{estimate.message}; {message}"
    elif estimate.message:
        message = f"{message}; {estimate.message}"
    failed = replace(estimate, success=False, message=message, diagnostics=diagnostics)
    return fitted.with_estimate(with_noise_variance(failed, fitted.cost, factor))


def _sobol_starts(space: ParameterSpace, n_starts: int, rng: np.random.Generator) -> Array:
    """The space's start and ``n_starts - 1`` scrambled Sobol points in the internal box (SI rows)."""
    if n_starts <= 1:
        return space.start[None, :]
    lo, hi = space.internal_bounds()
    finite = np.isfinite(lo) & np.isfinite(hi)
    sobol = qmc.Sobol(d=space.n, scramble=True, rng=rng)
    m = int(np.ceil(np.log2(n_starts - 1))) if n_starts > 2 else 0
    points = sobol.random_base2(m)[: n_starts - 1]
    u0 = space.to_internal(space.start)
    u = np.where(finite, lo + points * np.where(finite, hi - lo, 0.0), u0)
    return np.vstack([space.start, space.from_internal(u)])


def _check_denominator(pair: _Pair, den_e: Array, degree: int) -> None:
    if den_e.size - 1 != degree:
        msg = (
            f"experimental transfer function {pair.label} has {den_e.size - 1} poles but the model has {degree}; "
            f"identify (or prune) to the physical order {degree}"
        )
        raise DataError(msg)


class TwoStepTFEstimator(_TwoStep):
    """Physical parameters from transfer-function coefficients (thesis 3.6.2, normalized-square index eq. 3.99).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng
        As for :class:`Estimator`; ``rng`` seeds the Sobol start points.
    pairs : sequence of (input, output), optional
        Transfer functions to compare; default every model input and output present in the data (for time data:
        every excited input to every measured output).
    position : mapping, optional
        Axis positions of the model.
    identification : {"oe", "arx"}
        Step 1 for time data: output-error model of the physical order (exact ZOH inverse) or the thesis's
        high-order ARX pruned to the physical modes.
    arx_order : int
        Order of the ARX model (``identification="arx"``); the thesis used 40.
    band : (float, float), optional
        Frequency band (Hz) of the rational fit for FRF data.
    weights : mapping "input->output" -> float, optional
        Factor on that pair's residuals in the unweighted comparison (default 1); given, they select it under
        ``weighting="auto"``.
    n_starts : int
        Start points: the start and ``n_starts - 1`` Sobol points inside the bounds.
    intersample : {"zoh", "foh", "bl"}
        The inputs between samples of time data (:mod:`cappe.systems.statespace`): step 1 converts its discrete
        model by the exact inverse of the zero-order hold (default) or of the first-order hold; a band-limited input
        has no finite-order discrete equivalent, so ``"bl"`` fits a continuous model simulated with the
        band-limited input (see the module notes).
    weighting : {"auto", "covariance", "none"}
        The second step's weighting: by the covariance of step 1's coefficients (minimum distance, see the module
        notes), the normalized-square index (``"none"``), or the first where step 1 has a covariance (time data
        identified by ``"oe"``) and no ``weights`` are given (``"auto"``).

    Attributes
    ----------
    estimate_ : ParameterEstimate
        ``diagnostics`` lists the pairs, the experimental transfer functions, the compared and the ignored
        coefficients, and the multi-start runs.
    transfer_functions_ : tuple of TransferFunctionModel
        The experimental transfer functions of step 1.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> exact = model_transfer_functions(nm, [("F1", "d1"), ("F1", "d2"), ("F2", "d2")])
    >>> est = TwoStepTFEstimator(nm, n_starts=4, rng=0).fit(exact)
    >>> bool(np.allclose(est.estimate_.values, nm.nominal[est.space_.columns], rtol=1e-7))
    True
    """

    method = "two-step-tf"

    def _residuals(
        self, engine: _ModelTF, tfs: Sequence[TransferFunctionModel], weights: Array
    ) -> tuple[Callable[[Array], Array], Callable[[Array], Array], dict[str, Any]]:
        degree = engine.degree
        num_idx: list[NDArray[np.intp]] = []
        num_ref: list[Array] = []
        den_idx: list[NDArray[np.intp] | None] = []
        den_ref: list[Array] = []
        seen: list[Array] = []
        ignored: dict[str, list[int]] = {}
        for k, (pair, tf) in enumerate(zip(engine.pairs, tfs, strict=True)):
            num_e, den_e = _coefficients_of(tf)
            _check_denominator(pair, den_e, degree)
            idx = np.flatnonzero(engine.num_mask[k])
            if idx.size and idx.max() >= num_e.size:
                msg = (
                    f"experimental transfer function {pair.label} has a numerator of degree {num_e.size - 1} but the "
                    f"model's has degree {int(idx.max())}; identify with a higher numerator order"
                )
                raise DataError(msg)
            extra = [j for j in range(num_e.size) if j not in set(idx.tolist()) and num_e[j] != 0]
            if extra:
                ignored[pair.label] = extra
            ref = num_e[idx]
            didx = np.flatnonzero(engine.den_mask[:degree])
            dref = den_e[didx]
            if np.any(ref == 0) or np.any(dref == 0):
                msg = (
                    f"experimental transfer function {pair.label} has an exactly zero coefficient where the model's is "
                    f"not; the relative index (eq. 3.99) is undefined there"
                )
                raise DataError(msg)
            num_idx.append(idx)
            num_ref.append(ref)
            if any(np.array_equal(den_e, s) for s in seen):
                den_idx.append(None)  # a common denominator is compared once
                den_ref.append(np.zeros(0))
            else:
                seen.append(den_e)
                den_idx.append(didx)
                den_ref.append(dref)

        def parts(p: Array, jac: bool) -> tuple[Array, Array | None]:
            num, den, dnum, dden = engine.evaluate(p, jac)
            res: list[Array] = []
            jacs: list[Array] = []
            for k in range(len(engine.pairs)):
                w = weights[k]
                res.append(w * (num[k, num_idx[k]] - num_ref[k]) / num_ref[k])
                if dnum is not None:
                    jacs.append(w * dnum[k, num_idx[k]] / num_ref[k][:, None])
                di = den_idx[k]
                if di is not None:
                    res.append(w * (den[di] - den_ref[k]) / den_ref[k])
                    if dden is not None:
                        jacs.append(w * dden[di] / den_ref[k][:, None])
            return np.concatenate(res), (np.vstack(jacs) if jacs else None)

        def residuals(p: Array) -> Array:
            return parts(p, False)[0]

        def jacobian(p: Array) -> Array:
            return _required(parts(p, True)[1])

        info = {
            "compared": {
                pr.label: {"numerator_powers": num_idx[k].tolist(),
                           "denominator_powers": [] if den_idx[k] is None else den_idx[k].tolist()}  # type: ignore[union-attr]
                for k, pr in enumerate(engine.pairs)
            },
            "ignored_numerator_powers": ignored,
            "residuals": int(sum(i.size for i in num_idx) + sum(0 if d is None else d.size for d in den_idx)),
        }
        return residuals, jacobian, info


    def _weighted_residuals(
        self, engine: _ModelTF, step1: _Step1
    ) -> tuple[Callable[[Array], Array], Callable[[Array], Array], dict[str, Any]]:
        coef, cov = _required(step1.coefficients), _required(step1.covariance)
        degree = engine.degree
        n_pairs = len(engine.pairs)
        # every identified coefficient is compared: where the model's is a structural zero its value is 0, and the
        # identified one (noise about 0) still informs the others through their correlation (Markov estimate)
        generic = np.concatenate([np.concatenate([engine.num_mask[k], engine.den_mask[:degree]])
                                  for k in range(n_pairs)])
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        scale = np.where(generic & (coef != 0), np.abs(coef), np.where(std > 0, std, 1.0))
        transform, dropped = _whitening(cov / np.outer(scale, scale))

        def parts(p: Array, jac: bool) -> tuple[Array, Array | None]:
            num, den, dnum, dden = engine.evaluate(p, jac)
            model = np.concatenate([np.concatenate([num[k], den[:degree]]) for k in range(n_pairs)])
            r = transform @ ((np.where(generic, model, 0.0) - coef) / scale)
            if dnum is None or dden is None:
                return r, None
            d_model = np.vstack([np.vstack([dnum[k], dden[:degree]]) for k in range(n_pairs)])
            return r, transform @ (np.where(generic[:, None], d_model, 0.0) / scale[:, None])

        def residuals(p: Array) -> Array:
            return parts(p, False)[0]

        def jacobian(p: Array) -> Array:
            return _required(parts(p, True)[1])

        info = {
            "compared": {pr.label: {"numerator_powers": list(range(degree + 1)),
                                    "denominator_powers": list(range(degree)),
                                    "structural_zeros": np.flatnonzero(~engine.num_mask[k]).tolist()}
                         for k, pr in enumerate(engine.pairs)},
            "whitening": {"compared": int(coef.size), "dropped_directions": dropped},
            "residuals": int(transform.shape[0]),
        }
        return residuals, jacobian, info


def _required(jac: Array | None) -> Array:
    if jac is None:  # pragma: no cover - derivatives are always requested here
        msg = "internal error: no Jacobian"
        raise RuntimeError(msg)
    return jac


@dataclass(frozen=True)
class _RootSet:
    """Experimental roots of one polynomial with their residual weights."""

    roots: CArray
    weights: Array  # 1/sqrt(2) for members of complex pairs


def _root_set(roots: CArray) -> _RootSet:
    complex_member = np.abs(roots.imag) > 1e-12 * np.abs(roots)
    return _RootSet(roots, np.where(complex_member, np.sqrt(0.5), 1.0))


def _roots_of(coef_ascending: Array) -> CArray:
    c = np.trim_zeros(coef_ascending[::-1], "f")
    return np.asarray(np.roots(c), dtype=complex) if c.size > 1 else np.zeros(0, complex)


class TwoStepZPKEstimator(_TwoStep):
    """Physical parameters from poles, zeros and gains (thesis 3.6.2, eq. 3.103).

    Parameters
    ----------
    model, unknowns, bounds, start, values, rng, pairs, position, identification, arx_order, band, weights, n_starts,
    intersample, weighting
    roots : {"frequency-damping", "complex"}
        Residual form of a paired root (see the module notes).

    Attributes
    ----------
    estimate_ : ParameterEstimate
        ``diagnostics`` lists the pairs, the experimental transfer functions, the number of compared poles and zeros
        per pair and the experimental roots left unpaired at the estimate.
    transfer_functions_ : tuple of TransferFunctionModel
        The experimental transfer functions of step 1.

    Examples
    --------
    >>> from cappe.model import load_model
    >>> nm = NumericModel(load_model("builtin:two-mass-rig"))
    >>> exact = model_transfer_functions(nm, [("F1", "d1"), ("F1", "d2"), ("F2", "d2")])
    >>> est = TwoStepZPKEstimator(nm, n_starts=4, rng=0).fit(exact)
    >>> bool(np.allclose(est.estimate_.values, nm.nominal[est.space_.columns], rtol=1e-7))
    True
    """

    method = "two-step-zp"

    def __init__(
        self,
        model: NumericModel | Structure,
        unknowns: Sequence[str] | None = None,
        *,
        bounds: Mapping[str, Sequence[float]] | None = None,
        start: Mapping[str, float] | None = None,
        values: Mapping[str, float] | None = None,
        rng: RandomLike = None,
        pairs: Sequence[tuple[str, str]] | None = None,
        position: Mapping[str, float] | None = None,
        identification: str = "oe",
        arx_order: int = 40,
        band: tuple[float, float] | None = None,
        weights: Mapping[str, float] | None = None,
        n_starts: int = 16,
        roots: str = "frequency-damping",
        intersample: str = "zoh",
        weighting: str = "auto",
    ) -> None:
        super().__init__(
            model, unknowns, bounds=bounds, start=start, values=values, rng=rng, pairs=pairs, position=position,
            identification=identification, arx_order=arx_order, band=band, weights=weights, n_starts=n_starts,
            intersample=intersample, weighting=weighting,
        )
        self.roots = roots

    def _residuals(
        self, engine: _ModelTF, tfs: Sequence[TransferFunctionModel], weights: Array
    ) -> tuple[Callable[[Array], Array], Callable[[Array], Array], dict[str, Any]]:
        if self.roots not in _ROOT_FORMS:
            msg = f"roots must be 'frequency-damping' or 'complex'; got {self.roots!r}"
            raise DataError(msg)
        form = self.roots
        degree = engine.degree
        rho = engine.rho
        # structural trimming of the model polynomials: [low, high] powers that are generically non-zero
        num_span = []
        for k, pair in enumerate(engine.pairs):
            idx = np.flatnonzero(engine.num_mask[k])
            if idx.size == 0:
                msg = f"the model's transfer function {pair.label} is identically zero; it cannot be compared"
                raise DataError(msg)
            num_span.append((int(idx.min()), int(idx.max())))
        didx = np.flatnonzero(engine.den_mask)
        den_span = (int(didx.min()), int(didx.max()))
        exp_poles: list[_RootSet | None] = []
        exp_zeros: list[_RootSet] = []
        gains: list[float] = []
        seen: list[Array] = []
        for k, (pair, tf) in enumerate(zip(engine.pairs, tfs, strict=True)):
            num_e, den_e = _coefficients_of(tf)
            _check_denominator(pair, den_e, degree)
            lo_n, hi_n = num_span[k]
            n_zeros_model = hi_n - lo_n
            ze = _roots_of(num_e)
            ze = ze[np.abs(ze) > 0]
            if ze.size < n_zeros_model:
                msg = (
                    f"experimental transfer function {pair.label} has {ze.size} finite non-zero zeros but the model "
                    f"has {n_zeros_model}; identify with a higher numerator order"
                )
                raise DataError(msg)
            exp_zeros.append(_root_set(ze))
            if num_e.size <= lo_n or num_e[lo_n] == 0 or den_e[den_span[0]] == 0:
                msg = (
                    f"experimental transfer function {pair.label} has a zero low-frequency coefficient (s^{lo_n} of "
                    f"the numerator or s^{den_span[0]} of the denominator); its gain cannot be compared"
                )
                raise DataError(msg)
            gains.append(float(num_e[lo_n] / den_e[den_span[0]]))
            if any(np.array_equal(den_e, s) for s in seen):
                exp_poles.append(None)
            else:
                seen.append(den_e)
                pe = _roots_of(den_e)
                pe = pe[np.abs(pe) > 0] if den_span[0] > 0 else pe
                exp_poles.append(_root_set(pe))

        def root_terms(
            coef: Array, dcoef: Array | None, span: tuple[int, int], ref: _RootSet
        ) -> tuple[Array, Array | None, list[complex]]:
            lo, hi = span
            c = coef[lo : hi + 1]
            model_roots = _roots_of(c)  # in s / rho
            if model_roots.size == 0:
                return np.zeros(0), (np.zeros((0, 0)) if dcoef is not None else None), []
            lam = model_roots * rho
            cost = np.abs(lam[:, None] - ref.roots[None, :]) / np.abs(ref.roots)[None, :]
            rows, cols = linear_sum_assignment(cost)
            lam_m = lam[rows]
            lam_e = ref.roots[cols]
            w = ref.weights[cols]
            unpaired = [complex(ref.roots[j]) for j in range(ref.roots.size) if j not in set(cols.tolist())]
            dlam = None
            if dcoef is not None:
                x = model_roots[rows]
                powers = x[:, None] ** np.arange(c.size)[None, :]
                dp = np.arange(1, c.size)
                deriv = (powers[:, :-1] * (dp * c[1:])[None, :]).sum(axis=1)  # P'(x)
                dx = -np.einsum("rk,kj->rj", powers, dcoef[lo : hi + 1]) / deriv[:, None]
                dlam = dx * rho
            if form == "frequency-damping":
                om_m, om_e = np.abs(lam_m), np.abs(lam_e)
                ze_m, ze_e = -lam_m.real / om_m, -lam_e.real / om_e
                # relative damping error; absolute where the experimental root is undamped (zeta = 0)
                ze_scale = np.where(np.abs(ze_e) > 1e-12, np.abs(ze_e), 1.0)
                res = np.concatenate([w * (om_m - om_e) / om_e, w * (ze_m - ze_e) / ze_scale])
                jac = None
                if dlam is not None:
                    dom = (np.conj(lam_m)[:, None] * dlam).real / om_m[:, None]
                    dze = -dlam.real / om_m[:, None] + (lam_m.real / om_m**2)[:, None] * dom
                    jac = np.vstack([w[:, None] * dom / om_e[:, None], w[:, None] * dze / ze_scale[:, None]])
            else:
                rel = (lam_m - lam_e) / lam_e
                res = np.concatenate([w * rel.real, w * rel.imag])
                jac = None
                if dlam is not None:
                    drel = dlam / lam_e[:, None]
                    jac = np.vstack([w[:, None] * drel.real, w[:, None] * drel.imag])
            return res, jac, unpaired

        def parts(p: Array, want_jac: bool) -> tuple[Array, Array | None, dict[str, Any]]:
            num, den, dnum, dden, _, _ = engine.raw(p, want_jac)
            res: list[Array] = []
            jacs: list[Array] = []
            unpaired: dict[str, list[list[float]]] = {}
            unscale = rho ** -np.arange(degree + 1, dtype=float)
            for k, pair in enumerate(engine.pairs):
                wk = weights[k]
                ref = exp_poles[k]
                if ref is not None:
                    r, j, left = root_terms(den, dden, den_span, ref)
                    res.append(wk * r)
                    if j is not None:
                        jacs.append(wk * j)
                    if left:
                        unpaired[f"{pair.label} poles"] = [[z.real, z.imag] for z in left]
                r, j, left = root_terms(num[k], None if dnum is None else dnum[k], num_span[k], exp_zeros[k])
                res.append(wk * r)
                if j is not None and j.size:
                    jacs.append(wk * j)
                if left:
                    unpaired[f"{pair.label} zeros"] = [[z.real, z.imag] for z in left]
                lo_n, lo_d = num_span[k][0], den_span[0]
                g = num[k, lo_n] * unscale[lo_n] / (den[lo_d] * unscale[lo_d])
                res.append(np.array([wk * (g - gains[k]) / gains[k]]))
                if dnum is not None and dden is not None:
                    dg = g * (dnum[k, lo_n] / num[k, lo_n] - dden[lo_d] / den[lo_d])
                    jacs.append(wk * dg[None, :] / gains[k])
            return np.concatenate(res), (np.vstack(jacs) if want_jac else None), unpaired

        def residuals(p: Array) -> Array:
            return parts(p, False)[0]

        def jacobian(p: Array) -> Array:
            return _required(parts(p, True)[1])

        r_start, _, unpaired_start = parts(engine.space.start, False)
        info = {
            "roots": form,
            "compared": {
                pr.label: {"poles": 0 if exp_poles[k] is None else den_span[1] - den_span[0],
                           "zeros": num_span[k][1] - num_span[k][0], "gain": f"s^{num_span[k][0]} / s^{den_span[0]}"}
                for k, pr in enumerate(engine.pairs)
            },
            "unpaired_at_start": unpaired_start,
            "residuals": int(r_start.size),
        }
        return residuals, jacobian, info

    def _weighted_residuals(
        self, engine: _ModelTF, step1: _Step1
    ) -> tuple[Callable[[Array], Array], Callable[[Array], Array], dict[str, Any]]:
        if self.roots not in _ROOT_FORMS:
            msg = f"roots must be 'frequency-damping' or 'complex'; got {self.roots!r}"
            raise DataError(msg)
        coef, cov = _required(step1.coefficients), _required(step1.covariance)
        form = self.roots
        degree, rho = engine.degree, engine.rho
        size = 2 * degree + 1
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        didx = np.flatnonzero(engine.den_mask)
        den_span = (int(didx.min()), int(didx.max()))
        sets: list[_WeightedRoots] = []  # per pair: zeros, then poles
        gains: list[tuple[float, NDArray[np.intp], Array]] = []  # value, coefficient indices, d log g / d coef
        low: list[tuple[int, float]] = []  # structural zeros below the lowest generic power: (index, std)
        for k, pair in enumerate(engine.pairs):
            idx = np.flatnonzero(engine.num_mask[k])
            if idx.size == 0:
                msg = f"the model's transfer function {pair.label} is identically zero; it cannot be compared"
                raise DataError(msg)
            lo_n, hi_n, lo_d = int(idx.min()), int(idx.max()), den_span[0]
            base = k * size
            num_e = coef[base: base + degree + 1]
            den_e = np.append(coef[base + degree + 1: base + size], 1.0)
            if num_e[lo_n] == 0 or den_e[lo_d] == 0:
                msg = (f"experimental transfer function {pair.label} has a zero low-frequency coefficient (s^{lo_n} "
                       f"of the numerator or s^{lo_d} of the denominator); its gain cannot be compared")
                raise DataError(msg)
            low += [(base + j, std[base + j]) for j in range(lo_n)]
            low += [(base + degree + 1 + j, std[base + degree + 1 + j]) for j in range(lo_d)]
            zeros = _weighted_roots(num_e[lo_n:], base + lo_n + np.arange(degree + 1 - lo_n), (lo_n, hi_n),
                                    f"{pair.label} zeros")
            if zeros.roots.size < hi_n - lo_n:
                msg = (f"experimental transfer function {pair.label} has {zeros.roots.size} finite non-zero zeros but "
                       f"the model has {hi_n - lo_n}; identify with a higher numerator order")
                raise DataError(msg)
            poles = _weighted_roots(den_e[lo_d:], np.append(base + degree + 1 + lo_d + np.arange(degree - lo_d), -1),
                                    den_span, f"{pair.label} poles")
            sets += [zeros, poles]
            g_idx = np.array([base + lo_n, base + degree + 1 + lo_d if lo_d < degree else -1])
            gains.append((float(num_e[lo_n] / den_e[lo_d]), g_idx, np.array([1 / num_e[lo_n], -1 / den_e[lo_d]])))
        n_features = len(low) + sum(rs.roots.size + min(rs.n_model, rs.roots.size) for rs in sets) + len(gains)
        transforms: dict[tuple[bool, ...], Array] = {}

        def transform(paired: tuple[bool, ...]) -> Array:
            """Whitening of the residuals with this pairing (cov = F cov(coef) F^T, F: d features / d coef)."""
            if paired not in transforms:
                rows: list[Array] = []
                for j, sd in low:
                    row = np.zeros(coef.size)
                    row[j] = 1.0 / sd if sd > 0 else 0.0
                    rows.append(row)
                at = 0
                for rs in sets:
                    rows += _feature_rows(rs, paired[at: at + rs.roots.size], form, rho, coef.size)
                    at += rs.roots.size
                for _, g_idx, dlog in gains:
                    row = np.zeros(coef.size)
                    ok = g_idx >= 0
                    row[g_idx[ok]] = dlog[ok]
                    rows.append(row)
                f = np.vstack(rows)
                t, _ = _whitening(f @ cov @ f.T)
                transforms[paired] = t
            return transforms[paired]

        def parts(p: Array, want_jac: bool) -> tuple[Array, Array | None, tuple[bool, ...], dict[str, Any]]:
            num, den, dnum, dden, _, _ = engine.raw(p, want_jac)
            n_u = engine.space.n
            res: list[Array] = [np.array([-coef[j] / sd if sd > 0 else 0.0 for j, sd in low])]
            jacs: list[Array] = [np.zeros((len(low), n_u))]
            paired: list[bool] = []
            unpaired: dict[str, list[list[float]]] = {}
            unscale = rho ** -np.arange(degree + 1, dtype=float)
            for k in range(len(engine.pairs)):
                for rs, c, dc in ((sets[2 * k], num[k], None if dnum is None else dnum[k]),
                                  (sets[2 * k + 1], den, dden)):
                    r, j, flags = _weighted_root_terms(rs, c, dc, form, rho, n_u)
                    res.append(r)
                    jacs.append(j)
                    paired += flags
                    left = [complex(z) for z, f in zip(rs.roots, flags, strict=True) if not f]
                    if left:
                        unpaired[rs.label] = [[z.real, z.imag] for z in left]
            for k in range(len(engine.pairs)):
                lo_n, lo_d = int(np.flatnonzero(engine.num_mask[k]).min()), den_span[0]
                g = num[k, lo_n] * unscale[lo_n] / (den[lo_d] * unscale[lo_d])
                res.append(np.array([(g - gains[k][0]) / gains[k][0]]))
                if dnum is not None and dden is not None:
                    dg = g * (dnum[k, lo_n] / num[k, lo_n] - dden[lo_d] / den[lo_d])
                    jacs.append(dg[None, :] / gains[k][0])
                else:
                    jacs.append(np.zeros((1, n_u)))
            key = tuple(paired)
            t = transform(key)
            r_all = t @ np.concatenate(res)
            j_all = t @ np.vstack(jacs) if want_jac else None
            return r_all, j_all, key, unpaired

        r_start, _, key_start, unpaired_start = parts(engine.space.start, False)
        n_rows = r_start.size

        def fixed(v: Array) -> Array:  # a pairing of other rank (never seen) keeps the start's residual count
            if v.shape[0] >= n_rows:
                return v[:n_rows]
            return np.concatenate([v, np.zeros((n_rows - v.shape[0], *v.shape[1:]))])

        def residuals(p: Array) -> Array:
            return fixed(parts(p, False)[0])

        def jacobian(p: Array) -> Array:
            return fixed(_required(parts(p, True)[1]))

        info = {
            "roots": form,
            "compared": {pr.label: {"poles": int(sets[2 * k + 1].roots.size), "zeros": int(sets[2 * k].roots.size),
                                    "model_zeros": int(sets[2 * k].n_model), "gain": "low-frequency asymptote"}
                         for k, pr in enumerate(engine.pairs)},
            "unpaired_at_start": unpaired_start,
            "whitening": {"compared": int(n_features), "dropped_directions": int(n_features - n_rows)},
            "residuals": int(n_rows),
        }
        return residuals, jacobian, info


@dataclass(frozen=True)
class _WeightedRoots:
    """Experimental roots of one polynomial for the weighted comparison, with ``d root / d coef``."""

    label: str
    roots: CArray
    droots: CArray  # (n_roots, n_coef_total): derivative with respect to step 1's stacked coefficients
    weights: Array  # 1/sqrt(2) for members of complex pairs
    span: tuple[int, int]  # the model polynomial's generic powers [low, high]
    n_model: int


def _weighted_roots(c: Array, index: NDArray[np.intp], span: tuple[int, int], label: str) -> _WeightedRoots:
    """Roots of ``sum c_i x^i`` and their derivatives ``d root / d c_i = -root^i / P'(root)`` placed at ``index``
    (-1: a fixed coefficient, the monic denominator's leading 1)."""
    roots = _roots_of(c)
    total = int(index.max()) + 1
    d = np.zeros((roots.size, max(total, 1)), dtype=complex)
    if roots.size:
        powers = roots[:, None] ** np.arange(c.size)[None, :]
        deriv = (powers[:, :-1] * (np.arange(1, c.size) * c[1:])[None, :]).sum(axis=1)
        ok = index >= 0
        d[:, index[ok]] = -powers[:, ok] / deriv[:, None]
    complex_member = np.abs(roots.imag) > 1e-12 * np.abs(roots)
    return _WeightedRoots(label, roots, d, np.where(complex_member, np.sqrt(0.5), 1.0), span, span[1] - span[0])


def _feature_rows(rs: _WeightedRoots, paired: Sequence[bool], form: str, rho: float, n_coef: int) -> list[Array]:
    """``d residual / d coef`` of the residuals of one polynomial's experimental roots (:func:`_weighted_root_terms`;
    their sign does not matter for the covariance)."""
    dlam = np.zeros((rs.roots.size, n_coef), dtype=complex)
    dlam[:, : rs.droots.shape[1]] = rs.droots
    rows: list[Array] = []
    for r, is_paired in enumerate(paired):
        if not is_paired:
            continue
        lam, w = rs.roots[r], rs.weights[r]
        if form == "frequency-damping":
            om = abs(lam)
            dom = (np.conj(lam) * dlam[r]).real / om
            dze = -dlam[r].real / om + (lam.real / om**2) * dom
            ze = -lam.real / om
            ze_scale = abs(ze) if abs(ze) > 1e-12 else 1.0
            rows += [w * dom / om, w * dze / ze_scale]
        else:
            d = dlam[r] / lam
            rows += [w * d.real, w * d.imag]
    left = [r for r, f in enumerate(paired) if not f]
    if left:
        a = rho / rs.roots[left]
        # d poly(a)[1:] / d a_j = -poly(a without a_j); d a_j = -rho d root_j / root_j^2
        d_sym = np.zeros((len(left), n_coef), dtype=complex)
        for i, r in enumerate(left):
            others = np.poly(np.delete(a, i)) if len(left) > 1 else np.ones(1)
            d_sym += (-others)[:, None] * (-rho * dlam[r] / rs.roots[r] ** 2)[None, :]
        rows += list(d_sym.real)
    return rows


def _weighted_root_terms(rs: _WeightedRoots, c_scaled: Array, dc_scaled: Array | None, form: str, rho: float,
                         n_u: int) -> tuple[Array, Array, list[bool]]:
    """Residuals of one polynomial's experimental roots, their Jacobian and which roots were paired with a model
    root (Hungarian assignment on relative distance, as the unweighted comparison).

    Two residuals per paired root, in the experimental roots' order (relative frequency and damping, or the real
    and imaginary relative error), then the experimental roots the model does not have (its roots there are at
    infinity): the coefficients of ``prod (1 - s / root)`` in ``s / rho``, whose model value is 0. Those are smooth in
    step 1's coefficients where ``rho / root`` of two far roots is not (a square root of a noise coefficient)."""
    lo, hi = rs.span
    c = c_scaled[lo: hi + 1]
    model_roots = _roots_of(c)
    n_e = rs.roots.size
    flags = [False] * n_e
    found: dict[int, tuple[complex, Array | None]] = {}
    if model_roots.size:
        lam = model_roots * rho
        cost = np.abs(lam[:, None] - rs.roots[None, :]) / np.abs(rs.roots)[None, :]
        rows, cols = linear_sum_assignment(cost)
        dlam = None
        if dc_scaled is not None:
            x = model_roots[rows]
            powers = x[:, None] ** np.arange(c.size)[None, :]
            deriv = (powers[:, :-1] * (np.arange(1, c.size) * c[1:])[None, :]).sum(axis=1)
            dlam = -np.einsum("rk,kj->rj", powers, dc_scaled[lo: hi + 1]) / deriv[:, None] * rho
        for i, (m, e) in enumerate(zip(rows, cols, strict=True)):
            flags[e] = True
            found[int(e)] = (complex(lam[m]), None if dlam is None else dlam[i])
    res: list[float] = []
    jac: list[Array] = []
    for e in range(n_e):
        if not flags[e]:
            continue
        lm, dl = found[e]
        le, w = rs.roots[e], rs.weights[e]
        if form == "frequency-damping":
            om_m, om_e = abs(lm), abs(le)
            ze_m, zd_e = -lm.real / om_m, -le.real / om_e
            ze_scale = abs(zd_e) if abs(zd_e) > 1e-12 else 1.0
            res += [w * (om_m - om_e) / om_e, w * (ze_m - zd_e) / ze_scale]
            if dl is not None:
                dom = (np.conj(lm) * dl).real / om_m
                jac += [w * dom / om_e, w * (-dl.real / om_m + (lm.real / om_m**2) * dom) / ze_scale]
        else:
            rel = (lm - le) / le
            res += [w * rel.real, w * rel.imag]
            if dl is not None:
                jac += [w * (dl / le).real, w * (dl / le).imag]
    left = [e for e in range(n_e) if not flags[e]]
    if left:
        res += list(-np.poly(rho / rs.roots[left])[1:].real)
        jac += [np.zeros(n_u)] * len(left)
    jac_out = np.vstack(jac) if jac else np.zeros((len(res), n_u))
    if jac_out.shape[0] != len(res):
        jac_out = np.zeros((len(res), n_u))
    return np.asarray(res, dtype=float), jac_out, flags
