"""Which coefficients to identify, chosen from the data (`--coefficients auto[,NAME,...]`).

A vehicle file holds ~100 coefficients from empirical formulas, each 10-50 % off. Identifying
a hand-picked few leaves the others at their prior values, and their errors bias the few (no
error bar covers that bias; core/identification/diagnosis.py says so). Identifying all of them
fails the other way: most are not excited by a given run, and confounded sets give large,
correlated errors. This module picks the largest set the run determines, in two passes:

1. **Stepwise regression on the filter-error residuals** (Klein & Morelli 2006, "Aircraft
   System Identification", ch. 5, written for the filter-error method of
   core/identification/batch.py): at the prior (the vehicle file's values), the whitened
   innovations r of a 12-state EKF over the record and their sensitivities J to every candidate
   (finite differences: one filter run per candidate, on the data's own trajectory, since the
   filter follows the measurements). Then, starting from the coefficients the user named (always
   included) and the water current, try the candidates in order of their residual reduction (the
   partial F of the linearised fit, white) and add the first that
     - reduces the residual significantly: partial F >= F_TO_ENTER, the variance of its
       estimate from the Newey-West long-run variance of its scores (the residuals of a
       wrong prior are strongly correlated in time; a white-noise F would count every sample
       as new information);
     - is identifiable in the enlarged set: relative Cramer-Rao 1-sigma (linearised, white)
       below REL_STD_MAX and largest |correlation| with a member at most CORRELATION_MAX;
     - lowers the expected error (:func:`expected_error`): of the named coefficients, or of
       the whole model when none is named, counting for each coefficient its Cramer-Rao
       variance plus the bias the coefficients left at their prior (PRIOR_REL_STD 1-sigma)
       cause, by Schmidt's consider analysis. This keeps out a candidate that would mostly
       absorb the errors of others.
   Stop when none qualifies. A candidate that fails the identifiability test is left out for
   good (more members only widen the bounds); the others may still enter after others have.
2. **Identify, re-assess, identify again**: the chosen set is identified (EKF pass and
   filter-error refinement with the noise model from the data, core/identification/noise_fit.py,
   started at the prior), its covariance (sandwich when the residuals are coloured) re-checked with
   the identified values, and the members that turned weak (relative 1-sigma >= REL_STD_MAX) or
   strongly correlated (|rho| > CORRELATION_MAX) dropped one at a time, the worst first
   (fixing a parameter is conditioning: the covariance of the rest is the inverse of their
   block of the information matrix). If any was dropped, the rest are identified again,
   started at the first identification's values.

A hovering thruster vehicle (an ROV: Vehicle.hovers) is chosen for as a tank session
identifies it: its cross terms are no candidates (HOVER_CROSS_TERM), and after the
one-at-a-time pass its degrees of freedom's terms and thrust gains may enter as groups, judged
by their relative 1-sigma (:func:`_group_entries`, :func:`_identifiable_part`).

Pass 1 alone is :func:`choose_coefficients`: the live identifier (session/auto_choice.py) runs
only it, on its first `auto_window` seconds, and lets its filter identify the chosen set;
:func:`identify_auto` runs both passes.

Error bars: the final covariance adds the consider covariance of the coefficients left at the
file's values (added-mass terms a literal M^-1 cannot change included, their sensitivities from
a model with the exact inverse), so that it covers the bias a wrong prior causes. How far off
the left-out coefficients may be is read off the residuals, not assumed
(:func:`left_out_deviation`): one relative 1-sigma tau for all of them, the value under which
the part of the residuals that only they can explain is the median of its distribution
(CONSIDER_CONFIDENCE 0.5: median-unbiased; a record the file's values fit leaves tau near 0
and the bars statistical, one they do not fit widens them as far as the misfit says). The
widening of each member is traced to the left-out terms it comes from
(Selection.consider_sources). Measured in docs/accuracy.md (tools/auto_selection_campaign.py).

Coefficients never enter silently: every coefficient of the vehicle is either chosen or left
out with its reason (:class:`Selection`); the left-out ones keep the vehicle file's values.
Coefficients the user named are always identified, whatever their figures (the diagnosis then
calls them weak if they are).
"""
from dataclasses import replace
import math

import numpy as np
from scipy import special

from auv_ident.core.errors import ConfigError, DomainError
from auv_ident.core.identification.batch import FilterErrorResiduals, parameter_scale
from auv_ident.core.identification.noise_fit import identify_with_noise_model
from auv_ident.core.identification.results import (
    Choice,
    Linearisation,
    percent,
    readable,
    Selection,
    Start,
)
from auv_ident.core.identification.uncertainty import (
    bandwidth,
    CORRELATION_WEAK,
    long_run_variance,
    REL_STD_IDENTIFIABLE,
    REL_STD_WEAK,
)
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import CURRENT_NAMES, N_NU, N_STATE

AUTO = 'auto'
F_TO_ENTER = 9.0            # partial F (long-run variance) a candidate needs: 3 sigma
REL_STD_MAX = REL_STD_IDENTIFIABLE   # relative CRB 1-sigma of a member: below 5 %
CORRELATION_MAX = CORRELATION_WEAK   # |correlation| between members: at most 0.95
SENSITIVITY_STEP = 1e-4     # relative finite-difference step of the sensitivities
PRIOR_REL_STD = 0.2         # 1-sigma of a vehicle file's value, relative (formulas: 10-50 % off)
CONSIDER_CONFIDENCE = 0.5   # the left-out deviation: median-unbiased (module docstring)
MAX_LEFT_OUT_SCALE = 1.0    # the left-out deviation taken at most: 100 % of the file's values
SOURCES_SHOWN = 3           # left-out terms named per member as the source of its widening


def parse_request(vehicle, names):
    """The `coefficients` setting's names (a sequence: session.settings.names_of reads the
    command line's 'A,B' text into one) -> (auto, names).

    ['auto']: choose from the data; ['auto', A, B]: choose, always including A and B; [A, B]:
    exactly these; []: the vehicle's default set (names empty). Names are matched as
    Vehicle.index matches them and returned as the file spells them. Raises ConfigError naming
    an unknown coefficient, a name given twice, or 'auto' anywhere but first."""
    if isinstance(names, str):
        raise TypeError('parse_request takes a sequence of names, not text')
    tokens = [str(n).strip() for n in names if str(n).strip()]
    text = ','.join(tokens)
    auto = bool(tokens) and tokens[0].lower() == AUTO
    rest = tokens[1:] if auto else tokens
    if any(tok.lower() == AUTO for tok in rest):
        raise ConfigError(f"coefficients {text!r}: 'auto' must come first (auto,NAME,...)")
    names = []
    for tok in rest:
        if tok in CURRENT_NAMES:
            raise ConfigError(f'coefficients: {tok!r} is the water current; choose it with '
                              'the current setting (--current)')
        name = vehicle.names[vehicle.index(tok)]
        if name in names:
            raise ConfigError(f'coefficients {text!r}: {name} is listed twice')
        names.append(name)
    return auto, names


def candidate_coefficients(vehicle, mass_inverse):
    """The coefficients the selection may choose, and the reasons of the others.

    mass_inverse : the model's resolved choice ('exact' or 'mss_literal'); with the vehicle's
    fixed literal M^-1 the added-mass coefficients cannot change the model.
    Returns (candidates [names in file order], {name: reason})."""
    cands, left = [], {}
    for c, value in zip(vehicle.coefficients, vehicle.values):
        if vehicle.hovers and not _tank_term(c):
            left[c.name] = HOVER_CROSS_TERM
        elif c.is_added_mass and mass_inverse == 'mss_literal':
            left[c.name] = ("added mass: the vehicle's fixed (literal) mass inverse does not "
                            'change with it')
        elif value == 0.0:
            left[c.name] = ('zero in the vehicle file: no prior to scale the search by (name '
                            'it to identify it)')
        else:
            cands.append(c.name)
    return cands, left


# A hovering thruster vehicle (Vehicle.hovers: an ROV, a hovering AUV) is flown in a tank one
# or two sticks at a time (surge, sway, heave, yaw: core/simulation/maneuvers.py 'tank'), at
# speeds where its cross terms are a few percent of the damping. Its file's cross terms are
# Fossen's Coriolis of the diagonal added mass (X_vr = a2, Y_ur = -a1, ...: the vehicle file
# writes them from the added mass) and the couplings the user names; the manoeuvres cannot
# separate them from the diagonal terms they share an equation with. As candidates they made
# the choice fail whole: each, left at its prior with a 20 % error, was counted as a bias of
# every diagonal term, so no diagonal term lowered the expected error (measured on the
# independent BlueROV2 Heavy bag, seed 3, 600 s: 1 of 29 chosen, thrust_gain_fwd; every
# diagonal added mass and damping "would not lower the expected error"). The candidates are
# the thrust gains and the diagonal added mass and damping of each degree of freedom.
HOVER_CROSS_TERM = ('a cross term of a hovering thruster vehicle (the Coriolis of its added '
                    'mass, a coupling): a tank session of single sticks does not separate it '
                    "from the diagonal terms; kept at the file's value (name it to identify "
                    'it)')


def _tank_term(c):
    """Whether coefficient c is a term a tank session identifies (HOVER_CROSS_TERM): a thrust
    gain or the thrusters' time constant, a diagonal added mass (its column its equation), or
    a diagonal damping (the equation's own velocity, linear or times its magnitude: X_u, X_uu,
    ..., N_rr)."""
    if c.is_thrust_gain or c.is_thrust_lag:
        return True
    if c.is_added_mass:
        return c.added_mass_col == c.equation
    own = {c.equation, c.equation + N_NU}
    return c.equation in c.factors and set(c.factors) <= own


def sensitivities(model, cfg, runs, theta, T=None, max_step=None, max_bridge=0.25,
                  threads=None):
    """Filter-error residuals at theta and their sensitivities to every parameter (one filter
    run per parameter, on `threads` threads: None =
    core.identification.batch.difference_threads()).

    model : Model whose theta are the parameters; cfg : FilterConfig (noise, channels)
    runs : list of Record (one run or several, their residuals stacked in order)
    theta : (p,) the values to linearise at (file units; current in m/s)
    Returns (white (sum N, 12) whitened innovations, NaN = no measurement; J (sum N * 12, p)
    their derivatives, zero rows where no measurement; failed: indices of parameters whose step
    took the model out of its domain (their columns are zero)). Raises DomainError if the
    filter fails at theta itself."""
    fer = FilterErrorResiduals(model, cfg, runs, T=T, max_step=max_step,
                               max_bridge=max_bridge)
    theta = np.asarray(theta, dtype=float)
    steps = SENSITIVITY_STEP * parameter_scale(model, theta)
    try:
        r0, J, failed = fer.forward_differences(theta, steps, threads=threads)
    except DomainError:
        raise DomainError('the filter-error residuals cannot be computed at the vehicle '
                          "file's values (the model leaves its domain on this record)") from None
    white = fer.white.copy()
    return white, J, failed


def _set_figures(G, members, s2, prior):
    """Linearised white-noise CRB of a set: (relative 1-sigma, largest |correlation|, index of
    that partner) per member, from the information G[members, members] / s2. A member whose
    prior is 0 (a current component) has relative 1-sigma 0 (judged by others only)."""
    idx = np.asarray(members, dtype=int)
    try:
        cov = np.linalg.inv(G[np.ix_(idx, idx)]) * s2
    except np.linalg.LinAlgError:
        k = len(idx)
        return np.full(k, math.inf), np.ones(k), np.zeros(k, dtype=int)
    return _figures_of_cov(cov, prior[idx])


def _figures_of_cov(cov, values):
    """(relative 1-sigma, largest |correlation|, index of that partner) per parameter."""
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        rel = np.where(values != 0.0, sd / np.abs(values), 0.0)
        corr = np.nan_to_num(cov / np.outer(sd, sd))
    np.fill_diagonal(corr, 0.0)
    corr = np.abs(corr)
    n = len(sd)
    if n < 2:
        return rel, np.zeros(n), np.zeros(n, dtype=int)
    partner = np.argmax(corr, axis=1)
    return rel, corr[np.arange(n), partner], partner


def _hac_partial_f(J, r_set, J_set, proj, c, n_samples):
    """Partial F (Wald) of candidate c with the Newey-West variance of its estimate: with
    j_perp c's sensitivity with the members' part projected out, delta = j_perp^T r /
    j_perp^T j_perp fitted, the scores g_k = sum over the channels of sample k of
    j_perp * (r - delta j_perp) and F = delta^2 (j_perp^T j_perp)^2 / LRV(g). The scores are
    taken after the fit (under the alternative): before it, a candidate's own effect in the
    residuals would count as correlated noise and hide it."""
    j_perp = J[:, c] - (J_set @ proj if J_set.shape[1] else 0.0)
    jj = float(j_perp @ j_perp)
    if jj <= 0.0:
        return 0.0
    delta = float(j_perp @ r_set) / jj
    resid = (r_set - delta * j_perp).reshape(n_samples, N_STATE)
    g = (j_perp.reshape(n_samples, N_STATE) * resid).sum(axis=1)
    lrv = long_run_variance(g, bandwidth(resid))
    return float(delta ** 2 * jj ** 2 / lrv) if lrv > 0 else 0.0


def consider_bias(G, members, left, sigma):
    """Bias covariance of the members' estimates from the errors of the coefficients left at
    their prior (Schmidt's consider analysis, linearised): with d_L ~ (0, diag(sigma_L^2)),
    the least-squares estimate of the members moves by -G_SS^-1 G_SL d_L, whose covariance is
    B B^T with B = G_SS^-1 G_SL diag(sigma_L). Returns B B^T (|members|, |members|)."""
    S, L = np.asarray(members, dtype=int), np.asarray(left, dtype=int)
    if L.size == 0:
        return np.zeros((S.size, S.size))
    B = np.linalg.pinv(G[np.ix_(S, S)]) @ G[np.ix_(S, L)] * sigma[L][None, :]
    return B @ B.T


def _left_out_part(G, b, members, left):
    """The left-out coefficients' information and score with the members' part projected out
    (the members are fitted, so only what the members cannot absorb is evidence about the
    others): K = G_LL - G_LS G_SS^-1 G_SL, c = b_L - G_LS G_SS^-1 b_S."""
    S, L = np.asarray(members, dtype=int), np.asarray(left, dtype=int)
    proj = np.linalg.pinv(G[np.ix_(S, S)]) @ G[np.ix_(S, L)]
    K = G[np.ix_(L, L)] - G[np.ix_(L, S)] @ proj
    c = b[L] - proj.T @ b[S]
    return 0.5 * (K + K.T), c


def left_out_deviation(lin, members, left, white, weights=None,
                       confidence=CONSIDER_CONFIDENCE):
    """How far the coefficients left at the file's values may be off, by what the residuals
    allow: tau, one relative 1-sigma for all of them (d_L ~ (0, tau^2 diag(prior_L^2))).

    The whitened residuals of the identified set, r ~ J_L d_L + e, e white of unit variance
    (the configured noise), J the sensitivities at the file's values (the Linearisation): the
    members were fitted (their large, nonlinear corrections are in r already, which the
    residuals at the file's values would leave to a linear guess); what the left-out terms
    alone can explain is X = c^T K^+ c (:func:`_left_out_part`, b = J^T r).
    In the eigenvectors of W = diag|prior_L| K diag|prior_L| (eigenvalues lambda_i > 0),
    X = sum_i (1 + tau^2 lambda_i) chi2_1, taken as a gamma variable of that mean and variance
    (Satterthwaite). tau is the largest value under which an X as small as the one measured
    has probability 1 - confidence (0.5: the measured X is the median, a median-unbiased
    estimate; higher: an upper bound), at most MAX_LEFT_OUT_SCALE. The residuals and J are
    whitened alike (weights); coloured noise adds to X and so only widens the bars.

    lin : Linearisation (G, jacobian, prior); members, left : indices into it (the identified
    set with the current components; the left-out coefficients); white : (N, 12) the residuals
    of the identified set, whitened (NaN: no measurement); weights : (12,) per channel the
    factor that takes J (whitened by the configured noise) to the whitening of `white` (the
    configured over the effective 1-sigma), None: 1
    Returns (tau, {'explained': X, 'directions': len(lambda), 'point': the moment estimate
    sqrt(max(0, X - n) / sum lambda), 'suspects': [(name, partial F)] the left-out terms the
    residuals point at most, largest first (each alone: c_j^2 / K_jj, white)})."""
    info = {'explained': 0.0, 'directions': 0, 'point': 0.0, 'suspects': []}
    if not len(left) or lin.jacobian is None:
        return 0.0, info
    J, G = lin.jacobian, lin.G
    if weights is not None and np.any(np.asarray(weights) != 1.0):
        n = J.shape[0] // len(weights)
        J = (J.reshape(n, len(weights), -1)
             * np.asarray(weights, dtype=np.float32)[None, :, None]).reshape(J.shape)
        G = (J.T @ J).astype(float)
    score = (J.T @ np.nan_to_num(np.asarray(white, dtype=np.float32).ravel())).astype(float)
    K, c = _left_out_part(G, score, members, left)
    scale = np.abs(lin.prior[np.asarray(left, dtype=int)])
    lam, Q = np.linalg.eigh(scale[:, None] * K * scale[None, :])
    keep = lam > 1e-9 * max(float(lam.max()), 0.0)
    if not np.any(keep):
        return 0.0, info
    lam, Q = lam[keep], Q[:, keep]
    X = float(np.sum((Q.T @ (scale * c)) ** 2 / lam))
    with np.errstate(invalid='ignore', divide='ignore'):
        single = np.where(np.diag(K) > 0.0, c ** 2 / np.diag(K), 0.0)
    order = np.argsort(-single)
    info.update(explained=X, directions=int(lam.size),
                point=math.sqrt(max(0.0, X - lam.size) / float(lam.sum())),
                suspects=[(lin.names[left[j]], float(single[j])) for j in order[:SOURCES_SHOWN]
                          if single[j] >= F_TO_ENTER])

    def below(tau):
        # P(X_model <= X measured | tau) > 1 - confidence: tau is not yet excluded
        a = 1.0 + tau * tau * lam
        mean, var = float(a.sum()), 2.0 * float(np.sum(a * a))
        # scipy.stats.gamma.cdf(X, a, scale=s) is gammainc(a, X / s), the same numbers without
        # importing scipy.stats (about 20 MB resident, docs/reliability.md bounded memory)
        return special.gammainc(mean * mean / var, X / (var / mean)) > 1.0 - confidence

    lo, hi = 1e-6, MAX_LEFT_OUT_SCALE
    if not below(lo):
        return 0.0, info
    if below(hi):
        return hi, info
    for _ in range(60):             # bisection on log tau: 1e-6 .. 1 to 0.03 %
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if below(mid) else (lo, mid)
    return hi, info


def whitening_weights(fit):
    """(12,) per channel the configured over the effective 1-sigma of a NoiseFit: what takes
    the sensitivities at the file's values (whitened by the configured noise) to the whitening
    of the refined residuals (by the noise the refinement used); 1 where the configured noise
    was used. Weighting J, not the residuals, keeps the noise in the residuals at unit variance
    (a noise louder than configured is not taken for the left-out terms' deviation)."""
    return np.asarray(fit.configured_std, dtype=float) / np.asarray(fit.effective_std,
                                                                    dtype=float)


def consider_sources(G, members, left, sigma, names, member_names):
    """Per member, the left-out terms its consider variance comes from: {member name:
    {left-out name: share of its consider variance}}, the SOURCES_SHOWN largest of at least
    1 % (each term's own part (B_ij sigma_j)^2 over their sum; members without widening are
    left out)."""
    S, L = np.asarray(members, dtype=int), np.asarray(left, dtype=int)
    if L.size == 0:
        return {}
    B = np.linalg.pinv(G[np.ix_(S, S)]) @ G[np.ix_(S, L)] * sigma[L][None, :]
    parts = B ** 2
    out = {}
    for k, name in enumerate(member_names):
        total = float(parts[k].sum())
        if total <= 0.0:
            continue
        top = np.argsort(-parts[k])[:SOURCES_SHOWN]
        out[name] = {names[L[j]]: round(float(parts[k, j] / total), 3) for j in top
                     if parts[k, j] >= 0.01 * total}
    return out


def expected_error(G, members, pool_all, s2, prior, sigma, of_interest=()):
    """The selection's objective, from the expected squared relative error of a coefficient:
    PRIOR_REL_STD^2 for one left at its prior, and for a member its white-noise CRB variance
    plus the bias the left-out ones cause (:func:`consider_bias`), over its value squared.

    of_interest : indices (members) whose errors are the objective, the coefficients the user
        named; empty: the sum over every coefficient with a prior (pool_all: the candidates,
        the named ones and those only considered), where named coefficients the run does not
        determine (CRB 1-sigma >= REL_STD_WEAK of the value: no choice helps them) and the
        current components count nothing.
    """
    left = [c for c in pool_all if c not in set(members)]
    S = np.asarray(members, dtype=int)
    var = np.diag(np.linalg.pinv(G[np.ix_(S, S)])) * s2
    mse = var + np.diag(consider_bias(G, members, left, sigma))
    if len(of_interest):
        pos = [members.index(i) for i in of_interest]
        return float(np.sum(mse[pos] / prior[S[pos]] ** 2))
    with np.errstate(invalid='ignore', divide='ignore'):
        determined = var < (REL_STD_WEAK * prior[S]) ** 2
    coef = (prior[S] != 0.0) & determined
    return float(np.sum(mse[coef] / prior[S][coef] ** 2) + len(left) * PRIOR_REL_STD ** 2)


def _group_entries(G, b, rr, n_res, prior, names, members, groups, pool_all, of_interest):
    """The groups' step after the one-at-a-time stepwise (a hovering vehicle's degrees of
    freedom, :func:`tank_groups`): add, the best first, a group whose members not yet in
    enter together when each is identifiable in the enlarged set (relative 1-sigma below
    REL_STD_MAX, |correlation| at most CORRELATION_MAX), they reduce the residual
    significantly together (partial F per member, white, >= F_TO_ENTER) and lower the
    expected error; until none does. Besides each group, all of them at once less what is not
    identifiable with the rest (:func:`_identifiable_part`) is tried as one. One at a time,
    the added mass, linear and quadratic damping of one equation each absorb the others'
    prior errors (consider analysis) and none lowers the expected error, though the three
    together are determined; and every equation's force is the thrust gains' (measured: the
    independent BlueROV2 Heavy bag, seed 3, 600 s: one at a time 2 of 17 chosen, by groups
    4, thrust_gain_rev and the surge, sway, heave and yaw terms each "would not lower the
    expected error").
    Returns (members, steps [{name, partial_f, rel_std, max_correlation, expected_error,
    group}], names entered)."""
    sigma = PRIOR_REL_STD * np.abs(prior)
    members, steps, entered = list(members), [], set()
    while True:
        G_inv = np.linalg.pinv(G[np.ix_(members, members)]) if members else np.zeros((0, 0))
        rss = rr - (float(b[members] @ G_inv @ b[members]) if members else 0.0)
        s2 = max(1.0, max(rss, 1e-300) / max(1, n_res - len(members)))
        current = expected_error(G, members, pool_all, s2, prior, sigma, of_interest)
        best = None
        # the groups one by one, and all of them at once less what is not identifiable
        # with the rest: a thrust gain scales every equation's force, so the degrees of
        # freedom are determined only together with it and it only with them
        together = _identifiable_part(G, s2, prior, members, [c for g in groups for c in g])
        tries = [([c for c in g if c not in members], CORRELATION_MAX) for g in groups]
        for new, limit in tries + [(together, 1.0)]:
            if not new:
                continue
            trial = members + new
            rel, cmax, _ = _set_figures(G, trial, s2, prior)
            if np.any(rel[-len(new):] >= REL_STD_MAX) or np.any(cmax[-len(new):] > limit):
                continue
            T_inv = np.linalg.pinv(G[np.ix_(trial, trial)])
            f = (rss - (rr - float(b[trial] @ T_inv @ b[trial]))) / len(new) / s2
            after = expected_error(G, trial, pool_all, s2, prior, sigma, of_interest)
            if f >= F_TO_ENTER and after < current and (best is None or after < best[0]):
                best = (after, new, rel[-len(new):], cmax[-len(new):], f)
        if best is None:
            return members, steps, entered
        after, new, rel, cmax, f = best
        members += new
        entered.update(names[c] for c in new)
        label = ','.join(names[c] for c in new)
        steps += [{'name': names[c], 'partial_f': float(f), 'rel_std': float(r),
                   'max_correlation': float(m), 'expected_error': after, 'group': label}
                  for c, r, m in zip(new, rel, cmax)]


def _identifiable_part(G, s2, prior, members, extra):
    """The coefficients of extra (indices) not in members that are determined together with
    them: all of them, less the one with the largest relative 1-sigma one at a time while
    any is at REL_STD_MAX or above. No correlation limit here: a member's relative 1-sigma
    already carries what its correlations add (1 / (1 - rho^2) in the variance), and a
    hovering vehicle's two thrust gains are correlated 0.999 on a tank session (every stick
    drives forward and reverse curve sides in pairs) yet each determined within 0.4 %; left
    at its prior, the one left out biased every other term (prune judges them so too)."""
    new = [c for c in dict.fromkeys(extra) if c not in members]
    while new:
        rel = _set_figures(G, members + new, s2, prior)[0][len(members):]
        if np.all(rel < REL_STD_MAX):
            return new
        new.pop(int(np.argmax(rel)))
    return new


def tank_groups(names, vehicle, indices):
    """The groups of a hovering vehicle's candidates (indices into names) that enter
    together (:func:`_group_entries`): the thrust gains, and per equation its diagonal
    added mass and damping; [] for another vehicle."""
    if not vehicle.hovers:
        return []
    by = {}
    for i in indices:
        c = vehicle.coefficients[vehicle.index(names[i])]
        # the time constant goes with the gains: it scales nothing of one equation
        by.setdefault('gain' if c.is_thrust_gain or c.is_thrust_lag else c.equation,
                      []).append(i)
    return [g for g in by.values() if len(g) > 1]


def forward_stepwise(J, white, prior, names, forced, candidates, consider_only=(),
                     named=(), groups=()):
    """Pass 1 of the module docstring on one linearisation.

    J (N * 12, p), white (N, 12): sensitivities and residuals (sensitivities()); prior (p,)
    the values they were taken at; names (p,); forced: indices always in the set (named
    coefficients, current components); candidates: indices it may add; consider_only:
    indices never added whose prior errors count (added mass the model cannot change); named:
    the forced coefficients the user named, whose expected error is the objective if the run
    determines any of them (expected_error), else that of the whole model.
    Returns (chosen indices in order of entry, forced first; steps [{name, partial_f,
    rel_std, max_correlation, expected_error}]; {name: reason} for the candidates left
    out)."""
    n_samples = white.shape[0]
    r = np.nan_to_num(white.ravel())
    n_res = int(np.count_nonzero(r))
    G = J.T @ J
    b = J.T @ r
    rr = float(r @ r)
    sigma = PRIOR_REL_STD * np.abs(prior)
    members = list(forced)
    pool_all = (list(candidates) + list(consider_only)
                + [c for c in forced if prior[c] != 0.0])
    pool = [c for c in candidates if G[c, c] > 0.0]
    reasons = {names[c]: 'no sensitivity: this run does not excite it'
               for c in candidates if G[c, c] <= 0.0}
    last = {}
    steps = []
    if len(members):
        var0 = np.diag(np.linalg.pinv(G[np.ix_(members, members)]))
        s2_0 = max(1.0, (rr - float(b[members] @ np.linalg.pinv(
            G[np.ix_(members, members)]) @ b[members])) / max(1, n_res - len(members)))
        of_interest = [i for i in named if prior[i] != 0.0 and var0[members.index(i)] * s2_0
                       < (REL_STD_WEAK * prior[i]) ** 2]
    else:
        of_interest = []
    while pool:
        if members:
            G_inv = np.linalg.pinv(G[np.ix_(members, members)])
            delta = G_inv @ b[members]
            rss = rr - float(b[members] @ delta)
            J_set = J[:, members]
            r_set = r - J_set @ delta
        else:
            G_inv = np.zeros((0, 0))
            rss, J_set, r_set = rr, np.zeros((r.size, 0)), r
        s2 = max(1.0, max(rss, 1e-300) / max(1, n_res - len(members) - 1))
        current = expected_error(G, members, pool_all, s2, prior, sigma, of_interest)
        cand = np.array(pool)
        proj = G_inv @ G[np.ix_(members, cand)] if members else np.zeros((0, len(cand)))
        norm = G[cand, cand] - np.einsum('ij,ij->j', G[np.ix_(members, cand)], proj)
        cross = b[cand] - proj.T @ b[members] if members else b[cand]
        with np.errstate(invalid='ignore', divide='ignore'):
            f_white = np.where(norm > 0.0, cross ** 2 / norm / s2, 0.0)
        added = False
        for k in np.argsort(-f_white):
            c = int(cand[k])
            if f_white[k] < F_TO_ENTER:
                last[c] = ('residual reduction too small: partial F (white) '
                           f'{readable(f_white[k])} < {F_TO_ENTER:g}')
                continue
            trial = members + [c]
            rel, cmax, partner = _set_figures(G, trial, s2, prior)
            if rel[-1] >= REL_STD_MAX:
                reasons[names[c]] = (f'not identifiable: relative 1-sigma {percent(rel[-1])} '
                                     f'>= {100 * REL_STD_MAX:g} %')
                pool.remove(c)
                continue
            if cmax[-1] > CORRELATION_MAX:
                reasons[names[c]] = (f'correlated {cmax[-1]:.3f} with {names[trial[partner[-1]]]}'
                                     f' (limit {CORRELATION_MAX:g})')
                pool.remove(c)
                continue
            after = expected_error(G, trial, pool_all, s2, prior, sigma, of_interest)
            if after >= current:
                last[c] = ('would not lower the expected error: it absorbs the errors of '
                           'coefficients left at their prior (consider analysis, '
                           f'{readable(after)} >= {readable(current)})')
                continue
            f_hac = _hac_partial_f(J, r_set, J_set, proj[:, k], c, n_samples)
            if f_hac < F_TO_ENTER:
                last[c] = (f'residual reduction too small: partial F {readable(f_hac)} < '
                           f'{F_TO_ENTER:g} (long-run variance)')
                continue
            members.append(c)
            steps.append({'name': names[c], 'partial_f': f_hac, 'rel_std': float(rel[-1]),
                          'max_correlation': float(cmax[-1]), 'expected_error': after})
            pool.remove(c)
            added = True
            break
        if not added:
            break
    if groups:
        members, more, entered = _group_entries(G, b, rr, n_res, prior, names, members,
                                                groups, pool_all, of_interest)
        steps += more
        pool = [c for c in pool if names[c] not in entered]
        for n in entered:
            reasons.pop(n, None)
    for c in pool:
        reasons[names[c]] = last.get(c, 'not reached')
    return members, steps, reasons


def prune(names, estimate, cov, keep_always, correlated_ok=()):
    """Pass 2: drop, one at a time and the worst first, the members that are weak (relative
    1-sigma >= REL_STD_MAX) or strongly correlated (> CORRELATION_MAX) with the identified
    values; the covariance of the rest is the inverse of their block of the information.
    keep_always: names never dropped (named by the user, current components); correlated_ok:
    names dropped only if weak (a hovering vehicle's tank terms: :func:`_identifiable_part`
    says why).
    Returns (kept names, {dropped name: reason})."""
    names = list(names)
    est = np.asarray(estimate, dtype=float)
    info = np.linalg.pinv(np.asarray(cov, dtype=float))
    keep = list(range(len(names)))
    dropped = {}
    while True:
        sub = np.linalg.pinv(info[np.ix_(keep, keep)])
        values = np.array([0.0 if names[i] in CURRENT_NAMES else est[i] for i in keep])
        rel, cmax, partner = _figures_of_cov(sub, values)
        bad = [j for j, i in enumerate(keep) if names[i] not in keep_always
               and (rel[j] >= REL_STD_MAX
                    or (cmax[j] > CORRELATION_MAX and names[i] not in correlated_ok))]
        if not bad:
            return [names[i] for i in keep], dropped
        j = max(bad, key=lambda j: rel[j])
        i = keep[j]
        if rel[j] >= REL_STD_MAX:
            why = f'relative 1-sigma {percent(rel[j])} >= {100 * REL_STD_MAX:g} %'
        else:
            why = (f'correlated {cmax[j]:.3f} with {names[keep[partner[j]]]} (limit '
                   f'{CORRELATION_MAX:g})')
        dropped[names[i]] = 'dropped after the first identification: ' + why
        keep.pop(j)


def criteria():
    """The thresholds of the choice (Selection.criteria, the JSON `selection.criteria`)."""
    return {'f_to_enter': F_TO_ENTER, 'rel_std_max': REL_STD_MAX,
            'correlation_max': CORRELATION_MAX, 'prior_rel_std': PRIOR_REL_STD}


def choose_coefficients(make_model, cfg, runs, named=(), T=None, max_step=None,
                        max_bridge=0.25, threads=None):
    """Pass 1 of the module docstring alone: which coefficients the record asks for.

    The part of :func:`identify_auto` that chooses; the live identifier (session/auto_choice.py)
    runs only this and lets its filter identify the set. Costs one filter run over the record
    per candidate (and per added-mass term the model cannot change), then the stepwise pass.

    make_model, cfg, named, runs, T, max_step, max_bridge : as identify_auto
    threads : threads for the sensitivities (None: every usable CPU; the live node asks for 1)
    Returns a Choice: the Selection of the chosen set (every other coefficient left out with its
    reason) and the Linearisation it was made on. Raises DomainError if the filter leaves the
    model's domain at the prior."""
    named = list(named)
    base = make_model([])
    vehicle = base.vehicle
    cands, left_out = candidate_coefficients(vehicle, base.mass_inverse)
    for n in named:
        left_out.pop(n, None)
    pool = [n for n in cands if n not in named]
    all_model = make_model(named + pool)
    prior = all_model.theta_true
    white, J, failed = sensitivities(all_model, cfg, runs, prior, T=T, max_step=max_step,
                                     max_bridge=max_bridge, threads=threads)
    names = list(all_model.theta_names)
    forced = list(range(len(named))) + list(range(all_model.p_coef, all_model.p))
    for i in failed:
        if i >= len(named) and i < all_model.p_coef:
            left_out[names[i]] = 'a small change takes the model out of its domain'
    cand_idx = [i for i in range(len(named), all_model.p_coef) if i not in failed]
    # added mass the model cannot change (fixed literal M^-1) still has errors that bias the
    # rest: its sensitivities from a model with the exact inverse, for the consider analysis
    am = [c.name for c in vehicle.coefficients if c.is_added_mass and c.name in left_out
          and c.name not in named]
    consider_idx = []
    if am:
        am_model = Model(vehicle, am + list(base.current_names), mass_inverse='exact',
                         current=base.current, velocity_reference=base.velocity_reference)
        _, J_am, am_failed = sensitivities(am_model, cfg, runs, am_model.theta_true, T=T,
                                           max_step=max_step, max_bridge=max_bridge,
                                           threads=threads)
        keep_am = [i for i in range(len(am)) if i not in am_failed]
        consider_idx = list(range(all_model.p, all_model.p + len(keep_am)))
        J = np.hstack([J, J_am[:, keep_am]])
        names += [am[i] for i in keep_am]
        prior = np.concatenate([prior, am_model.theta_true[keep_am]])
        del J_am
    members, steps, reasons = forward_stepwise(J, white, prior, names, forced, cand_idx,
                                               consider_only=consider_idx,
                                               named=list(range(len(named))),
                                               groups=tank_groups(names, vehicle, cand_idx))
    left_out.update(reasons)
    chosen = [names[i] for i in members if i < all_model.p_coef]
    lin = Linearisation(G=J.T @ J, names=names, prior=prior,
                        left_candidates=list(range(len(named), all_model.p_coef))
                        + consider_idx, jacobian=J.astype(np.float32), white=white)
    sel = Selection(chosen=chosen, named=named, left_out=_in_file_order(vehicle, left_out),
                    steps=steps, candidates=len(cands), reassessed=False, criteria=criteria())
    return Choice(sel, lin)


def _in_file_order(vehicle, reasons):
    order = {n: i for i, n in enumerate(vehicle.names)}
    return dict(sorted(reasons.items(), key=lambda kv: order[kv[0]]))


def identify_auto(make_model, cfg, runs, named=(), T=None, refine_pass=True,
                  max_step=None, max_bridge=0.25, progress=None, hist_every=0):
    """Choose the coefficients from the data and identify them (module docstring).

    make_model : names -> Model identifying those coefficients (and the water current as the
        caller wants it; the current components are always in the set)
    cfg : FilterConfig of the record's noise (its coefficients and initial are replaced)
    runs : list of Record (one run or several: the residuals of all linearised, one set
        identified from all)
    named : coefficients always identified (file spelling)
    T, max_step, max_bridge, refine_pass, progress, hist_every : as
        identify_with_noise_model (the histories are those of the final identification)
    Returns the Estimate of the final identification (its model that of the chosen set, its
    estimate the model's theta, coefficients then current), with its Selection."""
    named = list(named)
    choice = choose_coefficients(make_model, cfg, runs, named=named, T=T, max_step=max_step,
                                 max_bridge=max_bridge)
    sel, lin = choice.selection, choice.linearisation
    vehicle = make_model([]).vehicle
    chosen, left_out = sel.chosen, dict(sel.left_out)

    def run(coefs, start=None):
        # the noise model is read off a pass from the file's values, as the choice was made
        # (identify_with_noise_model's `start`): the pruned re-identification starts at the
        # first estimates, but its noise model must not depend on that start
        c = replace(cfg, coefficients=list(coefs),
                    initial=np.array([vehicle.values[vehicle.index(n)] for n in coefs]))
        return identify_with_noise_model(make_model(coefs), c, runs, T=T,
                                         refine_pass=refine_pass, max_step=max_step,
                                         max_bridge=max_bridge, progress=progress,
                                         hist_every=hist_every, start=start)

    out = run(chosen)
    # a hovering vehicle's tank terms are judged by their relative 1-sigma alone, as they
    # were chosen (_identifiable_part): measured, the correlation limit dropped N_rr (0.981
    # with thrust_gain_fwd) and N_rdot (0.954 with N_rr), determined within 2 %
    tank = [c.name for c in vehicle.coefficients if vehicle.hovers and _tank_term(c)]
    kept, dropped = prune(out.model.theta_names, out.estimate, out.cov,
                          set(named) | set(CURRENT_NAMES), correlated_ok=tank)
    if dropped:
        left_out.update(dropped)
        kept_coefs = [n for n in kept if n not in CURRENT_NAMES]
        first = [out.estimate[out.model.theta_names.index(n)] for n in kept_coefs]
        out = run(kept_coefs, Start(np.array(first)))
        chosen = kept_coefs
    # error bars that cover the coefficients left at the file's values (consider analysis),
    # as far off as the residuals allow them to be
    names = lin.names
    idx = [names.index(n) for n in out.model.theta_names]
    left = [i for i in lin.left_candidates if names[i] not in chosen]
    # without a refinement, or when the process noise was matched to the innovations (that
    # filter tracks the model error into its states and its residuals hide it: a REMUS 100
    # campaign bag gave tau 0.5 % and errors of 9 sigma), the residuals at the file's values,
    # of the filter the sensitivities were taken with (the members' misfit beyond the linear
    # fit then counts as the left-out terms': wider, never narrower)
    if out.noise.white is None or out.noise.process_used:
        tau, evidence = left_out_deviation(lin, idx, left, lin.white)
    else:
        tau, evidence = left_out_deviation(lin, idx, left, out.noise.white,
                                           weights=whitening_weights(out.noise))
    sigma = tau * np.abs(lin.prior)
    out.statistical_cov = out.cov
    stat_sd = np.sqrt(np.diag(out.cov))
    out.cov = out.cov + consider_bias(lin.G, idx, left, sigma)
    with np.errstate(invalid='ignore', divide='ignore'):
        inflation = np.where(stat_sd > 0, np.sqrt(np.diag(out.cov)) / stat_sd, 1.0)
    out.selection = replace(
        sel, chosen=chosen, left_out=_in_file_order(vehicle, left_out),
        steps=[s for s in sel.steps if s['name'] in chosen], reassessed=True,
        consider_inflation={n: float(inflation[i])
                            for i, n in enumerate(out.model.theta_names)},
        consider_scale=float(tau),
        consider_sources=consider_sources(lin.G, idx, left, sigma, names,
                                          out.model.theta_names),
        suspects=[name for name, _ in evidence['suspects']],
        criteria=dict(sel.criteria, consider_confidence=CONSIDER_CONFIDENCE,
                      left_out_point=round(evidence['point'], 4)))
    return out
