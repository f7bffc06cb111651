"""The INS state and error perturbations the fusion tests share: every aid's H is checked around this state."""

import math

import numpy as np

from leosop.fusion.aids import InsView
from leosop.ins.error_model import DPOS, DV, EPS, NABLA, PHI
from leosop.ins.strapdown import NavState
from leosop.rotations import euler_to_dcm

LAT, LON, ALT = math.radians(40.1), math.radians(-105.15), 1600.0
# Perturbation sizes per state group for central differences: small enough that the second-order
# terms (phi^2 ~ 1e-12 rad, position 1e-3 m over 6e6 m radii) sit below 1e-9 of the first-order ones.
STEP = np.r_[np.full(3, 1e-6), np.full(3, 1e-5), np.full(2, 1e-10), 1e-4, np.full(3, 1e-7), np.full(3, 1e-5)]
#: Starlink's Ku-band downlink carrier of the LEO Doppler aids' tests.
CARRIER_HZ = 11.325e9


def computed_state():
    """The computed INS state of the tests: moving, tilted, with sensor biases and a body rate.

    Returns
    -------
    state : leosop.ins.strapdown.NavState
    bias_gyro_radps, bias_accel_mps2, omega_radps : ndarray, (3,)
    """
    C = euler_to_dcm(math.radians(3.0), math.radians(-2.0), math.radians(130.0))
    state = NavState.from_dcm(LAT, LON, ALT, [4.0, -7.0, 0.3], C)
    return state, np.array([1e-4, -2e-4, 3e-4]), np.array([0.02, -0.01, 0.03]), np.array([0.1, -0.2, 0.5])


def true_view(dx):
    """The truth that makes ``dx`` the computed-minus-true error of :func:`computed_state` (feedback sense).

    Parameters
    ----------
    dx : ndarray, (N_INS,)
        INS error state.

    Returns
    -------
    leosop.fusion.aids.InsView
    """
    state, bg, ba, omega = computed_state()
    truth = state.corrected(dx[PHI], dx[DV], dx[DPOS])
    return InsView(truth, bg + dx[EPS], ba + dx[NABLA], omega - dx[EPS])
