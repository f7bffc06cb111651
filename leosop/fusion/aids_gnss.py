"""GNSS PPP aids for the engine: one aid per epoch of dual-frequency code, phase and Doppler.

Per satellite j, ionosphere-free (IF) code ``P``, IF phase ``L`` [m] with
the satellite clock ``c dt_j`` (precise products) added back, and the range
rate ``r`` with the satellite clock drift added back::

    P_j + c dt_j       = rho_j + m_dry,j ZHD + m_wet,j ZWD + c dt_r         + noise
    L_j + c dt_j       = rho_j + m_dry,j ZHD + m_wet,j ZWD + c dt_r + B_j   + noise
    r_j + c ddt_j      = rho_dot_j                          + c ddt_r       + noise

``rho`` and ``rho_dot`` at the INS position and velocity (no lever arm),
``m_dry ZHD`` and ``m_wet`` the models of ``options.mapping`` and
``options.zhd_pressure`` at the INS (those of ``PppOptions``,
:func:`leosop.gnss.troposphere.slant_hydrostatic_and_wet`),
the zenith wet delay ``ZWD`` a random-walk state (:func:`zwd_block`) and
``B_j`` the undifferenced IF ambiguity [m] of satellite j's arc, one state
block per arc (:func:`ambiguity_block`, prior the arc's first ``L - P``).
The receiver clock ``c dt_r`` and its drift are removed by single
differences against the epoch's highest satellite (the SD covariance keeps
the reference's shared term). That is the receiver clock as a state with an
infinite prior renewed every epoch, its exact limit: a finite "diffuse"
sigma of ~1e5 m beside the phase's 9 mm leaves the Joseph update with a
condition number near 1e15, and the SD rows are the same information
without it. With undifferenced ambiguities the choice of the reference
changes nothing (the SD set with its covariance is invariant to it), so no
ambiguity is mapped or reset when it changes; only the differences
``B_j - B_ref`` are observed, which is what ambiguity fixing uses.

Weights ``sigma / sin(elev)`` per kind, code:phase 1:100 ([Liu 2016]);
satellites below the elevation mask (at the INS) give no rows. The rows of
:meth:`PppEpoch.design` are checked against finite differences of
:meth:`PppEpoch.predict`, and one update against the SD filter of
:mod:`leosop.gnss.ppp_ins`, in ``tests/fusion/test_aids_gnss.py``.
"""

import dataclasses

import numpy as np

from ..constants import DAY_S
from ..frames import C_e_n, geodetic_to_ecef
from ..gnss import models
from ..gnss.geometry import range_and_rate
from ..ins.error_model import DPOS, DV
from .aids import Aid, StateBlock
from .common import N_INS, pos_jacobian

__all__ = ["PppEpoch", "ambiguity_block", "zwd_block"]

ZWD_KEY = "zwd"


def zwd_block(options):
    """The zenith wet delay [m]: prior ``zwd0_m +- zwd_sigma_m``, random walk ``zwd_rw_m_per_rt_s`` (never dropped).

    ``options`` is a :class:`leosop.gnss.ppp_ins.PppInsOptions`.
    """
    return StateBlock(ZWD_KEY, (options.zwd0_m,), (options.zwd_sigma_m,), (options.zwd_rw_m_per_rt_s**2,))


def ambiguity_block(sv, arc_start_s, b0_m, sigma_m, step_s):
    """The IF ambiguity [m] of one arc: constant, prior ``b0_m +- sigma_m``.

    Dropped one epoch after the arc's last (a new arc then has a new key).
    """
    return StateBlock(f"amb {sv} {arc_start_s:.3f}", (float(b0_m),), (float(sigma_m),), (0.0,),
                      drop_after_s=1.5 * step_s)


class PppEpoch(Aid):
    """One GNSS epoch: SD IF code, SD IF phase and SD range rate of the satellites above the mask.

    Parameters
    ----------
    t_s : float
        Time on the filter's clock.
    t_orbit_s : float
        The same instant in seconds since ``orbits.ref_gps`` (reception time).
    orbits : leosop.gnss.products.Orbits
    orb_idx : ndarray of int, shape (m,)
        The epoch's satellites in ``orbits``.
    code_m, phase_m, rate_mps : ndarray, shape (m,)
        IF code and phase [m] and range rate [m/s], satellite clock and drift added back.
    amb_blocks : sequence of StateBlock, length m
        Each satellite's ambiguity block (:func:`ambiguity_block`).
    zwd : StateBlock
        The wet delay (:func:`zwd_block`).
    mjd0 : float
        Modified Julian date of ``t_orbit_s = 0`` (for the troposphere's climatologies).
    options : leosop.gnss.ppp_ins.PppInsOptions
        ``mask_deg``, the zenith sigmas ``sigma_code_m``, ``sigma_phase_m``, ``sigma_rate_mps`` and the
        troposphere models ``mapping``, ``zhd_pressure``.

    Attributes
    ----------
    used : ndarray of int
        Satellites (indices into ``orb_idx``) above the mask at the last
        :meth:`matrices` call, ``ref`` their reference (for ambiguity fixing).
    restarted : ndarray of int
        Satellites (indices into ``orb_idx``) whose phase row :meth:`screen`
        took for an outlier, ``n_outliers`` the rows it screened.
    """

    name = "ppp"
    gated = False  # outliers are screened per row (:meth:`screen`), not by the engine's whole-aid gate
    external_clock = True
    screens = True

    def __init__(self, t_s, t_orbit_s, orbits, orb_idx, code_m, phase_m, rate_mps, amb_blocks, zwd, mjd0, options):
        super().__init__(t_s)
        self.t_orbit_s = float(t_orbit_s)
        self.orbits, self.orb_idx = orbits, np.asarray(orb_idx, int)
        self.obs = np.stack([code_m, phase_m, rate_mps]).astype(float)  # (3, m)
        self.states = (zwd, *amb_blocks)
        self.mjd0 = float(mjd0)
        self.options = options
        self.sigma_zenith = np.array([options.sigma_code_m, options.sigma_phase_m, options.sigma_rate_mps])
        self.used, self.ref = np.zeros(0, int), -1
        self.restarted, self.n_outliers = np.zeros(0, int), 0

    def geometry(self, ins):
        """Range, rate, line of sight, elevation at the INS; shapes (m,), (m,), (m, 3), (m,); and ``C_e_n``."""
        s = ins.state
        C = C_e_n(s.lat_rad, s.lon_rad)
        rho, rate, los, _ = range_and_rate(self.orbits, self.orb_idx, self.t_orbit_s,
                                           geodetic_to_ecef(s.lat_rad, s.lon_rad, s.alt_m), C @ s.vel_enu_mps)
        elev = np.arcsin(np.clip(los @ C[:, 2], -1.0, 1.0))
        return rho, rate, los, elev, C

    def troposphere(self, elev_rad, state):
        """Slant hydrostatic delay [m] and wet mapping at ``elev_rad`` (m,) seen from the INS ``state``."""
        return models.slant_hydrostatic_and_wet(elev_rad, state.lat_rad, state.lon_rad, state.alt_m,
                                                self.mjd0 + self.t_orbit_s / DAY_S, mapping=self.options.mapping,
                                                zhd_pressure=self.options.zhd_pressure)

    def _rows(self, ins):
        """The epoch's model at ``ins``: undifferenced predictions (3, m), mappings, used satellites, reference."""
        s = ins.state
        rho, rate, los, elev, C = self.geometry(ins)
        slant_dry, m_wet = self.troposphere(elev, s)
        zwd = ins.states[ZWD_KEY][0]
        amb = np.array([ins.states[b.key][0] for b in self.states[1:]])
        rng = rho + slant_dry + m_wet * zwd
        used = np.flatnonzero(elev > np.radians(self.options.mask_deg))
        ref = used[int(np.argmax(elev[used]))] if used.size else -1
        return np.stack([rng, rng + amb, rate]), m_wet, los, elev, C, used, ref

    @staticmethod
    def _sd(values, used, ref):
        """Rows ``v_j - v_ref`` of the used satellites other than the reference, per kind: (3 (m' - 1),)."""
        others = used[used != ref]
        return (values[..., others] - values[..., ref, None]).reshape(-1)

    def predict(self, ins):
        """SD code, phase [m] and range rate [m/s] the INS and the states imply, shape (3 (m' - 1),)."""
        h, _, _, _, _, used, ref = self._rows(ins)
        return self._sd(h, used, ref)

    def design(self, ins):
        """``dh/dx``, shape (3 (m' - 1), 15 + 1 + m): INS errors, wet delay, ambiguities (the rate's position term,
        ``(v_sv - v - e e.(v_sv - v)) / rho``, below 2e-4 /s for GPS, neglected as in :mod:`leosop.gnss.ppp_ins`)."""
        _, m_wet, los, _, C, used, ref = self._rows(ins)
        return self._design(ins.state, m_wet, los, C, used, ref)

    def _design(self, s, m_wet, los, C, used, ref):
        m = self.orb_idx.size
        others = used[used != ref]
        n = others.size
        H = np.zeros((3, n, N_INS + 1 + m))
        d_los = los[others] - los[ref]
        H[0, :, DPOS] = H[1, :, DPOS] = -d_los @ C @ pos_jacobian(s.lat_rad, s.alt_m)
        H[0, :, N_INS] = H[1, :, N_INS] = m_wet[others] - m_wet[ref]
        H[1, np.arange(n), N_INS + 1 + others] = 1.0
        H[1, :, N_INS + 1 + ref] = -1.0
        H[2, :, DV] = -d_los @ C
        return H.reshape(3 * n, -1)

    def noise(self, ins):
        """``R``: per kind ``diag(var_j) + var_ref`` with ``var = (sigma / sin(elev))^2``, (3 (m' - 1),) square."""
        _, _, _, elev, _, used, ref = self._rows(ins)
        return self._noise(elev, used, ref)

    def _noise(self, elev, used, ref):
        var = (self.sigma_zenith[:, None] / np.sin(elev)) ** 2  # (3, m)
        others = used[used != ref]
        n = others.size
        R = np.zeros((3, n, 3, n))
        for kind in range(3):
            R[kind, :, kind, :] = np.diag(var[kind, others]) + var[kind, ref]
        return R.reshape(3 * n, 3 * n)

    def matrices(self, ins):
        """``(z, H, R)`` at ``ins``: innovation ``h(ins) - measured``, :meth:`design`, :meth:`noise`."""
        h, m_wet, los, elev, C, used, ref = self._rows(ins)
        self.used, self.ref = used, ref
        return (self._sd(h - self.obs, used, ref), self._design(ins.state, m_wet, los, C, used, ref),
                self._noise(elev, used, ref))

    def screen(self, z, H, R, P):
        """Outliers: the rows whose normalised innovation exceeds ``k_outlier``, the largest first, at most six.

        ``|z_i| / sqrt(S_ii)``, ``S = H P H^T + R``; removing a row changes
        no other row's ``S_ii``, so one pass ranks them. A phase outlier is
        taken for a slip the detector missed: that satellite's ambiguity
        restarts at this epoch's ``L - P`` with the prior sigma
        ``amb_sigma_m`` (:attr:`restarted`; its wide-lane average restarts
        in :mod:`leosop.gnss.ppp_ins_ar`).

        Parameters
        ----------
        z : ndarray, shape (r,)
        H : ndarray, shape (r, n_x)
        R : ndarray, shape (r, r)
        P : ndarray, shape (n_x, n_x)
            The covariance before the update.

        Returns
        -------
        keep : ndarray of bool, shape (r,)
        restart : list of StateBlock
            Ambiguity blocks to restart at their (new) prior.
        """
        w = np.abs(z) / np.sqrt(np.einsum("ij,jk,ik->i", H, P, H) + np.diag(R))
        order = np.argsort(-w)[:6]
        bad = order[w[order] > self.options.k_outlier]
        keep = np.ones(z.size, bool)
        keep[bad] = False
        others = self.used[self.used != self.ref]
        kind, row = np.divmod(bad, others.size)
        self.restarted = others[row[kind == 1]]
        self.n_outliers = bad.size
        b_m = self.obs[1] - self.obs[0]
        restart = [dataclasses.replace(self.states[1 + j], mean0=(float(b_m[j]),),
                                       sigma0=(self.options.amb_sigma_m,)) for j in self.restarted]
        return keep, restart

    def rate(self, ins):
        """``dh/dt`` of the SD rows as the INS moves (satellites fixed).

        ``-e . v`` for code and phase, 0 for the rate.
        """
        s = ins.state
        _, _, los, _, C, used, ref = self._rows(ins)
        move = -self._sd(los @ (C @ s.vel_enu_mps), used, ref)
        return np.r_[move, move, np.zeros(move.size)]
