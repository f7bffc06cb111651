"""Dual-frequency GPS observations of a moving receiver, simulated on real precise orbits and clocks.

The satellites are where the SP3 file puts them and their clocks are the
CLK file's; the receiver follows a :class:`leosop.ins.trajectory.Trajectory`
(antenna at the IMU). Per epoch and satellite above the mask, on L1 and L2::

    P_i = rho + c dt_r - c dt_sv + T + I_i + m_i + e_i                    [m]
    L_i = (rho + c dt_r - c dt_sv + T - I_i) / lambda_i
          + N_i + b_r,i + b_sv,i + mp_i + eps_i                              [cycles]
    rate = d rho/dt + c d(dt_r)/dt - c d(dt_sv)/dt + e_d                  [m/s] (the L1 Doppler times -lambda_1)

``T``: the hydrostatic slant delay plus a true zenith wet delay (random
walk) mapped, both by the models the PPP filters use (``mapping``,
``zhd_pressure``: [Boehm 2006]'s GMF and [Boehm 2007]'s GPT pressure by
default, :func:`leosop.gnss.troposphere.slant_hydrostatic_and_wet`);
``I_i``: first-order ionosphere (``40.3 TEC / f^2``, thin shell at 350 km);
``N_i``: integer ambiguities, new at each arc (rise, cycle slip, after an
outage); ``b_r,i``: receiver phase biases (fractional, common to
all satellites); ``b_sv,i``: satellite phase biases whose ionosphere-free
combination is zero (it is inside an integer-recovery clock, as the CNES
products are built) and whose wide-lane part ``b_sv,1 - b_sv,2`` is the
satellite wide-lane bias ``wsb`` the user is given (a CNES "WSB" product);
``m_i``, ``mp_i``: multipath-like first-order Gauss-Markov errors; ``e``,
``eps``: white noise; all scaled by ``1 / sin(elev)``. Cycle slips add
integers to ``N_i`` and raise the loss-of-lock flag; an outage removes every
observation for its duration and every arc restarts after it. Phase
wind-up, antenna offsets and tides are not simulated (nor corrected by the
filter that uses these data).
"""

from dataclasses import dataclass

import numpy as np

from ..constants import C_MPS, DAY_S
from ..frames import C_e_n, ecef_to_geodetic
from . import models
from .geometry import range_and_rate, satellite_clock
from .ppp import PppOptions
from .troposphere import mjd

__all__ = ["SimSettings", "GnssSim", "simulate", "F1_HZ", "F2_HZ"]

F1_HZ, F2_HZ = 1575.42e6, 1227.60e6


@dataclass(frozen=True)
class SimSettings:
    """Error budget of the simulated observations (raw, one frequency; SI units)."""

    mask_deg: float = 10.0
    code_sigma_m: float = 0.15
    phase_sigma_cyc: float = 0.008  # 1.5 mm on L1: code:phase 100:1 as [Liu 2016]
    rate_sigma_mps: float = 0.02
    code_mp_sigma_m: float = 0.15
    phase_mp_sigma_cyc: float = 0.005
    mp_tau_s: float = 2.0
    zwd0_m: float = 0.12
    zwd_rw_m_per_rt_s: float = 3e-5
    vtec_l1_m: float = 4.0
    rx_clock_rw_m_per_rt_s: float = 1.0
    slips_per_hour: float = 6.0
    outage_start_s: float | None = None
    outage_s: float = 60.0
    mapping: str = PppOptions.mapping
    zhd_pressure: str = PppOptions.zhd_pressure


@dataclass
class GnssSim:
    """Simulated observations, shapes (n_epochs, n_sats) unless stated.

    Attributes
    ----------
    t_s : ndarray, shape (n_epochs,)
        Epochs, seconds since the products' time origin (GPS time).
    sv : list of str
    orb_idx, clk_idx : ndarray of int, shape (n_sats,)
        Columns of the orbits and clocks.
    P1_m, P2_m, L1_cyc, L2_cyc, rate_mps : ndarray
        NaN where not observed.
    lli : ndarray of bool
        Loss of lock since the previous epoch (slip, start after an outage).
    wsb_cyc : ndarray, shape (n_sats,)
        Satellite wide-lane biases (given to the user, as a product).
    pos_ecef_m, vel_ecef_mps : ndarray, shape (n_epochs, 3)
        True antenna position and velocity.
    zwd_m : ndarray, shape (n_epochs,)
        True zenith wet delay.
    N1, N2 : ndarray of int
        True integer ambiguities.
    slips : list of (int, int)
        (epoch, satellite) of each injected cycle slip.
    """

    t_s: np.ndarray
    sv: list
    orb_idx: np.ndarray
    clk_idx: np.ndarray
    P1_m: np.ndarray
    P2_m: np.ndarray
    L1_cyc: np.ndarray
    L2_cyc: np.ndarray
    rate_mps: np.ndarray
    lli: np.ndarray
    wsb_cyc: np.ndarray
    pos_ecef_m: np.ndarray
    vel_ecef_mps: np.ndarray
    zwd_m: np.ndarray
    N1: np.ndarray
    N2: np.ndarray
    slips: list


#: Satellite-epochs per geometry call of :func:`simulate` (bounds its temporary arrays to a few MB).
_ROWS_PER_CALL = 2048


def _gauss_markov(rng, shape, tau_s, dt_s):
    """Unit-variance first-order Gauss-Markov sequences along axis 0."""
    a = np.exp(-dt_s / tau_s)
    w = rng.normal(size=shape) * np.sqrt(1.0 - a * a)
    out = np.empty(shape)
    out[0] = rng.normal(size=shape[1:])
    for k in range(1, shape[0]):
        out[k] = a * out[k - 1] + w[k]
    return out


def simulate(trajectory, t0_s, orbits, clocks, rng, settings=SimSettings(), *, step_s=1.0):
    """Simulate GPS L1/L2 code, phase and Doppler along a trajectory.

    Parameters
    ----------
    trajectory : leosop.ins.trajectory.Trajectory
        Sampled on a grid containing every ``step_s``.
    t0_s : float
        GPS time of the trajectory's start, seconds since the products' origin.
    orbits, clocks : leosop.gnss.products.Orbits, Clocks
        GPS, same time origin.
    rng : numpy.random.Generator
    settings : SimSettings

    Returns
    -------
    GnssSim
    """
    s = settings
    truth = trajectory.resample(step_s)
    n_ep = truth.t_s.size
    t = t0_s + truth.t_s - truth.t_s[0]
    pos = truth.pos_ecef_m
    vel = np.einsum("kij,kj->ki", C_e_n(truth.lat_rad, truth.lon_rad), truth.vel_enu_mps)
    sv = [v for v in orbits.sv if v[0] == "G" and v in clocks.sv]
    orb_idx = np.array([orbits.sv.index(v) for v in sv])
    clk_idx = np.array([clocks.sv.index(v) for v in sv])
    n_sv = len(sv)
    lam1, lam2 = C_MPS / F1_HZ, C_MPS / F2_HZ
    shape = (n_ep, n_sv)
    rho, rate, elev = (np.full(shape, np.nan) for _ in range(3))
    clk_sv, drift_sv = np.full(shape, np.nan), np.full(shape, np.nan)
    up = C_e_n(truth.lat_rad, truth.lon_rad)[:, :, 2]
    per = max(1, _ROWS_PER_CALL // max(n_sv, 1))  # epochs per geometry call: (rows, 3 instants, 11 nodes^2) floats
    for k0 in range(0, n_ep, per):
        ks = np.arange(k0, min(k0 + per, n_ep))
        r, rr, los, _ = range_and_rate(orbits, np.tile(orb_idx, ks.size), np.repeat(t[ks], n_sv),
                                       np.repeat(pos[ks], n_sv, axis=0), np.repeat(vel[ks], n_sv, axis=0))
        rho[ks], rate[ks] = r.reshape(-1, n_sv), rr.reshape(-1, n_sv)
        clk, drift = satellite_clock(orbits, clocks, np.tile(orb_idx, ks.size), np.tile(clk_idx, ks.size),
                                     np.repeat(t[ks], n_sv) - r / C_MPS)
        clk_sv[ks], drift_sv[ks] = clk.reshape(-1, n_sv), drift.reshape(-1, n_sv)
        for i, k in enumerate(ks):
            elev[k] = np.arcsin(np.clip(los[i * n_sv:(i + 1) * n_sv] @ up[k], -1.0, 1.0))
    seen = (elev > np.radians(s.mask_deg)) & np.isfinite(rho) & np.isfinite(clk_sv)
    if s.outage_start_s is not None:
        seen &= ~((truth.t_s >= s.outage_start_s) & (truth.t_s < s.outage_start_s + s.outage_s))[:, None]
    # Troposphere, ionosphere, receiver clock.
    lat, lon, alt = ecef_to_geodetic(pos)
    slant_dry, m_wet = models.slant_hydrostatic_and_wet(
        np.where(seen, elev, np.pi / 2), lat[:, None], lon[:, None], alt[:, None],
        mjd(orbits.ref_gps) + t[:, None] / DAY_S, mapping=s.mapping, zhd_pressure=s.zhd_pressure)
    zwd = s.zwd0_m + np.cumsum(np.r_[0.0, rng.normal(size=n_ep - 1)]) * s.zwd_rw_m_per_rt_s * np.sqrt(step_s)
    trop = slant_dry + zwd[:, None] * m_wet
    shell = 6371e3 / (6371e3 + 350e3)
    iono1 = s.vtec_l1_m / np.sqrt(1.0 - (shell * np.cos(np.where(seen, elev, np.pi / 2))) ** 2)
    iono2 = iono1 * (F1_HZ / F2_HZ) ** 2
    dtr = 3e4 + np.cumsum(np.r_[0.0, rng.normal(size=n_ep - 1)]) * s.rx_clock_rw_m_per_rt_s * np.sqrt(step_s)
    dtr_rate = np.gradient(dtr, step_s)
    # Arcs: a new one at each rise, after an outage and at each slip.
    gap = np.zeros(shape, bool)
    gap[0] = True
    gap[1:] = ~seen[:-1]
    new_arc = seen & gap
    slips = []
    n_slips = rng.poisson(s.slips_per_hour * n_ep * step_s / 3600.0)
    cand = np.argwhere(seen & ~new_arc)
    for e, j in cand[rng.choice(len(cand), size=min(n_slips, len(cand)), replace=False)] if len(cand) else []:
        slips.append((int(e), int(j)))
    lli = np.zeros(shape, bool)
    N1 = np.zeros(shape, np.int64)
    N2 = np.zeros(shape, np.int64)
    cur1 = rng.integers(-5_000_000, 5_000_000, n_sv)
    cur2 = cur1 - rng.integers(-20, 20, n_sv)
    slip_set = set(slips)
    for k in range(n_ep):
        fresh = np.flatnonzero(new_arc[k])
        cur1[fresh] = rng.integers(-5_000_000, 5_000_000, len(fresh))
        cur2[fresh] = cur1[fresh] - rng.integers(-20, 20, len(fresh))
        lli[k, fresh] = k > 0
        for j in np.flatnonzero(seen[k]):
            if (k, j) in slip_set:
                d1 = int(rng.choice([-1, 1]) * rng.integers(1, 6))
                d2 = int(rng.choice([-1, 1]) * rng.integers(0, 6))
                cur1[j] += d1
                cur2[j] += d2
                lli[k, j] = True
        N1[k], N2[k] = cur1, cur2
    wsb = rng.uniform(-0.5, 0.5, n_sv)
    # IF part of the satellite biases zero: g1 lam1 b1 - g2 lam2 b2 = lam_NL b1 + g2 lam2 wsb = 0.
    b_sv1 = -(F2_HZ**2 / (F1_HZ**2 - F2_HZ**2)) * lam2 * wsb / (C_MPS / (F1_HZ + F2_HZ))
    b_sv2 = b_sv1 - wsb
    b_r1, b_r2 = rng.uniform(0.0, 1.0, 2)
    sin_el = np.sin(np.where(seen, elev, np.pi / 2))
    gm = [_gauss_markov(rng, shape, s.mp_tau_s, step_s) for _ in range(4)]
    geo = rho + dtr[:, None] - clk_sv + trop
    P1 = geo + iono1 + (s.code_mp_sigma_m * gm[0] + s.code_sigma_m * rng.normal(size=shape)) / sin_el
    P2 = geo + iono2 + (s.code_mp_sigma_m * gm[1] + s.code_sigma_m * rng.normal(size=shape)) / sin_el
    L1 = ((geo - iono1) / lam1 + N1 + b_r1 + b_sv1
          + (s.phase_mp_sigma_cyc * gm[2] + s.phase_sigma_cyc * rng.normal(size=shape)) / sin_el)
    L2 = ((geo - iono2) / lam2 + N2 + b_r2 + b_sv2
          + (s.phase_mp_sigma_cyc * gm[3] + s.phase_sigma_cyc * lam1 / lam2 * rng.normal(size=shape)) / sin_el)
    rr = rate + dtr_rate[:, None] - drift_sv + s.rate_sigma_mps * rng.normal(size=shape) / sin_el
    for a in (P1, P2, L1, L2, rr):
        a[~seen] = np.nan
    return GnssSim(t_s=t, sv=sv, orb_idx=orb_idx, clk_idx=clk_idx, P1_m=P1, P2_m=P2, L1_cyc=L1, L2_cyc=L2,
                   rate_mps=rr, lli=lli & seen, wsb_cyc=wsb, pos_ecef_m=pos, vel_ecef_mps=vel, zwd_m=zwd,
                   N1=N1, N2=N2, slips=slips)
