"""Physical constants, SI units.

Each value names its source; constellation signal parameters are in
:mod:`leosop.constellations`. Nothing here is tunable: configuration lives
with the code that uses it.
"""

#: Speed of light in vacuum [m/s] (exact, SI definition).
C_MPS = 299_792_458.0

# WGS84 ellipsoid and gravity (NIMA TR8350.2).
#: Semi-major axis [m].
WGS84_A_M = 6_378_137.0
#: Flattening [-].
WGS84_F = 1.0 / 298.257223563
#: Semi-minor axis [m].
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
#: First eccentricity squared [-].
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
#: Earth rotation rate [rad/s] (WGS84 nominal mean angular velocity).
OMEGA_E_RAD_PER_S = 7.292115e-5
#: Earth gravitational constant GM [m^3/s^2].
GM_M3_PER_S2 = 3.986004418e14
#: Normal gravity at the equator [m/s^2].
GAMMA_E_MPS2 = 9.7803253359
#: Somigliana constant k = (b*gamma_p)/(a*gamma_e) - 1 [-].
SOMIGLIANA_K = 0.00193185265241
#: m = omega^2 a^2 b / GM [-], used in the free-air height term.
WGS84_M = 0.00344978650684

#: Standard gravity used to quote accelerometer errors in g [m/s^2].
G0_MPS2 = 9.80665

# Time.
#: Julian date of the J2000.0 epoch (TT).
JD_J2000 = 2_451_545.0
#: Julian date of the Unix epoch, 1970-01-01T00:00 UTC.
JD_UNIX_EPOCH = 2_440_587.5
#: Seconds per day.
DAY_S = 86_400.0
