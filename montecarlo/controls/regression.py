"""Control variates over replicas: the regression estimator and its standard error.

Replica ``i`` gives responses :math:`Y_i \\in \\mathbb R^q` (the system's time averages) and
controls :math:`C_i \\in \\mathbb R^p` (the harmonic twin's time averages, :mod:`.controls.twin`) whose
expectation :math:`\\mu` is known exactly. The regression estimator of :math:`E[Y]` is the
intercept of the least-squares fit :math:`Y_i = \\alpha + B (C_i - \\mu) + e_i`:

.. math::

    \\hat\\alpha = \\bar Y - \\hat B(\\bar C - \\mu),\\qquad
    \\widehat{\\mathrm{Cov}}(\\hat\\alpha) = \\hat\\Sigma_e
    \\Big[\\frac1R + (\\bar C - \\mu)^T S_{CC}^{-1} (\\bar C - \\mu)\\Big],\\qquad
    \\hat\\Sigma_e = \\frac{\\sum_i \\hat e_i \\hat e_i^T}{R - p - 1},

with :math:`S_{CC} = \\sum_i (C_i - \\bar C)(C_i - \\bar C)^T`. It is unbiased for any
coefficient (the controls have mean exactly :math:`\\mu`), the coefficient :math:`\\hat B`
is the variance-minimizing one estimated from the same replicas, and the covariance is the
exact least-squares covariance of the intercept, so it includes the coefficient's estimation
(the bracket) and the lost degrees of freedom (:math:`R - p - 1`). The variance-reduction
factor of a response is the ratio of its plain variance :math:`s_Y^2/R` to this one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fpe_harvester.errors import ParameterError

__all__ = ["Regression", "regression_estimate", "crossfit_estimate", "MIN_DOF", "enough_dof", "FOLDS",
           "crossfit_dof"]

#: Residual degrees of freedom (R - p - 1) required before p controls are used: at least
#: MIN_DOF and at least p. Estimating the coefficients inflates the residual variance by about
#: (R - 2)/(R - p - 2) (2 at the limit R = 2p + 1, 1.2 at R = 6p), which the regression's
#: covariance includes; below the limit the coefficients cost more variance than they remove.
MIN_DOF = 12


def enough_dof(replicas: int, p: int) -> bool:
    """Whether ``replicas`` leave enough residual degrees of freedom for ``p`` controls:
    :math:`R - p - 1 \\ge \\max(` :data:`MIN_DOF` :math:`, p)`."""
    return replicas - p - 1 >= max(MIN_DOF, p)

#: Folds of the cross-fitted estimator (:func:`crossfit_estimate`): each replica's coefficients
#: are fitted on the other 15/16 of the replicas.
FOLDS = 16


def crossfit_dof(replicas: int, p: int) -> bool:
    """Whether ``replicas`` are enough for the cross-fitted estimate with ``p`` controls: every
    fold's fit (all replicas but the fold's) meets :func:`enough_dof`."""
    return enough_dof(replicas - -(-replicas // FOLDS), p)

#: Eigenvalues of a fold's scaled Gram matrix below this fraction of the largest are left out of
#: its fit (:func:`crossfit_estimate`; the square of a singular-value cut of 1e-7).
_RANK_CUT = 1e-14

#: Relative spread over replicas below which a control counts as constant (round-off).
_FLAT = 1e-9


@dataclass(frozen=True)
class Regression:
    """Result of :func:`regression_estimate`.

    Attributes
    ----------
    mean : ndarray (q,)
        Regression estimates of the responses' expectations.
    cov : ndarray (q, q)
        Their covariance (coefficient estimation included).
    plain_mean, plain_cov : ndarray
        Sample mean and covariance of the mean without controls.
    coef : ndarray (q, p)
        Fitted coefficients :math:`\\hat B`.
    dof : int
        Residual degrees of freedom R - p - 1.
    """

    mean: np.ndarray
    cov: np.ndarray
    plain_mean: np.ndarray
    plain_cov: np.ndarray
    coef: np.ndarray
    dof: int

    @property
    def reduction(self) -> np.ndarray:
        """Variance-reduction factor per response, plain variance / regression variance."""
        return np.diag(self.plain_cov) / np.diag(self.cov)


def _arrays(Y, C, mu) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Y (R, q), C (R, p) and mu (p,) as float arrays, or :class:`ParameterError` naming the shapes."""
    Y = np.asarray(Y, dtype=float)
    C = np.asarray(C, dtype=float)
    mu = np.asarray(mu, dtype=float)
    if Y.ndim != 2 or C.ndim != 2 or C.shape[0] != Y.shape[0] or mu.shape != (C.shape[1],):
        raise ParameterError(f"shapes must be Y (R, q), C (R, p), mu (p,); got {Y.shape}, {C.shape}, "
                             f"{mu.shape}")
    return Y, C, mu


def regression_estimate(Y: np.ndarray, C: np.ndarray, mu: np.ndarray) -> Regression:
    """Regression (control-variate) estimate of the mean of ``Y`` over replicas.

    Parameters
    ----------
    Y : ndarray (R, q)
        Responses per replica.
    C : ndarray (R, p)
        Controls per replica, with known expectation ``mu``.
    mu : ndarray (p,)
        Exact expectation of the controls.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> c = rng.normal(size=(400, 1))
    >>> y = 2.0 + 3.0 * c + 0.1 * rng.normal(size=(400, 1))
    >>> r = regression_estimate(y, c, np.zeros(1))
    >>> bool(abs(r.mean[0] - 2.0) < 4 * np.sqrt(r.cov[0, 0])), bool(r.reduction[0] > 100)
    (True, True)
    """
    Y, C, mu = _arrays(Y, C, mu)
    R, p = C.shape
    dof = R - p - 1
    if dof < 1:
        raise ParameterError(f"need more replicas than controls + 1, got R = {R} with p = {p}")
    ybar = Y.mean(axis=0)
    Yc = Y - ybar
    plain_cov = Yc.T @ Yc / (R - 1) / R
    cbar = C.mean(axis=0)
    Cc = C - cbar
    # scale the controls to unit spread so that lstsq's rank cut is relative
    scale = np.sqrt((Cc**2).sum(axis=0))
    # a control that does not vary beyond round-off carries no information, and its mean's
    # round-off offset from mu would look like many of its standard errors: left out (e.g. the
    # twin's v xi estimate, deterministic when tau << dt)
    flat = scale <= _FLAT * np.sqrt(R) * np.maximum(np.abs(cbar), np.abs(mu))
    Cc = np.where(flat, 0.0, Cc)
    scale = np.where((scale > 0) & ~flat, scale, 1.0)
    coef_s, *_ = np.linalg.lstsq(Cc / scale, Yc, rcond=1e-10)
    coef = (coef_s / scale[:, None]).T
    resid = Yc - Cc @ coef.T
    sigma = resid.T @ resid / dof
    d = np.where(flat, 0.0, cbar - mu) / scale
    S = (Cc / scale).T @ (Cc / scale)
    lever = float(d @ np.linalg.lstsq(S, d, rcond=1e-10)[0])
    mean = ybar - coef @ np.where(flat, 0.0, cbar - mu)
    return Regression(mean=mean, cov=sigma * (1.0 / R + lever), plain_mean=ybar, plain_cov=plain_cov,
                      coef=coef, dof=dof)


def crossfit_estimate(Y: np.ndarray, C: np.ndarray, mu: np.ndarray, folds: int = FOLDS) -> Regression:
    """Cross-fitted control-variate estimate of the mean of ``Y`` over replicas.

    The replicas are split into ``folds`` folds by index (replica i in fold i mod ``folds``:
    fixed before any data are seen); replica i's controlled value is

    .. math::

        Z_i = Y_i - \\hat B_{-k(i)} (C_i - \\mu),

    with :math:`\\hat B_{-k}` the least-squares coefficients fitted on the replicas outside its
    fold k(i). :math:`\\hat B_{-k}` is independent of replica i and :math:`E[C_i] = \\mu`, so every
    :math:`Z_i` has mean :math:`E[Y]` exactly, whatever the fit: the estimate
    :math:`\\bar Z` is unbiased for any number of controls, and its error bar is the spread of
    the :math:`Z_i` over replicas, :math:`\\widehat{\\mathrm{Cov}}(\\bar Z) = S_Z / R` (R - 1
    degrees of freedom). In-sample regression (:func:`regression_estimate`) is exact for a linear
    relation but, with many controls, its intercept picks up the nonlinear part of the relation
    fitted on the same replicas; here the fit's error only adds variance, which the spread shows.

    Parameters and result as :func:`regression_estimate` (``coef`` the mean of the folds'
    coefficients, ``dof`` = R - 1); at least 2 replicas per fold.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> c = rng.normal(size=(400, 2))
    >>> y = 2.0 + c @ np.array([[3.0], [-1.0]]) + 0.1 * rng.normal(size=(400, 1))
    >>> r = crossfit_estimate(y, c, np.zeros(2))
    >>> bool(abs(r.mean[0] - 2.0) < 4 * np.sqrt(r.cov[0, 0])), bool(r.reduction[0] > 100)
    (True, True)
    """
    Y, C, mu = _arrays(Y, C, mu)
    R = Y.shape[0]
    if R < 2 * folds:
        raise ParameterError(f"cross-fitting needs at least 2 replicas per fold, got R = {R} for {folds} folds")
    fold = np.arange(R) % folds
    # one pass over the data: the folds' fits come from the whole Gram matrix minus each fold's
    # (centred and scaled globally first, so that the folds' re-centring is a small correction)
    cbar = C.mean(axis=0)
    sd = C.std(axis=0)
    flat = sd <= _FLAT * np.maximum(np.abs(cbar), np.abs(mu))
    scale = np.where(flat | (sd == 0), 1.0, sd)
    X = np.where(flat, 0.0, (C - cbar) / scale)
    Yc = Y - Y.mean(axis=0)
    G, H = X.T @ X, X.T @ Yc
    Z = np.empty_like(Y)
    coefs = []
    for k in range(folds):
        out = fold == k
        Xk, Yk = X[out], Yc[out]
        n = R - Xk.shape[0]
        mx, my = -Xk.sum(axis=0) / n, -Yk.sum(axis=0) / n
        Gt = G - Xk.T @ Xk - n * np.outer(mx, mx)
        Ht = H - Xk.T @ Yk - n * np.outer(mx, my)
        w, V = np.linalg.eigh(Gt)
        # the least-squares solution on the resolved directions (lstsq's rank cut, squared)
        keep = w > _RANK_CUT * max(w.max(), 0.0)
        coef = (V[:, keep] / w[keep]) @ (V[:, keep].T @ Ht)
        Z[out] = Y[out] - ((C[out] - mu) / scale) @ np.where(flat[:, None], 0.0, coef)
        coefs.append(np.where(flat[:, None], 0.0, coef / scale[:, None]).T)
    zbar, ybar = Z.mean(axis=0), Y.mean(axis=0)
    Zc, Yc = Z - zbar, Y - ybar
    return Regression(mean=zbar, cov=Zc.T @ Zc / (R - 1) / R, plain_mean=ybar, plain_cov=Yc.T @ Yc / (R - 1) / R,
                      coef=np.mean(coefs, axis=0), dof=R - 1)
