"""Dilution of precision: Doppler positioning ([Shen 2024] eq. 10) and range-based.

GDOP ``sqrt(trace((H^T H)^-1))`` of the Doppler rows of :mod:`leosop.geometry.doppler`
(eq. 10) is the same for either sign convention of the Doppler.
"""

import numpy as np
import numpy.typing as npt

__all__ = ["gdop", "cofactor", "cofactor_diagonal", "range_dops"]


def cofactor(H: npt.ArrayLike, weights: npt.ArrayLike | None = None, *, rcond: float = 1e-12
             ) -> npt.NDArray[np.float64]:
    """``(H^T W H)^-1`` per batch; NaN where fewer rows than columns or singular.

    Parameters
    ----------
    H : array_like, (..., n_rows, n_states)
    weights : array_like, (..., n_rows), optional
        Row weights (1/sigma^2); 0 drops a row (e.g. a satellite below the mask).
    rcond : float
        Smallest accepted eigenvalue ratio of ``H^T W H`` scaled to unit diagonal.

    Returns
    -------
    Q : ndarray, (..., n_states, n_states)
    """
    V, inv_lam, d = _eigen(H, weights, rcond)
    return np.einsum("...ik,...k,...jk->...ij", V, inv_lam, V) * d[..., :, None] * d[..., None, :]


def cofactor_diagonal(H: npt.ArrayLike, weights: npt.ArrayLike | None = None, *, rcond: float = 1e-12
                      ) -> npt.NDArray[np.float64]:
    """The diagonal of :func:`cofactor` (the same bits), without the off-diagonal terms DOPs do not use.

    Parameters
    ----------
    H : array_like, (..., n_rows, n_states)
    weights : array_like, (..., n_rows), optional
    rcond : float

    Returns
    -------
    q : ndarray, (..., n_states)
    """
    V, inv_lam, d = _eigen(H, weights, rcond)
    return np.einsum("...ik,...k,...ik->...i", V, inv_lam, V) * d * d


def _eigen(H, weights, rcond):
    """Eigenvectors ``V`` (..., n, n), inverse eigenvalues (..., n; NaN if rejected) and scales ``d`` (..., n) of
    ``D H^T W H D`` with unit diagonal, so that ``(H^T W H)^-1 = D V diag(inv_lam) V^T D``."""
    Hf = np.nan_to_num(np.asarray(H, dtype=float))
    w = np.ones(Hf.shape[:-1]) if weights is None else np.nan_to_num(np.asarray(weights, dtype=float))
    n_states = Hf.shape[-1]
    HtH = np.einsum("...ki,...k,...kj->...ij", Hf, w, Hf)
    # Columns differ by orders of magnitude (Hz/m against Hz/(m/s)): judge the
    # rank on the equilibrated matrix D HtH D with unit diagonal, then unscale.
    diag = np.einsum("...ii->...i", HtH)
    d = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    lam, V = np.linalg.eigh(HtH * d[..., :, None] * d[..., None, :])
    ok = (lam[..., 0] > rcond * np.abs(lam[..., -1])) & (np.count_nonzero(w, axis=-1) >= n_states) & (diag > 0).all(-1)
    inv_lam = np.where(ok[..., None], 1.0 / np.where(ok[..., None], lam, 1.0), np.nan)
    return V, inv_lam, d


def gdop(H: npt.ArrayLike, weights: npt.ArrayLike | None = None) -> npt.NDArray[np.float64]:
    """GDOP ``sqrt(trace((H^T W H)^-1))`` ([Shen 2024] eq. 10); NaN when undetermined.

    Parameters
    ----------
    H : array_like, (..., n_rows, n_states)
    weights : array_like, (..., n_rows), optional

    Returns
    -------
    gdop : ndarray, (...)
    """
    return np.sqrt(cofactor_diagonal(H, weights).sum(-1))


def range_dops(los_enu: npt.ArrayLike, weights: npt.ArrayLike | None = None) -> dict[str, npt.NDArray[np.float64]]:
    """Classic pseudorange DOPs from unit lines of sight in ENU.

    Parameters
    ----------
    los_enu : array_like, (..., n_sv, 3)
        Unit vectors from the receiver to the satellites.
    weights : array_like, (..., n_sv), optional
        0 drops a satellite.

    Returns
    -------
    dict of ndarray, (...)
        ``gdop, pdop, hdop, vdop, tdop``; NaN with fewer than 4 satellites.
    """
    u = np.asarray(los_enu, dtype=float)
    G = np.concatenate([-u, np.ones(u.shape[:-1] + (1,))], axis=-1)
    d = cofactor_diagonal(G, weights)
    return {
        "gdop": np.sqrt(d.sum(-1)),
        "pdop": np.sqrt(d[..., :3].sum(-1)),
        "hdop": np.sqrt(d[..., :2].sum(-1)),
        "vdop": np.sqrt(d[..., 2]),
        "tdop": np.sqrt(d[..., 3]),
    }
