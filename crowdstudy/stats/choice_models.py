"""Models of two-alternative forced choices (2AFC): a logistic mixed model with a random
intercept per participant (lme4's ``glmer(..., family = binomial)``, Laplace, nAGQ = 1) and
the Bradley-Terry model of k methods (``BradleyTerry2::BTm``, a logistic regression on the
differences of the two shown methods' indicators).

:func:`logistic_mixed_model` follows lme4: for given ``(theta, beta)`` the conditional
modes of the spherical random effects ``v`` (``u = theta v``, ``v ~ N(0, 1)``) come from
penalised iteratively reweighted least squares (PIRLS; one Newton step per participant,
since each participant has one random effect); the Laplace deviance

    d(theta, beta) = sum_i -2 log p(y_i | eta_i) + |v|^2 + sum_g log(1 + theta^2 sum_{i in g} w_i)

(``w = mu (1 - mu)`` at the modes) is minimised over ``theta >= 0`` and ``beta`` jointly,
as lme4 does in its second stage. The fixed effects' covariance is lme4's default: twice
the inverse of the finite-difference Hessian of ``d`` (step 1e-4), its ``beta`` block; at
a singular fit (``theta = 0``) lme4 falls back to the PIRLS ``(X' W X)^-1`` and so does
this. The log-likelihood is ``-d / 2``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from scipy import optimize
from scipy import stats as _st

from crowdstudy.errors import InvalidInputError

__all__ = ["LogisticMixedResult", "logistic_mixed_model", "BradleyTerryResult", "bradley_terry"]


@dataclasses.dataclass(frozen=True)
class LogisticMixedResult:
    """``fixed``: one row per coefficient (``term``, ``estimate`` in logits, ``SE``, ``z``,
    ``p``: Wald); ``variance``: the participant intercept's variance (logit^2);
    ``loglik``: the Laplace log-likelihood; ``n_obs``, ``n_participants``; ``singular``:
    the variance is 0 (the fixed effects' SEs are then the GLM's); ``converged``."""

    fixed: pd.DataFrame
    variance: float
    loglik: float
    n_obs: int
    n_participants: int
    singular: bool
    converged: bool


def _log_lik_terms(y: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """log p(y | eta) of Bernoulli answers, computed without overflow."""
    return -(y * np.logaddexp(0.0, -eta) + (1.0 - y) * np.logaddexp(0.0, eta))


class _Laplace:
    """The Laplace deviance of a random-intercept logistic model (see the module docstring)."""

    def __init__(self, y: np.ndarray, x: np.ndarray, groups: np.ndarray):
        self.y, self.x = y, x
        self.codes, uniq = pd.factorize(groups)
        self.g = len(uniq)
        self.v = np.zeros(self.g)  # warm start of the conditional modes

    def _sum(self, values: np.ndarray) -> np.ndarray:
        return np.bincount(self.codes, weights=values, minlength=self.g)

    def modes(self, theta: float, beta: np.ndarray) -> np.ndarray:
        """PIRLS: the conditional modes ``v`` at ``(theta, beta)`` (Newton, halving steps
        that do not raise the penalised log-likelihood of a participant)."""
        eta0 = self.x @ beta
        v = self.v.copy()

        def objective(vv):
            return self._sum(_log_lik_terms(self.y, eta0 + theta * vv[self.codes])) - 0.5 * vv**2

        current = objective(v)
        for _ in range(100):
            mu = 1.0 / (1.0 + np.exp(-(eta0 + theta * v[self.codes])))
            grad = theta * self._sum(self.y - mu) - v
            hess = theta**2 * self._sum(mu * (1.0 - mu)) + 1.0
            step = grad / hess
            trial = v + step
            new = objective(trial)
            for _ in range(30):
                worse = new < current - 1e-14 * np.abs(current)
                if not worse.any():
                    break
                step = np.where(worse, step / 2.0, step)
                trial = v + step
                new = objective(trial)
            v, current = trial, new
            if np.max(np.abs(step)) < 1e-12:
                break
        self.v = v
        return v

    def deviance(self, params: np.ndarray) -> float:
        theta, beta = float(params[0]), np.asarray(params[1:])
        v = self.modes(theta, beta)
        eta = self.x @ beta + theta * v[self.codes]
        mu = 1.0 / (1.0 + np.exp(-eta))
        logdet = np.log1p(theta**2 * self._sum(mu * (1.0 - mu))).sum()
        return float(-2.0 * _log_lik_terms(self.y, eta).sum() + v @ v + logdet)

    def hessian(self, params: np.ndarray, delta: float = 1e-4) -> np.ndarray:
        """Central finite-difference Hessian of the deviance (lme4's ``deriv12`` step)."""
        n = len(params)
        h = np.zeros((n, n))
        f0 = self.deviance(params)
        e = np.eye(n) * delta
        for i in range(n):
            h[i, i] = (self.deviance(params + e[i]) - 2.0 * f0 + self.deviance(params - e[i])) / delta**2
            for j in range(i):
                h[i, j] = h[j, i] = (
                    self.deviance(params + e[i] + e[j])
                    - self.deviance(params + e[i] - e[j])
                    - self.deviance(params - e[i] + e[j])
                    + self.deviance(params - e[i] - e[j])
                ) / (4.0 * delta**2)
        return h


def _glm(y: np.ndarray, x: np.ndarray, offset: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Logistic regression by IRLS: (beta, (X' W X)^-1)."""
    beta = np.zeros(x.shape[1])
    off = np.zeros(len(y)) if offset is None else offset
    for _ in range(100):
        mu = 1.0 / (1.0 + np.exp(-(x @ beta + off)))
        w = mu * (1.0 - mu)
        info = x.T @ (x * w[:, None])
        step = np.linalg.solve(info, x.T @ (y - mu))
        beta = beta + step
        if np.max(np.abs(step)) < 1e-13:
            break
    mu = 1.0 / (1.0 + np.exp(-(x @ beta + off)))
    info = x.T @ (x * (mu * (1.0 - mu))[:, None])
    return beta, np.linalg.inv(info)


def _check_binary(y: np.ndarray, x: np.ndarray) -> None:
    if len(y) <= x.shape[1] or np.linalg.matrix_rank(x) < x.shape[1]:
        raise InvalidInputError(f"the model's {x.shape[1]} coefficients are not estimable from {len(y)} choices")
    if y.min() == y.max():
        raise InvalidInputError(
            f"every one of the {len(y)} choices is the same; a logistic model is undefined (the share is 0 or 1)"
        )


def logistic_mixed_model(y, x, groups, names: list[str], *, polish: bool = True) -> LogisticMixedResult:
    """Fit ``y ~ X + (1 | group)`` (binomial, logit, Laplace) as described in the module
    docstring. ``y``: (n,) 0/1; ``x``: (n, p) fixed-effects design with its columns
    ``names``; ``groups``: (n,) participant ids. ``polish``: after the quasi-Newton
    descent, two Powell passes with tight tolerances (glmer's numbers to 1e-6; without
    them, ~1e-4 and several times faster: what a power simulation needs)."""
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    _check_binary(y, x)
    lap = _Laplace(y, x, np.asarray(groups).astype(str))
    beta0, _ = _glm(y, x)
    start = np.concatenate([[1.0], beta0])
    bounds = [(0.0, None)] + [(None, None)] * x.shape[1]
    opt = optimize.minimize(
        lap.deviance, start, method="L-BFGS-B", bounds=bounds, options={"ftol": 1e-15, "gtol": 1e-9}
    )
    for _ in range(2 if polish else 0):
        opt = optimize.minimize(
            lap.deviance,
            opt.x,
            method="Powell",
            bounds=bounds,
            options={"xtol": 1e-10, "ftol": 1e-15, "maxiter": 50000},
        )
    params = opt.x
    theta, beta = float(params[0]), params[1:]
    singular = theta < 1e-6
    cov = None
    if not singular:
        h = lap.hessian(params)
        try:
            inv = np.linalg.inv(h)
            cov = 2.0 * inv[1:, 1:]
            if np.linalg.eigvalsh(cov).min() <= 0:
                cov = None
        except np.linalg.LinAlgError:
            cov = None
    if cov is None:  # lme4's fallback: (X' W X)^-1 at the conditional modes
        v = lap.modes(theta, beta)
        mu = 1.0 / (1.0 + np.exp(-(x @ beta + theta * v[lap.codes])))
        cov = np.linalg.inv(x.T @ (x * (mu * (1.0 - mu))[:, None]))
    se = np.sqrt(np.diag(cov))
    z = beta / se
    fixed = pd.DataFrame({"term": names, "estimate": beta, "SE": se, "z": z, "p": 2.0 * _st.norm.sf(np.abs(z))})
    return LogisticMixedResult(
        fixed=fixed,
        variance=theta**2,
        loglik=-0.5 * lap.deviance(params),
        n_obs=len(y),
        n_participants=lap.g,
        singular=bool(singular),
        converged=bool(opt.success),
    )


@dataclasses.dataclass(frozen=True)
class BradleyTerryResult:
    """``abilities``: one row per method in the design's order (``method``, ``ability`` in
    logits, ``SE``, ``lower_CL``, ``upper_CL``: Wald ``level`` interval, ``z``, ``p``; the
    reference fixed at 0 with SE 0); ``loglik``; ``n_obs``."""

    abilities: pd.DataFrame
    loglik: float
    n_obs: int


def bradley_terry(first, second, first_won, methods: list[str], *, level: float = 0.95) -> BradleyTerryResult:
    """The Bradley-Terry model ``logit P(first beats second) = a_first - a_second`` with
    ``a`` of ``methods[0]`` (the reference) fixed at 0, by maximum likelihood (as
    ``BTm(cbind(win1, win2), player1, player2, refcat = methods[0])``; no random effect).
    ``first``, ``second``: (n,) method names per trial; ``first_won``: (n,) 0/1."""
    first, second = np.asarray(first).astype(str), np.asarray(second).astype(str)
    y = np.asarray(first_won, dtype=float)
    unknown = sorted((set(first) | set(second)) - set(methods))
    if unknown:
        raise InvalidInputError(f"method {str(unknown[0])!r} is not one of the design's methods {', '.join(methods)}")
    x = np.column_stack([(first == m).astype(float) - (second == m).astype(float) for m in methods[1:]])
    _check_binary(y, x)
    beta, cov = _glm(y, x)
    se = np.sqrt(np.diag(cov))
    crit = float(_st.norm.ppf(0.5 + level / 2.0))
    ability = np.concatenate([[0.0], beta])
    ses = np.concatenate([[0.0], se])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(ses > 0, ability / np.where(ses > 0, ses, 1.0), np.nan)
    table = pd.DataFrame(
        {
            "method": list(methods),
            "ability": ability,
            "SE": ses,
            "lower_CL": ability - crit * ses,
            "upper_CL": ability + crit * ses,
            "z": z,
            "p": np.where(np.isnan(z), np.nan, 2.0 * _st.norm.sf(np.abs(z))),
        }
    )
    return BradleyTerryResult(abilities=table, loglik=float(_log_lik_terms(y, x @ beta).sum()), n_obs=len(y))
