"""The simulated calibration bench: a rate table with an IMU on it.

Composes :mod:`sim_devices.world` (table state -> true specific force and
inertial rate in case axes) and :class:`sim_devices.truth.Truth` (those ->
raw sensor outputs).  See docs/simulation.md for the conventions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from . import world
from .chamber import ChamberAir
from .truth import Truth
from .world import ARCSEC, G_STANDARD, Site


@dataclass
class SimSegment:
    """One recorded segment.

    kind   "static" | "rotation"
    t      (N,) the IMU's time stamps, s, continuing across segments (gaps for moves); the
           sample stamped t was taken at table time t + bench.time_offset_s (with
           bench.time_stamp_jitter_ms the stamps scatter about that regular grid, the
           samples do not)
    accel  (N,3) raw accelerometer output (m/s^2 nominal)
    gyro   (N,3) raw gyro output (deg/s nominal)
    temp   (N,) IMU temperature, deg C
    meta   what the bench reports: static {"up_body"}; rotation
           {"axis_body", "rate_dps", "angle_deg" (encoder, over the window
           [t0 - dt/2, t_{N-1} + dt/2] of table time computed from the stamps)}
    truth  hidden true values, for tests and diagnostics only -- an
           estimator must not use them.
    """

    kind: str
    t: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    temp: np.ndarray
    meta: dict
    truth: dict = field(default_factory=dict, repr=False)


class SimulatedBench:
    """A rate table at a site, with the IMU described by ``truth`` mounted on it.

    All randomness derives from ``seed``: three independent streams (from
    ``numpy.random.SeedSequence(seed).spawn(3)``) for the geometry (headings,
    roll, mounting/table angle errors, ripple phase), the encoder errors and
    the sensor/disturbance noise, so that changing noise settings does not
    change the attitudes.
    """

    def __init__(self, truth: Truth, seed: int, start_s: float = 0.0):
        """``start_s``: device time (s) at which the bench's clock starts, the end of an earlier
        run on it (a run continued later: the warm-up, drifts and steps go on from there)."""
        self.truth = truth
        self.seed = seed
        ss = np.random.SeedSequence(seed)
        self._geom_rng, self._enc_rng, self._noise_rng = (
            np.random.default_rng(s) for s in ss.spawn(3))
        # further streams (spawned after the first three, which stay as they were): remount
        # errors and time-stamp jitter, so switching them on changes no other draw
        self._remount_rng, self._jitter_rng = (np.random.default_rng(s) for s in ss.spawn(2))
        self.site = Site(truth.bench.latitude_deg, truth.bench.height_m)
        self._g = self.site.g
        self._time_end = float(start_s)   # end of the last segment's window
        self._rotation_starts: dict = {}
        # the platter's state (issue 28): the IMU is mounted on the platter, the imbalance (and a
        # bearing's eccentricity, vibration_*; the wobble) is fixed to it, so the angle between the
        # two is fixed while the IMU stays mounted.  Per rotation key, where the table left that axis
        # (the IMU's attitude and the platter's angle from the imbalance's zero at the end of the last
        # rotation about it): platter_state / restore_platter carry it into a later session with the
        # IMU still mounted, which starts there; remount forgets it
        self._platter_left: dict = {}
        # the temperature chamber around the table (sim_devices/chamber.py): its air at the room's
        # temperature until a setpoint is given (set_chamber)
        self.chamber = ChamberAir(truth.temperature.start_c)

    # ------------------------------------------------------------ properties
    @property
    def sample_rate_hz(self) -> float:
        return float(self.truth.sample_rate_hz)

    @property
    def gravity_mps2(self) -> float:
        """Local gravity magnitude at the site (what the site knows), m/s^2."""
        return self._g

    @property
    def latitude_deg(self) -> float:
        return float(self.truth.bench.latitude_deg)

    @property
    def height_m(self) -> float:
        return float(self.truth.bench.height_m)

    @property
    def time_s(self) -> float:
        """Device time at the end of the last segment."""
        return self._time_end

    # -------------------------------------------------------------- chamber
    def set_chamber(self, setpoint_c: float, ramp_c_per_min: float) -> None:
        """The chamber is set to ``setpoint_c`` now (at the end of the last segment); its air
        ramps there at ``ramp_c_per_min``."""
        self.chamber.set(self._time_end, setpoint_c, ramp_c_per_min)

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` of bench time pass with nothing recorded (a chamber's ramp and soak)."""
        self._time_end += max(0.0, float(seconds))

    def imu_temperature(self, t) -> np.ndarray:
        """The IMU's temperature (degC) at table times ``t``, as its temperature channel reports it."""
        return self.truth.temperature.at(t, self.chamber)

    # -------------------------------------------------------------- helpers
    def _n_samples(self, duration_s: float) -> int:
        d = float(duration_s)
        if not math.isfinite(d) or d <= 0.0:
            raise ValueError(f"duration_s must be positive, got {duration_s!r}")
        n = int(round(d * self.sample_rate_hz))
        if n < 1:
            raise ValueError(f"duration_s={duration_s} gives no sample at {self.sample_rate_hz} Hz")
        return n

    def _times(self, n: int) -> np.ndarray:
        """IMU time stamps of the next segment, after the move and settling gap."""
        dt = 1.0 / self.sample_rate_hz
        t0 = self._time_end + self.truth.bench.move_s + self.truth.bench.settle_s + 0.5 * dt
        t = t0 + dt * np.arange(n)
        self._time_end = float(t[-1] + 0.5 * dt)
        return t

    def _mount_error(self) -> np.ndarray:
        """Random small rotation vector, rad, sigma per axis = table angle error."""
        return self._geom_rng.normal(0.0, self.truth.bench.table_angle_error_arcsec, 3) * ARCSEC

    def _remount_error(self) -> np.ndarray:
        """Placement error of a segment, rad (zero unless bench.remount_error_arcsec)."""
        sigma = self.truth.bench.remount_error_arcsec
        if sigma <= 0.0:
            return np.zeros(3)
        return self._remount_rng.normal(0.0, sigma, 3) * ARCSEC

    def _stamps(self, t: np.ndarray) -> np.ndarray:
        """The IMU's time stamps of samples taken at the nominal times ``t``: t plus white
        jitter of sigma bench.time_stamp_jitter_ms (the same array when there is none)."""
        sigma = self.truth.bench.time_stamp_jitter_ms * 1e-3
        if sigma <= 0.0:
            return t
        return t + self._jitter_rng.normal(0.0, sigma, len(t))

    def _measure(self, t, f_b, w_ib_rad, w_eb_b=None, wdot_eb_b=None):
        """Raw outputs of samples taken at table times ``t`` (temperature evaluated there)."""
        f_b = world.perturb_specific_force(
            f_b, self.truth.bench.accel_disturbance_ug * world.MICRO_G, self._noise_rng)
        temp = self.truth.temperature.at(t, self.chamber)
        accel, gyro = self.truth.measure(f_b, np.degrees(w_ib_rad), temp, self._noise_rng,
                                         w_eb_b=w_eb_b, wdot_eb_b=wdot_eb_b, t=t, air=self.chamber)
        return accel, gyro, temp

    # ------------------------------------------------------- platter (state)
    def platter_state(self) -> list:
        """Where the table left each rotation key (the IMU still mounted), for a later session
        (restore_platter): the IMU's attitude at the last rotation's end (quaternion x, y, z, w, case
        from ENU, its placement error included), the table axis (ENU), its heading, the placement
        error (rad) and the platter's angle (rad) from where the imbalance's phase counts."""
        out = []
        for k, (C, a_n, heading, delta, platter) in self._platter_left.items():
            out.append({"axis_body": [float(x) for x in k[0]],
                        "start_up_body": None if k[1] is None else [float(x) for x in k[1]],
                        "axis_elevation_deg": float(k[2]), "attitude_quat": [float(x) for x in C.as_quat()],
                        "axis_enu": [float(x) for x in a_n], "heading_rad": float(heading),
                        "placement_error_rad": [float(x) for x in delta], "platter_rad": float(platter)})
        return out

    def restore_platter(self, state) -> None:
        """A later session on the same table with the IMU still mounted (platter_state of the
        earlier one): a rotation about a key turned before starts where the table left it -- the
        IMU's attitude and the platter's angle (the imbalance where it was against the IMU)."""
        for d in state or ():
            hint = d.get("start_up_body")
            key = (tuple(np.round(np.asarray(d["axis_body"], float), 12)),
                   None if hint is None else tuple(np.round(np.asarray(hint, float), 12)),
                   float(d["axis_elevation_deg"]))
            left = (Rotation.from_quat(d["attitude_quat"]), np.asarray(d["axis_enu"], dtype=float),
                    float(d["heading_rad"]), np.asarray(d["placement_error_rad"], dtype=float), float(d["platter_rad"]))
            # a state the table cannot be in (a user's file): refused here, not a crash or an impossible
            # twin later -- finite 3-vectors, a unit table axis that the attitude turns onto the key's
            # case axis (to within 1 deg: placement and remount errors are arcseconds to arcminutes)
            for name, v in (("axis_enu", left[1]), ("placement_error_rad", left[3])):
                if v.shape != (3,) or not np.all(np.isfinite(v)):
                    raise ValueError(f"{name} must be 3 finite numbers, got {v.tolist()!r}")
            if not (math.isfinite(left[2]) and math.isfinite(left[4])):
                raise ValueError("heading_rad and platter_rad must be finite")
            if abs(float(np.linalg.norm(left[1])) - 1.0) > 1e-6:
                raise ValueError(f"axis_enu must be a unit vector, got {left[1].tolist()!r}")
            if float(np.dot(left[0].apply(left[1]), world._unit(key[0], "axis_body"))) < math.cos(math.radians(1.0)):
                raise ValueError("attitude_quat does not turn axis_enu onto axis_body")
            self._platter_left[key] = left
            self._rotation_starts[key] = left

    def remount(self) -> None:
        """The IMU taken off the platter and put back: every rotation key's start is drawn anew (its
        roll on the platter, its placement), the platter's zero where it then starts."""
        self._platter_left.clear()
        self._rotation_starts.clear()

    # -------------------------------------------------------------- segments
    def static(self, up_body, duration_s) -> SimSegment:
        """Hold the IMU with case direction ``up_body`` up for ``duration_s``."""
        up = world._unit(up_body, "up_body")
        n = self._n_samples(duration_s)
        heading = self._geom_rng.uniform(0.0, 2.0 * np.pi)
        delta = self._mount_error()
        remount = self._remount_error()
        C_bn = world.small_rotation(delta + remount) * world.attitude_up(up, heading)
        t = self._times(n)
        f_b, w_ib = world.static_kinematics(C_bn, n, self.site)
        f_true, w_true = f_b[0].copy(), w_ib[0].copy()
        accel, gyro, temp = self._measure(t + self.truth.bench.time_offset_s, f_b, w_ib)
        return SimSegment(
            kind="static", t=self._stamps(t), accel=accel, gyro=gyro, temp=temp,
            meta={"up_body": [float(x) for x in up]},
            truth={
                "C_bn": C_bn.as_matrix(),
                "heading_deg": math.degrees(heading),
                "attitude_error_rad": delta + remount,
                "remount_error_rad": remount,
                "up_body_true": C_bn.apply([0.0, 0.0, 1.0]),
                "f_b": f_true,
                "w_ib_dps": np.degrees(w_true),
            },
        )

    def rotation(self, axis_body, rate_dps, duration_s, *, start_up_body=None,
                 axis_elevation_deg: float = 0.0, drift_fraction: float = 0.0,
                 encoder: bool = True, record_ramp: str | None = None,
                 ramp_accel_dps2: float = 50.0, ramp_rest_s: float = 0.5) -> SimSegment:
        """Spin the IMU about case direction ``axis_body`` at ``rate_dps``.

        The table axis is Earth-fixed, ``axis_elevation_deg`` above the horizontal (0: a
        horizontal axis, the default; 90: a vertical axis pointing up).  The start attitude (at
        the first sample) is remembered per (axis_body, start_up_body, elevation), so the
        second call of a +/- pair starts from the same attitude.  ``drift_fraction`` changes
        the rate linearly by that fraction over the segment (-0.2: 20 % slower at the end, as a
        screwdriver); ``encoder=False`` reports no angle (a hand or screwdriver rotation).
        ``record_ramp`` "start": the recording opens with the table at rest for ``ramp_rest_s``
        (table time), then the table ramps up at ``ramp_accel_dps2`` and turns ``duration_s`` at the
        rate; "end": ``duration_s`` at the rate, then the brake at ``ramp_accel_dps2`` and
        ``ramp_rest_s`` at rest (world.ramp_profile); the rates at the window's edges are reported
        (``rate_start_dps``, ``rate_end_dps``, as the table's own rate read at those table times, through
        its encoder).
        """
        a_cmd = world._unit(axis_body, "axis_body")
        r = float(rate_dps)
        if not math.isfinite(r) or r == 0.0:
            raise ValueError(f"rate_dps must be non-zero and finite, got {rate_dps!r}")
        up_hint = None if start_up_body is None else world._unit(start_up_body, "start_up_body")
        key = (tuple(np.round(a_cmd, 12)),
               None if up_hint is None else tuple(np.round(up_hint, 12)), float(axis_elevation_deg))
        start = self._rotation_starts.get(key)
        if start is None:
            heading = self._geom_rng.uniform(0.0, 2.0 * np.pi)
            roll = self._geom_rng.uniform(0.0, 2.0 * np.pi)
            delta = self._mount_error()
            if self.truth.bench.remount_axes:
                # taken off and put back once for this axis: every rotation about it (both
                # directions) shares the placement
                delta = delta + self._remount_error()
            a_n = world.table_axis_enu(heading, math.radians(axis_elevation_deg))
            C_bn0 = world.small_rotation(delta) * world.attitude_axis(
                a_cmd, a_n, up_body=up_hint, roll_rad=roll)
            # the platter's angle at the start, from where the imbalance's phase counts: 0 at the
            # first start (a restored key starts where the table left it, restore_platter)
            start = (C_bn0, a_n, heading, delta, 0.0)
            self._rotation_starts[key] = start
        C_bn0, a_n, heading, delta, platter0 = start
        remount = np.zeros(3)
        if self.truth.bench.remount_rotations:
            # taken off the table and put back before every rotation segment, each half of a
            # +/- pair included: the remembered start attitude, turned by a fresh placement error
            remount = self._remount_error()
            C_bn0 = world.small_rotation(remount) * C_bn0

        ramp_s = abs(r) / float(ramp_accel_dps2) if record_ramp else 0.0
        n = self._n_samples(duration_s + (ramp_s + ramp_rest_s if record_ramp else 0.0))
        fs = self.sample_rate_hz
        dt = 1.0 / fs
        bench = self.truth.bench
        phase = self._geom_rng.uniform(0.0, 2.0 * np.pi)
        t = self._times(n)                      # nominal sample times (the stamps without jitter)
        tau = t + bench.time_offset_s           # table time at which each sample was taken
        w_rad = math.radians(r)
        duration = n * dt
        # the profile is defined in table time, theta = 0 at table time t[0]
        if record_ramp:
            window0 = t[0] - 0.5 * dt           # the window's start in table time, nominally
            ramp_at = window0 + (ramp_rest_s if record_ramp == "start" else float(duration_s))
            prof = dict(t0=t[0], rate_rad_s=w_rad, accel_rad_s2=math.radians(float(ramp_accel_dps2)),
                        ramp=record_ramp, ramp_at=ramp_at)
            profile = world.ramp_profile
        else:
            prof = dict(t0=t[0], rate_rad_s=w_rad, ripple_fraction=bench.rate_ripple_fraction,
                        ripple_hz=bench.rate_ripple_hz, ripple_phase_rad=phase,
                        drift_per_s=float(drift_fraction) / duration)
            profile = world.rate_profile
        theta, theta_dot, theta_ddot = profile(tau, **prof)
        wobble_rad = bench.wobble_arcsec * ARCSEC
        wobble_phase = math.radians(bench.wobble_phase_deg) + platter0     # turning with the platter
        if wobble_rad > 0.0:
            C_bn, w_b, wdot_b = world.wobbling_table(C_bn0, a_n, theta, theta_dot, theta_ddot,
                                                     wobble_rad, wobble_phase, harmonic=1)
        else:
            C_bn = world.table_attitude(C_bn0, a_n, theta)
            w_b, wdot_b = world.table_rates_body(C_bn0, a_n, theta_dot, theta_ddot)
        # the sensing point from the line this rotation turns about: the table axis that turns the
        # IMU about case axis k (the nearest to axis_body) is axis_offsets_m[k] further away
        lever = bench.lever_arm_m + bench.axis_offsets_m[int(np.argmax(np.abs(a_cmd)))]
        f_b, w_ib = world.body_kinematics(C_bn, w_b, wdot_b, lever, self.site)
        # the vibration's and the imbalance's phase: fixed to the platter, which starts at platter0
        vibration_phase = math.radians(bench.vibration_phase_deg) + platter0
        # the base's once-per-revolution vibration, from the table's angle, rate and angular
        # acceleration (zero at rest, ~ rate^2 at a steady rate; world.table_vibration_enu and
        # world.imbalance_acceleration_enu)
        if np.any(bench.vibration_mg):
            a_vib = world.table_vibration_enu(a_n, theta, theta_dot, theta_ddot,
                                              bench.vibration_mg * 1e-3 * G_STANDARD,
                                              math.radians(bench.vibration_ref_rate_dps), vibration_phase)
            f_b = f_b + np.atleast_2d(C_bn.apply(a_vib))
        if bench.imbalance_g_mm:
            a_imb = world.imbalance_acceleration_enu(a_n, theta, theta_dot, theta_ddot, bench.imbalance_g_mm * 1e-6,
                                                     bench.base_mass_kg, math.radians(bench.imbalance_phase_deg) + platter0)
            f_b = f_b + np.atleast_2d(C_bn.apply(a_imb))
        stamps = self._stamps(t)

        # encoder: true swept angle over the table-time window [t0 - dt/2, t_{N-1} + dt/2] that
        # the station computes from the IMU stamps, plus error
        edges, edge_rates, _ = profile(np.array([stamps[0] - 0.5 * dt, stamps[-1] + 0.5 * dt]), **prof)
        swept_deg = math.degrees(edges[1] - edges[0])
        # where the table leaves this axis: the window's end (the IMU's attitude and the platter's
        # angle there, the next session's start when the IMU stays mounted: restore_platter)
        theta_end = float(edges[1])
        self._platter_left[key] = (world.table_attitude(start[0], a_n, np.array([theta_end]))[0], a_n, heading, delta,
                                   math.remainder(platter0 + theta_end, 2.0 * math.pi))
        enc_err_arcsec = float(self._enc_rng.normal(0.0, bench.table_angle_error_arcsec))
        # an encoder scale error: the table turned (1 + e) times what the encoder reads
        k_axis = int(np.argmax(np.abs(a_cmd)))          # the table axis that turns it (table_axes 3)
        e_ppm = bench.encoder_scale_error_ppm + (bench.encoder_scale_error_per_axis_ppm[k_axis]
                                                 if bench.table_axes == 3 else 0.0)
        angle_deg = swept_deg / (1.0 + 1e-6 * e_ppm) + enc_err_arcsec / 3600.0

        accel, gyro, temp = self._measure(tau, f_b, w_ib, w_b, wdot_b)
        meta = {"axis_body": [float(x) for x in a_cmd], "rate_dps": r}
        if encoder:
            meta["angle_deg"] = angle_deg
        if bench.table_axes == 3:
            meta["table_axis"] = k_axis + 1
        if record_ramp:
            # the table's own rate read at the window's edges: it knows its angle only from its
            # encoder, so it reads the true rate over (1 + e) as it reads the angle (the true
            # rate reported here hid an encoder scale error from a recorded ramp's phase: issue 28)
            meta.update(record_ramp=record_ramp, ramp_accel_dps2=float(ramp_accel_dps2),
                        rate_start_dps=math.degrees(float(edge_rates[0])) / (1.0 + 1e-6 * e_ppm),
                        rate_end_dps=math.degrees(float(edge_rates[1])) / (1.0 + 1e-6 * e_ppm))
        return SimSegment(
            kind="rotation", t=stamps, accel=accel, gyro=gyro, temp=temp, meta=meta,
            truth={
                "C_bn0": C_bn0.as_matrix(),
                "axis_enu": a_n,
                "heading_deg": math.degrees(heading),
                "attitude_error_rad": delta,
                "remount_error_rad": remount,
                "lever_arm_m": lever,
                "axis_body_true": C_bn0.apply(a_n),
                "swept_angle_deg": swept_deg,
                "encoder_error_arcsec": enc_err_arcsec,
                "ripple_phase_rad": phase,
                "window_s": (float(stamps[0] - 0.5 * dt), float(stamps[-1] + 0.5 * dt)),
                "nominal_t": t,
                "time_offset_s": float(bench.time_offset_s),
                "wobble_rad": wobble_rad,
                "wobble_direction_enu": world.wobble_direction_enu(a_n, wobble_phase),
                "vibration_phase_rad": vibration_phase,
                "platter_start_rad": platter0,
            },
        )
