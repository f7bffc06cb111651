"""Truth trajectories and the ideal IMU increments that go with them.

A trajectory is flown from a small set of smooth commands, piece by piece:
horizontal ground speed, vertical speed, turn rate and an extra roll rate
([Chu 2009]'s rolling flight). Each command ramps between its values at the
ends of a piece with the C2 quintic ``S(x) = 10x^3 - 15x^4 + 6x^5``, so body
rates and accelerations are continuous. The kinematics

    lat' = v_N / (R_M + h),  lon' = v_E / ((R_N + h) cos lat),  h' = v_U,
    heading' = v_E tan(lat) / (R_N + h) + turn_rate

(heading clockwise from North; the first term keeps a straight flight on a
geodesic) are integrated with an 8th-order Runge-Kutta method (DOP853,
rtol 1e-12) and its dense output. The attitude follows the path: yaw from the
heading, pitch the flight-path angle ``atan2(v_U, v)``, roll the bank of a
coordinated turn ``atan(v * turn_rate / g0)`` plus the extra roll.

The ideal IMU increments over each sample interval are the integrals of the
true body rate ``omega_ib^b`` and specific force ``f^b`` (what a perfect
integrating IMU outputs), evaluated analytically at 4 Gauss-Legendre nodes
per interval; they are independent of any strapdown algorithm. Conventions
are those of :mod:`leosop` (ENU, body Right-Forward-Up, ``C_n_b``).
"""

import dataclasses
import math

import numpy as np
from scipy.integrate import solve_ivp

from .. import earth, frames
from ..constants import G0_MPS2
from ..errors import InputError
from ..rotations import dcm_to_euler, dcm_to_quat, euler_to_dcm, heading_from_yaw
from .track import NavTrack

__all__ = ["Trajectory", "Flight", "Segment", "plan_flight", "from_segments", "flight", "xian_baoji", "rolling_flight",
           "static"]

#: [Shen 2024], section 4.1: Xi'an and Baoji [deg], 3 km, 200 m/s, 782 s.
XIAN_DEG = (34.342, 108.940)
BAOJI_DEG = (34.363, 107.239)

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
#: IMU intervals integrated per block (bounds the memory of long trajectories).
_BLOCK_INTERVALS = 20_000
_RTOL = 1e-12
_ATOL = np.array([1e-14, 1e-14, 1e-8, 1e-14, 1e-12])  # lat, lon [rad], h [m], heading, roll [rad]


@dataclasses.dataclass(frozen=True)
class Trajectory(NavTrack):
    """True motion sampled at the IMU rate (a :class:`~leosop.ins.track.NavTrack`), with the ideal IMU increments.

    Attributes
    ----------
    t_s, lat_rad, lon_rad, alt_m, vel_enu_mps, C_n_b
        As in :class:`~leosop.ins.track.NavTrack`: shapes (n,), (n,), (n,),
        (n,), (n, 3), (n, 3, 3); ``t_s`` on a uniform sample grid from 0.
    dtheta_b_rad : ndarray, shape (n - 1, 3)
        Integral of the true body rate ``omega_ib^b`` over each interval.
    dvel_b_mps : ndarray, shape (n - 1, 3)
        Integral of the true specific force ``f^b`` over each interval.
    """

    dtheta_b_rad: np.ndarray
    dvel_b_mps: np.ndarray

    @property
    def dt_s(self):
        """Sample interval [s]."""
        return float(self.t_s[1] - self.t_s[0])

    @property
    def quat_n_b(self):
        """Attitude as scalar-first quaternions, shape (n, 4)."""
        return dcm_to_quat(self.C_n_b)

    @property
    def euler_rad(self):
        """Pitch, roll, yaw [rad] (see :mod:`leosop.rotations`), each shape (n,)."""
        return dcm_to_euler(self.C_n_b)

    @property
    def heading_deg(self):
        """Heading clockwise from North [deg], shape (n,)."""
        return np.degrees(heading_from_yaw(self.euler_rad[2]))

    def at(self, t_s):
        """The truth at sample times ``t_s`` (which must lie on the sample grid).

        Increments of the result are summed over the skipped samples, so they
        remain the exact integrals between the selected times.
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        k = np.rint((t - self.t_s[0]) / self.dt_s).astype(int)
        if np.any(k < 0) or np.any(k >= self.t_s.size) or np.any(np.abs(self.t_s[np.clip(k, 0, None)] - t) > 1e-6):
            raise InputError(f"t_s must lie on the trajectory's {self.dt_s} s sample grid within "
                             f"[{self.t_s[0]}, {self.t_s[-1]}] s")
        if k.size > 1 and np.any(np.diff(k) <= 0):
            raise InputError("t_s must be strictly increasing")
        cum_th = np.concatenate([np.zeros((1, 3)), np.cumsum(self.dtheta_b_rad, axis=0)])
        cum_dv = np.concatenate([np.zeros((1, 3)), np.cumsum(self.dvel_b_mps, axis=0)])
        return Trajectory(self.t_s[k], self.lat_rad[k], self.lon_rad[k], self.alt_m[k], self.vel_enu_mps[k],
                          self.C_n_b[k], np.diff(cum_th[k], axis=0), np.diff(cum_dv[k], axis=0))

    def resample(self, step_s):
        """The truth every ``step_s`` seconds (a multiple of the sample interval), e.g. 1 Hz output."""
        every = int(round(step_s / self.dt_s))
        if every < 1 or abs(every * self.dt_s - step_s) > 1e-9:
            raise InputError(f"step_s={step_s} must be a positive multiple of the sample interval {self.dt_s} s")
        return self.at(self.t_s[::every])


class Flight:
    """A flown profile sampled on demand: the truth at chosen samples, the ideal increments a block at a time.

    It gives what :class:`Trajectory` holds for every sample without holding
    it, for long flights (a Trajectory holds 176 B per sample with its
    increments: 380 MB for 6 h at 100 Hz). Every value is computed per sample or
    interval, so it is bit for bit the one a Trajectory holds.

    Attributes
    ----------
    rate_hz : float
        Sample rate.
    n_samples : int
        Samples; the increments cover the ``n_samples - 1`` intervals.
    """

    def __init__(self, builder, rate_hz, n_samples):
        self._builder, self.rate_hz, self.n_samples = builder, rate_hz, n_samples

    @property
    def dt_s(self):
        """Sample interval [s]."""
        return 1.0 / self.rate_hz

    def increments(self, k0, k1):
        """Ideal increments of intervals ``k0 .. k1 - 1``: ``dtheta_b_rad``, ``dvel_b_mps``, each shape (k1 - k0, 3).

        Gauss-Legendre nodes of every interval, (intervals, 4), a block of
        intervals at a time: the evaluation's temporaries (~2 kB per interval)
        would otherwise grow with the duration (5 GB for 6 h).
        """
        if not 0 <= k0 <= k1 <= self.n_samples - 1:
            raise InputError(f"intervals {k0}..{k1}: outside 0..{self.n_samples - 1}")
        half = 0.5 / self.rate_hz
        w = (half * _GL_W)[None, :, None]
        dtheta, dvel = np.empty((k1 - k0, 3)), np.empty((k1 - k0, 3))
        for b0 in range(k0, k1, _BLOCK_INTERVALS):
            tk = np.arange(b0, min(b0 + _BLOCK_INTERVALS, k1)) / self.rate_hz
            at_nodes = self._builder._evaluate(((tk[:, None] + half) + half * _GL_X[None, :]).ravel())
            dtheta[b0 - k0: b0 - k0 + tk.size] = np.sum(at_nodes["w_ib_b"].reshape(tk.size, 4, 3) * w, axis=1)
            dvel[b0 - k0: b0 - k0 + tk.size] = np.sum(at_nodes["f_b"].reshape(tk.size, 4, 3) * w, axis=1)
        return dtheta, dvel

    def track(self, every=1):
        """The truth at samples ``0, every, 2 every, ...``, a :class:`~leosop.ins.track.NavTrack`."""
        if int(every) != every or every < 1:
            raise InputError(f"every={every} must be a positive integer")
        t = np.arange(0, self.n_samples, int(every)) / self.rate_hz
        truth = self._builder._evaluate(t)
        return NavTrack(t, truth["lat"], truth["lon"], truth["h"], truth["vel"], truth["C_n_b"])

    def trajectory(self):
        """The :class:`Trajectory`: every sample and the ideal increments of every interval."""
        track = self.track()
        return Trajectory(*(getattr(track, f.name) for f in dataclasses.fields(NavTrack)),
                          *self.increments(0, self.n_samples - 1))


@dataclasses.dataclass(frozen=True)
class Segment:
    """One piece of a flight profile; the commands ramp to these values over it.

    ``None`` keeps the value at the end of the previous piece (zero at the
    start). Speeds in m/s, rates in deg/s; the extra roll rate is constant
    over the piece.
    """

    duration_s: float
    speed_mps: float | None = None
    climb_rate_mps: float | None = None
    turn_rate_deg_s: float | None = None
    roll_rate_deg_s: float = 0.0


def _smooth(x):
    """C2 ramp S(x) and its derivative dS/dx on [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2), 30.0 * x**2 * (1.0 - x) ** 2


@dataclasses.dataclass(frozen=True)
class _Piece:
    t0: float
    t1: float
    speed: tuple  # (start, end) [m/s]
    climb: tuple  # (start, end) [m/s]
    turn: tuple  # (start, end) [rad/s]
    roll_rate: float  # [rad/s]
    sol: object = None

    def commands(self, t):
        """Speed, climb and turn values and their time derivatives at times t."""
        T = self.t1 - self.t0
        s, ds = _smooth((np.asarray(t) - self.t0) / T) if T > 0 else (np.ones_like(t), np.zeros_like(t))
        out = []
        for a0, a1 in (self.speed, self.climb, self.turn):
            out += [a0 + (a1 - a0) * s, (a1 - a0) * ds / T if T > 0 else 0.0 * s]
        return out

    def rhs(self, t, y):
        lat, _, h, psi, _ = y
        v, _, vu, _, w, _ = (float(c) for c in self.commands(t))
        rm_h, rn_h, c, *_ = earth.local_terms(lat, h, 0.0, 0.0)
        ve, vn = v * math.sin(psi), v * math.cos(psi)
        return [vn / rm_h, ve / (rn_h * c), vu, ve * math.tan(lat) / rn_h + w, self.roll_rate]


def _fly(piece, y0, event=None):
    """Integrate one piece from state y0; return the piece with its solution (cut at a terminal event)."""
    sol = solve_ivp(piece.rhs, (piece.t0, piece.t1), y0, method="DOP853", rtol=_RTOL, atol=_ATOL,
                    dense_output=True, events=event)
    if not sol.success:
        raise RuntimeError(f"trajectory integration failed: {sol.message}")
    t_end = sol.t[-1]
    if event is not None and sol.t_events[0].size:
        t_end = float(sol.t_events[0][0])
    return dataclasses.replace(piece, t1=t_end, sol=sol.sol), sol.sol(t_end)


class _Builder:
    """Chains pieces, keeping the commands and state at the end of the last one."""

    def __init__(self, lat_rad, lon_rad, alt_m, heading_rad, pitch_rad=0.0, roll_rad=0.0):
        self.pieces = []
        self.y = np.array([lat_rad, lon_rad, alt_m, heading_rad, 0.0])
        self.t = 0.0
        self.speed = self.climb = self.turn = 0.0
        self.pitch0, self.roll0 = pitch_rad, roll_rad

    def add(self, duration_s, speed=None, climb=None, turn=None, roll_rate=0.0, event=None):
        speed = self.speed if speed is None else speed
        climb = self.climb if climb is None else climb
        turn = self.turn if turn is None else turn
        piece = _Piece(self.t, self.t + duration_s, (self.speed, speed), (self.climb, climb), (self.turn, turn),
                       roll_rate)
        piece, self.y = _fly(piece, self.y, event)
        self.pieces.append(piece)
        self.t = piece.t1
        if piece.t1 < piece.t0 + duration_s:  # cut by an event: commands at the cut
            self.speed, _, self.climb, _, self.turn, _ = (float(c) for c in piece.commands(piece.t1))
        else:
            self.speed, self.climb, self.turn = speed, climb, turn
        return piece

    def build(self, rate_hz, duration_s=None):
        """The :class:`Flight` of the pieces so far, sampled at ``rate_hz`` for ``duration_s`` (default all)."""
        duration_s = self.t if duration_s is None else duration_s
        if rate_hz <= 0 or not np.isfinite(rate_hz):
            raise InputError(f"rate_hz={rate_hz} must be a positive number")
        n = int(math.floor(duration_s * rate_hz + 1e-6)) + 1
        if n < 2:
            raise InputError(f"duration_s={duration_s} is shorter than one sample at rate_hz={rate_hz}")
        if (n - 1) / rate_hz > self.t + 1e-9:
            raise InputError(f"duration_s={duration_s} is longer than the profile ({self.t} s)")
        return Flight(self, float(rate_hz), n)

    def _evaluate(self, t):
        """Position, velocity, attitude, body rate and specific force at times t (analytic in the state)."""
        t = np.asarray(t, dtype=float)
        starts = np.array([p.t0 for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        y = np.empty((5, t.size))
        cmd = np.empty((6, t.size))
        roll_rate = np.empty(t.size)
        for i, piece in enumerate(self.pieces):
            m = idx == i
            if np.any(m):
                y[:, m] = piece.sol(t[m])
                cmd[:, m] = np.array(piece.commands(t[m]))
                roll_rate[m] = piece.roll_rate
        lat, lon, h, psi, roll_x = y
        v, v_dot, vu, vu_dot, w, w_dot = cmd
        R_M, R_N = earth.radii_m(lat)
        sp, cp = np.sin(psi), np.cos(psi)
        vel = np.stack([v * sp, v * cp, vu], axis=-1)
        psi_dot = v * sp * np.tan(lat) / (R_N + h) + w
        acc = np.stack([v_dot * sp + v * cp * psi_dot, v_dot * cp - v * sp * psi_dot, vu_dot], axis=-1)
        # Attitude and its Euler-angle rates.
        pitch = self.pitch0 + np.arctan2(vu, v)
        v2 = v * v + vu * vu
        pitch_dot = np.divide(v * vu_dot - vu * v_dot, v2, out=np.zeros_like(v2), where=v2 > 0)
        bank = v * w / G0_MPS2
        roll = self.roll0 + np.arctan(bank) + roll_x
        roll_dot = (v_dot * w + v * w_dot) / G0_MPS2 / (1.0 + bank**2) + roll_rate
        C = euler_to_dcm(pitch, roll, -psi)
        # omega_nb^b of C = Rz(yaw) Rx(pitch) Ry(roll): yaw' C^T e_z + pitch' Ry^T e_x + roll' e_y.
        w_nb = -psi_dot[:, None] * C[:, 2, :]
        w_nb[:, 0] += pitch_dot * np.cos(roll)
        w_nb[:, 2] += pitch_dot * np.sin(roll)
        w_nb[:, 1] += roll_dot
        w_ie = earth.earth_rate_enu(lat)
        w_en = earth.transport_rate_enu(lat, h, vel)
        w_ib = np.einsum("kji,kj->ki", C, w_ie + w_en) + w_nb
        f_n = acc + np.cross(2.0 * w_ie + w_en, vel) - earth.gravity_enu_mps2(lat, h)
        f_b = np.einsum("kji,kj->ki", C, f_n)
        return {"lat": lat, "lon": lon, "h": h, "vel": vel, "C_n_b": C, "w_ib_b": w_ib, "f_b": f_b}


def from_segments(lat_deg, lon_deg, alt_m, heading_deg, segments, *, pitch_deg=0.0, roll_deg=0.0,
                  rate_hz=100.0):
    """A trajectory flown from a start point through a list of :class:`Segment`.

    Parameters
    ----------
    lat_deg, lon_deg, alt_m : float
        Start position (geodetic, WGS84).
    heading_deg : float
        Initial heading clockwise from North.
    segments : sequence of Segment
    pitch_deg, roll_deg : float
        Constant attitude offsets added to the flight-path pitch and bank.
    rate_hz : float
        IMU sample rate.

    Returns
    -------
    Trajectory
    """
    b = _Builder(math.radians(lat_deg), math.radians(lon_deg), alt_m, math.radians(heading_deg),
                 math.radians(pitch_deg), math.radians(roll_deg))
    for i, seg in enumerate(segments):
        if not seg.duration_s > 0:
            raise InputError(f"segments[{i}].duration_s={seg.duration_s} must be > 0")
        b.add(seg.duration_s, seg.speed_mps,
              seg.climb_rate_mps, None if seg.turn_rate_deg_s is None else math.radians(seg.turn_rate_deg_s),
              math.radians(seg.roll_rate_deg_s))
    return b.build(rate_hz).trajectory()


def static(lat_deg, lon_deg, alt_m, pitch_deg, roll_deg, heading_deg, duration_s, rate_hz=100.0):
    """A vehicle at rest on the Earth: the IMU senses only Earth rate and gravity."""
    return from_segments(lat_deg, lon_deg, alt_m, heading_deg, [Segment(duration_s)], pitch_deg=pitch_deg,
                         roll_deg=roll_deg, rate_hz=rate_hz)


def rolling_flight(lat_deg=XIAN_DEG[0], lon_deg=XIAN_DEG[1], alt_m=3000.0, speed_mps=200.0, heading_deg=0.0,
                   roll_rate_deg_s=180.0, duration_s=150.0, rate_hz=100.0):
    """[Chu 2009]'s rolling flight: constant height and speed, rolling about the forward axis.

    [Chu 2009] (Table 2) gives the body rate ``[180, 0, 0] deg/s`` and specific
    force ``[0, cos(180 t), -sin(180 t)] g`` in its forward-up-right body
    frame over 150 s; in our Right-Forward-Up body that is a roll rate about
    the forward axis. The paper states no place, speed or heading; the
    defaults here are ours.
    """
    b = _Builder(math.radians(lat_deg), math.radians(lon_deg), alt_m, math.radians(heading_deg))
    b.speed = speed_mps
    b.add(duration_s, roll_rate=math.radians(roll_rate_deg_s))
    return b.build(rate_hz).trajectory()


def _target_enu(y, target_ecef):
    """Vector from the state's position to a target, in the local ENU frame."""
    pos = frames.geodetic_to_ecef(y[0], y[1], y[2])
    return frames.ecef_to_enu(target_ecef - pos, y[0], y[1])


def _wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def plan_flight(waypoints_deg, alt_m=None, speed_mps=200.0, rate_hz=100.0, duration_s=None, *,
                turn_rate_deg_s=3.0, roll_in_s=2.0, climb_rate_mps=10.0):
    """Fly geodesic legs between waypoints at constant ground speed.

    The flight starts at the first waypoint heading for the second. Each leg
    is a geodesic at constant height (after an optional climb at its start)
    aimed at the next waypoint and ends at the closest approach to it; then
    a coordinated turn (bank ``atan(v * rate / g0)``, rolled in and out over
    ``roll_in_s``) points the vehicle at the following waypoint.

    Parameters
    ----------
    waypoints_deg : array_like, shape (m, 2) or (m, 3)
        ``[lat_deg, lon_deg]`` or ``[lat_deg, lon_deg, alt_m]`` rows, m >= 2.
    alt_m : float, optional
        Height of waypoints given without one.
    speed_mps : float
        Horizontal ground speed.
    rate_hz : float
        IMU sample rate.
    duration_s : float, optional
        Cut the flight short, or keep flying the last leg beyond its
        waypoint, so that it lasts exactly this long. Default: end at the
        last waypoint.
    turn_rate_deg_s, roll_in_s, climb_rate_mps : float
        Turn rate of the coordinated turns, duration of the roll-in and
        roll-out ramps, and the vertical speed of climbs and descents.

    Returns
    -------
    Flight
        Sampled on demand; :func:`flight` gives the :class:`Trajectory`.
    """
    wp = np.asarray(waypoints_deg, dtype=float)
    if wp.ndim != 2 or wp.shape[0] < 2 or wp.shape[1] not in (2, 3):
        raise InputError(f"waypoints_deg must have shape (m, 2) or (m, 3) with m >= 2, got {wp.shape}")
    if wp.shape[1] == 2:
        if alt_m is None:
            raise InputError("alt_m is required when waypoints_deg has no height column")
        wp = np.column_stack([wp, np.full(len(wp), float(alt_m))])
    if not np.all(np.isfinite(wp)) or np.any(np.abs(wp[:, 0]) >= 89.0):
        raise InputError("waypoints_deg must be finite with |lat_deg| < 89")
    for name, val in (("speed_mps", speed_mps), ("turn_rate_deg_s", turn_rate_deg_s), ("roll_in_s", roll_in_s),
                      ("climb_rate_mps", climb_rate_mps)):
        if not val > 0:
            raise InputError(f"{name}={val} must be > 0")
    lat = np.radians(wp[:, 0])
    lon = np.radians(wp[:, 1])
    targets = frames.geodetic_to_ecef(lat, lon, wp[:, 2])
    d = _target_enu([lat[0], lon[0], wp[0, 2]], targets[1])
    b = _Builder(lat[0], lon[0], wp[0, 2], math.atan2(d[0], d[1]))
    b.speed = float(speed_mps)
    turn_max = math.radians(turn_rate_deg_s)
    for k in range(1, len(wp)):
        target = targets[k]
        last = k == len(wp) - 1
        if k > 1:
            _turn_towards(b, target, turn_max, roll_in_s)
        dh = wp[k, 2] - b.y[2]
        if abs(dh) > 1e-6:
            rate = math.copysign(climb_rate_mps, dh)
            hold = abs(dh) / climb_rate_mps - roll_in_s
            if hold < 0:  # short climb: lower the vertical speed instead
                rate, hold = dh / roll_in_s, 0.0
            b.add(roll_in_s, climb=rate)
            if hold > 0:
                b.add(hold)
            b.add(roll_in_s, climb=0.0)
            if float(np.dot(_target_enu(b.y, target)[:2], [math.sin(b.y[3]), math.cos(b.y[3])])) < 0:
                raise InputError(f"waypoints_deg[{k}]: leg too short for the climb of {dh:.1f} m")

        def passed(t, y, target=target):
            d = _target_enu(y, target)
            return d[0] * math.sin(y[3]) + d[1] * math.cos(y[3])

        passed.terminal = True
        passed.direction = -1
        if last and duration_s is not None:
            if duration_s > b.t:
                b.add(duration_s - b.t)
        else:
            dist = float(np.linalg.norm(_target_enu(b.y, target)))
            b.add(2.0 * dist / speed_mps + 10.0, event=passed)
        if duration_s is not None and b.t >= duration_s:
            break
    return b.build(rate_hz, duration_s)


def flight(waypoints_deg, alt_m=None, speed_mps=200.0, rate_hz=100.0, duration_s=None, **kwargs):
    """The :class:`Trajectory` of :func:`plan_flight` (same parameters), every sample held."""
    return plan_flight(waypoints_deg, alt_m, speed_mps, rate_hz, duration_s, **kwargs).trajectory()


def _turn_towards(b, target_ecef, turn_max, roll_in_s):
    """Append a coordinated turn that leaves the vehicle heading for the target."""
    start = (list(b.pieces), b.y.copy(), b.t, b.turn)
    d = _target_enu(b.y, target_ecef)
    angle = _wrap(math.atan2(d[0], d[1]) - b.y[3])
    for _ in range(4):  # the exit point moves with the angle: iterate the aim
        b.pieces, b.y, b.t, b.turn = list(start[0]), start[1].copy(), start[2], start[3]
        if abs(angle) < 1e-12:
            return
        rate = math.copysign(turn_max, angle)
        hold = abs(angle) / turn_max - roll_in_s
        if hold < 0:
            rate, hold = angle / roll_in_s, 0.0
        b.add(roll_in_s, turn=rate)
        if hold > 0:
            b.add(hold)
        b.add(roll_in_s, turn=0.0)
        d = _target_enu(b.y, target_ecef)
        err = _wrap(math.atan2(d[0], d[1]) - b.y[3])
        if abs(err) < 1e-9:
            return
        angle += err


def xian_baoji(rate_hz=100.0):
    """[Shen 2024]'s flight: Xi'an to Baoji at 3 km and 200 m/s for 782 s (section 4.1)."""
    return flight([XIAN_DEG, BAOJI_DEG], alt_m=3000.0, speed_mps=200.0, rate_hz=rate_hz, duration_s=782.0)
