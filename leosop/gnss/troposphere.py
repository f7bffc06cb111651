"""Troposphere: zenith hydrostatic delay, mapping functions, gradients.

Every function is vectorised over broadcastable arguments. The climatologies
of [Boehm 2006] (GMF) and [Boehm 2007] (GPT) are spherical harmonics of
degree and order 9 in the unnormalised associated Legendre functions without
the Condon-Shortley phase; their coefficients are the published ones (also
[IERS 2010] ch. 9, whose software's test values
``tests/gnss/test_models.py`` reproduces).
"""

import numpy as np

from ..errors import InputError

__all__ = ["CHEN_HERRING_C", "MAPPINGS", "ZHD_PRESSURES", "gmf_mapping", "gpt_pressure_hpa", "gradient_mapping",
           "mjd", "niell_mapping", "saastamoinen_zhd_m", "slant_hydrostatic_and_wet"]

#: Mapping functions and hydrostatic pressures :func:`slant_hydrostatic_and_wet` knows.
MAPPINGS = ("gmf", "niell")
ZHD_PRESSURES = ("gpt", "standard")
_MJD_ZERO = np.datetime64("1858-11-17", "D")


def mjd(time):
    """Modified Julian date (float days) of ``time`` (numpy.datetime64, any unit; array_like); same time scale."""
    return (np.asarray(time, "datetime64[ns]") - _MJD_ZERO) / np.timedelta64(1, "D")


def saastamoinen_zhd_m(lat_rad, alt_m, pressure_hpa=None):
    """Zenith hydrostatic delay [Saastamoinen 1972], formulation of [Davis 1985].

    ``ZHD = 0.0022768 P / (1 - 0.00266 cos 2 lat - 0.28e-6 h)``. Without a
    pressure the standard atmosphere gives it: ``P = 1013.25 (1 - 2.2557e-5
    h)^5.2568`` hPa ([Berg 1948]).

    Returns
    -------
    ndarray
        Zenith hydrostatic delay [m]; 2.31 m at sea level, 45 deg.
    """
    alt_m = np.asarray(alt_m, float)
    if pressure_hpa is None:
        pressure_hpa = 1013.25 * (1.0 - 2.2557e-5 * alt_m) ** 5.2568
    return 0.0022768 * pressure_hpa / (1.0 - 0.00266 * np.cos(2.0 * lat_rad) - 0.28e-6 * alt_m)


# [Niell 1996] mapping function coefficients at latitudes 15, 30, 45, 60, 75 deg.
_NMF_LAT = np.radians([15.0, 30.0, 45.0, 60.0, 75.0])
_NMF_H_AVG = np.array([
    [1.2769934e-3, 1.2683230e-3, 1.2465397e-3, 1.2196049e-3, 1.2045996e-3],
    [2.9153695e-3, 2.9152299e-3, 2.9288445e-3, 2.9022565e-3, 2.9024912e-3],
    [62.610505e-3, 62.837393e-3, 63.721774e-3, 63.824265e-3, 64.258455e-3]])
_NMF_H_AMP = np.array([
    [0.0, 1.2709626e-5, 2.6523662e-5, 3.4000452e-5, 4.1202191e-5],
    [0.0, 2.1414979e-5, 3.0160779e-5, 7.2562722e-5, 11.723375e-5],
    [0.0, 9.0128400e-5, 4.3497037e-5, 84.795348e-5, 170.37206e-5]])
_NMF_W = np.array([
    [5.8021897e-4, 5.6794847e-4, 5.8118019e-4, 5.9727542e-4, 6.1641693e-4],
    [1.4275268e-3, 1.5138625e-3, 1.4572752e-3, 1.5007428e-3, 1.7599082e-3],
    [4.3472961e-2, 4.6729510e-2, 4.3908931e-2, 4.4626982e-2, 5.4736038e-2]])
_NMF_HT = (2.53e-5, 5.49e-3, 1.14e-3)


def _marini(sin_el, a, b, c):
    """Continued fraction of [Marini 1972] normalised to 1 at zenith."""
    return (1.0 + a / (1.0 + b / (1.0 + c))) / (sin_el + a / (sin_el + b / (sin_el + c)))


def niell_mapping(elev_rad, lat_rad, alt_m, doy):
    """Hydrostatic and wet mapping functions of [Niell 1996].

    Parameters
    ----------
    elev_rad, lat_rad, alt_m, doy : array_like, broadcastable
        Elevation, geodetic latitude, height, day of year (UTC, fractional).

    Returns
    -------
    m_dry, m_wet : ndarray
        Both 1 at zenith, about 1/sin(elev) above 15 deg.
    """
    elev_rad, lat_rad, alt_m, doy = np.broadcast_arrays(*(np.asarray(v, float) for v in (elev_rad, lat_rad,
                                                                                          alt_m, doy)))
    alat = np.abs(lat_rad)
    phase = 2.0 * np.pi * (doy - 28.0) / 365.25 + np.where(lat_rad < 0, np.pi, 0.0)
    coef_h = [np.interp(alat, _NMF_LAT, _NMF_H_AVG[i]) - np.interp(alat, _NMF_LAT, _NMF_H_AMP[i]) * np.cos(phase)
              for i in range(3)]
    coef_w = [np.interp(alat, _NMF_LAT, _NMF_W[i]) for i in range(3)]
    s = np.sin(elev_rad)
    m_dry = _marini(s, *coef_h) + (1.0 / s - _marini(s, *_NMF_HT)) * alt_m * 1e-3
    m_wet = _marini(s, *coef_w)
    return m_dry, m_wet


# [Boehm 2006] GMF: spherical-harmonic coefficients (degree and order 9, 1e-5 units; n = 0..9, m = 0..n in
# that order) of the mean and annual amplitude of the hydrostatic (h) and wet (w) continued-fraction ``a``,
# cosine (a) and sine (b) parts, as published with the paper and in [IERS 2010] ch. 9. Rows: ah_mean,
# bh_mean, ah_amp, bh_amp, aw_mean, bw_mean, aw_amp, bw_amp.
_GMF_COEF = np.array("""
125.17 0.8503 0.06936 -6.76 0.1771 0.0113 0.5963 0.01808 0.002801 -0.001414 -1.212 0.093 0.003683 0.001095
4.671e-05 0.3959 -0.03867 0.005413 -0.0005289 0.0003229 2.067e-05 0.3 0.02031 0.0059 0.0004573 -7.619e-05
2.327e-06 3.845e-06 0.1182 0.01158 0.005445 6.219e-05 4.204e-06 -2.093e-06 1.54e-07 -4.28e-08 -0.4751 -0.0349
0.001758 0.0004019 -2.799e-06 -1.287e-06 5.468e-07 7.58e-08 -6.3e-09 -0.116 0.008301 0.0008771 9.955e-05
-1.718e-06 -2.012e-06 1.17e-08 1.79e-08 -1.3e-09 1e-10
0.0 0.0 0.03249 0.0 0.03324 0.0185 0.0 -0.1115 0.02519 0.004923 0.0 0.02737 0.01595 -0.0007332 0.0001933 0.0
-0.04796 0.006381 -0.0001599 -0.0003685 1.815e-05 0.0 0.07033 0.002426 -0.001111 -0.0001357 -7.828e-06 2.547e-06
0.0 0.005779 0.003133 -0.0005312 -2.028e-05 2.323e-07 -9.1e-08 -1.65e-08 0.0 0.03688 -0.0008638 -8.514e-05
-2.828e-05 5.403e-07 4.39e-07 1.35e-08 1.8e-09 0.0 -0.02736 -0.0002977 8.113e-05 2.329e-07 8.451e-07 4.49e-08
-8.1e-09 -1.5e-09 2e-10
-0.2738 -2.837 0.01298 -0.3588 0.02413 0.03427 -0.7624 0.07272 0.0216 -0.003385 0.4424 0.03722 0.02195 -0.001503
0.0002426 0.3013 0.05762 0.01019 -0.0004476 6.79e-05 3.227e-05 0.3123 -0.03535 0.00484 3.025e-06 -4.363e-05
2.854e-07 -1.286e-06 -0.6725 -0.0373 0.0008964 0.0001399 -3.99e-06 7.431e-06 -2.796e-07 -1.601e-07 0.04068
-0.01352 0.0007282 9.594e-05 2.07e-06 -9.62e-08 -2.742e-07 -6.37e-08 -6.3e-09 0.08625 -0.005971 0.0004705
2.335e-05 4.226e-06 2.475e-07 -8.85e-08 -3.6e-08 -2.9e-09 0.0
0.0 0.0 -0.1136 0.0 -0.1868 -0.01399 0.0 -0.1043 0.01175 -0.00224 0.0 -0.03222 0.01333 -0.002647 -2.316e-05 0.0
0.05339 0.01107 -0.003116 -0.0001079 -1.299e-05 0.0 0.004861 0.008891 -0.0006448 -1.279e-05 6.358e-06 -1.417e-07
0.0 0.03041 0.00115 -0.0008743 -2.781e-05 6.367e-07 -1.14e-08 -4.2e-08 0.0 -0.02982 -0.003 1.394e-05 -3.29e-05
-1.705e-07 7.44e-08 2.72e-08 -6.6e-09 0.0 0.01236 -0.0009981 -3.792e-05 -1.355e-05 1.162e-06 -1.789e-07 1.47e-08
-2.4e-09 -4e-10
56.4 1.555 -1.011 -3.975 0.03171 0.1065 0.6175 0.1376 0.04229 0.003028 1.688 -0.1692 0.05478 0.02473 0.0006059
2.278 0.006614 -0.0003505 -0.006697 0.0008402 0.0007033 -3.236 0.2184 -0.04611 -0.01613 -0.001604 5.42e-05
7.922e-05 -0.2711 -0.4406 -0.03376 -0.002801 -0.000409 -2.056e-05 6.894e-06 2.317e-06 1.941 -0.2562 0.01598
0.005449 0.0003544 1.148e-05 7.503e-06 -5.667e-07 -3.66e-08 0.8683 -0.05931 -0.001864 -0.0001277 0.0002029
1.269e-05 1.629e-06 9.66e-08 -1.015e-07 -5e-10
0.0 0.0 0.2592 0.0 0.02974 -0.5471 0.0 -0.5926 -0.103 -0.01567 0.0 0.171 0.09025 0.02689 0.002243 0.0 0.3439
0.02402 0.00541 0.001601 9.669e-05 0.0 0.09502 -0.03063 -0.001055 -0.0001067 -0.000113 2.124e-05 0.0 -0.3129
0.008463 0.0002253 7.413e-05 -9.376e-05 -1.606e-06 2.06e-06 0.0 0.2739 0.001167 -2.246e-05 -0.0001287 -2.438e-05
-7.561e-07 1.158e-06 4.95e-08 0.0 -0.1344 0.005342 0.0003775 -6.756e-05 -1.686e-06 -1.184e-06 2.768e-07 2.73e-08
5.7e-09
0.1023 -2.695 0.3417 -0.1405 0.3175 0.2116 3.536 -0.1505 -0.0166 0.02967 0.3819 -0.1695 -0.07444 0.007409
-0.006262 -1.836 -0.01759 -0.06256 -0.002371 0.0007947 0.0001501 -0.8603 -0.136 -0.03629 -0.003706 -0.0002976
1.857e-05 3.021e-05 2.248 -0.1178 0.01255 0.001134 -0.0002161 -5.817e-06 8.836e-07 -1.769e-07 0.7313 -0.1188
0.01145 0.001011 0.0001083 2.57e-06 -2.14e-06 -5.71e-08 2e-08 -1.632 -0.006948 -0.003893 0.0008592 7.577e-05
4.539e-06 -3.852e-07 -2.213e-07 -1.37e-08 5.8e-09
0.0 0.0 -0.08865 0.0 -0.4309 0.0634 0.0 0.1162 0.06176 -0.004234 0.0 0.253 0.04017 -0.006204 0.004977 0.0 -0.1737
-0.005638 0.0001488 0.0004857 -0.0001809 0.0 -0.1514 -0.01685 0.005333 -7.611e-05 2.394e-05 8.195e-06 0.0 0.09326
-0.01275 -0.0003071 5.374e-05 -3.391e-05 -7.436e-06 6.747e-07 0.0 -0.08637 -0.003807 -0.0006833 -3.861e-05
-2.268e-05 1.454e-06 3.86e-07 -1.068e-07 0.0 -0.02658 -0.001947 0.0007131 -3.506e-05 1.885e-07 5.792e-07 3.99e-08
2e-08 -5.7e-09
""".split(), float).reshape(8, 55) * 1e-5
_SH_N = np.repeat(np.arange(10), np.arange(1, 11))  # degree of each coefficient
_SH_M = np.concatenate([np.arange(n + 1) for n in range(10)])  # order
_DOUBLE_FACTORIAL = [1.0] + [float(np.prod(np.arange(1, 2 * m, 2))) for m in range(1, 10)]  # (2m-1)!!, m = 0..9
#: MJD of [Niell 1996]'s reference day, 28 January 1980, for the annual term of GMF as of NMF.
_MJD_JAN28_1980 = 44239.0 - 1.0 + 28.0


def _legendre_9(t):
    """Unnormalised associated Legendre functions ``P_nm(t)``, n, m <= 9, no Condon-Shortley phase.

    Shape (..., 55) in the order of ``_SH_N`` / ``_SH_M`` (the convention of [Heiskanen 1967] eq. 1-62).
    """
    t = np.asarray(t, float)
    u = np.sqrt(np.clip(1.0 - t * t, 0.0, None))
    p = {}
    for m in range(10):
        p[m, m] = _DOUBLE_FACTORIAL[m] * u**m  # (2m-1)!! u^m
        if m < 9:
            p[m + 1, m] = (2 * m + 1) * t * p[m, m]
        for n in range(m + 2, 10):
            p[n, m] = ((2 * n - 1) * t * p[n - 1, m] - (n + m - 1) * p[n - 2, m]) / (n - m)
    out = np.empty(t.shape + (_SH_N.size,))
    for i, nm in enumerate(zip(_SH_N.tolist(), _SH_M.tolist())):
        out[..., i] = p[nm]
    return out


def gmf_mapping(elev_rad, lat_rad, lon_rad, height_m, mjd):
    """Hydrostatic and wet Global Mapping Functions of [Boehm 2006].

    The continued fraction of [Marini 1972] with ``b, c`` as [Boehm 2006]
    (hydrostatic ``b = 0.0029``, ``c`` from latitude and season; wet ``b =
    0.00146, c = 0.04391``) and ``a`` from spherical harmonics of degree 9
    fit to three years of ECMWF ray traces (mean plus annual cosine, phase
    at 28 January as in [Niell 1996]); the hydrostatic height correction is
    Niell's. Where NMF's ``a`` depends on latitude only, GMF's also follows
    longitude (oceans, continents), which is the point of it for a coastal
    station.

    Parameters
    ----------
    elev_rad, lat_rad, lon_rad, height_m, mjd : array_like, broadcastable
        Elevation, geodetic latitude, longitude, height (above sea level;
        the hydrostatic function grows by 3.9e-4 per 100 m at 10 deg, so
        the ellipsoidal height, 40 m higher in Denmark, adds 0.4 mm of
        slant delay there), modified Julian date (UTC, fractional).

    Returns
    -------
    m_dry, m_wet : ndarray
        Both 1 at zenith.
    """
    # The coefficients depend on the site and day only: evaluated on their broadcast shape, not the elevations'.
    lat_rad, lon_rad, mjd = np.broadcast_arrays(*(np.asarray(v, float) for v in (lat_rad, lon_rad, mjd)))
    p = _legendre_9(np.sin(lat_rad))
    cos_m, sin_m = np.cos(_SH_M * lon_rad[..., None]), np.sin(_SH_M * lon_rad[..., None])
    ah_mean, ah_amp, aw_mean, aw_amp = (np.sum(p * (_GMF_COEF[k] * cos_m + _GMF_COEF[k + 1] * sin_m), axis=-1)
                                        for k in (0, 2, 4, 6))
    season = np.cos(2.0 * np.pi * (mjd - _MJD_JAN28_1980) / 365.25)
    south = lat_rad < 0
    c11, c10 = np.where(south, 0.007, 0.005), np.where(south, 0.002, 0.001)
    c_h = 0.062 + ((np.cos(2.0 * np.pi * (mjd - _MJD_JAN28_1980) / 365.25 + np.where(south, np.pi, 0.0)) + 1.0)
                   * c11 / 2.0 + c10) * (1.0 - np.cos(lat_rad))
    s = np.sin(np.asarray(elev_rad, float))
    m_dry = (_marini(s, ah_mean + ah_amp * season, 0.0029, c_h)
             + (1.0 / s - _marini(s, *_NMF_HT)) * np.asarray(height_m, float) * 1e-3)
    m_wet = _marini(s, aw_mean + aw_amp * season, 0.00146, 0.04391)
    return m_dry, m_wet


# [Boehm 2007] GPT: spherical-harmonic coefficients (degree and order 9, n = 0..9, m = 0..n) of the geoid
# undulation [m] and of the mean and annual amplitude of the pressure reduced to the geoid [hPa], cosine (a)
# and sine (b) parts, as published with the paper and in [IERS 2010] ch. 9. Rows: a_geoid, b_geoid, ap_mean,
# bp_mean, ap_amp, bp_amp (the temperature's are not needed for the hydrostatic delay).
_GPT_COEF = np.array("""
-0.56195 -0.060794 -0.20125 -0.06418 -0.036997 10.098 16.436 14.065 1.9881 0.64414 -4.7482 -3.229 0.50652 0.38279
-0.026646 1.7224 -0.2797 0.68177 -0.096658 -0.015113 0.0029206 -3.4621 -0.38198 0.032306 0.0069915 -0.0023068
-0.0013548 4.7324e-06 2.3527 1.2985 0.21232 0.022571 -0.0037855 2.9449e-05 -0.00016265 1.1711e-07 1.6732 0.19858
0.023975 -0.00090013 -0.0022475 -3.3095e-05 -1.204e-05 2.201e-06 -1.0083e-06 0.86297 0.58231 0.020545 -0.007811
-0.00014085 -8.8459e-06 5.7256e-06 -1.5068e-06 4.0095e-07 -2.4185e-08
0.0 0.0 -0.065993 0.0 0.065364 -5.832 0.0 1.6961 -1.3557 1.2694 0.0 -2.931 0.94805 -0.076243 0.041076 0.0
-0.51808 -0.34583 -0.043632 0.0022101 -0.010663 0.0 0.10927 -0.29463 0.0014371 -0.011452 -0.0028156 -0.0003533
0.0 0.44049 0.055653 -0.020396 -0.0017312 3.5805e-05 7.2682e-05 2.2535e-06 0.0 0.019502 0.027919 -0.0081812
0.0004454 8.8663e-05 5.5596e-05 2.4826e-06 1.0279e-06 0.0 0.060529 -0.035824 -0.0051367 3.0119e-05 -2.9911e-05
1.9844e-05 -1.2349e-06 -7.6756e-09 5.01e-08
1010.8 8.4886 1.4799 -13.897 0.0037516 -0.14936 12.232 -0.76615 -0.067699 0.0081002 -15.874 0.36614 -0.067807
-0.0036309 0.00059966 4.8163 -0.37363 -0.072071 0.0019998 -0.00062385 -0.00037916 4.7609 -0.39534 0.0086667
0.011569 0.0011441 -0.00014193 -8.5723e-05 0.65008 -0.50889 -0.015754 -0.0028305 0.00057458 3.2577e-05
-9.6052e-06 -2.7974e-06 1.353 -0.27271 -0.00030276 0.0036286 -0.00020398 1.5846e-05 -7.7787e-06 1.121e-06
9.902e-08 0.55046 -0.27312 0.0032532 -0.0024277 0.00011596 2.6421e-07 -1.3263e-06 2.7322e-07 1.4058e-07
4.9414e-09
0.0 0.0 -1.2878 0.0 0.70444 0.33222 0.0 -0.29636 0.0072248 0.0079655 0.0 1.0854 0.011145 -0.036513 0.0031527 0.0
-0.48434 0.052023 -0.013091 0.0018515 0.00015422 0.0 0.68298 0.0025261 -0.00099703 -0.0010829 0.00017688
-3.1418e-05 0.0 -0.37018 0.043234 0.0072559 0.00031516 2.0024e-05 -8.0581e-06 -2.3653e-06 0.0 0.10298 -0.015086
0.0056186 3.2613e-05 4.0567e-05 -1.3925e-06 -3.6219e-07 -2.0176e-08 0.0 -0.18364 0.018508 0.00075016 -9.6139e-05
-3.1995e-06 1.3868e-07 -1.9486e-07 3.0165e-10 -6.4376e-10
-0.10444 0.16618 -0.063974 1.0922 0.57472 -0.30277 -3.5087 0.0071264 -0.1403 0.03705 0.40208 -0.30431 -0.13292
0.0046746 -0.00015902 2.8624 -0.39315 -0.064371 0.016444 -0.0023403 4.2127e-05 1.9945 -0.60907 -0.035386
-0.001091 -0.00012799 4.097e-05 2.2131e-05 -0.53292 -0.29765 -0.032877 0.0017691 5.9692e-05 3.1725e-05 2.0741e-05
-3.7622e-07 2.6372 -0.31165 0.016439 0.00021633 0.00017485 2.1587e-05 6.1064e-06 -1.3755e-08 -7.8748e-08 -0.59152
-0.17676 0.0081807 0.0010445 0.00023432 9.3421e-06 2.8104e-06 -1.5788e-07 -3.0648e-08 2.6421e-10
0.0 0.0 0.9334 0.0 0.82346 0.22082 0.0 0.96177 -0.01565 0.0012708 0.0 -0.39913 0.02802 0.028334 0.0008598 0.0
0.30545 -0.021691 0.00064067 -3.6528e-05 -0.00011166 0.0 -0.076974 -0.018986 0.0056896 -0.00024159 -0.00023033
-9.6783e-06 0.0 -0.10218 -0.013916 -0.0041025 -5.134e-05 -7.0114e-05 -3.3152e-07 1.6901e-06 0.0 -0.012422
0.0025072 0.0011205 -0.00013034 -2.3971e-05 -2.6622e-06 5.7852e-07 4.5847e-08 0.0 0.044777 -0.0030421 2.6062e-05
-7.2421e-05 1.9119e-06 3.9236e-07 2.239e-07 2.9765e-09 -4.6452e-09
""".split(), float).reshape(6, 55)


def gpt_pressure_hpa(lat_rad, lon_rad, alt_m, mjd):
    """Surface pressure of the Global Pressure and Temperature model of [Boehm 2007].

    A degree-9 spherical-harmonic climatology (mean plus annual cosine, phase
    at 28 January) of the pressure on the geoid, fit to three years of
    ECMWF monthly means, reduced to the site's orthometric height (``alt_m``
    minus the model's own degree-9 geoid) with ``P = P0 (1 - 2.26e-5
    H)^5.225``. Where the standard atmosphere has 1013.25 hPa at sea level
    everywhere, GPT follows the climatological highs and lows (a few hPa at
    mid-latitudes; 1 hPa moves the hydrostatic zenith delay by 2.3 mm).

    Parameters
    ----------
    lat_rad, lon_rad, alt_m, mjd : array_like, broadcastable
        Geodetic latitude, longitude, ellipsoidal height, modified Julian
        date (UTC, fractional).

    Returns
    -------
    pressure_hpa, undulation_m : ndarray
        The pressure, and the geoid undulation used for the height.
    """
    lat_rad, lon_rad, alt_m, mjd = np.broadcast_arrays(*(np.asarray(v, float) for v in (lat_rad, lon_rad, alt_m,
                                                                                          mjd)))
    p = _legendre_9(np.sin(lat_rad))
    cos_m, sin_m = p * np.cos(_SH_M * lon_rad[..., None]), p * np.sin(_SH_M * lon_rad[..., None])
    undulation, p_mean, p_amp = (np.sum(_GPT_COEF[k] * cos_m + _GPT_COEF[k + 1] * sin_m, axis=-1)
                                 for k in (0, 2, 4))
    p0 = p_mean + p_amp * np.cos(2.0 * np.pi * (mjd - _MJD_JAN28_1980) / 365.25)
    return p0 * (1.0 - 2.26e-5 * (alt_m - undulation)) ** 5.225, undulation


#: [Chen 1997]'s gradient mapping constant for the total delay (0.0031 hydrostatic, 0.0007 wet alone).
CHEN_HERRING_C = 0.0032


def gradient_mapping(elev_rad, az_rad):
    """Partials of the slant delay on the north and east troposphere gradients, [Chen 1997].

    The slant delay's asymmetric part is ``m_g(e) (G_N cos a + G_E sin a)``
    with ``m_g(e) = 1 / (sin e tan e + C)``, ``C = 0.0032``: for a
    refractivity varying linearly across the horizon, ``G`` is the
    height-weighted integral of its horizontal gradient (metres; about a
    millimetre at mid-latitudes), ``1 / (sin e tan e)`` is the flat-Earth
    geometry and ``C`` the Earth's curvature, which keeps it finite at the
    horizon (about 29 at 10 deg, 0 at the zenith).

    Parameters
    ----------
    elev_rad, az_rad : array_like, broadcastable
        Elevation and azimuth (clockwise from north).

    Returns
    -------
    ndarray, shape (..., 2)
        ``d slant / d (G_N, G_E)`` (dimensionless).
    """
    elev_rad, az_rad = np.broadcast_arrays(np.asarray(elev_rad, float), np.asarray(az_rad, float))
    m_g = 1.0 / (np.sin(elev_rad) * np.tan(elev_rad) + CHEN_HERRING_C)
    return np.stack([m_g * np.cos(az_rad), m_g * np.sin(az_rad)], axis=-1)


def slant_hydrostatic_and_wet(elev_rad, lat_rad, lon_rad, alt_m, mjd, *, mapping="gmf", zhd_pressure="gpt"):
    """Slant hydrostatic delay and wet mapping of one model choice: the troposphere of every GNSS filter.

    ``mapping`` is ``"gmf"`` (:func:`gmf_mapping`) or ``"niell"`` (:func:`niell_mapping`, with the day of
    year from ``mjd``); ``zhd_pressure`` is ``"gpt"`` (:func:`gpt_pressure_hpa`) or ``"standard"`` (the
    standard atmosphere of :func:`saastamoinen_zhd_m`). The PPP filters take both from their options
    (``PppOptions``, ``PppInsOptions``), so that float, fixed and PPP/INS solutions share one model.

    Parameters
    ----------
    elev_rad, lat_rad, lon_rad, alt_m, mjd : array_like, broadcastable
        Elevation, geodetic latitude, longitude, ellipsoidal height, modified Julian date (fractional).
    mapping : {"gmf", "niell"}
    zhd_pressure : {"gpt", "standard"}

    Returns
    -------
    slant_dry_m, m_wet : ndarray
        ``ZHD m_dry`` [m] and the wet mapping (1 at zenith), the broadcast shape.

    Raises
    ------
    InputError
        An unknown ``mapping`` or ``zhd_pressure``.
    """
    if mapping not in MAPPINGS:
        raise InputError(f"mapping {mapping!r}: expected one of {', '.join(MAPPINGS)}")
    if zhd_pressure not in ZHD_PRESSURES:
        raise InputError(f"zhd_pressure {zhd_pressure!r}: expected one of {', '.join(ZHD_PRESSURES)}")
    mjd = np.asarray(mjd, float)
    if mapping == "gmf":
        m_dry, m_wet = gmf_mapping(elev_rad, lat_rad, lon_rad, alt_m, mjd)
    else:
        year_start = (_MJD_ZERO + np.floor(mjd).astype("timedelta64[D]")).astype("datetime64[Y]")
        doy = mjd - (year_start - _MJD_ZERO).astype("timedelta64[D]").astype(float) + 1.0
        m_dry, m_wet = niell_mapping(elev_rad, lat_rad, alt_m, doy)
    pressure_hpa = gpt_pressure_hpa(lat_rad, lon_rad, alt_m, mjd)[0] if zhd_pressure == "gpt" else None
    return saastamoinen_zhd_m(lat_rad, alt_m, pressure_hpa) * m_dry, m_wet
