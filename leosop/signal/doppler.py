"""Doppler of the pilot comb, one interface: :func:`estimate_block` (and :func:`estimate_blocks` for a batch).

Each block: a coarse search (:mod:`leosop.signal.coarse`), then one of three
fine methods (:mod:`leosop.signal.fine`): ``ml`` and ``fmlef`` on the central
tone as [Shen 2024] describes them, or ``fast`` (default), the joint comb ML
of Doppler and Doppler rate.

Doppler here is the central tone's frequency at the block centre minus its
nominal frequency (DESIGN 4.2), positive when the satellite approaches.
"""

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import InputError
from .coarse import MAX_DOPPLER_HZ, MAX_RATE_HZ_PER_S, PFA, CoarseEstimate, coarse_fft
from .fft import fft
from .fine import fine_fast, fine_fmlef, fine_ml, start_step_hz
from .pilot import PilotComb
from .quality import DISAGREE_SIGMA, constant_tone_sigma_hz, fit_status

__all__ = ["METHODS", "Method", "BlockEstimates", "estimate_block", "estimate_blocks", "ml_grid_points"]

#: The fine estimators ``estimate_block`` and ``estimate_blocks`` accept as ``method``.
METHODS = ("fast", "fmlef", "ml")
#: The estimators' names, for type checkers.
Method = Literal["fast", "fmlef", "ml"]


@dataclass
class BlockEstimates:
    """Estimates for a batch of blocks, each field shape (n_blocks,); NaN where not detected; ``status`` strings."""

    doppler_hz: np.ndarray
    doppler_rate_hz_per_s: np.ndarray
    cn0_dbhz: np.ndarray
    sigma_hz: np.ndarray
    detected: np.ndarray
    status: np.ndarray


def _check_iq(iq: npt.ArrayLike, sample_rate_hz: float) -> npt.NDArray[np.complexfloating]:
    if not np.isfinite(sample_rate_hz) or sample_rate_hz <= 0:
        raise InputError(f"sample_rate_hz={sample_rate_hz} must be a finite number > 0")
    iq = np.asarray(iq)
    if iq.ndim != 1 or not np.iscomplexobj(iq):
        raise InputError(f"IQ samples must be a 1-D complex array, got {iq.dtype} of shape {iq.shape}")
    return iq


def _check_finite(value):
    """A NaN or inf sample makes every FFT bin (and any sum) non-finite."""
    if not np.isfinite(value):
        raise InputError("IQ samples contain NaN or inf")


def ml_grid_points(coarse_error_hz: float, resolution_hz: float) -> int:
    """How many frequencies ``ml`` evaluates per block for a coarse estimate good to ``coarse_error_hz``.

    Its grid spans +-10 start steps (:func:`~.fine.fine_ml`) at ``resolution_hz``;
    each point costs a pass over the block's samples.
    """
    return 2 * int(round(10.0 * start_step_hz(coarse_error_hz) / resolution_hz)) + 1


def estimate_block(iq: npt.ArrayLike, sample_rate_hz: float, *, method: Method = "fast",
                   comb: PilotComb | None = None, resolution_hz: float = 1e-3, coarse_hz: float | None = None,
                   coarse_error_hz: float | None = None, max_doppler_hz: float = MAX_DOPPLER_HZ,
                   max_rate_hz_per_s: float = MAX_RATE_HZ_PER_S, doppler_accel_hz_per_s2: float = 0.0,
                   pfa: float = PFA) -> dict[str, float | bool | str]:
    """Doppler of the comb's central tone at the centre of one block.

    Parameters
    ----------
    iq : ndarray of complex, shape (n,)
    sample_rate_hz : float
    method : {"fast", "fmlef", "ml"}
    comb : PilotComb, optional
    resolution_hz : float
        Final step of ``ml`` and ``fmlef`` (``fast`` is continuous).
    coarse_hz, coarse_error_hz : float, optional
        An outside coarse estimate (e.g. the STFT track) and its half-width;
        by default the block's own FFT provides them.
    max_doppler_hz, max_rate_hz_per_s, pfa : float
        Search limits and false-alarm probability of the comb detector.
    doppler_accel_hz_per_s2 : float
        Predicted rate of change of the Doppler rate (``fast``; see :func:`fine_fast`).

    Returns
    -------
    dict with ``doppler_hz``, ``doppler_rate_hz_per_s`` (``fast`` only, else
    NaN), ``cn0_dbhz``, ``sigma_hz``, ``detected`` and ``status``
    (:mod:`leosop.signal.quality`: ``"ok"`` only when every check passes;
    ``fast`` also gives ``crlb_sigma_hz``, the Cramér-Rao bound that
    ``sigma_hz`` is at least).
    Everything but ``detected`` and ``status`` is NaN when no pilot is found.
    ``ml`` and ``fmlef`` are checked against the joint comb fit of the same
    block, started from their estimate: it gives their C/N0 (central tone),
    the chirp their sigma is taken under (:func:`~.quality.constant_tone_sigma_hz`,
    inflated by the central tone's residual noise, plus the grid's
    quantisation) and a second estimate to agree with.
    """
    if method not in METHODS:
        raise InputError(f"method={method!r} must be one of {', '.join(METHODS)}")
    if not resolution_hz > 0:
        raise InputError(f"resolution_hz={resolution_hz} must be > 0")
    comb = comb or PilotComb()
    iq = _check_iq(iq, sample_rate_hz)
    nan = float("nan")
    out: dict[str, float | bool | str] = dict(doppler_hz=nan, doppler_rate_hz_per_s=nan, cn0_dbhz=nan, sigma_hz=nan,
                                              detected=False, status="no pilot detected")
    dur = iq.shape[-1] / sample_rate_hz
    if coarse_hz is None:
        smear = max_rate_hz_per_s * dur if method == "fast" else 0.0
        spectrum = fft(iq, scratch=True)
        _check_finite(spectrum[0])
        coarse = coarse_fft(spectrum, sample_rate_hz, comb, max_doppler_hz=max_doppler_hz,
                            smear_hz=smear, pfa=pfa)
        if not coarse.detected:
            return out
    else:
        _check_finite(np.sum(iq))
        if not np.isfinite(coarse_hz):
            return out
        err = coarse_error_hz if coarse_error_hz is not None else sample_rate_hz / iq.shape[-1]
        coarse = CoarseEstimate(float(coarse_hz), float(err), True, nan, nan)
    out["detected"] = True
    fit_kw: dict[str, Any] = dict(max_rate_hz_per_s=max_rate_hz_per_s,
                                  doppler_accel_hz_per_s2=doppler_accel_hz_per_s2, pfa=pfa)
    if method == "fast":
        fit = fine_fast(iq, sample_rate_hz, comb, coarse, **fit_kw)
        out.update(doppler_hz=fit.doppler_hz, doppler_rate_hz_per_s=fit.doppler_rate_hz_per_s,
                   cn0_dbhz=fit.cn0_dbhz, sigma_hz=fit.sigma_hz, crlb_sigma_hz=fit.crlb_sigma_hz,
                   status=fit_status(fit, max_rate_hz_per_s))
        return out
    # The paper's estimators start from the strongest bin of the central tone,
    # good to half a bin when the tone is steady.
    start = start_step_hz(coarse.error_hz if coarse_hz is not None else 0.5 * sample_rate_hz / iq.shape[-1])
    if method == "fmlef":
        d = fine_fmlef(iq, sample_rate_hz, coarse.doppler_hz, resolution_hz, start)
    else:
        d = fine_ml(iq, sample_rate_hz, coarse.doppler_hz, resolution_hz, 10.0 * start)
    fit = fine_fast(iq, sample_rate_hz, comb, CoarseEstimate(d, 2.0 / dur, True, nan, nan), **fit_kw)
    cn0 = float(fit.tone_cn0_dbhz[comb.n_tones // 2])
    # The central tone's residual (another satellite's tone near it) inflates the white-noise sigma.
    inflate = np.sqrt(max(1.0, float(fit.tone_noise_ratio[comb.n_tones // 2])))
    sigma = np.hypot(inflate * constant_tone_sigma_hz(iq.shape[-1], sample_rate_hz, fit.doppler_rate_hz_per_s, cn0),
                     resolution_hz / np.sqrt(12.0))
    status = fit_status(fit, max_rate_hz_per_s)
    if status == "ok" and not np.isfinite(cn0):
        status = "weak comb"  # no central tone in the fit
    elif status == "ok" and not np.isfinite(sigma):
        status = "rate too high for a constant tone"
    elif status == "ok" and not abs(d - fit.doppler_hz) <= DISAGREE_SIGMA * np.hypot(sigma, fit.sigma_hz):
        status = "disagrees with the comb fit"
    out.update(doppler_hz=d, cn0_dbhz=cn0, sigma_hz=float(sigma), status=status)
    return out


def estimate_blocks(iq_blocks: npt.ArrayLike, sample_rate_hz: float, *, method: Method = "fast",
                    comb: PilotComb | None = None, resolution_hz: float = 1e-3, max_doppler_hz: float = MAX_DOPPLER_HZ,
                    max_rate_hz_per_s: float = MAX_RATE_HZ_PER_S, doppler_accel_hz_per_s2: npt.ArrayLike = 0.0,
                    pfa: float = PFA, show_progress: bool = False) -> BlockEstimates:
    """:func:`estimate_block` over the rows of ``iq_blocks`` (n_blocks, n_samples).

    ``doppler_accel_hz_per_s2`` may be a scalar or one value per block
    (e.g. predicted from the orbits).

    Returns
    -------
    BlockEstimates
    """
    from ..progress import progress

    blocks = np.asarray(iq_blocks)
    if blocks.ndim != 2:
        raise InputError(f"iq_blocks must have shape (n_blocks, n_samples), got {blocks.shape}")
    comb = comb or PilotComb()
    accel = np.broadcast_to(np.asarray(doppler_accel_hz_per_s2, dtype=float), blocks.shape[:1])
    rows = [estimate_block(b, sample_rate_hz, method=method, comb=comb, resolution_hz=resolution_hz,
                           max_doppler_hz=max_doppler_hz, max_rate_hz_per_s=max_rate_hz_per_s,
                           doppler_accel_hz_per_s2=a, pfa=pfa)
            for b, a in zip(progress(blocks, desc="doppler", unit="block") if show_progress else blocks, accel)]
    cols = {k: np.array([r[k] for r in rows]) for k in rows[0]} if rows else {}
    return BlockEstimates(**{k: cols.get(k, np.empty(0)) for k in BlockEstimates.__dataclass_fields__})
