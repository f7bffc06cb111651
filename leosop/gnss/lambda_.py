"""Integer least-squares ambiguity resolution: LAMBDA ([Teunissen 1995], [de Jonge 1996]).

The float ambiguities ``a_hat`` (n,) with covariance ``Q`` (n, n) are
decorrelated by an integer unimodular ``Z`` (integer Gauss transformations
and permutations of the ``L^T D L`` factors, the reduction of [de Jonge
1996] in the ordering of [Chang 2005]); the integer vectors closest to
``z_hat = Z^T a_hat`` in the metric of ``Q_z = Z^T Q Z`` are then found by
a depth-first search of a shrinking ellipsoid ([Chang 2005], "MLAMBDA"
search), and mapped back with ``Z^-T``. Validation of the fix: the ratio of
the second-best to the best squared norm ([Euler 1991] ratio test) and,
when it fails, partial fixing, which drops the least precise ambiguity and
tries again on the rest; optionally also a lower bound on the probability
of a correct fix, the bootstrapped success rate of the decorrelated
ambiguities ([Teunissen 1998]: ``prod_i erf(1 / (2 sqrt(2 D_i)))``, a sharp
lower bound of the ILS success rate).
"""

import numpy as np

from scipy.special import erf

__all__ = ["ltdl", "decorrelate", "search", "ils", "partial_fix", "bootstrap_success_rate"]


def ltdl(Q):
    """Factor ``Q = L^T diag(D) L`` with ``L`` unit lower triangular.

    Parameters
    ----------
    Q : ndarray, shape (n, n)
        Symmetric positive definite.

    Returns
    -------
    L : ndarray, shape (n, n)
    D : ndarray, shape (n,)

    Raises
    ------
    ValueError
        ``Q`` is not positive definite.
    """
    A = np.array(Q, float)
    n = A.shape[0]
    L = np.zeros((n, n))
    D = np.zeros(n)
    for i in range(n - 1, -1, -1):
        D[i] = A[i, i]
        if not D[i] > 0.0:
            raise ValueError("ambiguity covariance is not positive definite")
        L[i, :i + 1] = A[i, :i + 1] / np.sqrt(D[i])
        A[:i, :i] -= np.outer(L[i, :i], L[i, :i])
        L[i, :i + 1] /= L[i, i]
    return L, D


def decorrelate(Q):
    """Integer decorrelation (reduction) of ``Q``.

    Returns
    -------
    Z : ndarray of float (integer values), shape (n, n)
        Unimodular; the decorrelated ambiguities are ``z = Z^T a``.
    L, D : ndarray, shapes (n, n), (n,)
        Factors of ``Z^T Q Z = L^T diag(D) L``, ``|L[i, j]| <= 1/2`` below
        the diagonal and ``D`` in (nearly) decreasing order.
    """
    L, D = ltdl(Q)
    n = len(D)
    Z = np.eye(n)
    j, k = n - 2, n - 2
    while j >= 0:
        i = j + 1
        while j <= k and i < n:  # integer Gauss transformations of column j, rows i = j + 1, ..., n - 1 in turn
            nz = np.rint(L[i:, j]).nonzero()[0]  # those that round to 0 change nothing: on to the next that does not
            if not nz.size:
                break
            i += int(nz[0])
            mu = np.rint(L[i, j])
            L[i:, j] -= mu * L[i:, i]
            Z[:, j] -= mu * Z[:, i]
            i += 1
        delta = D[j] + L[j + 1, j] ** 2 * D[j + 1]
        if delta + 1e-6 < D[j + 1]:  # swap j and j + 1: the conditional variances become more even
            eta = D[j] / delta
            lam = D[j + 1] * L[j + 1, j] / delta
            D[j], D[j + 1] = eta * D[j + 1], delta
            a0, a1 = L[j, :j].copy(), L[j + 1, :j].copy()
            L[j, :j] = -L[j + 1, j] * a0 + a1
            L[j + 1, :j] = eta * a0 + lam * a1
            L[j + 1, j] = lam
            L[j + 2:, j:j + 2] = L[j + 2:, j:j + 2][:, ::-1]  # column swaps (numpy buffers the overlap)
            Z[:, j:j + 2] = Z[:, j:j + 2][:, ::-1]
            k, j = j, n - 2
        else:
            j -= 1
    return Z, L, D


def search(L, D, z_hat, n_cands=2):
    """The ``n_cands`` integer vectors nearest ``z_hat`` in the metric ``(L^T diag(D) L)^-1``.

    Parameters
    ----------
    L, D : ndarray, shapes (n, n), (n,)
    z_hat : ndarray, shape (n,)
    n_cands : int

    Returns
    -------
    z : ndarray, shape (n_cands, n)
        Candidates, best first.
    sq_norm : ndarray, shape (n_cands,)
        Their squared distances ``(z_hat - z)^T Q_z^-1 (z_hat - z)``.
    """
    n = len(D)
    best = np.full((n_cands, n), np.nan)
    norms = np.full(n_cands, np.inf)
    S = np.zeros((n, n))
    dist = np.zeros(n)
    zb = np.zeros(n)
    z = np.zeros(n)
    step = np.zeros(n)
    k = n - 1
    zb[k] = z_hat[k]
    z[k] = np.rint(zb[k])
    y = zb[k] - z[k]
    step[k] = 1.0 if y >= 0 else -1.0
    max_dist = np.inf
    while True:
        new = dist[k] + y * y / D[k]
        if new < max_dist:
            if k > 0:
                k -= 1
                dist[k] = new
                S[k, :k + 1] = S[k + 1, :k + 1] + (z[k + 1] - zb[k + 1]) * L[k + 1, :k + 1]
                zb[k] = z_hat[k] + S[k, k]
                z[k] = np.rint(zb[k])
                y = zb[k] - z[k]
                step[k] = 1.0 if y >= 0 else -1.0
                continue
            worst = int(np.argmax(norms))
            if new < norms[worst]:
                best[worst], norms[worst] = z, new
                if np.all(np.isfinite(norms)):
                    max_dist = norms.max()
            z[0] += step[0]
            y = zb[0] - z[0]
            step[0] = -step[0] - np.sign(step[0])
        else:
            if k == n - 1:
                break
            k += 1
            z[k] += step[k]
            y = zb[k] - z[k]
            step[k] = -step[k] - np.sign(step[k])
    order = np.argsort(norms)
    return best[order], norms[order]


def ils(a_hat, Q, n_cands=2):
    """Integer least-squares solutions of ``a_hat ~ N(a, Q)``, ``a`` integer.

    Parameters
    ----------
    a_hat : ndarray, shape (n,)
    Q : ndarray, shape (n, n)

    Returns
    -------
    a : ndarray, shape (n_cands, n)
        Best and next candidates (integers as floats).
    sq_norm : ndarray, shape (n_cands,)
        ``(a_hat - a)^T Q^-1 (a_hat - a)`` of each.
    """
    a, norms, _ = _ils(a_hat, Q, n_cands)
    return a, norms


def _ils(a_hat, Q, n_cands):
    """:func:`ils` and the conditional variances ``D`` (n,) of its decorrelation (for the success rate)."""
    a_hat = np.asarray(a_hat, float)
    shift = np.round(a_hat)  # search near zero: the same lattice, smaller numbers
    Z, L, D = decorrelate(Q)
    z, norms = search(L, D, Z.T @ (a_hat - shift), n_cands)
    a = np.linalg.solve(Z.T, z.T).T
    return np.round(a) + shift, norms, D


def bootstrap_success_rate(D):
    """Bootstrapped success rate from the conditional variances ``D`` (n,) of decorrelated ambiguities."""
    return float(np.prod(erf(1.0 / (2.0 * np.sqrt(2.0 * np.asarray(D, float))))))


def partial_fix(a_hat, Q, *, ratio_min=3.0, min_fixed=4, success_min=0.0):
    """Fix the largest subset that passes the ratio test (and the success-rate bound).

    All ambiguities first; while ``sq_norm[1] / sq_norm[0] < ratio_min`` or
    the bootstrapped success rate is below ``success_min``, the one with
    the largest variance is dropped (it is the least likely to be fixed
    correctly), down to ``min_fixed``.

    Returns
    -------
    fixed : ndarray of bool, shape (n,)
        Which ambiguities are fixed (all False when none passes).
    a_fixed : ndarray, shape (n,)
        Integer values where ``fixed``, NaN elsewhere.
    ratio : float
        Ratio of the accepted (or last tried) subset.
    """
    a_hat = np.asarray(a_hat, float)
    keep = np.ones(len(a_hat), bool)
    var = np.diag(Q).copy()
    ratio = 0.0
    while keep.sum() >= max(min_fixed, 1):
        idx = np.flatnonzero(keep)
        Qs = Q[np.ix_(idx, idx)]
        a, norms, D = _ils(a_hat[idx], Qs, 2)
        ratio = norms[1] / max(norms[0], 1e-12)
        if ratio >= ratio_min and (success_min <= 0.0 or bootstrap_success_rate(D) >= success_min):
            out = np.full(len(a_hat), np.nan)
            out[idx] = a[0]
            return keep, out, ratio
        keep[idx[np.argmax(var[idx])]] = False
    return np.zeros(len(a_hat), bool), np.full(len(a_hat), np.nan), ratio
