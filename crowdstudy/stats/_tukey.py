"""Distribution function of the studentized range, computed the way R's ``ptukey`` does
(Copenhaver & Holland, 1988: Gauss-Legendre quadrature of Hartley's form of the range
distribution, integrated against the density of the standard-error estimate), vectorized
with numpy so a whole family of contrasts costs about a millisecond.

Following R makes Tukey-adjusted p-values agree with emmeans to ~1e-10 instead of the
~1e-5 of an independent integrator (scipy.stats.studentized_range), and it is faster.
"""

from __future__ import annotations

import numpy as np
from scipy.special import gammaln, ndtr

__all__ = ["studentized_range_sf", "studentized_range_ppf", "range_cdf"]

_X12, _W12 = np.polynomial.legendre.leggauss(12)  # inner quadrature (range of normals)
_X16, _W16 = np.polynomial.legendre.leggauss(16)  # outer quadrature (error df)
_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


def range_cdf(w, n_means: int) -> np.ndarray:
    """P(range of ``n_means`` independent standard normals < w), elementwise over ``w``.

    Hartley's form: ``(2 Phi(w/2) - 1)^k + 2k int_{w/2}^{8} phi(y) (Phi(y) - Phi(y - w))^(k-1) dy``
    with the integral split into 3 equal parts (2 when w > 3), 12 Gauss-Legendre nodes
    each, and R's cut-offs (nodes with y^2 > 60 or a negligible integrand are skipped; a
    total below exp(-30) is 0; w >= 16 gives 1).
    """
    w = np.atleast_1d(np.asarray(w, dtype=float))
    k = float(n_means)
    half = 0.5 * w
    first = 2.0 * ndtr(half) - 1.0
    first = np.where(first >= np.exp(-50.0 / k), first**k, 0.0)
    parts = np.where(w > 3.0, 2, 3)
    width = (8.0 - half) / parts  # each part's length
    total = np.zeros_like(w)
    for part in range(3):
        lo = half + part * width
        centre = lo + 0.5 * width
        y = centre[:, None] + 0.5 * width[:, None] * _X12[None, :]  # (n, 12)
        diff = ndtr(y) - ndtr(y - w[:, None])
        keep = (y * y <= 60.0) & (diff >= np.exp(-30.0 / (k - 1.0))) & (part < parts)[:, None]
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            term = np.where(keep, _W12[None, :] * np.exp(-0.5 * y * y) * np.abs(diff) ** (k - 1.0), 0.0)
        total += term.sum(axis=1) * width * k * _INV_SQRT_2PI
    prob = total + first
    prob = np.where(prob <= np.exp(-30.0), 0.0, prob)
    return np.where(half >= 8.0, 1.0, np.minimum(prob, 1.0))


def studentized_range_sf(q, n_means: int, df: float) -> np.ndarray:
    """P(Q > q) for the studentized range of ``n_means`` means with ``df`` error df (q >= 0).

    The lower-tail integral runs over unit intervals of the chi variable (half, quarter
    or eighth units above 100, 800, 5000 df), 16 Gauss-Legendre nodes each, up to 50
    intervals, stopping at the first interval (after at least one unit) that adds
    <= 1e-14, as R does. Above 25000 df the range distribution itself is used.
    """
    q = np.atleast_1d(np.asarray(q, dtype=float))
    if n_means < 2 or df < 2:
        raise ValueError(f"studentized range needs n_means >= 2 and df >= 2, got {n_means}, {df}")
    out = np.ones_like(q)
    pos = q > 0
    inf = np.isinf(q)
    out[inf] = 0.0
    work = pos & ~inf
    if not work.any():
        return out
    qw = q[work]
    if df > 25000:
        out[work] = 1.0 - range_cdf(qw, n_means)
        return out
    half_df = 0.5 * df
    ulen = 1.0 if df <= 100 else 0.5 if df <= 800 else 0.25 if df <= 5000 else 0.125
    lead = half_df * np.log(df) - df * np.log(2.0) - gammaln(half_df) + np.log(ulen)
    centres = (2.0 * np.arange(1, 51) - 1.0) * ulen  # (50,)
    t = centres[:, None] + _X16[None, :] * ulen  # (50, 16)
    log_dens = lead + (half_df - 1.0) * np.log(t) - t * (0.25 * df)
    use = log_dens >= -30.0
    weight = np.where(use, _W16[None, :] * np.exp(np.where(use, log_dens, 0.0)), 0.0)
    idx = np.nonzero(use.ravel())[0]
    args = qw[:, None] * np.sqrt(0.5 * t.ravel()[idx])[None, :]  # (nq, used)
    inner = range_cdf(args.ravel(), n_means).reshape(args.shape)
    contrib = np.zeros((len(qw), t.size))
    contrib[:, idx] = inner * weight.ravel()[idx][None, :]
    per_interval = contrib.reshape(len(qw), 50, 16).sum(axis=2)  # (nq, 50)
    stop = (np.arange(1, 51) * ulen >= 1.0)[None, :] & (per_interval <= 1e-14)
    first_stop = np.where(stop.any(axis=1), stop.argmax(axis=1), 50)
    mask = np.arange(50)[None, :] < first_stop[:, None]
    lower = np.minimum((per_interval * mask).sum(axis=1), 1.0)
    out[work] = 0.5 - lower + 0.5
    return out


def _qtukey_start(p: float, n_means: float, df: float) -> float:
    """Odeh & Evans (1974, AS 70) starting value of the studentized-range quantile, as R's
    ``qtukey`` uses it."""
    ps = 0.5 - 0.5 * p
    yi = np.sqrt(np.log(1.0 / (ps * ps)))
    t = yi + (
        (((yi * -0.453642210148e-04 - 0.204231210125) * yi - 0.342242088547) * yi - 1.0) * yi + 0.322232421088
    ) / (
        (((yi * 0.38560700634e-02 + 0.103537752850) * yi + 0.531103462366) * yi + 0.588581570495) * yi
        + 0.993484626060e-01
    )
    if df < 120.0:
        t += (t * t * t + t) / df / 4.0
    q = 0.8832 - 0.2368 * t
    if df < 120.0:
        q += -1.214 / df + 1.208 * t / df
    return float(t * (q * np.log(n_means - 1.0) + 1.4142))


def studentized_range_ppf(p: float, n_means: int, df: float) -> float:
    """Quantile ``q`` with ``P(Q < q) = p`` of the studentized range, found as R's ``qtukey``
    finds it: secant iterations on the lower-tail probability from the AS 70 start, until
    two iterates differ by < 1e-4 (at most 50), so critical values agree with R's."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p}")
    if n_means < 2 or df < 2:
        raise ValueError(f"studentized range needs n_means >= 2 and df >= 2, got {n_means}, {df}")

    def lower(x: float) -> float:
        return 1.0 - float(studentized_range_sf([x], n_means, df)[0]) - p

    x0 = _qtukey_start(p, n_means, df)
    v0 = lower(x0)
    x1 = max(0.0, x0 - 1.0) if v0 > 0.0 else x0 + 1.0
    v1 = lower(x1)
    ans = x1
    for _ in range(1, 50):
        ans = x1 - v1 * (x1 - x0) / (v1 - v0)
        v0 = v1
        x0 = x1
        if ans < 0.0:
            ans = 0.0
        v1 = lower(ans)
        x1 = ans
        if abs(x1 - x0) < 1e-4:
            return float(ans)
    return float(ans)
