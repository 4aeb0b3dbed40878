"""What an identification takes and returns, by name.

One identification (core/identification/pipeline.py) of one run or several:

- :class:`Record` : one run's paired data (t, Y, U), the unit every method takes a list of;
- :class:`FilterPass` : one pass of the augmented EKF over the runs (its final estimate, its
  histories, its mean NIS);
- :class:`NoiseFit` : the noise model read off the data and what was done with it
  (core/identification/noise_fit.py);
- :class:`Selection`, :class:`Linearisation`, :class:`Choice` : the automatic choice of the
  coefficients (core/identification/selection.py);
- :class:`Estimate` : the model's parameters identified with the noise model (the EKF pass's
  and the final estimate with their covariances; coefficients, then current components);
- :class:`Diagnosis` : identifiability and whether the data contradict the assumptions
  (core/identification/diagnosis.py);
- :class:`Identification` : what every command reports: the coefficients with their error
  bars, the water current, the noise model, the diagnosis, the selection.
"""
from dataclasses import dataclass, field
import math
from typing import Any, Callable, Optional

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.model.current import current_estimate, CurrentEstimate
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import State


@dataclass(frozen=True)
class Record:
    """One run of the vehicle, as the identification methods take it.

    t : (N,) sample times (s), strictly increasing; jitter, dropouts and gaps allowed
    Y : (N, 12) measurements (NaN: missing)
    U : (N, 7) inputs, U[k] the command in force over [t_k, t_k+1) (zero-order hold)
    """

    t: np.ndarray
    Y: np.ndarray
    U: np.ndarray

    @property
    def samples(self) -> int:
        """Rows of the record (measurements and command changes)."""
        return len(self.t)


@dataclass
class FilterPass:
    """One pass of the augmented EKF over the runs in turn (core.identification.batch.run_ekf).

    stats : (5,) the compiled loop's statistics summed over the runs (stats[0] the last status)
    history : the last run's histories (empty without hist_every)
    R, Q : the final measurement and process noise covariances
    theta0 : (p,) the start of the first run; theta, theta_cov : the final estimate
    mean_nis_per_dof, steps : over all runs
    whites : per run its whitened innovations (N_i, 12) when asked for (want_white), else empty
    """

    stats: np.ndarray
    history: dict
    R: np.ndarray
    Q: np.ndarray
    theta0: np.ndarray
    theta: np.ndarray
    theta_cov: np.ndarray
    mean_nis_per_dof: float
    steps: int
    whites: list = field(default_factory=list)


@dataclass
class Refinement:
    """The filter-error refinement's outcome (core.identification.batch.refine).

    estimate : (p,) theta at the optimum; cov : (p, p) its white-noise covariance
    cost : the cost per residual (its mean whitened square; 1 when the noise model holds)
    information : (p, p) J^T J, J the Jacobian of the whitened innovations with respect to
        theta (1 / theta's units^2)
    scores : (sum N, p) J_k^T r_k per sample k (its 12 rows of J and of the innovations r):
        the sums a sandwich covariance is made of (the whole J is never formed)
    converged, message, nfev : the optimiser's verdict, message and function evaluations
    white : (sum N, 12) the whitened innovations at the optimum (NaN: no measurement), when
        asked for (details)
    ar1_cov : (p, p) the covariance under the innovations' AR(1) noise model, when asked for
        (refine's ar1)
    """

    estimate: np.ndarray
    cov: np.ndarray
    cost: float
    information: np.ndarray
    scores: np.ndarray
    converged: bool
    message: str
    nfev: int
    white: Optional[np.ndarray] = None
    ar1_cov: Optional[np.ndarray] = None


@dataclass(frozen=True)
class PassEstimate:
    """The final estimate (p,) and covariance (p, p) of an EKF pass made elsewhere (the bag
    replay's, the live node's path)."""

    estimate: np.ndarray
    cov: np.ndarray


@dataclass
class NoiseFit:
    """The noise model of a record and what was done with it.

    model : per channel name, noise_model()'s dict (level, ar1, tau_s, ljung_box, p_white,
        white, samples), from the innovations of the EKF pass with the configured noise
    configured_std, effective_std : (12,) the configured and the effective 1-sigma
    used : True if the effective noise replaced the configured one
    covariance : 'white' ((J^T J)^-1 times the residual variance), 'ar1' (uncertainty.py
        ar1_covariance: the effective noise's exact one) or 'sandwich'
    inflation : (p,) sandwich 1-sigma / white (or ar1) 1-sigma of each coefficient
    lags : the sandwich's lag window (samples)
    white : (N, 12) whitened innovations at the refined solution; information : (p, p) J^T J
        and scores : (N, p) J_k^T r_k per sample, of their Jacobian J with respect to the
        parameters
    ekf_run : the EKF pass whose estimate is reported (the configured noise's, or the
        effective noise's when used; None when a pass made elsewhere was kept)
    configured_pass : the EKF pass with the configured noise
    configured_q, effective_q : (12,) the configured per-step process noise 1-sigma (the
        states' units) and the one used (the matched one when process_used)
    process_used : True if the process noise was matched to the innovations
        (core/identification/noise_fit.py); process_levels : (12,) the innovation levels of the
        configured pass; noise_only_levels : (12,) those of the pass with the measurement noise
        at these levels and the configured process noise, made when a level crossed the
        process-noise threshold (None: not made, or it failed)
    bounds : the runs' first rows in the stacked refined residuals ([0, N_1, ..., sum N])
    refine_cost : the refinement's cost per residual (its mean whitened square; 1 when the
        noise model holds)
    """

    model: dict
    configured_std: np.ndarray
    effective_std: np.ndarray
    used: bool
    covariance: str = 'white'
    inflation: Optional[np.ndarray] = None
    lags: int = 0
    refine_converged: bool = True
    refine_message: str = ''
    notes: list = field(default_factory=list)
    white: Optional[np.ndarray] = None
    information: Optional[np.ndarray] = None
    scores: Optional[np.ndarray] = None
    ekf_run: Optional[FilterPass] = None
    configured_pass: Optional[FilterPass] = None
    configured_q: Optional[np.ndarray] = None
    effective_q: Optional[np.ndarray] = None
    process_used: bool = False
    process_levels: Optional[np.ndarray] = None
    noise_only_levels: Optional[np.ndarray] = None
    bounds: Optional[list] = None
    refine_cost: float = math.nan

    @property
    def reported_pass(self) -> Optional[FilterPass]:
        """The EKF pass whose estimate is reported: ekf_run, or the configured pass when a
        pass made elsewhere with the configured noise was kept."""
        return self.ekf_run if self.ekf_run is not None else self.configured_pass

    def document(self) -> dict:
        """JSON-ready dict (the result's `noise_model`)."""
        return {
            'channels': {n: {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                             for k, v in d.items()} for n, d in self.model.items()},
            'configured_std': [float(v) for v in self.configured_std],
            'effective_std': [float(v) for v in self.effective_std],
            'used': bool(self.used), 'covariance': self.covariance,
            'inflation': None if self.inflation is None else [float(v) for v in self.inflation],
            'lags': int(self.lags), 'notes': list(self.notes),
            'configured_q_state': _floats(self.configured_q),
            'effective_q_state': _floats(self.effective_q),
            'process_noise_used': bool(self.process_used),
            'process_levels': _levels_doc(self.process_levels),
            'noise_only_levels': _levels_doc(self.noise_only_levels),
            'runs': 1 if self.bounds is None else len(self.bounds) - 1,
            'configured_mean_nis_per_dof': (None if self.configured_pass is None else
                                            _finite(self.configured_pass.mean_nis_per_dof)),
            'mean_nis_per_dof': (None if self.ekf_run is None else
                                 _finite(self.ekf_run.mean_nis_per_dof)),
            'refined_cost_per_residual': _finite(self.refine_cost)}


def readable(x: float, digits: int = 3) -> str:
    """A number for a person: `digits` significant digits, never an exponent ('12200',
    '0.0413', '< 0.001'); 'unbounded' for an infinity, '-' when not a number."""
    if not math.isfinite(x):
        return '-' if math.isnan(x) else 'unbounded'
    value = float(f'{x:.{digits}g}')
    if value == 0.0:
        return '0'
    if abs(value) < 1e-3:
        return '< 0.001' if value > 0 else '> -0.001'
    if abs(value) >= 10.0 ** digits:
        return f'{value:.0f}'
    return f'{value:.{digits}g}'


def percent(fraction: float) -> str:
    """A fraction as a percentage of 2 significant digits ('13 %', '0.41 %', '12200 %')."""
    value = 100.0 * fraction
    if math.isfinite(value) and abs(value) >= 10.0:
        return f'{value:.0f} %'
    return readable(value, 2) + ' %'


def confidence_words(confidence: float) -> str:
    """How the left-out deviation was read off the residuals, in words."""
    if confidence == 0.5:
        return 'median-unbiased'
    return f'the {100 * confidence:.0f} % upper bound'


def times(ratio: float, digits: int = 3) -> str:
    """A ratio of `digits` significant digits without an exponent ('1.52x', '130x',
    '2410x')."""
    return f'{ratio:.0f}x' if abs(ratio) >= 10.0 ** (digits - 1) else f'{ratio:.{digits}g}x'


def _finite(x: float | None) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def _floats(a: ArrayLike | None) -> list[float] | None:
    return None if a is None else [float(v) for v in np.asarray(a, dtype=float)]


def _levels_doc(a: ArrayLike | None) -> list[float | None] | None:
    """(12,) innovation levels for JSON: None for a channel without one (NaN)."""
    return None if a is None else [_finite(float(v)) for v in np.asarray(a, dtype=float)]


@dataclass
class Selection:
    """The outcome of the automatic choice (core/identification/selection.py).

    chosen : the coefficients identified (named ones first, then in order of entry)
    named : those the user named (always chosen)
    left_out : {name: reason} for every other coefficient of the vehicle (file values kept)
    steps : per coefficient added by the stepwise pass: partial F, relative CRB 1-sigma and
        largest correlation when it entered
    candidates : how many coefficients the selection could choose from
    consider_inflation : per identified parameter, its final 1-sigma over the statistical one
        (identify_auto; empty when the set was only chosen)
    consider_scale : the relative 1-sigma of the left-out coefficients the residuals allow
        (core.identification.selection.left_out_deviation), which the consider covariance uses;
        None when the set was only chosen
    consider_sources : {member: {left-out coefficient: share of its consider variance}}, the
        terms each widening comes from (the largest few)
    suspects : the left-out coefficients the residuals point at most (largest partial F alone,
        white, at least the entry threshold), largest first
    reassessed : True when pass 2 ran (identify_auto); False for pass 1 alone
        (choose_coefficients, the live identifier's choice)
    criteria : the thresholds the choice applied ({'f_to_enter', 'rel_std_max',
        'correlation_max', 'prior_rel_std'})
    """

    chosen: list
    named: list
    left_out: dict
    steps: list = field(default_factory=list)
    candidates: int = 0
    consider_inflation: dict = field(default_factory=dict)
    reassessed: bool = True
    criteria: dict = field(default_factory=dict)
    consider_scale: Optional[float] = None
    consider_sources: dict = field(default_factory=dict)
    suspects: list = field(default_factory=list)

    def document(self) -> dict:
        """JSON-ready dict (the result's `selection`)."""
        return {'chosen': list(self.chosen), 'named': list(self.named),
                'left_out': dict(self.left_out), 'steps': list(self.steps),
                'candidates': int(self.candidates),
                'consider_inflation': dict(self.consider_inflation),
                'consider_scale': self.consider_scale,
                'consider_sources': {n: dict(d) for n, d in self.consider_sources.items()},
                'suspects': list(self.suspects),
                'criteria': dict(self.criteria,
                                 method='stepwise regression on the filter-error residuals '
                                        '(partial F with the long-run variance)'
                                        + (', then identify, re-assess and identify again'
                                           if self.reassessed else ' (no re-assessment)'))}

    def summary(self) -> list:
        """Lines for the command line: the chosen set, then the left-out ones by reason."""
        lines = [f'automatic selection: {len(self.chosen)} of {self.candidates} candidate '
                 'coefficients chosen (' + ', '.join(self.chosen) + ')'
                 + (f'; named: {", ".join(self.named)}' if self.named else '')]
        groups: dict[str, list[str]] = {}
        for name, why in self.left_out.items():
            key = why.split(':')[0].split(' (')[0]
            groups.setdefault(key, []).append(name)
        if self.consider_inflation:
            lines.append(self.widening_line())
        lines.append('left out (vehicle file values kept; reasons per coefficient in the JSON '
                     '`selection`):')
        for key, members in groups.items():
            lines.append(f'  {key}: {", ".join(members)}')
        return lines

    def widening_line(self) -> str:
        """One sentence: how far the left-out coefficients may be off by the residuals, how
        much that widens the error bars, and where the widest one's widening comes from."""
        if not self.consider_inflation:
            return ''
        worst = max(self.consider_inflation, key=lambda n: self.consider_inflation[n])
        ratio = self.consider_inflation[worst]
        tau = self.consider_scale
        if tau is None:
            allowed = ''
        elif tau < 5e-4:
            allowed = 'the residuals show them at those values; '
        else:
            allowed = (f'the residuals put them {percent(tau)} of their values off, 1-sigma, '
                       + confidence_words(self.criteria['consider_confidence']) + '; ')
        head = ("error bars include the errors of the coefficients left at the file's values "
                f'({allowed}consider analysis): ')
        if ratio < 1.005:
            return head + 'the statistical ones to within 0.5 %'
        src = self.consider_sources.get(worst, {})
        return (head + f'up to {times(ratio)} the statistical ones ({worst}'
                + (', from ' + ', '.join(f'{n} {100 * share:.0f} %' for n, share in src.items())
                   if src else '') + ')')


@dataclass
class Linearisation:
    """What the choice linearised, for the consider analysis of the final error bars.

    G : (q, q) information J^T J of the whitened residuals at the prior, over every parameter
        the pass saw (the named and candidate coefficients, the current components, then the
        added mass only considered)
    names : (q,) their names; prior : (q,) the values the sensitivities were taken at
    left_candidates : indices of the coefficients whose errors bias the set when they are left
        at their prior (the candidates and the considered added mass)
    jacobian : (N * 12, q) the sensitivities J (float32) behind G, kept for the evidence of
        the left-out terms in the final residuals (selection.left_out_deviation); None when
        not kept
    white : (N, 12) the whitened residuals at the prior (NaN: no measurement), or None
    """

    G: np.ndarray
    names: list
    prior: np.ndarray
    left_candidates: list
    jacobian: Optional[np.ndarray] = None
    white: Optional[np.ndarray] = None


@dataclass
class Choice:
    """The automatic choice alone (core.identification.selection.choose_coefficients): the
    Selection, and the Linearisation it was made on."""

    selection: Selection
    linearisation: Linearisation


@dataclass(frozen=True)
class Start:
    """Where an identification starts when that is not where its noise model is read off
    (core/identification/noise_fit.py :func:`identify_with_noise_model`): the user's guesses
    (`--initial`), a warm start's estimate and covariance, or the automatic choice's first
    estimates for its pruned re-identification.

    initial : (p_coef,) the coefficients' start (their units)
    theta_cov0 : (p_coef, p_coef) their initial covariance, or None for the configured
        diag((p0_rel |initial|)^2)
    """

    initial: np.ndarray
    theta_cov0: Optional[np.ndarray] = None


@dataclass(frozen=True)
class SelectionRequest:
    """Choose the coefficients from the data (`--coefficients auto[,NAME,...]`).

    make_model : names -> Model identifying those coefficients (and the water current as the
        caller wants it)
    named : the coefficients always identified (file spelling)
    """

    make_model: Callable[[list], Model]
    named: tuple = ()


@dataclass
class Estimate:
    """The model's parameters (coefficients, then any current components) identified.

    model : the Model identified (with an automatic choice: of the chosen set)
    ekf_estimate, ekf_cov : (p,), (p, p) the EKF pass's
    estimate, cov : the final ones (refined, or the EKF pass's without a refinement); cov the
        covariance the residuals support (core/identification/noise_fit.py)
    noise : the noise model (None when identified without one, core.identification.batch)
    selection : the automatic choice, or None when the coefficients were given
    statistical_cov : with an automatic choice, cov without the consider covariance of the
        left-out coefficients: what the run's information alone says (the identifiability
        verdicts are judged by it); None: cov is that
    """

    model: Model
    ekf_estimate: np.ndarray
    ekf_cov: np.ndarray
    estimate: np.ndarray
    cov: np.ndarray
    noise: Optional[NoiseFit] = None
    selection: Optional[Selection] = None
    statistical_cov: Optional[np.ndarray] = None


@dataclass
class Diagnosis:
    """Do the data contradict the identification's assumptions
    (core.identification.diagnosis.diagnose)?

    consistent : whether the error bars can be trusted
    messages : the first says whether the result can be trusted and why (a NOT plausible
        result says that first); then the problems and notes
    checks : the figures behind them
    identifiability : per parameter verdicts (None without a refinement)
    plausible : whether the estimates are physically plausible for the vehicle file
        (core/identification/plausibility.py); implausible : why not, per coefficient
    """

    consistent: bool
    messages: list
    checks: dict
    identifiability: Optional[dict] = None
    plausible: bool = True
    implausible: list = field(default_factory=list)

    @property
    def trusted(self) -> bool:
        """Consistent and plausible: the result and its error bars can be used."""
        return self.consistent and self.plausible

    def document(self) -> dict:
        """JSON-ready dict (the result's `diagnosis`)."""
        return {'consistent': self.consistent, 'plausible': self.plausible,
                'trusted': self.trusted, 'implausible': list(self.implausible),
                'messages': self.messages, 'checks': self.checks}


@dataclass
class Identification:
    """What an identification reports: the coefficients (names, estimate, 1-sigma, covariance,
    the EKF pass's), the water current split off, and how they were obtained.

    initial : the coefficients' start; truth : their true values when known (else None)
    steps, mean_nis_per_dof : of the EKF pass reported; wall_s : s the identification took
    refined : whether the batch refinement ran
    history, R_final, Q_final : the reported EKF pass's histories and final noise covariances
    current : the water current (None: still water, not asked)
    noise, diagnosis, selection : the noise model, the diagnosis and the automatic choice
        (None when not made: core.identification.batch.identify has neither)
    model : the Model identified; runs : the records it was identified from
    """

    names: list
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    ekf_estimate: np.ndarray
    ekf_std: np.ndarray
    initial: np.ndarray
    truth: Optional[np.ndarray]
    steps: int
    wall_s: float
    mean_nis_per_dof: float
    refined: bool
    history: dict = field(default_factory=dict)
    R_final: Optional[np.ndarray] = None
    Q_final: Optional[np.ndarray] = None
    current: Optional[CurrentEstimate] = None
    noise: Optional[NoiseFit] = None
    diagnosis: Optional[Diagnosis] = None
    selection: Optional[Selection] = None
    model: Optional[Model] = None
    runs: list = field(default_factory=list)

    def error_pct(self, which: str = 'estimate') -> Optional[np.ndarray]:
        if self.truth is None:
            return None
        est = getattr(self, which)
        return 100.0 * (est - self.truth) / np.abs(self.truth)

    @classmethod
    def of(cls, estimate: Estimate, runs: list, **fields: Any) -> 'Identification':
        """The Identification of `estimate` made from `runs`: the coefficients' part of its
        parameters, the water current split off (core.model.current.current_estimate, judged
        on the headings of the runs), the noise model and selection it carries; `fields` the
        others (initial, truth, steps, wall_s, mean_nis_per_dof, refined, ...)."""
        model = estimate.model
        pc = model.p_coef
        est = np.asarray(estimate.estimate, dtype=float)
        cov = np.asarray(estimate.cov, dtype=float)
        ekf_est = np.asarray(estimate.ekf_estimate, dtype=float)
        ekf_cov = np.asarray(estimate.ekf_cov, dtype=float)
        psi = np.concatenate([np.asarray(r.Y)[:, State.PSI] for r in runs])
        current = current_estimate(model, est, cov, ekf_est, ekf_cov, psi)
        truth = fields.pop('truth', None)
        return cls(names=list(model.theta_names[:pc]), estimate=est[:pc],
                   std=np.sqrt(np.diag(cov[:pc, :pc])), cov=cov[:pc, :pc],
                   ekf_estimate=ekf_est[:pc], ekf_std=np.sqrt(np.diag(ekf_cov[:pc, :pc])),
                   truth=None if truth is None else np.asarray(truth, float),
                   current=current, noise=estimate.noise, selection=estimate.selection,
                   model=model, runs=list(runs), **fields)
