"""One measurement model for every segment kind, fitted by weighted nonlinear least squares.

Model (frame p of the accelerometers, see station/model/calibration.py):
  accel_raw = K_a T_a f_p + b_a (+ effects)      gyro_raw = K_g T_g R_po w_p + b_g (+ effects)
Static segment j (attitude C_pn,j unknown: a nuisance):
  f_p = C_pn [0, 0, g],   w_p = C_pn Omega_E,n          (Omega_E,n from the site latitude)
Rotation segment s about table axis l (unit, in p; one per physical axis, a nuisance), encoder
angle A over the window T, phase phi from 0 to A:
  f_p(phi) = kappa l + cos(phi) v - sin(phi) (l x v) + w x (w x d)     v = g sin(alpha) (cos psi e1 + sin psi e2)
(its mean, first and second harmonics are compared with the data's)
  w_p      = (A/T + e) l                                               (e: Earth rate along the axis)
kappa = g cos(alpha) (gravity along the axis: alpha, the axis' angle from up, so that gravity
across it, g sin(alpha), never reaches a square root's edge), e and the mounting offset d from
the rotation centre are nuisances of the bench; psi (where gravity is at the start) is one per
segment, and so is chi, where the Earth rate across the axis is at the start, over a part turn.
(e is not bounded by Omega_E as alpha bounds kappa: a turn whose encoder angle is off then
shows it as e with its prior, and the fit converges to a failing chi2 rather than stalling at
the bound.)
Hand rotation h of unknown angle from static j to static k (no encoder; station/estimate/
hand_rotation.py): the up of static j carried through the turn integrated from the compensated
gyro samples must be the up of static k (two residuals per turn); the statics' gyro means then
give the gyro bias, with the Earth rate modelled when the latitude is known and as noise when not.
The data are the segment summaries (station/estimate/summaries.py), each divided by its noise;
the encoder's angle error enters the gyro integrals' covariance.  The solution starts from the
2010 algebraic one; the covariance is (J^T J)^-1 at the solution.
The residual is computed for all segments (and for a batch of parameter vectors) in one
vectorised pass; the Jacobian is taken by complex step (exact to rounding) in one batch, with the
hand turns to first order about the point, or by forward differences when an effect is not
complex-step safe (docs/method-lsq.md, "How the fit is computed").
"""
from __future__ import annotations

import copy
import dataclasses
import itertools
import warnings
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from station.core import units
from station.model.calibration import Calibration, misalignment_angles
from station.core.errors import UserError
from station.estimate import arrays, hand_rotation, noise_model, solver, table_geometry, zhang2010
from station.estimate.summaries import Summaries, summarise
from station.model.geometry import cross, normalised, positive_part, tangent_basis
from station.model.effect import Effect, SampleContext
from station.model.rotation import align_vectors, matrix_from_rotvec, rotvec_from_matrix
from station.model.table_encoder_scale import turned_time

EARTH_RATE_RAD = 7.292115e-5
WEAK_PRIOR_RAD = 3.0             # a prior on nuisance angles that only matters when nothing else does
WOUND_RAD = 1.5 * np.pi          # a static's rotation vector longer than this is wound (Model.canonical)
PHASES = 12                      # phase grid for the harmonics of a rotation (exact to 5th order)
UP = np.array([0.0, 0.0, 1.0])
# zero-mean priors (internal units) on the gyro block when no rotation has a known angle
NO_ROTATION_PRIORS = {"gyro_scale": 1e3, "gyro_misalignment": 1e3, "gyro_bias": 1e6, "inter_triad": 1e3}
BATCH_VALUES = 1_000_000         # residuals (rows x perturbed vectors) in one batch of a Jacobian (~0.15 GB of temporaries)
LARGE_MODEL = 300                # parameters above which the fit works on a sparse Jacobian (Model.is_large)
COMPLEX_STEP = 1e-20             # the Jacobian's imaginary step, relative to each parameter's size
FORWARD_STEP = 1e-7              # the forward-difference step (effects that are not complex-step safe)

# Parameters of the base model: name, internal -> reported scale, reported unit
GLOBAL = [("accel_scale", 1.0, "1"), ("accel_misalignment", 1 / units.ARCSEC_RAD, "arcsec"),
          ("accel_bias", 1 / units.UG_MPS2, "ug"), ("gyro_scale", 1.0, "1"),
          ("gyro_misalignment", 1 / units.ARCSEC_RAD, "arcsec"), ("gyro_bias", 3600.0, "deg/h"),
          ("inter_triad", 1 / units.ARCSEC_RAD, "arcsec")]
SUFFIX = {"accel_misalignment": ("yz", "zy", "zx"), "gyro_misalignment": ("yz", "zy", "zx")}


def lower_unit_rows(angles: np.ndarray) -> np.ndarray:
    """Sensing directions from the misalignment angles (yz, zy, zx), exact (paper eq. 3)."""
    s_yz, s_zy, s_zx = np.sin(angles[0]), -np.sin(angles[1]), np.sin(angles[2])
    return np.array([[1.0, 0.0, 0.0],
                     [s_yz, np.sqrt(1.0 - s_yz**2), 0.0],
                     [s_zy, s_zx, np.sqrt(max(1.0 - s_zy**2 - s_zx**2, 0.0))]])


class Layout:
    """Named slices of the parameter vector."""

    def __init__(self):
        self.blocks: dict[str, slice] = {}
        self.size = 0

    def add(self, name: str, n: int) -> slice:
        self.blocks[name] = slice(self.size, self.size + n)
        self.size += n
        return self.blocks[name]

    def __getitem__(self, name: str) -> slice:
        return self.blocks[name]


@dataclass
class Start:
    """Initial values: the algebraic solution and the bench nuisances derived from it."""
    ka: np.ndarray
    alpha: np.ndarray
    ba: np.ndarray
    kg: np.ndarray
    gamma: np.ndarray
    bg: np.ndarray
    theta: np.ndarray
    notes: list = field(default_factory=list)


def _align_vectors(a, b, weights=None) -> np.ndarray:
    """Rotation.align_vectors(a, b)'s rotation matrix (station.model.rotation: no scipy import),
    with no warning when it is not uniquely defined (degenerate vectors: the fit's
    identifiability then says so, in words)."""
    return align_vectors(a, b, weights)


def _start(s: Summaries) -> Start:
    means_a = np.array([st.accel for st in s.statics])
    means_w = np.array([st.gyro for st in s.statics])
    try:
        L_a, b_a = zhang2010.fit_accelerometers(means_a, s.gravity_mps2)
    except UserError:       # too few attitudes for the ellipsoid: nominal accelerometers
        L_a, b_a = np.eye(3), np.zeros(3)
    pairs = _pairs(s)
    notes = []
    try:
        for p in pairs:
            p.phi = p.integral_plus - p.integral_minus
        L_g = _fit_gyro_matrix(pairs, s, notes)
        b_g = zhang2010.fit_gyro_bias(L_g, means_w)
    except UserError:
        L_g, b_g = np.eye(3), means_w.mean(axis=0)
        if s.hand_rotations:        # the turns between statics, with the accelerometers' ups
            ups = (means_a - b_a) @ L_a.T
            ups /= np.linalg.norm(ups, axis=1)[:, None]
            nominal = s.gyro_nominal if s.gyro_raw else 1.0     # raw without a nominal: None
            scale = hand_rotation.start_scale(hand_rotation.Integrator(s.hand_rotations), b_g, ups, nominal)
            L_g = np.eye(3) / scale
            notes.append(f"gyro started from the hand rotations: scale {scale:.6g} (a 1-D search)")
    # inter-triad start: each rotation axis seen by the gyros and, through the plane in which
    # gravity turns (the first harmonic), by the accelerometers (eqs. 41 and 44-47)
    axes_o, axes_p = [], []
    for r in s.rotations:
        l_o = L_g @ (r.gyro_integral - b_g * r.duration_s) * np.sign(r.angle_deg)
        l_p = -np.cross(L_a @ r.accel_cos, L_a @ r.accel_sin)
        if np.linalg.norm(l_p) > 0.1 * s.gravity_mps2**2 and np.linalg.norm(l_o) > 0:
            axes_o.append(l_o / np.linalg.norm(l_o))
            axes_p.append(l_p / np.linalg.norm(l_p))
    if len(axes_o) >= 2 and _one_line(axes_p):
        # every usable axis on one line (a design's turns about one axis across gravity, the
        # others near the vertical): the rotation about it is not seen; started at none (the
        # nominal mounting) instead of an arbitrary one (issue 28: 94 deg about z on the chamber
        # design of known attitudes, the fit stuck at reduced chi2 7e7)
        eye = list(np.eye(3))
        R_po = _align_vectors(np.array(axes_o + eye), np.array(axes_p + eye),
                              weights=[1.0] * len(axes_o) + [ONE_LINE_PRIOR] * 3)
        notes.append("inter-triad start: the rotation axes the accelerometers see lie on one line; "
                     "the rotation about it started at zero")
    elif len(axes_o) >= 2:
        R_po = _align_vectors(np.array(axes_o), np.array(axes_p))
    else:
        R_po = np.eye(3)
        notes.append("no algebraic start for the inter-triad rotation: started from zero")
    ka, Ta = zhang2010.scale_and_T(L_a)
    kg, Tg = zhang2010.scale_and_T(L_g)
    return Start(ka, misalignment_angles(Ta), b_a, kg, misalignment_angles(Tg), b_g,
                 rotvec_from_matrix(R_po), notes)


#: the largest relative error of the gyro matrix's start along a direction the rotation pairs
#: determine (_fit_gyro_matrix): beyond, the direction is started nominal.  LM recovers from a
#: start 1e-3 off in a few evaluations (the twin captures' starts are that far from the minimum)
GYRO_START_TOLERANCE = 1e-3


def _fit_gyro_matrix(pairs: list, s: Summaries, notes: list) -> np.ndarray:
    """zhang2010.fit_gyro_matrix (|L_g phi_j| = the swept angle of pair j: M = L_g^T L_g, linear in
    its six entries), where the pairs' axes determine M; else M from the directions they do
    determine and nominal (isotropic, at the pairs' mean scale) along the others.

    A design whose rotations all lie in one plane (the designer's chamber scheme with the
    temperature coefficients as its criterion: axes x and x +/- z only) leaves M's y-y entry
    to the y-components of the axes, ~1e-3 (the misalignments): fitted, it came out at 570
    times its size (gyro scale y 0.0018 at the start), the gyro bias and the inter-triad start
    (0.72 rad) with it, and LM stopped at its limit of 1000 evaluations at a reduced chi2 of
    1936 (issue 28, seed 1018).  Each pair's noise relative to its swept angle (gyro white noise
    over both turns and two encoder angles) moves M along a singular direction of the design D
    (rows 2-u-squared terms, ~2 |u| per unit of u) by ~2 sqrt(N) noise / s_i: a direction is fitted
    where that is below GYRO_START_TOLERANCE, else left at the nominal (the truncated least
    squares about it).  Where every direction is fitted (optimal9: s_min / s_max ~ 0.3, the
    threshold ~1e-5 of it) the start is zhang2010's, bit for bit."""
    if len(pairs) < 6:
        return zhang2010.fit_gyro_matrix(pairs)         # (says why it cannot)
    u = np.array([p.phi / p.swept_deg for p in pairs])
    x, y, z = u.T
    D = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z])
    white = float(np.max(s.gyro_sigma)) ** 2 / s.sample_rate_hz
    noise = max(np.sqrt(white * (p.duration_plus_s + p.duration_minus_s) + 2 * s.table_angle_sigma_deg**2)
                / abs(p.swept_deg) for p in pairs)
    sv = np.linalg.svd(D, compute_uv=False)
    least = 2.0 * np.sqrt(len(pairs)) * noise / GYRO_START_TOLERANCE
    if sv[-1] >= least:
        return zhang2010.fit_gyro_matrix(pairs)
    level = float(np.median(1.0 / np.sum(u * u, axis=1)))       # |L_g u| = 1: M ~ level I
    nominal = np.array([level, level, level, 0.0, 0.0, 0.0])
    m = nominal + np.linalg.lstsq(D, 1.0 - D @ nominal, rcond=least / sv[0])[0]
    notes.append(f"gyro start: {int(np.sum(sv < least))} of the gyro matrix's 6 directions not seen by the "
                 "rotation pairs' axes, started nominal")
    return zhang2010.lower_factor(np.array([[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]]))


#: the inter-triad start's axes lie on one line when the second singular value of the unit axes
#: (stacked, N x 3) is below ONE_LINE of the first (all within ~3 deg of one line: sin 3 deg =
#: 0.05); then identity pairs of weight ONE_LINE_PRIOR (far below the axes' 1 each) fix the
#: rotation about that line at zero and move the rest by ~1e-6 rad
ONE_LINE = 0.05
ONE_LINE_PRIOR = 1e-6


def _one_line(axes: list) -> bool:
    """Whether the unit axes all lie within ~ONE_LINE rad of one line (either sign)."""
    sv = np.linalg.svd(np.array(axes), compute_uv=False)
    return bool(sv[1] < ONE_LINE * sv[0])


def _start_gyro_matrix(st: Start) -> np.ndarray:
    """M_g = K_g T_g R_po of a start."""
    return np.diag(st.kg) @ lower_unit_rows(st.gamma) @ matrix_from_rotvec(st.theta)


def _pairs(s: Summaries) -> list:
    """Rotation summaries of the same axis with opposite angles, as the algebraic solver wants."""
    out = []
    for g in range(s.groups):
        segs = [r for r in s.rotations if r.group == g]
        plus = [r for r in segs if r.angle_deg > 0]
        minus = [r for r in segs if r.angle_deg < 0]
        for p, m in zip(plus, minus):
            out.append(zhang2010.RotationPair(
                name=f"{p.name}/{m.name}", axis_body=p.axis_body, phi=None,
                swept_deg=p.angle_deg - m.angle_deg, duration_diff_s=p.duration_s - m.duration_s,
                integral_plus=p.gyro_integral, integral_minus=m.gyro_integral,
                duration_plus_s=p.duration_s, duration_minus_s=m.duration_s, accel=None))
    return out


def _earth_rate_visible(r, s: Summaries) -> bool:
    """Whether the Earth rate across the axis leaves a trace in this rotation's gyro integral:
    over a uniform turn it integrates to zero over whole turns, and to at most 2 Omega T / A over
    the rest of one (a recorded ramp: Omega times its own phase's weights);
    below three times the integral's noise it is not modelled (its start angle would be an
    unobservable nuisance).

    About an axis turned one way only it must also stand out from a tilt of the axis: the
    integral across the axis is (rate + e) T times the tilt plus the Earth rate's, and with no
    turn the other way (whose rate T has the other sign) only the accelerometers see the tilt,
    to about sqrt 2 sigma_a / (g sqrt n).  Over a short fast turn the Earth rate's part, at most
    2 Omega T / A / A as a tilt, is a small fraction of that (300 deg/s over 120 degrees: 0.08):
    modelled, its start angle chi and the Earth rate along the axis were set by the noise of the
    tilt, with |e| <= Omega binding or passed (errors of the calibration up to 40 sigma, reduced
    chi2 up to 31).  Not modelled, the tilt takes it: a misfit of the accelerometers below the
    tilt's 1-sigma."""
    A = np.radians(abs(r.angle_deg))
    weights = getattr(r, "earth_weights_s", None)
    if weights is not None:
        # a recorded ramp (record_ramp): the turn is not uniform, so whole turns do not average
        # the Earth rate out; its trace is Omega times the weights over the window's own phase
        # (summaries._ramp_keys): a 719.8 degree window ramped at 50 deg/s^2 left 0.0065 deg
        # against 2e-5 deg of noise, and with the whole-turns rule its fit failed (reduced chi2
        # 864-1546 over four seeds; the review of the fifteenth session)
        largest = np.degrees(EARTH_RATE_RAD) * float(np.hypot(*weights))
    else:
        turns = abs(r.angle_deg) / 360.0
        if abs(turns - round(turns)) < 1e-3:
            return False
        largest = 2.0 * np.degrees(EARTH_RATE_RAD) * r.duration_s / A
    noise = np.max(s.gyro_sigma) * np.sqrt(r.duration_s / s.sample_rate_hz)
    if not largest > 3.0 * noise:
        return False
    if _turned_one_way(r, s):
        tilt_sigma = np.sqrt(2.0) * np.max(s.accel_sigma) / (s.gravity_mps2 * np.sqrt(r.samples))
        return np.radians(largest) / A > tilt_sigma
    return True


def _turned_one_way(r, s: Summaries) -> bool:
    """Whether every steady turn about r's axis turns the same way as r."""
    return all(q.angle_deg * r.angle_deg > 0 for q in s.rotations if q.group == r.group and q.steady)


def _earth_factor(rots: list) -> np.ndarray:
    """The Earth rate's integral across each rotation's axis as a complex factor f of u, the Earth
    rate across the axis at the window's start (E = f u in the tangent plane, l x w as i w):
    T/A (sin A - i (1 - cos A)) over a uniform turn, w_c - i w_s over a recorded ramp (its
    ``earth_weights_s``, the residuals' _rot_earth).  The starts (_earth_phase_start,
    _other_crossing) took every window as uniform: over a ramp window (a 360 deg turn and its
    ramp, 100 deg/s, 50 deg/s^2) the "other crossing" so placed was no crossing at all (chi2
    1.85e5 above the minimum on the designer's table-attitude chunk), and each vertical axis' flip
    cost a whole fit back to the same minimum (issue 28: 26 axes, 1,523 evaluations)."""
    out = np.empty(len(rots), complex)
    for j, r in enumerate(rots):
        w = getattr(r, "earth_weights_s", None)
        if w is not None:
            out[j] = w[0] - 1j * w[1]
        else:
            A = np.radians(r.angle_deg)
            out[j] = r.duration_s / A * (np.sin(A) - 1j * (1.0 - np.cos(A)))
    return out


def _earth_angle_group(s: Summaries, k: int) -> bool:
    """Whether axis k's Earth rate may be parametrised by its angle beta from the axis (Model.
    _earth_along_across; Model._earth_phase_start chooses): turns about it both ways have an
    Earth-rate phase (the gyro integrals of the two directions then fix the axis' tilt, so the
    Earth rate across it is measured and |e| <= Omega matters).  Elsewhere e stays free: a turn
    whose encoder slipped by 0.5 % among whole ones reads it as e, beyond Omega, and the fit
    fails its chi2 (with beta it stalled at beta = 0, where e has no gradient: "not
    converged")."""
    visible = [r for r in s.rotations if r.group == k and r.steady and _earth_rate_visible(r, s)]
    return any(r.angle_deg > 0 for r in visible) and any(r.angle_deg < 0 for r in visible)


class Model:
    """The whitened residual function of the base model plus effects."""

    def __init__(self, s: Summaries, effects: list[Effect], attitudes: str = "auto",
                 start: Start | None = None, like: "Model | None" = None):
        """``start``: the algebraic start of these summaries when it is known (another Model's
        ``start``: a candidate effect's score test builds a model per candidate), else made here.
        ``like``: a model of the same summaries and attitudes with other effects, whose start
        (``start`` is then not used) and initial nuisances (static attitudes, rotation axes,
        whitening) are taken instead of computed again (they do not depend on the effects)."""
        if like is not None and like.s is not s:
            like = None                 # (of other summaries: nothing to take)
        if like is not None:
            start = like.start
        self.s, self.effects = s, effects
        self.noise = noise_model.of(s)
        self.turn_sigma_deg = like.turn_sigma_deg if like is not None else 0.0
        # the factor k^2 on the recorded ramps' stated placement variance (angle_sigma_deg^2):
        # 1 as stated; lsq.fit estimates it from their scatter where they are enough to say
        # (_ramp_reweight; a model taken ``like`` another starts from the stated 1-sigma again)
        self.ramp_k2 = 1.0
        # variance added to every pose mean (accel 3, gyro 3, summary units^2; its gyro part also
        # to the gyro integrals, times T^2): the noise model's terms, raised by lsq.fit where a
        # group is reweighted (noise_model: the bias moving between poses)
        self.pose_extra = (like.pose_extra if like is not None else self.noise.pose_variance()).copy()
        self.start = start if start is not None else _start(s)
        self.notes = list(self.start.notes)     # the start is shared: never appended to
        starts = [x.t_mid_s for x in (*s.statics, *s.rotations) if np.isfinite(x.t_mid_s)]
        self.t0 = min(starts) if starts else 0.0        # the run's start, for time-dependent terms
        for e in effects:
            e.setup(s)
        self.hands = list(s.hand_rotations)
        if attitudes == "auto":
            attitudes = "unknown" if len(s.statics) >= 9 else "table"
            if self.hands and all(st.up_body is not None for st in s.statics):
                # hand poses on a few faces, repeated: as many attitudes as distinct faces
                ups = {tuple(np.round(np.asarray(st.up_body, float), 3)) for st in s.statics}
                attitudes = "unknown" if len(ups) >= 9 else "table"
        if attitudes not in ("unknown", "table"):
            raise UserError(f"attitudes must be 'unknown' or 'table', not {attitudes!r}")
        self.attitudes = attitudes
        self.with_latitude = s.latitude_deg is not None
        self.hand_earth_vertical = False
        if self.hands and self.with_latitude and not hand_rotation.heading_visible(
                s, 1.0 if not s.gyro_raw else s.gyro_nominal or float(np.mean(np.abs(self.start.kg)))):
            # hand poses whose gyro cannot see the Earth turn: up only, the Earth rate's vertical
            # component modelled, its horizontal one (direction unknown) as noise
            self.with_latitude, self.hand_earth_vertical = False, True
        g, lat = s.gravity_mps2, np.radians(s.latitude_deg or 0.0)
        self.f_n = np.array([0.0, 0.0, g])
        self.omega_n = np.degrees(EARTH_RATE_RAD) * np.array([0.0, np.cos(lat), np.sin(lat)])
        self.omega_dps = np.degrees(EARTH_RATE_RAD)
        self.prior_sigma = np.radians(max(s.table_angle_sigma_deg, 1.0 / 3600.0))

        L = self.layout = Layout()
        for name, _, _ in GLOBAL:
            L.add(name, 3)
        if attitudes == "table":
            L.add("mounting_rotation", 3)
        for j in range(len(s.statics)):
            L.add(f"static{j}", 3 if self.with_latitude else 2)
        for k in range(s.groups):
            L.add(f"axis{k}", 4)           # axis tangent (2), alpha (from up), e
        for i in range(len(s.rotations)):
            # where gravity is at the start; and the Earth rate, unless the turns are whole
            r = self.s.rotations[i]
            L.add(f"phase{i}", 0 if not r.steady else 2 if _earth_rate_visible(r, s) else 1)
        # the axes whose fourth column is the Earth's axis' angle from the table axis, beta (the
        # Earth rate along the axis Omega cos beta, across it Omega sin beta) rather than e, the
        # rate along the axis, itself (_earth_along_across): of those turned both ways by part
        # turns, the ones whose e the start finds within reach of |e| = Omega (_earth_phase_start)
        self.earth_angle = np.zeros(s.groups, bool)
        # the mounting offset(s) from the table's rotation centre: one vector for every rotation
        # unless the capture's table geometry says otherwise (table_geometry.py)
        self.geometry = s.geometry if s.geometry is not None else table_geometry.unstated()
        self.offset_set, self.offset_axis = self.geometry.offset_sets(s.rotations)
        if s.rotations and s.mounting_offset_m is None:
            if self.offset_axis == [None]:
                L.add("mounting_offset", 3)
            else:           # per mounting, or across each axis (2: its part along the axis is not seen)
                for m, k in enumerate(self.offset_axis):
                    L.add(f"mounting_offset{m}", 3 if k is None else 2)
        # gravity along each axis from the table's recorded elevation of it (1-sigma level_sigma_rad)
        self.level_groups = ([k for k in range(s.groups) if k in self.geometry.elevation_deg
                              and any(r.steady for r in s.rotations if r.group == k)]
                             if self.geometry.level_sigma_rad else [])
        for e in effects:
            L.add(f"effect:{e.id}", len(e.params))
        # a calibration names its parameters (parameters, correlation, fit.not_determined): two of
        # one name cannot be told apart in it (a held one took a revealed namesake with it)
        owner = {f"{block}_{suffix}": "the base model" for block, _, _ in GLOBAL for suffix in SUFFIX.get(block, "xyz")}
        for e in effects:
            for p in e.params:
                if p.name in owner:
                    raise UserError(f"parameter {p.name!r}: of {owner[p.name]} and of effect {e.id!r} (a "
                                    "calibration names its parameters: one name cannot be two; rename one)")
                owner[p.name] = f"effect {e.id!r}"
        self.static_colour = hand_rotation.static_colours(len(s.statics), self.hands) if self.hands else None
        self.priors: dict[int, float] = {}     # column -> 1-sigma of a zero-mean prior
        self._initialise(like if like is not None and self._same_nuisances(like) else None)
        self._prepare()

    def _same_nuisances(self, other: "Model") -> bool:
        """Whether ``other`` has this model's summaries, start and parameters but the effects'."""
        mine = {k: v for k, v in self.layout.blocks.items() if not k.startswith("effect:")}
        theirs = {k: v for k, v in other.layout.blocks.items() if not k.startswith("effect:")}
        return (other.s is self.s and other.start is self.start and mine == theirs
                and (other.attitudes, other.with_latitude, other.hand_earth_vertical)
                == (self.attitudes, self.with_latitude, self.hand_earth_vertical))

    def refresh(self):
        """Forget the cached row layout and Jacobian structure (after priors were added)."""
        self.__dict__.pop("_groups", None)
        self._rows = None
        self._last_jacobian = None

    # --- initial values ---------------------------------------------------------------------
    def _initialise(self, like: "Model | None" = None):
        s, L = self.s, self.layout
        st = self.start
        x = np.zeros(L.size)
        if like is not None:        # the same nuisances (_same_nuisances): taken, not computed
            for name, sl in L.blocks.items():
                if not name.startswith("effect:"):
                    x[sl] = like.x0[like.layout[name]]
            self.static_ref, self.axis_ref = like.static_ref, like.axis_ref
            self.axis_basis, self.gyro_whiten = like.axis_basis, like.gyro_whiten
            self.earth_angle = like.earth_angle.copy()
            self._rotation_axes_raw = like._rotation_axes_raw
            self.ramp_windows = like.ramp_windows
            self.ramp_signs = getattr(like, "ramp_signs", {})
            if like.ramp_k2 != self.ramp_k2:
                self._gyro_integral_whitening()
            if self.hands:
                self._initialise_hands(st)
            self.x0, self.x0_plain = x, x.copy()
            for name, sl in L.blocks.items():
                if not name.startswith("effect:"):
                    self.x0_plain[sl] = like.x0_plain[like.layout[name]]
            return
        for name, value in (("accel_scale", st.ka), ("accel_misalignment", st.alpha), ("accel_bias", st.ba),
                            ("gyro_scale", st.kg), ("gyro_misalignment", st.gamma), ("gyro_bias", st.bg),
                            ("inter_triad", st.theta)):
            x[L[name]] = value
        Ma, Mg = self._matrices(x)
        La, Lg = np.linalg.inv(Ma), np.linalg.inv(Mg)
        # static attitudes: up from the accelerometers, heading from the Earth rate
        self.static_ref = []
        for j, stat in enumerate(s.statics):
            up_p = La @ (stat.accel - st.ba)
            up_p /= np.linalg.norm(up_p)
            if self.with_latitude:
                earth_p = Lg @ (stat.gyro - st.bg)
                C0 = _align_vectors([up_p, earth_p], [UP, self.omega_n], weights=[1e6, 1.0])
                self.static_ref.append(C0)
            else:
                self.static_ref.append(up_p)
        # rotation axes in p from the gyro integrals; gravity along them and its start phase
        self.axis_ref = []
        for k in range(s.groups):
            segs = [r for r in s.rotations if r.group == k]
            v = sum(np.sign(r.angle_deg) * (Lg @ (r.gyro_integral - st.bg * r.duration_s)) for r in segs)
            l0 = v / np.linalg.norm(v)
            self.axis_ref.append(l0)
            kappa = np.mean([l0 @ (La @ (r.accel_dc - st.ba)) for r in segs])
            x[L[f"axis{k}"]][2] = np.arccos(np.clip(kappa / s.gravity_mps2, -0.999, 0.999))
        self.axis_basis = [tangent_basis(l0) for l0 in self.axis_ref]
        for i, r in enumerate(s.rotations):
            if not r.steady:
                continue
            l0 = self.axis_ref[r.group]
            e1, e2 = self.axis_basis[r.group]
            v = La @ r.accel_cos
            x[L[f"phase{i}"].start] = np.arctan2(v @ e2, v @ e1)
        self.x0_plain = x.copy()        # the start before the Earth-rate phases are started
        self._earth_phase_start(x, choose=True)
        for k in np.flatnonzero(self.earth_angle):
            self.x0_plain[L[f"axis{k}"].start + 3] = np.pi / 2      # beta: no Earth rate along the axis
        self._rotation_axes_raw = [Mg @ self.axis_ref[r.group] for r in s.rotations]
        self._gyro_integral_whitening()
        if self.hands:
            self._initialise_hands(st)
        self.x0 = x

    def _gyro_integral_whitening(self):
        """The rotations' gyro integral whitening: white noise, the bias' instability over the
        window (pose_extra's gyro part times T^2) and the encoder error along the axis; a recorded
        ramp's placement (its angle_sigma_deg times the factor k = sqrt(ramp_k2)) along it too.
        ``ramp_windows``: {name: the placement's share of the whitened rows, W a k sigma} of every
        rotation with a placement 1-sigma (noise_groups.placement_component)."""
        s = self.s
        self.gyro_whiten, self.ramp_windows, self.ramp_signs = [], {}, {}
        for r, axis_raw in zip(s.rotations, self._rotation_axes_raw):
            cov = np.diag(s.gyro_sigma**2 * r.duration_s / s.sample_rate_hz + self.pose_extra[3:] * r.duration_s**2)
            # a recorded ramp's own angle error (its reads placed on the IMU's clock, issue 28
            # review item 1: RotationSummary.angle_sigma_deg) in quadrature with the encoder's
            placement = getattr(r, "angle_sigma_deg", 0.0)
            angle_var = s.table_angle_sigma_deg**2 + self.ramp_k2 * placement**2
            cov += angle_var * np.outer(axis_raw, axis_raw)
            whiten = np.linalg.inv(np.linalg.cholesky(cov))
            self.gyro_whiten.append(whiten)
            if placement > 0:
                self.ramp_windows[r.name] = whiten @ np.asarray(axis_raw, float) * (placement * np.sqrt(self.ramp_k2))
                # the sign that turns its angle error into its reads' timing error: the rate's, and
                # the turning edge at the window's end (a ramp up) or at its start (a brake); times
                # the window's timing scale |rate| / angle_sigma (a timing error tau is tau |rate| /
                # angle_sigma in its placement residual: windows of different stated 1-sigma weigh a
                # common or drifting timing differently; review of the nineteenth session)
                edge = r.table_rate_end_dps if r.record_ramp == "start" else r.table_rate_start_dps
                rate = abs(edge) if edge else abs(r.rate_dps)
                self.ramp_signs[r.name] = (float(np.sign(r.angle_deg) or 1.0) * (-1.0 if r.record_ramp == "end" else 1.0)
                                           * (rate / placement if rate > 0 else 1.0))

    def set_pose_extra(self, extra) -> None:
        """Set the variance added to every pose mean (6,) and rebuild the weights that use it."""
        self.pose_extra = np.asarray(extra, float).copy()
        self._gyro_integral_whitening()
        if self.hands:
            self._hand_weights()
        self._prepare()
        self.refresh()

    def _earth_phase_start(self, x, choose: bool = False):
        """Start the Earth-rate phases chi of the rotations that end elsewhere than they start
        (their second phase nuisance), with the axis tilt and the Earth rate e along it, from
        the gyro integrals at the calibration, axes and psi of x (changed in place).

        Over a part turn the Earth rate across the axis integrates to E = (T/A)(sin A u -
        (1 - cos A) l x u), u the Earth rate across the axis at the start, at angle chi in the
        axis' tangent plane.  Started at chi = 0 (and the axis from the gyro integrals, which E
        tilts by about |E| / A) the fit fell into a wrong basin: each chi settles where E and a
        tilt of the shared axis l together make up the integrals, and the accelerometer harmonics,
        which see the true axis, are left with a misfit (120 degree turns: a reduced chi2 of 3.5
        on the station's own simulator, 3 with no noise at all).  Gravity and the Earth rate are
        both fixed to the Earth, so across a table axis the angle from gravity to the Earth rate,
        delta = chi - psi, is the same for every segment about it (psi: where gravity is at the
        start, from the accelerometers' first harmonic).  In the tangent plane as complex
        numbers (l x w is i w) the integral across the axis is c_i d + g_i exp(i delta), d a
        further tilt of the axis, c_i = (rate_i + e) T_i, g_i = (f1_i - i f2_i) |u| exp(i psi_i):
        linear in d and w = exp(i delta), solved by least squares (a ridge keeps d small where
        the segments cannot tell them apart, e.g. one turn about an axis).  Where gravity barely
        has a part across the axis (psi then unknown) each chi is taken from its own integral
        with the axis as it is.  Only the start: the model keeps a chi per segment.

        ``choose``: also choose the axes whose Earth rate is parametrised by beta (earth_angle):
        those turned both ways by part turns where e, as the gyro integrals along the axis put
        it, is within three of its 1-sigma of |e| = Omega (the edge the solver could step past)."""
        s, L = self.s, self.layout
        _, Mg = self._matrices(x)
        Lg, bg = np.linalg.inv(Mg), x[L["gyro_bias"]]
        for k in range(s.groups):
            segs = [i for i, r in enumerate(s.rotations)
                    if r.group == k and L[f"phase{i}"].stop - L[f"phase{i}"].start == 2]
            if not segs:
                continue
            axis = L[f"axis{k}"]
            ref, (t1, t2) = self.axis_ref[k], self.axis_basis[k]
            l = normalised(ref + x[axis.start] * t1 + x[axis.start + 1] * t2)
            e1 = normalised(t1 - (t1 @ l) * l)          # as _blocks: psi and chi are angles from e1
            e2 = cross(l, e1)
            rots = [s.rotations[i] for i in segs]
            T = np.array([r.duration_s for r in rots])
            y = np.array([Lg @ (r.gyro_integral - bg * r.duration_s) for r in rots])    # deg
            rate = np.array([r.rate_dps for r in rots])
            # e from the integrals along the axis, (1 + s)(rate + e) T with s what is left of the
            # gyro's scale error along it: by least squares with e's prior (0 +- omega / sqrt 3,
            # the weak_e rows) and s's (1 %), each row weighted by its noise.  Turns one way only
            # cannot tell e from s (e then stays near 0), and over a short turn the encoder's
            # angle error alone is a large part of the Earth rate (2" over 0.4 s: 0.33 omega)
            noise = np.sqrt(np.max(s.gyro_sigma)**2 * T / s.sample_rate_hz + s.table_angle_sigma_deg**2) / T
            noise = np.maximum(noise, 1e-12)    # (a quantised gyro without an encoder error: no noise seen)
            design = np.vstack([np.column_stack([rate, np.ones(len(segs))]) / noise[:, None],
                                [[1.0 / 1e-2, 0.0], [0.0, np.sqrt(3.0) / self.omega_dps]]])
            e = float(np.linalg.lstsq(design, np.append((y @ l / T - rate) / noise, [0.0, 0.0]), rcond=None)[0][1])
            if choose and _earth_angle_group(s, k):
                e_sigma = float(np.sqrt(np.linalg.pinv(design.T @ design)[1, 1]))
                self.earth_angle[k] = self.omega_dps - abs(e) < 3.0 * e_sigma
                x[axis.start + 3] = np.pi / 2 if self.earth_angle[k] else 0.0
            e = float(np.clip(e, -0.9 * self.omega_dps, 0.9 * self.omega_dps))
            across = np.sqrt(self.omega_dps**2 - e * e)
            A = np.radians([r.angle_deg for r in rots])
            if not np.all(np.isfinite(y)) or np.any(A == 0.0):
                continue
            f = _earth_factor(rots)                                 # E = f u in the tangent plane
            c = (rate + e) * T
            resid = y - c[:, None] * l
            z = resid @ e1 + 1j * (resid @ e2)
            psi = np.array([x[L[f"phase{i}"].start] for i in segs])
            if np.sin(x[axis.start + 2])**2 > 0.04:       # gravity across the axis: psi is seen
                g = f * across * np.exp(1j * psi)
                noise = np.sqrt(np.max(s.gyro_sigma)**2 * np.max(T) / s.sample_rate_hz
                                + s.table_angle_sigma_deg**2)
                ridge = max(noise / 1e-2, 1e-6 * float(np.sqrt(np.mean(c * c))))     # |d| ~ 10 mrad
                design = np.vstack([np.column_stack([c, g]), [ridge, 0.0]])
                d, w = np.linalg.lstsq(design, np.append(z, 0.0), rcond=None)[0]
                chi = psi + np.angle(w)
                tilted = l + d.real * e1 + d.imag * e2
                x[axis.start:axis.start + 2] = [tilted @ t1 / (tilted @ ref), tilted @ t2 / (tilted @ ref)]
            else:
                chi = np.angle(z) - np.angle(f)
            x[axis.start + 3] = np.arccos(e / self.omega_dps) if self.earth_angle[k] else e
            for i, value in zip(segs, chi):
                x[L[f"phase{i}"].start + 1] = np.angle(np.exp(1j * value))
        return x

    def _initialise_hands(self, st: Start):
        """Hand rotations: the integrator, the tangent plane of each pose after a turn, and the
        noise of the matched direction (module doc of hand_rotation)."""
        s = self.s
        self.integrator = hand_rotation.Integrator(self.hands)
        ups = [ref @ UP if self.with_latitude else ref for ref in self.static_ref]
        self.hand_basis = np.array([tangent_basis(ups[h.after]) for h in self.hands])     # (H,2,3)
        self._hand_kg = np.abs(st.kg)
        omega = np.degrees(EARTH_RATE_RAD)
        # the Earth rate not modelled, r: all of it without the latitude (a random direction:
        # r^2/3 per axis), the horizontal part when only the vertical one is (r^2/2 per
        # horizontal axis); its turn over T moves the up by its component across the up
        if self.with_latitude:
            unmodelled, share = 0.0, 0.0
        elif self.hand_earth_vertical:
            unmodelled, share = omega * np.cos(np.radians(s.latitude_deg)), 0.5
        else:
            unmodelled, share = omega, 1.0 / 3.0
        self._hand_earth_var = np.array([share * (unmodelled * h.duration_s) ** 2 for h in self.hands])
        self.hand_duration = np.array([h.duration_s for h in self.hands])
        # without the full attitudes the poses' gyro means give the bias, the unmodelled Earth
        # rate as noise: covariance white/N + M_g C M_g^T, C = r^2/3 I, or r^2/2 (I - u u^T)
        # across the pose's up u (fixed at the start's values)
        M_g = _start_gyro_matrix(st)
        self._hand_static_earth = []
        for j, stat in enumerate(s.statics):
            u = ups[j]
            C = (share * unmodelled**2 * (np.eye(3) - np.outer(u, u)) if self.hand_earth_vertical
                 else share * unmodelled**2 * np.eye(3))
            self._hand_static_earth.append(M_g @ C @ M_g.T)
        self._hand_weights()
        if self.hand_earth_vertical:
            self.notes.append("Earth rate: its vertical component modelled (latitude known), its "
                              "horizontal one as noise: the gyros cannot see the poses' heading")

    def _hand_weights(self):
        """The turns' variance (deg^2: white noise integrated over the turn, the bias' instability
        over it, the Earth rate not modelled) and the poses' gyro whitening (white over the
        samples, pose_extra, the Earth rate not modelled: M_g C M_g^T)."""
        s = self.s
        per_sample_dps = s.gyro_sigma / self._hand_kg
        var = np.array([np.mean(per_sample_dps**2) * h.dt**2 * h.samples for h in self.hands])
        var = var + np.mean(self.pose_extra[3:] / self._hand_kg**2) * self.hand_duration**2 + self._hand_earth_var
        self._hand_var_deg2 = var
        self.set_turn_sigma(self.turn_sigma_deg)
        self.static_gyro_whiten = [
            np.linalg.inv(np.linalg.cholesky(np.diag(s.gyro_sigma**2 / stat.samples + self.pose_extra[3:]) + earth))
            for stat, earth in zip(s.statics, self._hand_static_earth)]

    def set_turn_sigma(self, sigma_deg: float) -> None:
        """The hand turns' explicit 1-sigma per turn (deg, noise_model), added to each turn's
        white-noise and bias-instability variance."""
        self.turn_sigma_deg = float(sigma_deg)
        self.hand_sigma_rad = np.radians(np.sqrt(self._hand_var_deg2 + self.turn_sigma_deg**2))

    # --- pieces -----------------------------------------------------------------------------
    def _matrices(self, x):
        L = self.layout
        Ma = np.diag(x[L["accel_scale"]]) @ lower_unit_rows(x[L["accel_misalignment"]])
        Mg = (np.diag(x[L["gyro_scale"]]) @ lower_unit_rows(x[L["gyro_misalignment"]])
              @ matrix_from_rotvec(x[L["inter_triad"]]))
        return Ma, Mg

    def _column_groups(self):
        """Columns that can be perturbed together: the same local parameter of every static,
        axis or rotation segment moves disjoint residual rows."""
        L = self.layout
        _, tags = self._pieces(self.x0)
        rows, at = {}, 0
        for tag, n, _ in tags:
            rows.setdefault(tag, []).extend(range(at, at + n))
            at += n
        local = {}
        for name, sl in L.blocks.items():
            for prefix, kind in (("static", "static"), ("axis", "axis"), ("phase", "rot")):
                if name.startswith(prefix) and name[len(prefix):].isdigit():
                    j = int(name[len(prefix):])
                    owned = list(rows.get((kind, j), [])) + list(rows.get(("weak", j), []) if kind == "static" else [])
                    key = prefix
                    if kind == "static" and self.static_colour is not None:
                        owned += [r for i, h in enumerate(self.hands) if j in (h.before, h.after)
                                  for r in rows.get(("hand", i), [])]
                        key = (prefix, self.static_colour[j])
                    if kind == "axis":
                        owned += list(rows.get(("weak_axis", j), [])) + list(rows.get(("level", j), []))
                        owned += [r for i, rot in enumerate(self.s.rotations) if rot.group == j
                                  for r in rows.get(("rot", i), [])]
                    for k in range(sl.stop - sl.start):     # and its own prior's row, if it has one
                        own = owned + list(rows.get(("prior", sl.start + k), []))
                        local.setdefault((key, k), []).append((sl.start + k, np.array(own, dtype=int)))
                    break
        local_cols = {c for members in local.values() for c, _ in members}
        dense = [[(c, None)] for c in range(L.size) if c not in local_cols]
        self.data_rows = np.ones(at, dtype=bool)
        for tag, idx in rows.items():
            if tag[0] in ("weak", "weak_axis"):
                self.data_rows[idx] = False
        return dense + list(local.values()), at

    def row_labels(self, x) -> list[tuple[str, str, str, str]]:
        """(segment, kind, quantity, axis) of every residual row, in order."""
        rot_parts = [(q, a) for q in ("accel_dc", "accel_cos", "accel_sin", "accel_cos2", "accel_sin2",
                                      "gyro_integral") for a in "xyz"]
        labels = []
        for tag, n, quantity in self._pieces(x)[1]:
            kind, j = tag
            if kind in ("static", "weak"):
                name = self.s.statics[j].name
                axes = "xyz" if n == 3 else ["|w|"]
                labels += [(name, "static", quantity, a) for a in axes]
            elif kind == "rot":
                parts = rot_parts if quantity == "rotation" else rot_parts[-3:]
                labels += [(self.s.rotations[j].name, "rotation", q, a) for q, a in parts]
            elif kind == "hand":
                labels += [(self.hands[j].name, "rotation", quantity, a) for a in ("t1", "t2")]
            elif kind == "weak_axis":
                labels += [(f"axis{j}", "rotation", quantity, "e" if quantity == "earth_prior" else "kappa")]
            elif kind == "level":
                labels += [(f"axis{j}", "rotation", quantity, "elevation")]
            elif kind == "axis":
                labels += [(f"axis{j}", "rotation", quantity, a) for a in "xyz"]
            else:
                labels += [("prior", "prior", quantity, str(j))]
        return labels

    def _sizes(self, x) -> np.ndarray:
        """Each parameter's size, the unit of its Jacobian step: |x|, at least 1e-2 (internal
        units) or, for an effect's parameter, its typical size when that is finite (a forward
        step of 1e-9 on a parameter whose typical size is 100 left the column to rounding noise)."""
        if not hasattr(self, "_step_floor"):
            floor = np.full(self.layout.size, 1e-2)
            for e in self.effects:
                sizes = [p.typical / abs(p.scale) if p.scale and np.isfinite(p.typical / p.scale) else 0.0
                         for p in e.params]
                floor[self.layout[f"effect:{e.id}"]] = np.maximum(sizes, 1e-2)
            self._step_floor = floor
        return np.maximum(np.abs(x), self._step_floor)

    @property
    def complex_step(self) -> bool:
        """Whether the Jacobian is taken by complex step: every effect says it is safe
        (``Effect.complex_step``) and none has shown otherwise (_ComplexUnsafe)."""
        if self._unsafe is None:
            self._unsafe = [e.id for e in self.effects if not getattr(e, "complex_step", False)]
        return not self._unsafe

    @property
    def jacobian_method(self) -> str:
        """How the Jacobian is taken, in words (for benchmarks and notes)."""
        return "complex step" if self.complex_step else f"forward differences ({', '.join(self._unsafe)})"

    def _linearised_hands(self, x):
        """While the Jacobian is taken, the hand turns to first order about x (no integration per
        gyro column: hand_rotation.Integrator.linearise)."""
        if self.hands:
            _, Mg = self._matrices(x)
            self.integrator.linearise(np.linalg.inv(Mg), x[self.layout["gyro_bias"]])

    def _derivatives(self, x, sets) -> tuple[np.ndarray, np.ndarray]:
        """(steps, D): D[n] is the change of the residuals when every column c of sets[n] moves
        by steps[c], to first order; all sets in one batched evaluation, the hand turns to first
        order about x.  By complex step (D = Im r(x + i steps) exactly: no difference is taken,
        so no rounding is divided by the step) when the model allows it, else forward
        differences."""
        x = np.asarray(x, float)
        if self.complex_step:
            steps = COMPLEX_STEP * self._sizes(x)
            X = np.tile(x.astype(complex), (len(sets), 1))
            for n, cols in enumerate(sets):
                X[n, cols] += 1j * steps[cols]
        else:
            r0 = self.residuals(x)
            steps = FORWARD_STEP * self._sizes(x)
            X = np.tile(x, (len(sets), 1))
            for n, cols in enumerate(sets):
                X[n, cols] += steps[cols]
        if not len(sets):
            return steps, np.zeros((0, self._rows))
        self._linearised_hands(x)
        # in batches of at most BATCH_VALUES residuals (a large model: the batch's intermediate
        # arrays, complex 3x3 per point, were 0.5 GB at 4,000 segments and grow with rows x sets)
        per = max(1, BATCH_VALUES // max(self._rows or 1, 1))
        try:
            parts = []
            for at in range(0, len(X), per):
                R = self._residuals_batch(X[at:at + per])
                parts.append(R.imag if np.iscomplexobj(R) else R - r0)
                del R
        except _ComplexUnsafe as unsafe:
            self._unsafe = [unsafe.effect_id]
            return self._derivatives(x, sets)
        finally:
            if self.hands:
                self.integrator.exact()
        return steps, (parts[0] if len(parts) == 1 else np.concatenate(parts))

    def jacobian_columns(self, x, columns) -> np.ndarray:
        """The Jacobian's given columns only (one batched evaluation, _derivatives)."""
        self._ensure_layout()
        columns = np.asarray(columns, int)
        steps, D = self._derivatives(x, [[c] for c in columns])
        return (D / steps[columns][:, None]).T

    def jacobian(self, x) -> np.ndarray:
        """The Jacobian by complex step (forward differences when an effect is not safe), the
        columns that move disjoint rows perturbed together (_column_groups), every perturbed
        vector in one batched evaluation; the hand turns to first order about x."""
        return self._jacobian(x, sparse=False)

    def sparse_jacobian(self, x):
        """jacobian(x) as a scipy.sparse CSR matrix, never held dense: each segment's nuisances
        move only that segment's rows (a large model: is_large)."""
        return self._jacobian(x, sparse=True)

    def _jacobian(self, x, sparse: bool):
        x = np.asarray(x, float)
        self._ensure_layout()
        if not hasattr(self, "_groups"):
            self._groups, self._jacobian_rows = self._column_groups()
        key = (x.tobytes(), sparse)
        if self._last_jacobian is not None and self._last_jacobian[0] == key:
            return self._last_jacobian[1].copy()     # the solver's last one, at its solution
        steps, D = self._derivatives(x, [[c for c, _ in members] for members in self._groups])
        if sparse:
            J = self._sparse_from(D, steps, len(x))
            self._last_jacobian = (key, J.copy())
            return J
        group, rows, cols = self._dense_index()
        J = np.zeros((self._jacobian_rows, len(x)))
        J[rows, cols] = D[group, rows] / steps[cols]
        self._last_jacobian = (key, J.copy())
        return J

    def _dense_index(self):
        """Where the column groups' derivatives go in the dense Jacobian: for every entry its
        group (D's row), its residual row and its column, built once per _column_groups (the
        Jacobian's assembly looped over the groups' members on every call: ~15 % of a fit's CPU,
        issue 27)."""
        cached = self.__dict__.get("_dense_index_of")
        if cached is not None and cached[0] is self._groups:
            return cached[1]
        every = np.arange(self._jacobian_rows)
        group, rows, cols = [], [], []
        for n, members in enumerate(self._groups):
            for c, owned in members:
                at = every if owned is None else owned
                group.append(np.full(len(at), n))
                rows.append(at)
                cols.append(np.full(len(at), c))
        index = tuple(np.concatenate(a).astype(int) if a else np.zeros(0, int) for a in (group, rows, cols))
        self._dense_index_of = (self._groups, index)
        return index

    def _sparse_from(self, D, steps, size: int):
        """The sparse Jacobian (CSR) from _derivatives' D of the column groups: built column by
        column as CSC (32-bit indices, each column's rows once), then CSR.  (From COO triplets
        with 64-bit row and column arrays it took 4 copies of 24 bytes a value: 2 GB at 100,000
        segments, where the values are 0.5 GB.)"""
        from scipy.sparse import csc_matrix

        n_rows = self._jacobian_rows
        counts = np.zeros(size, np.int64)
        for members in self._groups:
            for c, owned in members:
                counts[c] = n_rows if owned is None else len(owned)
        indptr = np.concatenate([[0], np.cumsum(counts)])
        index_type = np.int32 if indptr[-1] < 2**31 and n_rows < 2**31 else np.int64
        indices = np.empty(indptr[-1], index_type)
        data = np.empty(indptr[-1])
        every = np.arange(n_rows, dtype=index_type)
        for d, members in zip(D, self._groups):
            for c, owned in members:
                at = every if owned is None else np.asarray(owned, index_type)
                indices[indptr[c]:indptr[c + 1]] = at
                data[indptr[c]:indptr[c + 1]] = d[at] / steps[c]
        J = csc_matrix((data, indices, indptr.astype(index_type)), shape=(n_rows, size))
        J.sort_indices()
        return J.tocsr()

    @property
    def is_large(self) -> bool:
        """Whether the fit works on the sparse Jacobian (least_squares' trust-region method with
        LSMR steps) rather than MINPACK's Levenberg-Marquardt, whose dense QR costs rows x
        parameters^2 a step: 3.6 s at 300 segments, 15 minutes at 2,000."""
        return self.layout.size > LARGE_MODEL

    def local_columns(self) -> np.ndarray:
        """The columns of the segments' own nuisances (static attitudes, rotation phases, the
        axis of each group of rotations about one axis): the others (the calibration, the
        effects, the mounting) are few whatever the capture's length.  (The axes were kept with
        the calibration: 400 rotation pairs about random axes made 1,600 dense columns, 19 s.)"""
        def local(name):
            return any(name.startswith(p) and name[len(p):].isdigit() for p in ("static", "phase", "axis"))

        return np.array(sorted(c for name, sl in self.layout.blocks.items() if local(name)
                               for c in range(sl.start, sl.stop)), dtype=int)

    # --- the residuals ----------------------------------------------------------------------
    # One vectorised pass: every static, every rotation on its phase grid and every hand turn at
    # once, each effect called once with all those sample points stacked (statics first, then
    # the rotations' phase points); the rows are then put in the order of row_labels() (per
    # segment) by a fixed permutation.  Everything that does not depend on x is computed once,
    # in _prepare().

    def _prepare(self):
        """The constants of the residual: data, weights, index arrays, the row permutation."""
        s, L = self.s, self.layout
        S, R, K = len(s.statics), len(s.rotations), s.groups
        pad = L.size            # x is extended by a zero: the index of an absent nuisance
        stat, rots = s.statics, s.rotations
        self._st_data = np.array([np.concatenate([q.accel, q.gyro]) for q in stat]).reshape(S, 6)
        self._st_root_n = np.sqrt(np.array([q.samples for q in stat], float)).reshape(S, 1)
        # each pose mean's weight: white noise over its samples and the noise model's terms per
        # pose (noise_model: quantised mean, bias instability); root n / sigma when they are 0
        extra = self.pose_extra
        sigma = np.concatenate([s.accel_sigma, s.gyro_sigma]).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            self._st_weight = self._st_root_n / np.sqrt(sigma**2 + self._st_root_n**2 * extra)     # (S, 6)
            self._st_norm_weight = self._st_root_n[:, 0] / np.sqrt(np.mean(s.gyro_sigma)**2
                                                                  + self._st_root_n[:, 0]**2 * np.mean(extra[3:]))
        width = 3 if self.with_latitude else 2
        self._st_cols = np.array([np.arange(L[f"static{j}"].start, L[f"static{j}"].stop) for j in range(S)],
                                 int).reshape(S, width)
        if self.with_latitude:      # C0 f_n, C0 Omega_n, C0 up per static: the attitude's reference
            C0 = np.array(self.static_ref, float).reshape(S, 3, 3)
            self._st_ref_vectors = np.einsum("sij,kj->ski", C0, np.array([self.f_n, self.omega_n, UP]))
        else:
            self._st_ref = np.array(self.static_ref, float).reshape(S, 3)
            self._st_basis = np.array([tangent_basis(r) for r in self.static_ref]).reshape(S, 2, 3)
        self._st_up_index = np.array([j for j, q in enumerate(stat) if q.up_body is not None], int)
        self._st_up_body = np.array([np.asarray(stat[j].up_body, float) for j in self._st_up_index]).reshape(-1, 3)
        if self.hands and not self.with_latitude:
            self._st_gyro_whiten = np.array(self.static_gyro_whiten).reshape(S, 3, 3)
        # rotations on the phase grid
        phases = 2 * np.pi * np.arange(PHASES) / PHASES
        self._cos_p, self._sin_p = np.cos(phases), np.sin(phases)
        grid = np.column_stack([np.ones(PHASES), self._cos_p, self._sin_p, np.cos(2 * phases), np.sin(2 * phases)])
        self._harmonics = (grid * np.array([1.0, 2.0, 2.0, 2.0, 2.0])).T / PHASES        # (5, PHASES)
        shapes = []
        for r in rots:
            if r.rate_coef is not None:
                shapes.append([grid @ r.rate_coef, grid @ r.rate_sq_coef, grid @ r.rate_dot_coef])
            else:
                w_k = np.full(PHASES, np.radians(r.rate_dps) * np.sqrt(r.rate_sq_factor))
                shapes.append([w_k, w_k**2, np.zeros(PHASES)])
        self._rot_rate_shape = np.array(shapes, float).reshape(R, 3, PHASES)     # w, w^2, dw/dt
        # a recorded ramp's w^2 and dw/dt times 1, cos p, sin p, cos 2p, sin 2p on the grid, from the
        # window's own harmonics of each product (SampleContext.ramp_products); None without one
        ramps = [i for i, r in enumerate(rots) if getattr(r, "ramp_coef", None) is not None]
        self._ctx_ramp_products = None
        if ramps:
            products = np.full((S + R * PHASES, 2, 5), np.nan)
            for i in ramps:
                products[S + i * PHASES:S + (i + 1) * PHASES] = np.einsum("pk,fmk->pfm", grid, rots[i].ramp_coef)
            self._ctx_ramp_products = products
        # the measured rate's change across each window along its turn, and the turn the samples
        # measured (gyro units: the ratio is unit-free): a window shifted by dt turns
        # |A| + dt (w_end - w_start), while the rate's shape above was scaled to the encoder's |A|
        # (summaries._rate): see _rate_shape_factor.  A recorded ramp's is at the table's stated
        # rate (rate_from_table): no change counted, c = 1
        turn = np.array([r.gyro_integral for r in rots], float).reshape(R, 3)
        size = np.linalg.norm(turn, axis=1)
        along = np.divide(turn, size[:, None], out=np.zeros_like(turn), where=size[:, None] > 0)
        self._rot_turn_measured = size
        self._rot_edge_change = np.array([np.asarray(r.gyro_end, float) - np.asarray(r.gyro_start, float)
                                          for r in rots], float).reshape(R, 3)
        self._rot_rate_change = np.einsum("rc,rc->r", along, self._rot_edge_change)
        self._rot_rate_change[[bool(getattr(r, "rate_from_table", False)) for r in rots]] = 0.0    # c = 1
        self._rot_group = np.array([r.group for r in rots], int)
        self._rot_e1 = np.array([self.axis_basis[r.group][0] for r in rots]).reshape(R, 3)
        self._rot_phase_cols = np.array([(list(range(L[f"phase{i}"].start, L[f"phase{i}"].stop)) + [pad, pad])[:2]
                                         for i in range(R)], int).reshape(R, 2)
        self._rot_rate = np.array([r.rate_dps for r in rots], float)
        self._rot_duration = np.array([r.duration_s for r in rots], float)
        A = np.radians(np.array([r.angle_deg for r in rots], float))
        visible = np.array([_earth_rate_visible(r, s) for r in rots], bool)
        with np.errstate(invalid="ignore", divide="ignore"):
            self._rot_earth = np.where(visible[:, None], np.column_stack(
                [self._rot_duration / A * np.sin(A), self._rot_duration / A * (1.0 - np.cos(A))]), 0.0).reshape(R, 2)
        for i, r in enumerate(rots):    # a recorded ramp: the Earth rate's weights over its own phase
            if visible[i] and getattr(r, "earth_weights_s", None) is not None:
                self._rot_earth[i] = r.earth_weights_s
        self._rot_data = np.array([[r.accel_dc, r.accel_cos, r.accel_sin, r.accel_cos2, r.accel_sin2]
                                   for r in rots], float).reshape(R, 5, 3)
        # the harmonics' whitening: the noise covariance of a rotation's coefficients is
        # sigma^2 / samples * G^-1, G the basis' Gram matrix per sample over the arc recorded
        # (RotationSummary.gram): whitened by G's symmetric square root, diag(1, 1/sqrt 2, ...)
        # over whole revolutions; over part of one the coefficients are correlated and far less
        # certain (200 degrees: a condition of 186; the whole-revolution weights made a fit
        # of such rotations fail with a reduced chi2 of 20)
        self._rot_whiten = np.array([_harmonic_whitening(r.gram) for r in rots], float).reshape(R, 5, 5)
        self._rot_weight = (np.sqrt(np.array([r.samples for r in rots], float))[:, None]
                            / np.asarray(s.accel_sigma, float)[None, :]).reshape(R, 1, 3)
        self._rot_gyro = np.array([r.gyro_integral for r in rots], float).reshape(R, 3)
        self._rot_gyro_whiten = np.array(self.gyro_whiten, float).reshape(R, 3, 3)
        self._axis_cols = np.array([np.arange(L[f"axis{k}"].start, L[f"axis{k}"].stop) for k in range(K)],
                                   int).reshape(K, 4)
        self._axis_ref = np.array(self.axis_ref, float).reshape(K, 3)
        self._axis_basis = np.array(self.axis_basis, float).reshape(K, 2, 3)
        self._axis_body = np.array([next(r.axis_body for r in rots if r.group == k) for k in range(K)],
                                   float).reshape(K, 3)
        self._offset = (None if s.rotations and s.mounting_offset_m is None
                        else np.asarray(s.mounting_offset_m if s.mounting_offset_m is not None else np.zeros(3), float))
        # each rotation's offset: its set's columns (pad: none) times a basis (3-vector: identity;
        # across one axis: that axis' tangent basis), so that offset_r = sum_k x[cols_rk] basis_rk
        cols, basis = np.full((R, 3), pad, int), np.zeros((R, 3, 3))
        for i, m in enumerate(self.offset_set if self._offset is None else []):
            block = L["mounting_offset"] if "mounting_offset" in L.blocks else L[f"mounting_offset{m}"]
            k = self.offset_axis[m]
            cols[i, :block.stop - block.start] = np.arange(block.start, block.stop)
            basis[i, :block.stop - block.start] = np.eye(3) if k is None else self.axis_basis[k]
        self._offset_cols, self._offset_basis = cols, basis
        self._level_cols = np.array([L[f"axis{k}"].start + 2 for k in self.level_groups], int)
        self._level_alpha = np.radians(90.0 - np.array([self.geometry.elevation_deg[k] for k in self.level_groups],
                                                       float))
        # the context's columns that do not depend on x: statics, then PHASES rows per rotation
        segs = list(stat) + [r for r in rots for _ in range(PHASES)]
        self._ctx_temp = np.array([np.nan if q.temp_c is None else q.temp_c for q in segs], float)
        self._ctx_t = np.array([q.t_mid_s - self.t0 for q in segs], float)
        self._ctx_index = np.array([float(q.index) for q in segs], float)
        self._ctx_temp_rate = np.array([q.temp_rate_c_per_s for q in segs], float)
        # time since each rotation's start at its phase points (effects of the table's angle)
        self._ctx_turned = np.concatenate([np.zeros(S)] + [turned_time(r.angle_deg, r.duration_s, PHASES)
                                                           for r in rots])
        self._ctx_turned_sq = np.concatenate([np.zeros(S)] + [turned_time(r.angle_deg, r.duration_s, PHASES, 2)
                                                              for r in rots])
        self._rot_angle_at_phase = self._ctx_turned[S:].reshape(R, PHASES) * np.array(
            [np.radians(r.angle_deg) / r.duration_s if r.duration_s > 0 else 0.0 for r in rots]).reshape(R, 1)
        self._last_jacobian = None
        self._unsafe = None         # ids of the effects that are not complex-step safe (None: not asked yet)
        self.evaluations = 0        # residual evaluations (the Jacobian's included), for benchmarks
        self._integral_effects = [e for e in self.effects
                                  if getattr(type(e), "integral", Effect.integral) is not Effect.integral]
        self._shift_effects = [e for e in self._integral_effects
                               if getattr(type(e), "window_shift_s", Effect.window_shift_s) is not Effect.window_shift_s]
        if self.hands:
            self._hand_before = np.array([h.before for h in self.hands], int)
            self._hand_after = np.array([h.after for h in self.hands], int)
        self._rows = None

    def _row_layout(self):
        """Tags (segment, rows, quantity) in row order, and the permutation from the blocks
        computed by _blocks() to that order."""
        s = self.s
        S, R, K, H = len(s.statics), len(s.rotations), s.groups, len(self.hands)
        table = self.attitudes == "table"
        gyro_block = "s_gyro_norm" if not (self.with_latitude or self.hands) else "s_gyro"
        blocks = [("s_accel", S, 3), (gyro_block, S, 3 if gyro_block == "s_gyro" else 1)]
        if table:
            blocks.append(("s_attitude", len(self._st_up_index), 3))
        if self.with_latitude:
            blocks.append(("s_weak", S, 3))
        if H:
            blocks.append(("hand", H, 2))
        if table:
            blocks.append(("axis_prior", K, 3))
        blocks += [("weak_e", K, 1), ("weak_kappa", K, 1), ("rot", R, 18), ("prior", len(self.priors), 1),
                   ("level", len(self.level_groups), 1)]
        offset, at = {}, 0
        for name, n, w in blocks:
            offset[name] = (at, w)
            at += n * w
        entries = []

        def put(tag, quantity, block, item, columns):
            base, w = offset[block]
            entries.append((tag, quantity, base + item * w + np.asarray(columns, int)))

        up_item = {j: n for n, j in enumerate(self._st_up_index)}
        for j in range(S):
            put(("static", j), "accel", "s_accel", j, range(3))
            put(("static", j), "gyro" if gyro_block == "s_gyro" else "gyro_norm", gyro_block, j,
                range(3 if gyro_block == "s_gyro" else 1))
            if table and j in up_item:
                put(("static", j), "attitude_prior", "s_attitude", up_item[j], range(3))
            if self.with_latitude:
                put(("weak", j), "weak_prior", "s_weak", j, range(3))
        for i in range(H):
            put(("hand", i), "gravity_after_turn", "hand", i, range(2))
        if table:
            for k in range(K):
                put(("axis", k), "axis_prior", "axis_prior", k, range(3))
        for k in range(K):
            put(("weak_axis", k), "earth_prior", "weak_e", k, [0])
            if not any(r.steady for r in s.rotations if r.group == k):
                put(("weak_axis", k), "weak_prior", "weak_kappa", k, [0])
        for n, k in enumerate(self.level_groups):
            put(("level", k), "level_prior", "level", n, [0])
        for i, r in enumerate(s.rotations):
            if r.steady:
                put(("rot", i), "rotation", "rot", i, range(18))
            else:       # a hand turn: its angle and axis only, through the gyro
                put(("rot", i), "rotation_gyro", "rot", i, range(15, 18))
        for n, c in enumerate(self.priors):
            put(("prior", c), "effect_prior", "prior", n, [0])
        self._tags = [(tag, len(idx), quantity) for tag, quantity, idx in entries]
        self._perm = np.concatenate([idx for _, _, idx in entries]) if entries else np.zeros(0, int)
        self._block_sizes = [(name, n * w) for name, n, w in blocks]
        self._prior_key = tuple(self.priors.items())
        self._prior_cols = np.array(list(self.priors), int)
        self._prior_sigma = np.array(list(self.priors.values()), float)
        self._rows = len(self._perm)

    def residuals(self, x) -> np.ndarray:
        """The whitened residuals, in the order of row_labels()."""
        return self._residuals_batch(np.asarray(x, float)[None, :])[0]

    def canonical(self, x) -> np.ndarray | None:
        """x with every static attitude's rotation vector (its rotation from the start's attitude,
        static_ref) wound past WOUND_RAD replaced by the one of the same rotation turned the other
        way (angle 2 pi k - angle, below pi); None where none is (and with the Earth rate's
        headings unknown: a static is then its up vector, not a rotation vector).  The data rows
        are the same there (they read the rotation), the weak prior's rows (WEAK_PRIOR_RAD, on the
        vector) lower.  The solvers keep their accepted points so (solver.LevenbergMarquardt's and
        solver.dogbox's ``canonical``).  Twentieth session: the first steps of LM and dogbox on
        failing fits (traditional24 beside a +100 and a +200 deg/h gyro bias step) wound 7 and 15
        of 24 statics' headings to 5-13 rad, where the weak prior held them near 2 pi, at which
        the map from the vector to the rotation is singular across the vector (its singular values
        there sin(a/2) / (a/2): the statics' columns 7-9 times below their largest norms): LM, dogbox
        and the second solve crawled to their limits (2,002 evaluations, not converged); kept so,
        the fits converge in 62 and 177.  Between pi and WOUND_RAD (those values >= 0.30) a
        static is left as it is: converging fits of the suite pass there (statics at 3.2-4.3 rad
        in four tests), and their paths stay theirs."""
        if not self.with_latitude or not len(self.s.statics):
            return None
        cols = self._st_cols
        P = np.asarray(x, float)[cols]
        angle = np.sqrt(np.einsum("sc,sc->s", P, P))
        wound = angle > WOUND_RAD
        if not wound.any():
            return None
        turns = np.floor((angle[wound] + np.pi) / (2 * np.pi))
        out = np.array(x, float)
        out[cols[wound]] = P[wound] * (1.0 - 2 * np.pi * turns / angle[wound])[:, None]
        return out

    def _residuals_batch(self, X) -> np.ndarray:
        """The residuals of every row of X (B, parameters): (B, rows), in one vectorised pass."""
        self._ensure_layout()
        self.evaluations += len(X)
        with warnings.catch_warnings():
            if np.iscomplexobj(X):      # a complex number cast to float drops the derivative: an error
                warnings.simplefilter("error", np.exceptions.ComplexWarning)
            flat = np.concatenate([b.reshape(len(X), -1) for b in self._blocks(X)], axis=1)
        return flat[:, self._perm]

    def _ensure_layout(self):
        """The row layout, rebuilt (with the Jacobian's structure) when the priors were set or
        changed without refresh()."""
        if self._rows is None or self._prior_key != tuple(self.priors.items()):
            self.refresh()
            self._row_layout()

    def _pieces(self, x):
        """The whitened residuals in pieces, and a (tag, length, quantity) per piece naming what
        owns it."""
        r = self.residuals(x)
        ends = np.cumsum([n for _, n, _ in self._tags])
        return np.split(r, ends[:-1]) if len(ends) else [], list(self._tags)

    def _matrices_batch(self, X):
        """M_a = K_a T_a and M_g = K_g T_g R_po of every row of X: (B,3,3) each."""
        L = self.layout
        Ma = X[:, L["accel_scale"], None] * _lower_unit_rows_batch(X[:, L["accel_misalignment"]])
        Mg = (X[:, L["gyro_scale"], None] * _lower_unit_rows_batch(X[:, L["gyro_misalignment"]])
              @ matrix_from_rotvec(X[:, L["inter_triad"]]))
        return Ma, Mg

    def _blocks(self, X) -> list:
        """The residual blocks of _row_layout() for every row of X, each (B, items, width)."""
        s, L = self.s, self.layout
        B = len(X)
        Xe = np.concatenate([X, np.zeros((B, 1))], axis=1)
        Ma, Mg = self._matrices_batch(X)
        b_a, b_g = X[:, L["accel_bias"]], X[:, L["gyro_bias"]]
        S, R, K = len(s.statics), len(s.rotations), s.groups
        g = s.gravity_mps2
        # static attitudes: specific force, inertial rate and up, frame p
        P = X[:, self._st_cols]                                                  # (B,S,d)
        if self.with_latitude:
            C = matrix_from_rotvec(P)                                           # (B,S,3,3)
            f_s, w_s, up = np.moveaxis(C @ self._st_ref_vectors.transpose(0, 2, 1), -1, 0)     # (3,B,S,3)
        else:
            up = normalised(self._st_ref + np.einsum("bsk,skc->bsc", P, self._st_basis))
            f_s = self.f_n[2] * up
            w_s = self.omega_n[2] * up if self.hand_earth_vertical else np.zeros_like(up)
        # axes and the rotations' phase grids
        PA = X[:, self._axis_cols]                                               # (B,K,4)
        l_k = normalised(self._axis_ref + np.einsum("bkj,kjc->bkc", PA[..., :2], self._axis_basis))
        alpha_k = PA[..., 2]
        e_k, across_k = self._earth_along_across(PA[..., 3])
        kappa_k = g * np.cos(alpha_k)
        l, kappa, e = l_k[:, self._rot_group], kappa_k[:, self._rot_group], e_k[:, self._rot_group]   # (B,R,..)
        g_across = g * np.sin(alpha_k[:, self._rot_group])
        e1 = normalised(self._rot_e1 - np.einsum("rc,brc->br", self._rot_e1, l)[..., None] * l)
        e2 = cross(l, e1)
        phase = Xe[:, self._rot_phase_cols]                                      # (B,R,2)
        psi, chi = phase[..., 0:1], phase[..., 1:2]
        v = g_across[..., None] * (np.cos(psi) * e1 + np.sin(psi) * e2)
        earth_perp = across_k[:, self._rot_group, None] * (np.cos(chi) * e1 + np.sin(chi) * e2)
        earth_integral = self._rot_earth[:, :1] * earth_perp - self._rot_earth[:, 1:] * cross(l, earth_perp)
        offset = (np.einsum("brk,rkc->brc", Xe[:, self._offset_cols], self._offset_basis)
                  if self._offset is None else self._offset)
        l_x_d = cross(l, np.broadcast_to(offset, l.shape))
        w_k, wsq_k, wdot_k = (self._rot_rate_shape[:, j, :, None] for j in range(3))    # (R,PHASES,1)
        shift = self._window_shift(X)
        if shift is not None:       # the samples' window shifted: their rate's shape is c times the summary's
            c = self._rate_shape_factor(shift)[..., None, None]                 # (B,R,1,1)
            w_k, wsq_k, wdot_k = c * w_k, c * c * wsq_k, c * wdot_k             # (B,R,PHASES,1)
        f_r = (kappa[..., None, None] * l[:, :, None, :] + self._cos_p[:, None] * v[:, :, None, :]
               - self._sin_p[:, None] * cross(l, v)[:, :, None, :]
               + wsq_k * cross(l, l_x_d)[:, :, None, :] + wdot_k * l_x_d[:, :, None, :])   # (B,R,PHASES,3)
        if shift is not None:
            # the summary's phases are the gyro's turn scaled to the encoder's A, the samples turned
            # A + dt dw: gravity's true phase is c times the summary's (review of toffdc28)
            g_turn = -self._sin_p[:, None] * v[:, :, None, :] - self._cos_p[:, None] * cross(l, v)[:, :, None, :]
            step = shift[:, None] * self._rot_rate_change[None, :]                  # dt dw, (B,R)
            with np.errstate(invalid="ignore", divide="ignore"):     # c - 1, not c less 1 (rounding)
                c_less_1 = np.where(self._rot_turn_measured > 0, step / (self._rot_turn_measured - step), 0.0)
            f_r = f_r + c_less_1[..., None, None] * self._rot_angle_at_phase[None, :, :, None] * g_turn
        w_r = np.broadcast_to(((self._rot_rate + e)[..., None] * l)[:, :, None, :], f_r.shape)
        # the model's raw outputs at every point, effects included
        f_p = np.concatenate([f_s, f_r.reshape(B, -1, 3)], axis=1)              # (B, S + R PHASES, 3)
        w_p = np.concatenate([w_s, w_r.reshape(B, -1, 3)], axis=1)
        a = f_p @ Ma.transpose(0, 2, 1) + b_a[:, None, :]     # matmul: ~10x einsum here
        w = w_p @ Mg.transpose(0, 2, 1) + b_g[:, None, :]
        if self.effects:
            a, w = self._add_effects(X, a, w, f_p, w_p, Ma, Mg, l, w_k, wdot_k, offset, wsq_k)
        blocks = []
        # statics
        blocks.append((self._st_data[:, :3] - a[:, :S]) * self._st_weight[:, :3])
        if self.with_latitude:
            blocks.append((self._st_data[:, 3:] - w[:, :S]) * self._st_weight[:, 3:])
        elif self.hands:    # the bias, the unmodelled Earth rate within the noise
            blocks.append(np.einsum("sij,bsj->bsi", self._st_gyro_whiten, self._st_data[:, 3:] - w[:, :S]))
        else:               # only |Omega_E| known: the norm of the compensated rate (the
            # pseudo-inverse where a trial step of the solver makes M_g singular; the inverse by
            # LU otherwise, which complex step goes through: an SVD's does not)
            try:
                Mg_inv = np.linalg.inv(Mg)
            except np.linalg.LinAlgError:
                Mg_inv = np.linalg.pinv(Mg)
            rate = np.sqrt(np.einsum("bis,bis->bs", *2 * [Mg_inv @ (self._st_data[:, 3:] - b_g[:, None, :])
                                                           .transpose(0, 2, 1)]))
            blocks.append(((rate - self.omega_dps) * self._st_norm_weight)[..., None])
        table = self.attitudes == "table"
        if table:
            C_mount = matrix_from_rotvec(X[:, L["mounting_rotation"]])
            blocks.append(cross(up[:, self._st_up_index], np.einsum("uj,bij->bui", self._st_up_body, C_mount))
                          / self.prior_sigma)
        if self.with_latitude:
            blocks.append(P / WEAK_PRIOR_RAD)
        if self.hands:
            blocks.append(self._hand_block(Mg, b_g, up, w_s))
        if table:
            blocks.append(cross(l_k, np.einsum("kj,bij->bki", self._axis_body, C_mount)) / self.prior_sigma)
        blocks.append((e_k * np.sqrt(3.0) / self.omega_dps)[..., None])
        blocks.append((kappa_k / g / WEAK_PRIOR_RAD)[..., None])
        # rotations: mean and harmonics of the accelerometers, gyro integral
        a_r = a[:, S:].reshape(B, R, PHASES, 3)
        w_mean = w[:, S:].reshape(B, R, PHASES, 3).mean(axis=2)
        harmonics = self._harmonics @ a_r                                        # (B,R,5,3)
        integral = w_mean * self._rot_duration[:, None] + earth_integral @ Mg.transpose(0, 2, 1)
        for eff in self._integral_effects:
            batch = _own_batch(eff)
            if batch is not None:       # every row of X at once (TimeOffset: B x R calls of integral before)
                integral = integral + _checked(eff, batch, X[:, L[f"effect:{eff.id}"]], s.rotations)
                continue
            for n in range(B):
                px = X[n, L[f"effect:{eff.id}"]]
                for i, r in enumerate(s.rotations):
                    term = _checked(eff, eff.integral, px, r)
                    if term is not None:
                        integral[n, i] += term
        if shift is not None:
            # a term that is the samples' window shift times the measured rate's change counts the
            # Earth rate's change across the axis between the window's edges, which the Earth
            # integral above already takes over the samples' phases (their window, shifted), or
            # which a whole turn averages out: only the table rate's change, along M_g l, is the
            # shift's.  The measured change's part across M_g l is taken out (issue 28: nineteenth
            # session, the Earth's change at the phases 0 and A, which across the axis held a dry
            # run's time offset toward 0; twentieth, at the edge means' own phases, 1.5 samples
            # in, and in whole turns too, whose Earth rate is not modelled: at noise x 0.01 the
            # rest pulled a 10 ms offset 0.04 ms, 2 sigma, low)
            m = l @ Mg.transpose(0, 2, 1)                                        # (B,R,3)
            d = self._rot_edge_change
            along = np.einsum("brc,rc->br", m, d) / np.einsum("brc,brc->br", m, m)
            integral = integral - shift[:, None, None] * (d[None] - along[..., None] * m)
        gyro_rows = (self._rot_gyro_whiten @ (self._rot_gyro - integral)[..., None])[..., 0]
        whitened = np.einsum("rij,brjc->bric", self._rot_whiten, self._rot_data - harmonics) * self._rot_weight
        blocks.append(np.concatenate([whitened.reshape(B, R, 15),
                                      gyro_rows], axis=2))
        blocks.append((X[:, self._prior_cols] / self._prior_sigma)[..., None])
        # the table's elevation of each axis: alpha, its angle from up, is 90 deg - elevation
        blocks.append(((X[:, self._level_cols] - self._level_alpha) / (self.geometry.level_sigma_rad or 1.0))[..., None])
        return blocks

    def _window_shift(self, X):
        """The samples' window's shift against the encoder's (s) of every row of X, (B,), summed
        over the effects that say one (window_shift_s); None when none does."""
        total = None
        for eff in self._shift_effects:
            shift = [_checked(eff, eff.window_shift_s, X[n, self.layout[f"effect:{eff.id}"]]) for n in range(len(X))]
            if shift[0] is not None:
                shift = np.array(shift).reshape(len(X))
                total = shift if total is None else total + shift
        return total

    def _rate_shape_factor(self, shift):
        """(B, R): the factor c by which the table's rate at the samples exceeds the summary's rate
        shape under a window shift dt (issue 28, twentieth session).  The summary takes the rate's
        shape from the gyro scaled to the encoder's mean rate A/T (summaries._rate: the gyro's scale
        is not known there), but samples stamped in the encoder's window [t0, t1] were taken over
        [t0 + dt, t1 + dt] on the table's clock and turned A + dt (w(t1) - w(t0)): the table's rate
        at every sample is the shape times c = (A + dt dw) / A, its square c^2 times the shape's,
        its derivative c times.  A ramp of 100 deg/s at 10 ms: c - 1 = 1 deg / A, and the
        centripetal force at the mounting offset (w^2 l x (l x d): the accelerometers' mean) off
        by 2 (c - 1) of itself.  In the gyro's own units: A = I - dt dw, I the turn the samples
        measured (the gyro's scale and units cancel in the ratio).  A recorded ramp's rate is the
        table's stated one (RotationSummary.rate_from_table), which the shift does not change: 1."""
        step = shift[:, None] * self._rot_rate_change[None, :]                  # dt dw, (B,R)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = self._rot_turn_measured / (self._rot_turn_measured - step)
        return np.where(self._rot_turn_measured > 0, c, 1.0)

    def _earth_along_across(self, column):
        """The Earth rate along each axis and across it (B, K each) from the axes' fourth column.

        About the axes of earth_angle the column is beta, the angle from the table axis to the
        Earth's: Omega cos beta along, Omega sin beta across (a negative one is chi + pi).  It
        was e, with sqrt(Omega^2 - e^2) across, cut at 0: over short part turns the encoder's
        angle error alone leaves e uncertain by a large part of Omega (2" over 0.4 s: 0.33 Omega)
        and the solver could step past |e| = Omega, where nothing is left across the axis and
        neither e nor chi has a gradient there from the integrals across it, which are then made
        up by tilting the axis (300 deg/s, 120 degree turns about axes 26 deg from the Earth's:
        reduced chi2 40).  Elsewhere the column is e itself, unbounded (a capture of whole turns
        with a slipped encoder reads its error as e and fails its chi2 rather than stall at a
        bound)."""
        mask = self.earth_angle
        free = np.where(mask, 0.0, column)
        along = np.where(mask, self.omega_dps * np.cos(column), column)
        across = np.where(mask, self.omega_dps * np.sin(column), np.sqrt(positive_part(self.omega_dps**2 - free**2)))
        return along, across

    def _add_effects(self, X, a, w, f_p, w_p, Ma, Mg, l, w_k, wdot_k, offset=None, wsq_k=None):
        """a and w with every effect's terms added (the Effect interface: one parameter vector,
        all sample points; _checked: under complex step an unsafe term raises _ComplexUnsafe).
        An effect whose class gives the batch form (Effect.accel_batch, _own_term_batch) is called
        once for all B rows of X, with a context whose per-row fields have a leading B axis; the
        others once per row, with that context's row n (the same numbers)."""
        L, S, B = self.layout, len(self.s.statics), len(X)
        R = len(self.s.rotations)
        if offset is not None:      # the mounting offset at every point (statics: 0), (B, N, 3)
            offset = np.concatenate([np.zeros((B, S, 3), dtype=np.result_type(offset)),
                                     np.repeat(np.broadcast_to(offset, (B, R, 3)), PHASES, axis=1)], axis=1)
        zeros = np.zeros((B, S, 3))
        # the rate's square as the rows take it (the base model's mounting offset's, wsq_k) and the
        # rotation's axis: an effect's centripetal term (SampleContext.centripetal) over a recorded
        # ramp, where the square of the rate's harmonics is not its square's (twentieth session)
        # (the rate shapes are (R, PHASES, 1), or (B, R, PHASES, 1) where a window shift scales them
        # per row: _rate_shape_factor; wsq then (N,) shared or (B, N))
        if wsq_k is None:
            wsq = None
        elif wsq_k.ndim == 3:
            wsq = np.concatenate([np.zeros(S), np.broadcast_to(wsq_k[..., 0], (R, PHASES)).reshape(-1)])
        else:
            wsq = np.concatenate([np.zeros((B, S)), np.broadcast_to(wsq_k[..., 0], (B, R, PHASES)).reshape(B, -1)], axis=1)
        axis = None if wsq is None else np.concatenate(
            [zeros, np.broadcast_to(l[:, :, None, :], (B, R, PHASES, 3)).reshape(B, -1, 3)], axis=1)
        ctx = SampleContext(
            f_p=f_p, w_p=w_p,
            w_table=np.concatenate([zeros, (w_k * l[:, :, None, :]).reshape(B, -1, 3)], axis=1),
            wdot_table=np.concatenate([zeros, (wdot_k * l[:, :, None, :]).reshape(B, -1, 3)], axis=1),
            temp_c=self._ctx_temp, accel_matrix=Ma, gyro_matrix=Mg, t_s=self._ctx_t,
            segment_index=self._ctx_index, temp_rate_c_per_s=self._ctx_temp_rate, turned_s=self._ctx_turned,
            turned_sq_s2=self._ctx_turned_sq, offset_m=offset, wsq_table=wsq, axis_table=axis,
            ramp_products=self._ctx_ramp_products)
        rows = None                 # the per-row contexts, made when an effect has no batch form
        for eff in self.effects:
            P = X[:, L[f"effect:{eff.id}"]]
            for name, out in (("accel", a), ("gyro", w)):
                batch = _own_term_batch(eff, name)
                if batch is not None:
                    term = _checked(eff, batch, P, ctx)
                    if term is not None:
                        out = out + term
                else:
                    if rows is None:
                        rows = [dataclasses.replace(ctx, f_p=f_p[n], w_p=w_p[n], w_table=ctx.w_table[n],
                                        wdot_table=ctx.wdot_table[n], accel_matrix=Ma[n], gyro_matrix=Mg[n],
                                        offset_m=None if offset is None else offset[n],
                                        axis_table=None if axis is None else axis[n],
                                        wsq_table=wsq if wsq is None or wsq.ndim == 1 else wsq[n]) for n in range(B)]
                    term = getattr(eff, name)
                    out = out.copy()
                    for n in range(B):
                        t = _checked(eff, term, P[n], rows[n])
                        if t is not None:
                            out[n] = out[n] + t
                if name == "accel":
                    a = out
                else:
                    w = out
        return a, w

    def _hand_block(self, Mg, b_g, ups, w_static) -> np.ndarray:
        """(B, H, 2) whitened residuals: the up after each turn against the up before carried through it."""
        B, H = len(Mg), len(self.hands)
        dR = self.integrator.turns_batch(np.linalg.inv(Mg), b_g)         # B*H turns, (B*H,3,3)
        before = ups[:, self._hand_before].reshape(-1, 3)
        if self.with_latitude:      # the Earth turns the up during the turn
            earth = w_static[:, self._hand_before] * (np.pi / 180.0) * self.hand_duration[:, None]   # rad
            before = np.einsum("nij,nj->ni", matrix_from_rotvec(earth.reshape(-1, 3)), before)
        d = ups[:, self._hand_after] - np.einsum("nji,nj->ni", dR, before).reshape(B, H, 3)
        return np.einsum("hkc,bhc->bhk", self.hand_basis, d) / self.hand_sigma_rad[:, None]


def _lower_unit_rows_batch(angles: np.ndarray) -> np.ndarray:
    """lower_unit_rows of every row of angles (B,3): (B,3,3)."""
    s_yz, s_zy, s_zx = np.sin(angles[:, 0]), -np.sin(angles[:, 1]), np.sin(angles[:, 2])
    T = np.zeros((len(angles), 3, 3), dtype=angles.dtype)      # complex under complex step
    T[:, 0, 0] = 1.0
    T[:, 1, 0], T[:, 1, 1] = s_yz, np.sqrt(1.0 - s_yz**2)
    T[:, 2, 0], T[:, 2, 1] = s_zy, s_zx
    T[:, 2, 2] = np.sqrt(positive_part(1.0 - s_zy**2 - s_zx**2))
    return T


def _checked(effect, term, px, *args):
    """An effect's term (accel, gyro or integral) at px.  Under complex step (px complex) a term
    that comes back real, or a complex number cast to float on the way (TypeError, numpy's
    ComplexWarning, made an error while the complex batch runs), raises _ComplexUnsafe."""
    complex_step = np.iscomplexobj(px)
    try:
        out = term(px, *args)
    except (TypeError, np.exceptions.ComplexWarning):
        if complex_step:
            raise _ComplexUnsafe(effect.id)
        raise
    if complex_step and out is not None and not np.iscomplexobj(out):
        raise _ComplexUnsafe(effect.id)
    return out


class _ComplexUnsafe(Exception):
    """An effect dropped the imaginary part of the complex step (a cast to float, a real array
    returned): the Jacobian is then taken by forward differences."""

    def __init__(self, effect_id: str):
        super().__init__(effect_id)
        self.effect_id = effect_id


@dataclass
class FitResult:
    x: np.ndarray
    covariance: np.ndarray          # of the parameters in covariance_columns (internal units)
    model: Model
    chi2: float
    dof: int
    residuals: np.ndarray
    rank_deficient: list = field(default_factory=list)   # columns in the Jacobian's null space
    covariance_columns: np.ndarray | None = None         # None: every column, in order

    def covariance_of(self, columns) -> np.ndarray:
        """The covariance of these columns of x (a large model keeps it only for the columns
        that are not a segment's own nuisance: Model.local_columns)."""
        columns = np.asarray(columns, int)
        if self.covariance_columns is not None:
            where = {c: k for k, c in enumerate(self.covariance_columns)}
            columns = np.array([where[c] for c in columns], int)
        return self.covariance[np.ix_(columns, columns)]


class _Reduced:
    """The Jacobian for what is computed from it at the solution (covariance, null space, blind
    effect parameters).  A small model: J itself, every column.  A large one (Model.is_large,
    J sparse): the columns that are not a segment's own nuisance (G), with those nuisances (L)
    eliminated: J_G - J_L B, B the least-squares fit of J_G by J_L (normal equations of J_L,
    which are block-diagonal: one small block per segment, by sparse LU).  Its Gram matrix is
    the Schur complement of J^T J, so its SVD gives the covariance of G and the directions of G
    the data cannot see exactly as the whole Jacobian's would, at a cost linear in the segments."""

    def __init__(self, model: Model, J):
        if not model.is_large:
            self.J, self.columns, self.scale = np.asarray(J), np.arange(model.layout.size), None
            return
        from scipy.sparse import diags
        from scipy.sparse.linalg import splu

        local = model.local_columns()
        mask = np.ones(model.layout.size, bool)
        mask[local] = False
        self.columns = np.flatnonzero(mask)
        J = J.tocsc()
        J_L, J_G = J[:, local], J[:, self.columns].toarray()
        # J_L's columns scaled to unit norm (a zero one left out: it projects nothing)
        norms = np.sqrt(np.asarray(J_L.multiply(J_L).sum(axis=0))).ravel()
        J_L = J_L[:, np.flatnonzero(norms > 0)] @ diags(1.0 / norms[norms > 0])
        self._J_L = J_L
        try:
            self._lu = splu((J_L.T @ J_L).tocsc())
        except RuntimeError:              # nuisances the data cannot tell apart: least squares
            self._lu = None
        self.J = self._local_fit_removed(J_G)
        # what the reduced columns are measured against: their own size before the reduction
        # (a column the nuisances produce exactly is left as rounding, which its own norm would
        # blow up to a unit column: aliasing missed, a 1-sigma of 1e13 instead of none)
        self.scale = np.linalg.norm(J_G, axis=0)

    def _local_fit_removed(self, M: np.ndarray) -> np.ndarray:
        """M - J_L B, B the least-squares fit of M's columns by the nuisances' columns J_L."""
        J_L = self._J_L
        if self._lu is not None:
            return M - J_L @ self._lu.solve(np.asarray(J_L.T @ M))
        from scipy.sparse.linalg import lsmr

        B = np.column_stack([lsmr(J_L, M[:, k], atol=1e-14, btol=1e-14, maxiter=10 * J_L.shape[1])[0]
                             for k in range(M.shape[1])])
        return M - J_L @ B.reshape(J_L.shape[1], M.shape[1])

    def outside(self, M: np.ndarray) -> np.ndarray:
        """A large model's: M (rows x k) less its projection on the Jacobian's column space, what
        the model's parameters cannot produce (a score test's candidate columns).  That space is
        the nuisances' columns' and, orthogonal to it, the reduced columns' (self.J, measured
        against their size before the reduction: a column the nuisances produce adds nothing):
        a cost linear in the segments, where the whole Jacobian's SVD is cubic."""
        if "_basis" not in self.__dict__:
            u, sv, _ = np.linalg.svd(self.J / np.where(self.scale > 0, self.scale, 1.0), full_matrices=False)
            self._basis = u[:, sv > 1e-10 * sv[0]] if len(sv) else u
        W = self._local_fit_removed(np.asarray(M, float))
        return W - self._basis @ (self._basis.T @ W)

    @property
    def svd(self) -> "_ScaledSVD":
        """The scaled SVD of the reduced J (computed once)."""
        if "_svd" not in self.__dict__:
            self._svd = _ScaledSVD(self.J, self.scale)
        return self._svd

    def full(self, columns) -> list:
        """Columns of the reduced J (indices into it) back to columns of x."""
        return [int(self.columns[k]) for k in columns]


def reduced_at_solution(result: FitResult) -> _Reduced:
    """A large model's Jacobian at the solution with the segments' nuisances eliminated
    (_Reduced; computed once per result): what is read from the Jacobian after the fit, at a
    cost linear in the segments (e.g. _Reduced.outside, for the diagnosis' score tests)."""
    reduced = result.__dict__.get("_reduced")
    if reduced is None:
        reduced = result._reduced = _Reduced(result.model, result.model.sparse_jacobian(result.x))
    return reduced


FULL_CIRCLE_GRAM = np.diag([1.0, 0.5, 0.5, 0.5, 0.5])   # of 1, cos, sin, cos 2, sin 2 over whole turns


def _harmonic_whitening(gram) -> np.ndarray:
    """The symmetric square root of a rotation's Gram matrix per sample (whole revolutions when
    None): rows that whiten its harmonic coefficients (times sqrt(samples) / sigma)."""
    w, V = np.linalg.eigh(FULL_CIRCLE_GRAM if gram is None else np.asarray(gram, float))
    return (V * np.sqrt(np.clip(w, 0.0, None))) @ V.T


#: the solver's evaluation limit: a fit that reaches it is "not converged" (verdict.py).  imucal's
#: hand session (six poses, no usable turn) needs 209; twin captures 5 to 30
MAX_EVALUATIONS = 1000

#: LM is creeping (_lm) when CREEP_WINDOW evaluations in a row lower the lowest chi2 by less than
#: CREEP_GAIN chi2 units, a unit being max(1, chi2 / degrees of freedom): the change of chi2 that
#: moves a parameter by its 1-sigma (near a minimum chi2 - chi2_min = |delta / sigma|^2, and a
#: failing fit's 1-sigma is multiplied by sqrt(reduced chi2), verdict.py, so there the unit is the
#: reduced chi2).  The rule scales with the problem: an absolute 1e-6 of chi2 (the twelfth
#: session's rule) never fired on a failing fit (chi2 ~400: diagnose --auto's fits beside a bias
#: step at the wrong time gain 0.005-0.02 of chi2 per 25 evaluations, a pace at which 3,000
#: evaluations gain 0.9 and still go on, while dogbox from the crept point reaches the minimum,
#: 1.0 lower, in 37).  Firing is only a trigger, not a stop: where it fires the best point is
#: taken as the minimum only if a Gauss-Newton step from it would gain less than CREEP_CHI2 (a
#: parameter within sqrt(1e-6) = 1e-3 sigma of its minimum), else dogbox goes on from it and LM,
#: watched again, confirms.  So the threshold trades evaluations for a detour, not accuracy:
#: CREEP_GAIN = 0.05 units per 25 evaluations (2e-3 per evaluation; a point within 1 sigma of the
#: minimum moving 0.025 sigma per window or less) fires on those fits after ~50 evaluations and
#: on imucal's session as before; converging fits gain far more per window until they stop on
#: their tolerances (twin captures: 5 to 30 evaluations in all; Meyer's problem, 126, unwatched:
#: tests/test_lsq_creep.py)
CREEP_WINDOW = 25
CREEP_GAIN = 0.05
CREEP_CHI2 = 1e-6
#: where LM goes on after dogbox crept, a column whose scale (MINPACK keeps the largest norm the
#: column has had) exceeds its norm there STALE_SCALE times is scaled afresh by that norm: imucal's
#: annotated session (raw counts started at scale 1, 208 at the minimum) kept scales 1e5 times the
#: norms at the minimum and crept to the limit of 1,000 evaluations (chi2 1.1495); renewed, it
#: converges (chi2 1.068738) in 278, as LM restarted from scratch did.  The tilted Monte Carlo's
#: fits (tests/test_lsq_partial_arcs.py) keep ratios of 2-65 there: LM goes on with its state
STALE_SCALE = 100.0
#: the last phase (LM after dogbox crept too, or after LM crept again) was unwatched: a failing fit
#: ran there to the limit of 1,000 evaluations gaining hundredths of a chi2 unit (the eighteenth
#: session: a gyro bias step of +100 deg/h between the statics and the rotations, 550 evaluations
#: from chi2 1576.92 to 1576.76, 0.02 units, the written parameters moving < 0.01 sigma; the
#: Gauss-Newton step, which the at-minimum test reads, promised 29 of chi2 along the headings of two
#: statics where chi2 rises after 1 % of that step: the linear model does not see the valley).  It
#: is watched (_SettledWatch): it stops, "settled" and not converged, where its last CREEP_WINDOW
#: evaluations gained so little that MAX_EVALUATIONS more at that pace would gain less than
#: SETTLED_CHI2 chi2 units, that window gained less than SETTLED_SHARE of what the Gauss-Newton step
#: would (which is at least AT_MINIMUM_CHI2 units: a converging LM, e.g. imucal's annotated session
#: 79 evaluations into its last phase, gains what is left within a window), and that step moves no
#: written parameter by SETTLED_SIGMA of its 1-sigma (verdict.py's REMAINING_STEP_SIGMA: the file
#: then says the written parameters are at the minimum).  Otherwise LM goes on as before, on the
#: same path (its tolerances or the limit).  The nineteenth session found that where (i) and (ii)
#: hold LM crawls in a valley that is not the minimum's (the settled fits of the +100 and +150 deg/h
#: steps were 1.0-5.8 chi2 units above a minimum that dogbox from the start reaches in ~50
#: evaluations, written parameters 0.09-0.17 sigma away): there dogbox is tried from the solve's
#: start once (_dogbox_from_start), as where LM's first phase has spent half its evaluations
#: (_LMSolve.finish), and a solve that ends not converged (limit or settled) takes its end if lower
SETTLED_CHI2 = 0.05
SETTLED_SIGMA = 0.01
SETTLED_SHARE = 0.1
#: the first words of _solve's note for a fit that settled (verdict.py and diagnose read them)
SETTLED_NOTE = "the fit stopped where it crept"
#: a fit that met its tolerances is at a minimum when a Gauss-Newton step from it would gain less
#: than this many chi2 units: every parameter within 1e-2 sigma of it (verdict.py's rule for a fit
#: stopped at its limit: the written parameters within 1 % of their 1-sigma); beyond, the fit is
#: solved once more from there and, still short, reported not converged (issue 28)
AT_MINIMUM_CHI2 = 1e-4
#: _best_start's trial of each start (issue 27's heavy tail): every start is solved for up to
#: TRIAL_EVALUATIONS evaluations; one that has not converged by then while a finished start's
#: minimum is more than HOPELESS_RATIO times below its sum of squares is not finished.  Measured on
#: the 300 simulated part-turn captures of benchmarks/batch_throughput.py (optimal9, 5 s dwells and
#: rotations; docs/performance.md "Fifteenth session"): every start that ended at the lowest
#: minimum converged within 69 evaluations (from x0_plain: 52-69 where it was the lowest, 3 % of
#: captures, 0.13-4.5 % of chi2 below the others: a trial by chi2 at 20-50 evaluations, where it
#: is still 600-10^4 times above them, chose the wrong minimum on 2-9 of the 300); every start
#: still running after 100 evaluations ended above the others' minimum (by 3-20 %, or at the
#: 1,000-evaluation limit 900-3,400 times above it), 300-2.5*10^4 times above it at the 100th.
#: So: 100 (1.45 x the slowest winner) and 10 (30 x below the least hopeless at 100)
TRIAL_EVALUATIONS = 100
HOPELESS_RATIO = 10.0
#: _minimise's search of the other crossings (_other_crossing): every combination of flips of up to
#: CROSSING_SEARCH_AXES eligible axes (2^8 - 1 at most), then each axis alone until no flip lowers
#: the sum of squares.  A flip is screened by the sum of squares a Gauss-Newton step from it
#: predicts (one residual and one Jacobian: _predicted_cost) and solved whole only where that is
#: below CROSSING_SCREEN_RATIO times the lowest minimum found so far (of the combinations, the
#: best two so).  Measured (nineteenth session, docs/performance.md): on the 10 captures of
#: tests/test_lsq_partial_arcs.py whose axes are near the vertical (630 combinations, 60 single
#: flips, each also solved whole) the whole solve ended at 0.934-1.010 (combinations) and
#: 0.921-1.000 (single flips) times the predicted sum of squares, and the lowest prediction of
#: each capture's combinations was its lowest whole solve (the 3-evaluation solves that screened
#: them before ranked it first on 9 of 10); so a flip that ends below the minimum is predicted
#: below 1.09 times it, and 1.5 leaves a margin.  Every fit
#: ended where it did before, bit for bit (those 10, 64 more about vertical axes, 100 of
#: benchmarks/batch_throughput.py's part-turn captures, which have no eligible axis), with 47 % of
#: the residual evaluations and 47 % of the Jacobians on the 10 (4,545 -> 2,120; 3,819 -> 1,810).
#: The review (revarcs) found those ratios noise-free captures' only: on low-noise ones (noise x
#: 0.02-0.2) the whole solve of a combination ended at 0.0012-0.95 of its prediction (up to ~800
#: times above) and the lowest prediction was not the lowest whole solve; every fit still ended
#: below every combination (127 captures: 102 bit for bit, the rest within 1.3e-8 of chi2 either
#: way; no skipped flip's whole solve below the minimum by more than 4e-9), because the flips fall
#: back to the same minimum -- that, not the margin, is what held.  A capture whose better flip is
#: predicted that badly would be skipped: not seen, not excluded
CROSSING_SEARCH_AXES = 8
CROSSING_SCREEN_RATIO = 1.5
AXES_FIRST_GYRO_WEIGHT = 1e-3     # the rotations' gyro integrals' weight while the axes are fitted first
AXES_FIRST_EVALUATIONS = 10       # and that fit's evaluations: only a start (chi and e, barely held by
                                  #   the weak gyro rows, wander there without converging; 8 to 100 gave
                                  #   the same final fit of optimal9's part turns at 10-300 deg/s)


def _has_earth_phases(model: Model) -> bool:
    """Whether some rotation ends elsewhere than it starts (an Earth-rate phase chi among its
    nuisances)."""
    return any(sl.stop - sl.start == 2 for name, sl in model.layout.blocks.items() if name.startswith("phase"))


def _minimise(model: Model, x0: np.ndarray, solve):
    """solve(x0); where some rotation has an Earth-rate phase, also solve from the axes fitted
    first (_axes_first) and from the start as it was before the Earth-rate phases were started
    (Model.x0_plain: chi and e at 0), and keep the lowest sum of squares: no start alone found
    the right basin on every part-turn capture tried (single turns one way, axes near the
    vertical or the Earth's axis).  The three are tried before they are finished (_best_start): a
    start still far (10x) above a minimum found after its 100-evaluation trial is not solved to
    the evaluation limit.  So the old promise -- with the plain start among them no fit ends
    worse than from it alone -- holds only as measured, not by construction: a start dropped
    after its trial could in principle have ended lower (on 1,000 simulated part-turn captures
    none did: every fit ended at the minimum solving each start whole reached; docs/performance.md,
    "Fifteenth session: the starts")."""
    if not _has_earth_phases(model):
        return solve(x0)
    res = _best_start(model, [x0, _axes_first(model, x0, solve), model.x0_plain], solve)
    eligible = [k for k in range(model.s.groups) if _other_crossing(model, res.x, k) is not None]
    if 1 < len(eligible) <= CROSSING_SEARCH_AXES:
        tried = []
        for flips in itertools.product((False, True), repeat=len(eligible)):
            if not any(flips):
                continue
            x = res.x
            for k in itertools.compress(eligible, flips):
                x = _other_crossing(model, x, k)
                if x is None:
                    break
            if x is not None:
                tried.append((_predicted_cost(model, x), x))
        for predicted, x in sorted(tried, key=lambda t: t[0])[:2]:
            if predicted < CROSSING_SCREEN_RATIO * res.cost:
                other = solve(x)
                res = other if other.cost < res.cost else res
    improved = True
    while improved:           # then each axis alone, until no flip lowers the sum of squares
        improved = False
        for k in range(model.s.groups):
            start = _other_crossing(model, res.x, k)
            if start is not None and _predicted_cost(model, start) < CROSSING_SCREEN_RATIO * res.cost:
                other = solve(start)
                if other.cost < res.cost * (1 - 1e-9):
                    res, improved = other, True
    return res


def _own_term_batch(effect, name: str):
    """The effect's batch form of accel (name "accel") or gyro ("gyro"), or None (Effect.batch_term:
    a plugin that subclasses a library effect and overrides accel alone gets its accel called row
    by row, not its parent's batch).  An effect not derived from Effect (duck-typed) has none."""
    find = getattr(effect, "batch_term", None)
    return None if find is None else find(name)


def _own_batch(effect):
    """The effect's integral_batch where the class that defines its integral defines it too (a
    plugin that subclasses TimeOffset and overrides integral alone gets integral called, not its
    parent's batch: review of arcs); else None."""
    for cls in type(effect).__mro__:
        if "integral" in vars(cls) or "integral_batch" in vars(cls):
            return effect.integral_batch if "integral_batch" in vars(cls) else None
    return None


def _predicted_cost(model: Model, x: np.ndarray) -> float:
    """The sum of squares (halved, as a solve's cost) a Gauss-Newton step from x would reach by
    the linear model: _minimise's screen of a crossing's flip (CROSSING_SCREEN_RATIO).  The
    Jacobian the solver left (the one at its solution, Model._last_jacobian) is kept."""
    last = model._last_jacobian
    try:
        r = model.residuals(x)
        J = model.sparse_jacobian(x) if model.is_large else model.jacobian(x)
        left = r + J @ _gauss_newton_step(J, r)
    finally:
        model._last_jacobian = last
    return 0.5 * float(left @ left)


class _Whole:
    """A start solved whole at its first trial (_best_start's trial for a solve that cannot pause:
    the large models' trf, or an _lm a test replaced)."""

    crept = False

    def __init__(self, solve, start):
        self.solve, self.start, self.result = solve, start, None

    def trial(self, n: int) -> float:
        self.result = self.solve(self.start)
        return self.chi2

    @property
    def chi2(self) -> float:
        return 2.0 * self.result.cost

    def finish(self):
        return self.result


def _best_start(model: Model, starts: list, solve):
    """The lowest minimum from the starts, each tried first (TRIAL_EVALUATIONS): the starts are
    finished in the order of their sum of squares after the trial, a start whose trial ended
    more than HOPELESS_RATIO times above the lowest minimum found so far is not finished, unless
    every minimum found failed (stopped at the limit, or short of a minimum).  A start whose LM
    crept within its trial (paused there by _lm's watch, its dogbox detour still to come) is
    finished: its sum of squares there says little of where the detour takes it (cap0057 of the
    300 part-turn captures: from x0_plain, 10^4 times above the others where the watch fired, its
    detour and LM reach the lowest minimum, 3.4 % below theirs, at 69 evaluations).  Equal
    minima: the earlier start's."""
    begin = getattr(solve, "begin", None)
    tries = [begin(x) if begin is not None else _Whole(solve, x) for x in starts]
    for t in tries:
        t.trial(TRIAL_EVALUATIONS)
    best, best_i, left = None, None, []
    for i in sorted(range(len(tries)), key=lambda i: (tries[i].chi2, i)):
        t = tries[i]
        if best is not None and t.result is None and not t.crept and t.chi2 > HOPELESS_RATIO * 2.0 * best.cost:
            left.append(i)
            continue
        res = t.finish()
        if best is None or res.cost < best.cost or (res.cost == best.cost and i < best_i):
            best, best_i = res, i
    if left and _failed(best):
        for i in left:
            res = tries[i].finish()
            if res.cost < best.cost or (res.cost == best.cost and i < best_i):
                best, best_i = res, i
    return best


def _failed(res) -> bool:
    """A dense solve's result that stopped at its evaluation limit or short of a minimum."""
    return res.status == 0 or (isinstance(res.jac, np.ndarray) and not _at_minimum(res, AT_MINIMUM_CHI2))


def _other_crossing(model: Model, x: np.ndarray, k: int):
    """About an axis near the vertical turned both ways by part turns, the start at the other
    solution of its gyro integrals (None elsewhere).

    With gravity along the axis the accelerometers do not see where each turn starts (psi), so
    nothing ties the Earth rate's phases chi to them.  Across the axis a segment's integral is
    c_i d + f_i |u| exp(i chi_i) (Model._earth_phase_start), |u| known from e: each integral puts
    the tilt d on a circle of radius |f_i| |u| / |c_i| about z_i / c_i, and a turn each way two
    circles crossing at two points, each fitting the integrals exactly.  The accelerometers see
    the axis (gravity along it) and tell them apart, but only through a misfit the calibration
    and the mounting offset can partly take: from the other point the solver stays there
    (noise-free, axes within 12 deg of the vertical at 10 deg/s: reduced chi2 0.12-1.6 where it
    is 0).  So the fit is also started at the other point, d reflected across the line of the
    circles' centres, and its chi from there."""
    s, L = model.s, model.layout
    axis = L[f"axis{k}"]
    segs = [i for i, r in enumerate(s.rotations)
            if r.group == k and L[f"phase{i}"].stop - L[f"phase{i}"].start == 2]
    if not _earth_angle_group(s, k) or not segs or np.sin(x[axis.start + 2])**2 > 0.04:
        return None
    x = x.copy()
    _, Mg = model._matrices(x)
    Lg, bg = np.linalg.inv(Mg), x[L["gyro_bias"]]
    ref, (t1, t2) = model.axis_ref[k], model.axis_basis[k]
    l = normalised(ref + x[axis.start] * t1 + x[axis.start + 1] * t2)
    e1 = normalised(t1 - (t1 @ l) * l)
    e2 = cross(l, e1)
    rots = [s.rotations[i] for i in segs]
    T = np.array([r.duration_s for r in rots])
    A = np.radians([r.angle_deg for r in rots])
    e, across = (float(v[0, k]) for v in model._earth_along_across(x[model._axis_cols][None, :, 3]))
    c = (np.array([r.rate_dps for r in rots]) + e) * T
    f = _earth_factor(rots)
    y = np.array([Lg @ (r.gyro_integral - bg * r.duration_s) for r in rots]) - c[:, None] * l
    z = y @ e1 + 1j * (y @ e2)
    a, b = int(np.argmax(c)), int(np.argmin(c))
    p1, p2 = z[a] / c[a], z[b] / c[b]
    if c[a] <= 0 or c[b] >= 0 or p1 == p2 or across == 0.0:
        return None
    u = (p2 - p1) / abs(p2 - p1)
    d = p1 + u * np.conj(-p1 / u)          # d = 0 (the axis now) reflected across the centres' line
    # a turn about the axis without an Earth-rate phase (whole turns, or a trace below the noise:
    # _earth_rate_visible) has no chi to take the tilt: its integral across the axis moves by A d,
    # so where that is beyond three of its noise (the gyro's over T and the encoder's angle) the
    # reflected point fits no integral of it and there is no other crossing (issue 28: the
    # designer's chunks turn each axis in steady whole-turn pairs beside ramp windows; 12 urad of
    # tilt put 1.5e5 of chi2 on a whole turn's integral, and each of 26 vertical axes' flips cost
    # a whole fit back to the same minimum: 1,523 evaluations where 50 reach it)
    for i, r in enumerate(s.rotations):
        if r.group == k and r.steady and L[f"phase{i}"].stop - L[f"phase{i}"].start != 2:   # (a hand turn's angle is nominal)
            noise = np.sqrt(np.max(s.gyro_sigma)**2 * r.duration_s / s.sample_rate_hz + s.table_angle_sigma_deg**2)
            if abs(r.angle_deg) * abs(d) > 3.0 * noise:
                return None
    tilted = l + d.real * e1 + d.imag * e2
    x[axis.start:axis.start + 2] = [tilted @ t1 / (tilted @ ref), tilted @ t2 / (tilted @ ref)]
    for i, chi in zip(segs, np.angle(z - c * d) - np.angle(f)):
        x[L[f"phase{i}"].start + 1] = chi
    return x


def _axes_first(model: Model, x0: np.ndarray, solve) -> np.ndarray:
    """Where some rotation ends elsewhere than it starts (an Earth-rate phase chi among its
    nuisances), a start fitted with the rotations' gyro integrals at a small weight.  Their part
    across the axis is the Earth rate's integral over the part turn, which chi turns about the
    axis and a tilt of the axis l (shared by the segments about it) can stand in for: from a start
    with l a little off, the fit can settle in a basin where chi and the tilt make up the integrals
    together and the accelerometers, which see the true axis, keep a misfit (noise-free captures
    of single turns one way, or about tilted axes: reduced chi2 0.7 to 16 from the start alone).  The accelerometers
    (the plane in which gravity turns, gravity along the axis) and the statics put the axes where
    they are first; with l right each chi has one basin.  The model and its weights are the
    same after (the gyro integrals still determine chi and e in this first fit)."""
    whiten = model._rot_gyro_whiten
    model._rot_gyro_whiten = whiten * AXES_FIRST_GYRO_WEIGHT
    model._last_jacobian = None
    try:
        x = solve(x0, AXES_FIRST_EVALUATIONS).x
    finally:
        model._rot_gyro_whiten = whiten
        model._last_jacobian = None
    # the weak gyro rows can leave M_g singular (2 deg/s over 20 degrees about vertical axes:
    # singular values 0.84, 0.33, 1e-17): no start there, the fit starts from the others
    if not np.all(np.isfinite(x)) or np.linalg.matrix_rank(model._matrices(x)[1]) < 3:
        return x0
    # the gyro integrals' weight was small: chi may have wandered; started again at these axes
    return model._earth_phase_start(x.copy())


class _Creeping(Exception):
    """Raised by _CreepWatch around dogbox (solver.dogbox or scipy's): its iterations creep."""


class _CreepWatch:
    """The lowest chi2 seen and where; creeping when CREEP_WINDOW evaluations in a row lowered it by
    less than CREEP_GAIN chi2 units (max(1, reduced chi2) at the lowest point: the change of chi2
    that moves a parameter by 1 sigma).  ``seen`` is the numpy LM's watch (it pauses the solve,
    its state kept); called as the residual function it wraps ``fun`` and raises _Creeping (for
    dogbox, which is not paused but abandoned)."""

    def __init__(self, fun):
        self.fun, self.n = fun, 0
        self.best_chi2, self.best_x = np.inf, None
        self.history: list[float] = []          # the lowest chi2 after each evaluation

    def seen(self, x, r, norm=None) -> bool:
        """Record an evaluation (residuals r at x); whether the solve creeps."""
        self.n += 1
        chi2 = float(r @ r) if norm is None else norm * norm
        if chi2 < self.best_chi2:
            self.best_chi2, self.best_x = chi2, np.array(x, float)
        self.history.append(self.best_chi2)
        return (len(self.history) > CREEP_WINDOW
                and self.history[-1 - CREEP_WINDOW] - self.best_chi2 < CREEP_GAIN * self.unit(r, x))

    def __call__(self, x):
        r = self.fun(x)
        if self.seen(x, r):
            raise _Creeping
        return r

    def unit(self, r, x) -> float:
        """The chi2 unit at the lowest point: max(1, chi2 / degrees of freedom)."""
        dof = len(r) - len(x)
        return max(1.0, self.best_chi2 / dof) if dof > 0 else 1.0


#: the detour's dogbox: solver.dogbox (numpy, the algorithm of scipy's without bounds: no scipy import,
#: ~0.3 s of CPU of a small capture's estimate) when True, scipy.optimize.least_squares(method=
#: "dogbox", x_scale="jac") when False (docs/method-lsq.md, fourteenth session)
NUMPY_DOGBOX = True


def _dogbox(fun, x0, jac, *, max_nfev: int, canonical=None, **tolerances):
    """Dogbox (x_scale="jac") from x0: solver.dogbox (its points in ``canonical``'s chart:
    Model.canonical), or scipy's when NUMPY_DOGBOX is off."""
    if NUMPY_DOGBOX:
        return solver.dogbox(fun, x0, jac, max_nfev=max_nfev, canonical=canonical, **tolerances)
    from scipy.optimize import least_squares

    return least_squares(fun, x0, jac=jac, method="dogbox", x_scale="jac", max_nfev=max_nfev, **tolerances)


def _lm(model: Model, start: np.ndarray, evaluations: int = MAX_EVALUATIONS):
    """MINPACK's Levenberg-Marquardt (x_scale="jac", tolerances 1e-10), watched for creeping.

    On a few captures (imucal's example session: six poses and three turns; part turns near the
    Earth's axis) LM creeps along a curved valley of directions the data barely see (the gyro
    misalignments, the inter-triad rotation and the turn axes' tilts trading against one
    another): each step is held short by the valley's curvature, the sum of squares falls by
    ~3e-8 of chi2 per evaluation, and it stopped at MAX_EVALUATIONS (imucal's session: 1,000
    evaluations, 1.5 s, 0.009 of chi2 above the minimum, 0.08 sigma short of it along the
    valley).  When CREEP_WINDOW evaluations in a row gain less than CREEP_GAIN chi2 units (the
    constants, above) LM pauses (solver.LevenbergMarquardt keeps its state) and its point is
    taken as the minimum if a Gauss-Newton step from it would gain less than CREEP_CHI2 (the
    step is not taken); else the dogleg of scipy's "dogbox" (solver.dogbox, in numpy: steps in
    the trust region's box, not damped along the valley's steep sides: 43 evaluations there to
    the minimum; 37 on a failing fit of diagnose --auto where LM gained 0.9 of chi2 in 3,000)
    goes on from it, watched the same way, and LM resumes from dogbox's lowest point with the
    scaling, radius and damping it had (the fourteenth session: it restarted from scratch
    before, and relearnt them at the cost of tens of evaluations per fit), watched again.  When it creeps again it is at the minimum
    by the same test, or goes on unwatched with the evaluations left (as before the watch: its
    tolerances, or the limit and status 0, not converged).  Where dogbox creeps too, LM goes on
    unwatched from dogbox's lowest point at once, its stale column scales renewed (STALE_SCALE).
    The tilted Monte Carlo of tests/test_lsq_partial_arcs.py: 3,499 residual evaluations with the
    restart, 1,606 resumed, 1,569 for LM unwatched (benchmarks/solver_evaluations.py).  A fit
    that converges without creeping takes exactly the path it always did.  (_LMSolve: the same
    solve, which can first be run for a trial of a few evaluations and then finished.)"""
    return _LMSolve(model, start, evaluations).finish()


_numpy_lm = _lm


class _LMSolve:
    """_lm's solve as an object: ``trial(n)`` runs its first LM phase until n evaluations (or until
    it converges or creeps) and pauses there with LM's state kept; ``finish()`` goes on as _lm
    would have (evaluation for evaluation the same path as an uninterrupted _lm: the pause is LM's
    own, solver.LevenbergMarquardt.run's watch).  _minimise tries its starts so (TRIAL_EVALUATIONS)."""

    def __init__(self, model: Model, start: np.ndarray, evaluations: int = MAX_EVALUATIONS):
        self.model, self.evaluations = model, evaluations
        self.options = dict(xtol=1e-10, ftol=1e-10, gtol=1e-10)      # (solver scales by the columns)
        self.lm = solver.LevenbergMarquardt(model.residuals, start, model.jacobian, **self.options,
                                            canonical=getattr(model, "canonical", None))
        self.watch = _CreepWatch(model.residuals)
        self.watch.seen(self.lm.x, self.lm.f, self.lm.fnorm)
        self.result = None            # once finished (or converged within a trial)
        self.crept = False            # the first phase paused by the creep watch

    @property
    def chi2(self) -> float:
        """The lowest sum of squares LM has accepted so far (where a trial paused)."""
        return self.lm.fnorm ** 2

    @property
    def nfev(self) -> int:
        return self.lm.nfev

    def trial(self, n: int) -> float:
        """Run the first phase until LM has made n evaluations in all; returns chi2 there."""
        if self.result is not None or self.crept:
            return self.chi2
        lm, watch = self.lm, self.watch

        def pause(x, f, norm):
            self.crept = watch.seen(x, f, norm)
            return self.crept or lm.nfev >= n

        if lm.run(self.evaluations, pause) is not None:
            self.result = lm.result()
        return self.chi2

    def finish(self):
        """The solve to its end (_lm's result)."""
        if self.result is not None:
            return self.result
        lm, watch = self.lm, self.watch
        half = self.evaluations // 2 if self.evaluations >= MAX_EVALUATIONS else 0

        def pause(x, f, norm):
            self.crept = watch.seen(x, f, norm)
            return self.crept or 0 < half <= lm.nfev     # (>=: the chart adds an evaluation to a step)

        while not self.crept and self.result is None:
            if lm.run(self.evaluations, pause) is not None:
                self.result = lm.result()
            elif not self.crept:
                # half its evaluations spent, LM neither converged nor crept: a steady descent
                # (chatfield18's failing fit: 0.4-1.7 chi2 units per window to the limit).  Dogbox
                # from the start; its end is the fit's where it converged below LM's point (else
                # LM goes on, its path unchanged, and dogbox's end is kept for the limit).  Until
                # the review of this session LM went on unless, at the pace of its last window, it
                # could not reach dogbox's end: on 16 failing captures (chatfield18, optimal9,
                # traditional24 with bias steps) it went on 3 times and ended above dogbox's end
                # each time, twice at its limit (1,033 and 1,045 evaluations where ~540 did)
                half = 0
                here = lm.result()
                other = _dogbox_from_start(self.model, lm, here)
                if other is not None and other.status > 0 and other.cost < here.cost:
                    self.result = other
        if self.result is None:
            self.result = _detours(self.model, lm, self.evaluations, self.options)
        if self.evaluations >= MAX_EVALUATIONS and (self.result.status == 0 or getattr(lm, "from_start", None) is not None):
            # not converged (at the limit, or settled): dogbox from the start, once (a short solve,
            # a trial of AXES_FIRST_EVALUATIONS or CROSSING_SEARCH_EVALUATIONS, stops there by design);
            # converged where the second solve already ran (half its evaluations): its end where lower
            # and converged too (not a lower point at dogbox's limit for a converged LM)
            other = _dogbox_from_start(self.model, lm, self.result)
            if other is not None and (self.result.status == 0 or other.status > 0):
                self.result = other
        return self.result


def _detours(model: Model, lm, evaluations: int, options: dict):
    """_lm after its first LM phase crept (lm paused there): the Gauss-Newton test, dogbox's
    detour and LM resumed, as _lm's docstring says."""
    for detour in (False, True):
        res = lm.result()             # LM's point: the lowest it accepted
        if _at_minimum(res):
            # at the minimum: a Gauss-Newton step would gain less than CREEP_CHI2 units of chi2
            # (the parameters within ~1e-3 sigma of it); LM was only failing its relative
            # tolerance on a small sum of squares (a poses-only fit whose gyro block rests on wide
            # priors: chi2 0.18, ftol 1e-10 asks for 1e-11).  The step is not taken (along
            # directions only wide priors hold it is not a small step)
            res.status = 2
            return res
        if detour or lm.nfev >= evaluations:
            break
        dog = _CreepWatch(model.residuals)
        try:
            alt = _dogbox(dog, lm.x, model.jacobian, max_nfev=max(evaluations - lm.nfev, 1),
                          canonical=getattr(model, "canonical", None), **options)
        except _Creeping:
            # dogbox creeps too (diagnose --auto's fits beside a bias step at a wrong time, GN's
            # step gaining ~17 of chi2 ~470): LM goes on unwatched from the lowest point, with
            # what is left of the evaluations (its own tolerances, or the limit: not converged),
            # its scaling renewed where it is stale (STALE_SCALE)
            lm.nfev += dog.n
            if dog.best_chi2 < lm.fnorm**2:
                lm.move_to(dog.best_x, rescale=STALE_SCALE)
            break
        lm.nfev += alt.nfev
        if dog.best_chi2 < lm.fnorm**2:
            lm.move_to(alt.x, alt.fun)        # LM resumes from dogbox's point with its state
        again = _CreepWatch(model.residuals)
        again.seen(lm.x, lm.f, lm.fnorm)
        if lm.run(evaluations, again.seen) is not None:
            return lm.result()
    return _last_phase(model, lm, evaluations)


def _last_phase(model: Model, lm, evaluations: int):
    """LM on after both solvers crept: to its tolerances or the limit, as before the watch, unless
    it settles first (_SettledWatch): then its result has status 0 (not converged) and ``settled``
    True, which _solve says in the fit's notes.  Pausing to test does not change LM's path (its
    state is kept): a fit that does not settle takes, evaluation for evaluation, the path it took."""
    watch = _SettledWatch(model, lm)
    while lm.run(evaluations, watch.seen) is None:
        res = lm.result()             # LM's point: the lowest it accepted (its Jacobian, kept by LM)
        settled = watch.settled(res)
        if watch.crawling and evaluations >= MAX_EVALUATIONS:
            # LM crawls: its pace would not gain SETTLED_CHI2 units in MAX_EVALUATIONS more and the
            # linear model does not describe its path (tests (i), (ii)): dogbox from the start, once
            other = _dogbox_from_start(model, lm, res)
            if other is not None:
                return other
        if settled:
            res.status, res.settled, res.window_gain = 0, True, watch.window_gain
            return res
    return lm.result()


def _dogbox_from_start(model: Model, lm, res):
    """A second solve where LM has not converged (its last phase crawls, _SettledWatch.crawling;
    it has spent half its evaluations in its first phase, _LMSolve.finish; or it stopped at its
    limit or settled): dogbox from where LM started (lm.x0), with a budget of its own
    (MAX_EVALUATIONS: another solve, as _best_start's other starts have, not counted against LM's,
    whose path and limit stay as they were), watched: abandoned where it creeps while its sum of
    squares is not below LM's (res); its result (``nfev``: LM's and its own evaluations), where it
    ends below LM's point, else None.  Run once per solve (lm.tried_from_start); its end is kept
    (lm.from_start) for a later call, which returns it where it is below that call's res.

    LM on a failing fit (a missing effect: chi2 units of 6-35) can enter a valley along the
    statics' attitudes (nuisances) where the linear model is wrong (its Gauss-Newton step raises
    chi2 by 10^2-10^6; the eighteenth session's "settled" fits stopped there); the dogleg in its
    box from the start does not enter it.  On the captures of docs/performance.md "Nineteenth
    session" it converged in 37-81 evaluations, 0.005-5.8 chi2 units below where LM settled, crawled
    or stopped at its limit (and below where 6,000 unwatched LM evaluations end)."""
    if getattr(lm, "tried_from_start", False):
        other = lm.from_start          # (tried at half LM's evaluations: its end kept)
        if other is None or other.cost >= res.cost:
            return None
        other.nfev = lm.nfev + lm.from_start_nfev
        return other
    lm.tried_from_start, lm.from_start, lm.from_start_nfev = True, None, 0
    floor = 2.0 * res.cost
    watch = _CreepWatch(model.residuals)

    def fun(x):
        r = model.residuals(x)
        if watch.seen(x, r) and watch.best_chi2 >= floor:
            raise _Creeping
        return r

    try:
        other = _dogbox(fun, lm.x0, model.jacobian, max_nfev=MAX_EVALUATIONS, canonical=getattr(model, "canonical", None),
                        xtol=lm.xtol, ftol=lm.ftol, gtol=lm.gtol)
    except _Creeping:
        lm.from_start_nfev = watch.n
        return None
    lm.from_start, lm.from_start_nfev = other, other.nfev
    if other.cost >= res.cost:
        return None
    other.nfev = lm.nfev + lm.from_start_nfev
    return other


class _SettledWatch(_CreepWatch):
    """_CreepWatch's record with _last_phase's rule.  ``seen`` pauses LM where its last CREEP_WINDOW
    evaluations lowered the lowest chi2 by less than SETTLED_CHI2 * CREEP_WINDOW / MAX_EVALUATIONS
    chi2 units (MAX_EVALUATIONS more at that pace would gain less than SETTLED_CHI2), at most once
    per window (``settled`` costs an SVD of the Jacobian).  ``settled`` then says whether to stop:
    when the Gauss-Newton step from LM's point (i) would gain at least AT_MINIMUM_CHI2 units (below,
    _solve's own test takes the point for a minimum: LM is left to its tolerances, as before), (ii)
    more than 1 / SETTLED_SHARE times what the window gained (LM realises a small share of what
    the linear model says is left: it creeps along a curve that model does not see, where a
    converging LM gains what is left within a few steps), and (iii) moves no written parameter
    by SETTLED_SIGMA of its 1-sigma."""

    def __init__(self, model: Model, lm):
        super().__init__(model.residuals)
        self.written = _reported_columns(SimpleNamespace(model=model))
        self.seen(lm.x, lm.f, lm.fnorm)
        self.tested_at = 0
        self.window_gain = self.gauss_newton_gain = self.step_sigma = None      # at the last test
        self.crawling = False         # at the last test: (i) and (ii) held

    def seen(self, x, r, norm=None) -> bool:
        super().seen(x, r, norm)
        if len(self.history) <= CREEP_WINDOW or len(self.history) - self.tested_at < CREEP_WINDOW:
            return False
        self.window_gain = self.history[-1 - CREEP_WINDOW] - self.best_chi2
        return self.window_gain < SETTLED_CHI2 * CREEP_WINDOW / MAX_EVALUATIONS * self.unit(r, x)

    def settled(self, res) -> bool:
        """The test at LM's point (res: fun and jac there), as the class says."""
        self.tested_at = len(self.history)
        svd = _ScaledSVD(np.asarray(res.jac))
        keep = svd.sv > 1e-12 * svd.sv[0]                 # (lstsq's rcond in _gauss_newton_step)
        c = svd.u[:, keep].T @ res.fun
        self.gauss_newton_gain = float(c @ c)
        unit = self.unit(res.fun, res.x)
        self.crawling = not (self.gauss_newton_gain < AT_MINIMUM_CHI2 * unit
                             or self.window_gain >= SETTLED_SHARE * self.gauss_newton_gain)
        if not self.crawling:
            return False
        step = -(svd.vt[keep].T @ (c / svd.sv[keep])) / svd.norms
        with np.errstate(invalid="ignore", divide="ignore"):
            moved = np.abs(step[self.written]) / np.sqrt(np.diag(svd.covariance())[self.written])
        moved = moved[np.isfinite(moved)]
        self.step_sigma = float(moved.max()) if moved.size else 0.0
        return self.step_sigma < SETTLED_SIGMA


def _gauss_newton_gain(res, svd: "_ScaledSVD | None" = None) -> float:
    """The chi2 a Gauss-Newton step from res (a least_squares-like result: fun, jac) would gain
    by the linear model: g^T (J^T J)^+ g with g = J^T r, zero at a minimum (the gradient is).
    ``svd``: the scaled SVD of res.jac when one is at hand (_solve's, for the covariance), read
    instead of another factorisation of J when it is of that very matrix."""
    fun, jac = res.fun, np.asarray(res.jac)
    if svd is not None and svd.u is not None and np.array_equal(svd.J, jac):
        return svd.gauss_newton_gain(fun)
    left = fun + jac @ _gauss_newton_step(jac, fun)
    return float(fun @ fun - left @ left)


def _at_minimum(res, chi2_units: float = None, svd: "_ScaledSVD | None" = None) -> bool:
    """Whether a Gauss-Newton step from res would gain less than ``chi2_units`` (CREEP_CHI2 by
    default) chi2 units, a unit max(1, chi2 / degrees of freedom) (_CreepWatch.unit: a failing
    fit's 1-sigma is scaled by its square root): every parameter within ~sqrt(CREEP_CHI2) = 1e-3
    sigma of the minimum (chi2 - chi2_min = |delta / sigma|^2 near it).  ``svd``: _gauss_newton_gain's."""
    fun, jac = res.fun, np.asarray(res.jac)
    dof = len(fun) - jac.shape[1]
    unit = max(1.0, float(fun @ fun) / dof) if dof > 0 else 1.0
    return _gauss_newton_gain(res, svd) < (CREEP_CHI2 if chi2_units is None else chi2_units) * unit


def _solve(model: Model, x0: np.ndarray):
    """(x, covariance of reduced.columns, residuals, reduced Jacobian) at the solution."""
    if model.is_large:
        # each step solved to rounding (LSMR's default, as many iterations as parameters, stops
        # short on ill-conditioned models such as hand-pose logs: 100 steps and twice the chi2)
        def solve(start, evaluations=MAX_EVALUATIONS):
            from scipy.optimize import least_squares     # (large models only)

            return least_squares(model.residuals, start, jac=model.sparse_jacobian, method="trf", tr_solver="lsmr",
                                 tr_options={"atol": 1e-14, "btol": 1e-14, "maxiter": 10 * model.layout.size},
                                 x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=evaluations)
        res = _minimise(model, x0, solve)
        stopped_short = False         # (the check needs the dense Jacobian)
        reduced = _Reduced(model, model.sparse_jacobian(res.x))
    else:
        def solve(start, evaluations=MAX_EVALUATIONS):
            return _lm(model, start, evaluations)
        # the numpy LM pauses for _best_start's trials; an _lm replaced (tests) is solved whole
        solve.begin = (lambda start: _LMSolve(model, start)) if _lm is _numpy_lm else None
        res = _minimise(model, x0, solve)
        # the Jacobian at the solution (the solver's last, kept by Model.jacobian) factorised once:
        # the at-minimum test, the covariance, the null space and the leverages read its SVD
        reduced = _Reduced(model, model.jacobian(res.x))
        stopped_short = res.status != 0 and not _at_minimum(res, AT_MINIMUM_CHI2, reduced.svd)
        if stopped_short:
            # stopped by its tolerances where a Gauss-Newton step still gains: once more from there
            again = solve(res.x)
            if again.cost <= res.cost:
                res = again
                reduced = _Reduced(model, model.jacobian(res.x))
            stopped_short = res.status != 0 and not _at_minimum(res, AT_MINIMUM_CHI2, reduced.svd)
        model.solution_svd = reduced.svd       # (_solution_svd: the noise groups' leverages)
    model.stopped_short = res.status != 0 and not model.is_large and stopped_short
    model.converged = res.status != 0 and not model.stopped_short
    model.remaining_step = None
    model.stop_note = None        # the note saying where the solver stopped (at its limit, or settled)
    model.settled = res.status == 0 and getattr(res, "settled", False)
    if model.settled:     # _last_phase: said how it stopped
        model.remaining_step = _gauss_newton_step(res.jac, res.fun)
        note = (f"{SETTLED_NOTE}, {res.nfev} evaluations into its last solve (at most {MAX_EVALUATIONS} each): "
                f"its last phase crept along a valley the linear model does not see (its last {CREEP_WINDOW} "
                f"evaluations lowered chi2 by {res.window_gain:.2g}, less than {SETTLED_SHARE:g} of what a "
                f"Gauss-Newton step promises, a pace at which {MAX_EVALUATIONS} more would lower it by less than "
                f"{SETTLED_CHI2:g} of a chi2 unit, max(1, reduced chi2)), and that step moves no written "
                f"parameter by {SETTLED_SIGMA:g} of its 1-sigma; not a minimum, so not converged; the values "
                "and 1-sigma are those where it stopped")
        if note not in model.notes:
            model.notes.append(note)
        model.stop_note = note
    elif res.status == 0:       # max_nfev: said, not hidden (a stress test found statics-only captures there)
        model.remaining_step = _gauss_newton_step(res.jac, res.fun)
        note = (f"the fit stopped at its limit of {MAX_EVALUATIONS} evaluations before it converged (a direction the "
                "data barely see: with static attitudes only, the poses' headings and the gyro block); "
                "the values and 1-sigma are those where it stopped")
        if note not in model.notes:
            model.notes.append(note)
        model.stop_note = note
    elif not model.converged:
        # the solver's tolerances were met (a step or a reduction too small) but not at a minimum:
        # a Gauss-Newton step from there still gains more than AT_MINIMUM_CHI2 chi2 units (issue
        # 28: a noisy fit from a start in the wrong basin ended at reduced chi2 1.2e7 "converged")
        model.remaining_step = _gauss_newton_step(res.jac, res.fun)
        gain = _gauss_newton_gain(res)
        note = (f"the fit stopped on its tolerances where a Gauss-Newton step still lowers chi2 by {gain:.3g} "
                f"(chi2 {2 * res.cost:.6g}): not at a minimum, so not converged; the values and 1-sigma are "
                "those where it stopped")
        if note not in model.notes:
            model.notes.append(note)
    return res.x, reduced.svd.covariance(), res.fun, reduced


def _gauss_newton_step(J, r) -> np.ndarray:
    """The step a converged fit would still take from where the solver stopped: the least-squares
    solution of J d = -r (minimum norm: a direction the data do not see takes no step).  Read
    against each parameter's 1-sigma it says whether the values written are at the minimum even
    though the solver stopped (verdict.py: the written parameters within 1 % of their 1-sigma)."""
    if not isinstance(J, np.ndarray):              # a large model's sparse Jacobian
        from scipy.sparse.linalg import lsmr

        return lsmr(J, -r, atol=1e-14, btol=1e-14, maxiter=10 * J.shape[1])[0]
    J = np.asarray(J)
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    d, *_ = np.linalg.lstsq(J / norms, -r, rcond=1e-12)
    return d / norms


class _ScaledSVD:
    """The SVD of J with its columns scaled by their norms (or ``scale``: _Reduced's; a zero one
    taken as 1), from which the covariance and the null space are read: computed once per
    Jacobian (each reading took its own SVD: four per fit)."""

    def __init__(self, J: np.ndarray, scale=None):
        self.J = J
        self.norms = np.array(np.linalg.norm(J, axis=0) if scale is None else scale, float)
        self.norms[self.norms == 0] = 1.0
        u, self.sv, self.vt = np.linalg.svd(J / self.norms, full_matrices=False)
        # the left singular vectors of a dense model's J (scaled by its column norms: scale None)
        # are kept for what else is read from that J at the solution, without another
        # factorisation of it (issue 27: three per fit before): the Gauss-Newton gain of the
        # at-minimum test and the leverages of the noise groups (noise_groups.leverages, the same
        # SVD of the same matrix, so the same numbers to the last bit).  Not a large model's
        # (its reduced J has a row per measurement)
        self.u = u if scale is None else None

    def gauss_newton_gain(self, r) -> float:
        """_gauss_newton_gain through this SVD (J the solver's at r): the chi2 a Gauss-Newton step
        would gain by the linear model, ||U_k^T r||^2 over the singular values above 1e-12 of the
        largest (lstsq's rcond=1e-12 there)."""
        keep = self.sv > 1e-12 * self.sv[0] if self.sv.size else self.sv.astype(bool)
        c = self.u[:, keep].T @ r
        return float(c @ c)

    def covariance(self) -> np.ndarray:
        """(J^T J)^-1 (J^T J would square J's condition).  A direction the data cannot see at
        all (a zero singular value, e.g. a nuisance with a zero column) gets zero variance and
        leaves the others untouched."""
        keep = self.sv > 1e-13 * self.sv[0]
        v = self.vt[keep].T / self.sv[keep]
        return (v @ v.T) / np.outer(self.norms, self.norms)

    def null(self) -> np.ndarray:
        """The directions the data cannot see at all (rows, in scaled columns)."""
        return self.vt[self.sv < 1e-9 * self.sv[0]]

    def null_columns(self) -> list:
        """Columns that take part in a direction the data cannot see at all: their value is not
        determined, whatever covariance() says."""
        null = self.null()
        zero = np.flatnonzero(np.linalg.norm(self.J, axis=0) == 0)
        return sorted(set(zero.tolist()) | set(np.flatnonzero(np.max(np.abs(null), axis=0) > 1e-6).tolist()
                                                if null.size else []))


def covariance(J: np.ndarray, scale=None) -> np.ndarray:
    """(J^T J)^-1 through the SVD of the column-scaled J (_ScaledSVD.covariance)."""
    return _ScaledSVD(J, scale).covariance()


def _null_columns(J: np.ndarray, scale=None) -> list:
    """_ScaledSVD.null_columns of J."""
    return _ScaledSVD(J, scale).null_columns()


def _effect_columns(model: Model, effects=None):
    """(column, Param) of every parameter of ``effects`` (default: the model's)."""
    for e in model.effects if effects is None else effects:
        sl = model.layout[f"effect:{e.id}"]
        for k, p in enumerate(e.params):
            yield sl.start + k, p


def _held(model: Model) -> list:
    """(column, Param) of the effect parameters held by their prior (model.unobservable)."""
    return [(c, p) for c, p in _effect_columns(model) if p.name in model.unobservable and c in model.priors]


def _blind_effect_parameters(model: Model, reduced: _Reduced) -> list:
    """Effect parameters the data cannot reveal: in the null space of the Jacobian (exactly
    aliased with other parameters), or with a 1-sigma above their typical size."""
    if not model.effects:
        return []
    null, cov = reduced.svd.null(), reduced.svd.covariance()
    where = {int(c): k for k, c in enumerate(reduced.columns)}
    blind = []
    for c, p in _effect_columns(model):
        if c in model.priors:
            continue
        j = where[c]          # (an effect's columns are never a segment's own nuisance)
        aliased = null.size and np.max(np.abs(null[:, j])) > 1e-6
        if aliased or np.sqrt(cov[j, j]) * p.scale > p.typical:
            blind.append((c, p))
    return blind


CONTRADICTED = 3.0      # a prior of 0 +/- typical that the fit ends beyond this many widths from


def _contradicted_priors(model: Model, x) -> list:
    """(column, Param) of the effect parameters held by the prior of _blind_effect_parameters that
    the data pull beyond CONTRADICTED prior widths from zero all the same, of every effect but the
    last (the one added to the others): the capture does
    reveal them, at a size the typical one does not describe, and the prior would only bias them
    (and what is correlated with them).  Judged at the start, an accelerometer K3_z beside a
    scale that follows temperature over a warm-up (1-sigma 150 ug/g^3 against the typical 100)
    was held and fitted at 1,599 for 3,500, the temperature slope of the z accelerometer took
    the rest (-198 ppm/degC for 0) and the fit failed (reduced chi2 4.1 against 0.93 freed;
    benchmarks/diagnose_goal.py, K3+gyro_scale_tempco)."""
    out = []
    # the last effect is the newcomer (--add's order, the loop's refit of its model and a candidate):
    # its parameters stay held where the capture cannot resolve them; a bias drift over a warm-up
    # fitted freely at 9,000 ug/h for a bias quadratic in temperature (typical 100: held, it is
    # rejected and temperature_bias kept, tests/test_effects_recovered.py)
    # -- unless the data measure them alone and the fit then passes: _newcomer_released
    for c, p in _effect_columns(model, model.effects[:-1]):
        if p.name in model.unobservable and c in model.priors and model.priors[c] == p.typical / p.scale \
                and abs(x[c]) > CONTRADICTED * model.priors[c]:
            out.append((c, p))
    return out


NEWCOMER_REVEALED = 2.0    # the newcomer's released only where the data alone give each 1-sigma below this many typical sizes


def _newcomer_released(model: Model, x, cov, r, reduced):
    """(x, cov, r, reduced) with the newcomer's held parameters (the last effect's, which
    _contradicted_priors leaves held) released, all together, where the data measure them: a
    held parameter's prior is contradicted by its own check (the pull of held_pulls beyond
    held_pull_limit), and with every prior of the newcomer removed no parameter of it is aliased
    (null space), each one's 1-sigma is within NEWCOMER_REVEALED typical sizes, and the fit
    explains the data (verdict.chi2_verdict does not fail).  Else they stay held, as before.
    (Issue 28, twenty-first session: a table encoder 1000 ppm short, 1-sigma 10.4 ppm against
    its typical 10, was held and read 481 +- 7 ppm, chi2 4,899/93.)"""
    if not model.effects or not model.unobservable:
        return x, cov, r, reduced
    where = {int(c): k for k, c in enumerate(reduced.columns)}
    held = [(c, p) for c, p in _effect_columns(model, model.effects[-1:])
            if p.name in model.unobservable and c in model.priors and model.priors[c] == p.typical / p.scale]
    pulls = {}
    for c, p in held:
        tau2 = float(model.priors[c]) ** 2
        data = tau2 - float(cov[where[c], where[c]])
        if data > HELD_PULL_MIN_SHARE * tau2:
            pulls[c] = float(x[c] / np.sqrt(data))
    if not any(abs(w) > held_pull_limit(len(pulls)) for w in pulls.values()):
        return x, cov, r, reduced
    from station.estimate.distributions import P_FAIL, REDUCED_CHI2_FAIL
    from station.estimate.distributions import chi2_verdict as _rule

    def chi2_verdict(chi2, dof):
        return _rule(chi2, dof, P_FAIL, REDUCED_CHI2_FAIL)

    # (the priors and the data rows as they were, in their order: x, cov, r and reduced are theirs)
    priors, unobservable, data_rows = dict(model.priors), list(model.unobservable), model.data_rows

    def restored():
        model.priors.clear()
        model.priors.update(priors)
        model.unobservable[:] = unobservable
        model.refresh()
        model.data_rows = data_rows
        return x, cov, r, reduced

    # the released fit's chi2 foreseen from the held one's (linearised: the prior rows removed, their
    # residuals e = x_H / tau and their hat matrix P_HH / tau^2: chi2 - e^T (I - P_HH / tau^2)^-1 e),
    # so a release that fails is not solved for (a creeping fit: ~350 evaluations)
    cols = [c for c, _ in held]
    tau = np.array([priors[c] for c in cols])
    k = [where[c] for c in cols]
    e = x[cols] / tau
    hat = cov[np.ix_(k, k)] / np.outer(tau, tau)
    foreseen = float(r @ r) - float(e @ np.linalg.solve(np.eye(len(cols)) - hat, e))
    dof = int(np.count_nonzero(data_rows)) - model.layout.size + _held_by_weak_priors(model, reduced, cov)
    if dof <= 0 or chi2_verdict(foreseen, dof)["result"] == "fails":
        return x, cov, r, reduced
    for c, p in held:
        del model.priors[c]
        model.unobservable.remove(p.name)
    model.refresh()

    def revealed(red):          # none aliased, each 1-sigma within NEWCOMER_REVEALED typical sizes
        at, null, c_ = {int(c): k for k, c in enumerate(red.columns)}, red.svd.null(), red.svd.covariance()
        return all(not (null.size and np.max(np.abs(null[:, at[c]])) > 1e-6)
                   and np.sqrt(c_[at[c], at[c]]) * p.scale <= NEWCOMER_REVEALED * p.typical for c, p in held)

    # judged first where the held fit ended (no solve: the gate barely depends on where the fit ends)
    if not revealed(_Reduced(model, model.sparse_jacobian(x) if model.is_large else model.jacobian(x))):
        return restored()
    x1, cov1, r1, reduced1 = _solve(model, x)
    dof = int(np.count_nonzero(model.data_rows)) - model.layout.size + _held_by_weak_priors(model, reduced1, cov1)
    data = r1[model.data_rows]
    if revealed(reduced1) and dof > 0 and chi2_verdict(float(data @ data), dof)["result"] != "fails":
        model.notes.append("released, the data contradicting their prior and measuring them: "
                           + ", ".join(p.name for _, p in held))
        return x1, cov1, r1, reduced1
    return restored()


HELD_PULL_P = 1e-3      # the family-wise false-alarm rate of the held priors' pull test (held_pulls)
HELD_PULL_MIN_SHARE = 1e-6      # the data's least share of a held parameter's information to be tested


def held_pulls(result: "FitResult") -> dict:
    """{name: pull} of every effect parameter held by its prior (model.unobservable: 0 +/- tau,
    tau its typical size) that the data inform at all: the prior row's normalised residual
    x / sqrt(tau^2 - P), x its posterior value and P its posterior variance (issue 28, nineteenth
    session).  For one parameter it is d / sqrt(tau^2 + sigma_d^2), d +/- sigma_d what the data
    alone say of it (x = d tau^2 / (tau^2 + sigma_d^2), P = tau^2 sigma_d^2 / (tau^2 + sigma_d^2)):
    the prior-predictive check of the prior.  Standard normal (linearised) when the parameter is
    of its typical size, as the prior says; narrower when it is 0 (for one held parameter its
    variance is sigma_d^2 / (tau^2 + sigma_d^2), at least 1/2 since its sigma_d exceeds tau; held
    parameters the data see only together can be far narrower: optimal9's even rate-squared terms,
    sigma_d 0.68 tau given the others' priors, their pulls' sd 0.17 at 0, docs/design.md); so a pull beyond
    held_pull_limit says the capture contradicts the typical size and that holding it at 0 biases
    what is correlated with it.  A parameter whose information the data hold less than
    HELD_PULL_MIN_SHARE of (sigma_d above 1,000 tau: x is then the prior's within the solver's
    tolerance, and no effect of a typical size's thousands exists) is not tested."""
    model = result.model
    out = {}
    for c, p in _held(model):
        tau2 = float(model.priors[c]) ** 2
        data = tau2 - float(result.covariance_of([c])[0, 0])        # tau^4 / (tau^2 + sigma_d^2)
        if data > HELD_PULL_MIN_SHARE * tau2:
            out[p.name] = float(result.x[c] / np.sqrt(data))
    return out


def held_pull_limit(tested: int) -> float:
    """The |pull| beyond which a held prior is contradicted (held_pulls): the two-sided
    HELD_PULL_P point of a standard normal, Bonferroni over the ``tested`` parameters (3.29 for
    one, 3.76 for six)."""
    from station.estimate.distributions import norm_ppf

    return norm_ppf(1.0 - HELD_PULL_P / (2.0 * max(tested, 1)))


def contradicted_held(result: "FitResult") -> tuple[dict, float]:
    """({name: pull} of the held parameters whose pull is beyond held_pull_limit, the limit)."""
    pulls = held_pulls(result)
    limit = held_pull_limit(len(pulls))
    return {n: w for n, w in pulls.items() if abs(w) > limit}, limit


def fit(s: Summaries, effects: list[Effect] | None = None, attitudes: str = "auto",
        like: Model | None = None, turn_sigma_deg: float | None = None, pose_extra=None,
        start_from: FitResult | None = None) -> FitResult:
    """Fit the model.  An effect parameter this capture cannot reveal (aliased with others, or
    1-sigma above its typical size) gets a prior of zero +/- its typical size, is named in
    ``model.unobservable``, and the fit is repeated: the parameters the capture does reveal then
    carry the uncertainty of the ones it does not, instead of a bias from fixing them.  Which
    ones are blind barely depends on where the fit ends, so the start is examined first.
    ``like``: a model of the same summaries with other effects (a refit that adds or removes
    one), whose start and initial nuisances are taken (Model's like: the same fit, less work).
    ``turn_sigma_deg``: the hand turns' 1-sigma per turn (station/estimate/noise_model.py), or
    None: estimated from the turns' scatter when they scatter beyond their white noise.
    ``start_from``: another fit of these poses (the joint fit, for the poses' own fit), whose
    values start this one where they mean the same (start_blocks): from the algebraic start the
    poses-only fit of imucal's session took 167 evaluations, from the joint fit's values 40, to the
    same minimum (the accelerometer block within 1e-10 sigma, every parameter within 4e-5 sigma).
    ``pose_extra``: the variance added to every pose mean (6,), another fit's (the poses' own fit
    is weighted as the joint one was: station/estimate/poses.py), not estimated here.  Else,
    when the poses' halves show a sensor's bias moving (noise_model), its static means' scatter
    between the poses is estimated: the accelerometers' from the poses alone (a fit of the
    statics only: no turn or rotation can push them there, and the pose check compares the
    accelerometer block with that fit), the gyros' in the joint fit (without turns or rotations
    the poses see the gyro only through the Earth rate's magnitude)."""
    model = Model(s, list(effects or []), attitudes, like=like)
    if start_from is not None:
        start_blocks(model, start_from)
    model.turn_source, model.turn_scatter_before, model.reweighted = None, None, {}
    statics = [] if pose_extra is not None else _static_groups(model)
    if "static accel" in statics and (s.rotations or s.hand_rotations):
        own = fit(dataclasses.replace(s, rotations=[], hand_rotations=[], skipped=[]),
                  copy.deepcopy(list(effects or [])), attitudes)
        pose_extra = model.pose_extra.copy()
        pose_extra[:3] = own.model.pose_extra[:3]
        if "static accel" in own.model.reweighted:
            model.reweighted["static accel"] = own.model.reweighted["static accel"]
        statics = [g for g in statics if g != "static accel"]
    if pose_extra is not None:
        model.set_pose_extra(pose_extra)
    if model.hands and turn_sigma_deg is not None:
        model.set_turn_sigma(turn_sigma_deg)
        model.turn_source = "stated"
    model.unobservable = []
    if not s.rotations and not s.hand_rotations:
        # nothing turned by a known angle: the gyro block is held only by wide priors (so the fit
        # stays solvable); station.estimate.verdict then leaves it out of the calibration
        L = model.layout
        for block, width in NO_ROTATION_PRIORS.items():
            for c in range(L[block].start, L[block].stop):
                model.priors[c] = width
        model.refresh()
    rows, columns = len(model.residuals(model.x0)), model.layout.size
    if rows < columns:
        raise UserError(f"the capture cannot determine the model: {rows} measurements for {columns} "
                        "unknowns (record more static attitudes or rotations, or add fewer effects)")
    reduced = None            # (the start's Jacobian: only to look for blind effect parameters)
    if model.effects:
        reduced = _Reduced(model, model.sparse_jacobian(model.x0) if model.is_large else model.jacobian(model.x0))
    x = None
    while True:
        blind = _blind_effect_parameters(model, reduced)
        if not blind and x is not None:
            break
        for c, p in blind:
            model.priors[c] = p.typical / p.scale
            model.unobservable.append(p.name)
        model.refresh()
        x, cov, r, reduced = _solve(model, model.x0)
    released = _contradicted_priors(model, x)
    if released:
        for c, p in released:
            del model.priors[c]
            model.unobservable.remove(p.name)
        model.refresh()
        x, cov, r, reduced = _solve(model, model.x0)
    x, cov, r, reduced = _newcomer_released(model, x, cov, r, reduced)
    x, cov, r, reduced = _reweight(model, x, cov, r, reduced, turns=turn_sigma_deg is None, statics=statics)
    x, cov, r, reduced = _ramp_reweight(model, x, cov, r, reduced)
    if (model.ramp_estimate or {}).get("estimated") and model.unobservable:
        x, cov, r, reduced = _revealed_by_ramps(model, x, cov, r, reduced)
    dof = len(r[model.data_rows]) - model.layout.size + _held_by_weak_priors(model, reduced, cov)
    r = r[model.data_rows]      # the weak priors on nuisance angles are not data
    if not s.rotations and not s.hand_rotations:     # the gyro block's wide priors are not data
        dof -= sum(model.layout[b].stop - model.layout[b].start for b in NO_ROTATION_PRIORS)
    cov, held = _held_values_freed(model, x, cov, reduced)
    dof -= held
    return FitResult(x=x, covariance=cov, model=model, chi2=float(r @ r), dof=dof, residuals=r,
                     rank_deficient=reduced.full(reduced.svd.null_columns()),
                     covariance_columns=reduced.columns if model.is_large else None)


def _held_values_freed(model: Model, x: np.ndarray, cov: np.ndarray, reduced: "_Reduced"):
    """(covariance, how many values) with the values an effect holds where a profile located them
    but the data determine (``Effect.held_values``: a bias step's time inside a segment, where the
    share of that segment's samples after it is a continuous number the segment's own means fix)
    freed: each one's column of the Jacobian (central differences of the residuals over its
    ``h``) joins the fit's, and the covariance of the parameters becomes the block of the
    enlarged one's inverse (a rank-one update per value: C + u u^T / d, u = C J^T c, d = |c|^2 -
    c^T J u, c less what the nuisances of a large model produce), so the step's 1-sigma is that
    of a fit with the time free, not of one that knows it (issue 28: the size's 1-sigma was up to
    ~30 % below its scatter).  Each value's own 1-sigma, 1/sqrt(d) scaled by nothing (the
    nominal noise, as the covariance), is set on the effect (``<name>_sigma``).  The fitted values
    are those at the located time (a profile's best split).  Then ``Effect.held_covariance``
    ((layout blocks, matrix in their internal units)) is added to those blocks' covariance: what the located value's
    uncertainty beyond that neighbourhood adds (a bias step's size over the other times the
    profile found about as likely)."""
    freed = 0
    for effect in model.effects:
        values = effect.held_values() if callable(getattr(effect, "held_values", None)) else ()
        for name, h in values:
            v0 = getattr(effect, name)
            try:
                setattr(effect, name, v0 + h)
                up = model.residuals(x)
                setattr(effect, name, v0 - h)
                down = model.residuals(x)
            finally:
                setattr(effect, name, v0)
            c = (up - down) / (2.0 * h)
            if model.is_large:
                c = reduced._local_fit_removed(c[:, None])[:, 0]
            Jc = reduced.J.T @ c
            u = cov @ Jc
            d = float(c @ c - Jc @ u)
            if not np.isfinite(d) or d <= 1e-12 * float(c @ c):
                # the data cannot tell the value from the parameters: its 1-sigma is unbounded
                setattr(effect, f"{name}_sigma", float("inf"))
                continue
            cov = cov + np.outer(u, u) / d
            setattr(effect, f"{name}_sigma", float(1.0 / np.sqrt(d)))
            freed += 1
        extra = effect.held_covariance() if callable(getattr(effect, "held_covariance", None)) else None
        if extra is not None and getattr(effect, "location_spread_of", None) == segments_key(model.s):
            # (only for the capture it was computed from: design --from locates a step in the
            # capture and fits it with the segments it adds)
            # what the located value's own uncertainty beyond its linear neighbourhood adds (a
            # bias step's size over the other times about as likely as the located one)
            blocks, extra = extra
            columns = [c for b in blocks for c in range(model.layout[b].start, model.layout[b].stop)]
            where = {int(c): k for k, c in enumerate(reduced.columns)}
            if len(columns) == len(extra) and all(c in where for c in columns):
                at = np.array([where[c] for c in columns], int)
                cov = cov.copy()
                cov[np.ix_(at, at)] += extra
    return cov, freed


def segments_key(s: Summaries) -> tuple:
    """The segments of summaries (name, mean time): what a profile's numbers belong to."""
    return tuple((x.name, float(x.t_mid_s)) for x in (*s.statics, *s.rotations))


def start_blocks(model: Model, other: FitResult) -> None:
    """Start ``model`` (x0) at ``other``'s values of every block both have (not the effects'),
    when their static attitudes are offsets from the same references (without the latitude:
    the ups of the same accelerometer start) and every shared block has one size; else nothing
    is changed (the calibration alone, with the attitudes of the algebraic start, started
    imucal's poses-only fit worse: 600 evaluations).  A start only: the fit still goes to its
    own minimum."""
    theirs, mine = other.model.layout, model.layout
    shared = [name for name in mine.blocks if not name.startswith("effect:") and name in theirs.blocks]
    if (model.with_latitude or other.model.with_latitude
            or len(model.static_ref) != len(other.model.static_ref)
            or not np.array_equal(np.asarray(model.static_ref, float), np.asarray(other.model.static_ref, float))
            or any(mine[n].stop - mine[n].start != theirs[n].stop - theirs[n].start for n in shared)):
        return
    for name in shared:
        model.x0[mine[name]] = other.x[theirs[name]]


def _held_by_weak_priors(model: Model, reduced: _Reduced, cov: np.ndarray) -> int:
    """How many parameters the weak priors on nuisance angles hold rather than the data (they
    are not data, so what they hold takes no degree of freedom from it): the weak rows' share of
    the fit's hat matrix, tr(C J_w^T J_w), C the covariance and J_w the weak rows' Jacobian,
    rounded (1 for a parameter the data do not see at all, 0 for one they determine).  Before,
    only gravity along an axis turned by hand alone was counted, and part turns one way only at
    300 deg/s, whose Earth rate along each axis rests on its prior, were short of 6 of 87
    (pooled reduced chi2 1.16 over six seeds; 1.08 now).  A large model (sparse, its nuisances
    eliminated from the covariance): that one case."""
    s = model.s
    if model.is_large:
        return sum(1 for k in range(s.groups) if not any(rot.steady for rot in s.rotations if rot.group == k))
    Jw = reduced.J[~model.data_rows]
    return int(round(float(np.sum((Jw @ cov) * Jw)))) if len(Jw) else 0


def _static_groups(model: Model) -> list:
    """The static groups whose noise may be estimated from their scatter: a sensor whose poses'
    halves show its bias moving within a pose (noise_model.PoseInstability.sensor_p)."""
    inst = model.noise.instability
    if inst is None:
        return []
    limit = noise_model.P_TERM / 2.0
    return [g for g, p in zip(("static accel", "static gyro"), inst.sensor_p) if p < limit]


def _reweight(model: Model, x, cov, r, reduced, turns: bool, statics: list):
    """Groups whose noise is estimated from their own scatter (noise_model): the hand turns'
    1-sigma per turn (``turns``: not stated), and a sensor's static means when its poses' halves
    show that its bias moves within a pose (the mechanism seen in data the fit does not use; its
    size between poses, over the session, is what the group's scatter says).  While such a group
    scatters beyond its stated noise (p < noise_groups.P_NAMED), its variance is raised by what
    its variance component says is missing (the harmonic mean of its rows' variances times
    s^2 - 1: exact when they are equal) and the model refitted from where it is.  Every other
    group keeps its stated noise and is tested against it.  ``statics``: the static groups that
    may be reweighted here (_static_groups, less those estimated elsewhere)."""
    from station.estimate.noise_groups import P_NAMED, variance_components

    def components(x):
        J = None if model.is_large else np.asarray(model.jacobian(x))
        out = variance_components(model.row_labels(x), model.residuals(x), J, parameters=model.layout.size,
                                  by_axis=statics, svd=_solution_svd(model, J), ramps=_ramp_names(model))
        if J is not None:       # kept for to_calibration's fit.noise_groups at the same x
            model.components_at = (np.array(x, copy=True), [{k: v for k, v in c.items() if k != "axes"} for c in out])
        return {c["group"]: c for c in out}

    def axis_ratios(g):
        """A static group's scatter squared per sensor axis (x, y, z): each axis's bias wanders
        by its own amount (an MPU's z gyro more than its x and y); an axis whose rows are too
        few to say, or a group without axes (|w| only), takes the group's."""
        c = comps.get(g, {})
        axes = c.get("axes", {})
        return np.array([axes.get(a, {}).get("scatter", c.get("scatter", 1.0)) ** 2 for a in "xyz"])

    eligible = (["hand turn"] if model.hands and turns else []) + list(statics)
    if not eligible:
        return x, cov, r, reduced
    comps = components(x)
    active = [g for g in eligible if g in comps and _scatters(comps[g], P_NAMED)]
    model.reweighted.update({g: {"scatter_before": float(comps[g]["scatter"])} for g in active})
    if "hand turn" in active:
        model.turn_source, model.turn_scatter_before = "estimated", float(comps["hand turn"]["scatter"])
    if not active:
        return x, cov, r, reduced
    s = model.s
    base, turn = model.pose_extra.copy(), 0.0
    extra = base.copy()
    samples = np.array([st.samples for st in s.statics], float)
    sigma = np.concatenate([s.accel_sigma, s.gyro_sigma]).astype(float)
    for _ in range(noise_model.TURN_ITERATIONS):
        ratios = {g: (np.array([comps.get(g, {}).get("scatter", 1.0) ** 2]) if g == "hand turn" else axis_ratios(g))
                  for g in active}
        if all(np.all(np.abs(v - 1.0) < noise_model.TURN_TOLERANCE) for v in ratios.values()):
            break
        for g, s2 in ratios.items():
            if g == "hand turn":
                current = model._hand_var_deg2 + turn
                turn = max(0.0, turn + (s2[0] - 1.0) * len(current) / float(np.sum(1.0 / current)))
            else:
                k = np.arange(3) + (0 if g == "static accel" else 3)
                current = sigma[k][None, :] ** 2 / samples[:, None] + extra[k][None, :]     # (poses, 3)
                step = (s2 - 1.0) * len(current) / np.sum(1.0 / current, axis=0)
                extra[k] = np.maximum(base[k], extra[k] + step)
        if model.hands:
            model.set_turn_sigma(np.sqrt(turn))
        model.set_pose_extra(extra)
        x, cov, r, reduced = _solve(model, x)
        comps = components(x)
    for g in active:        # a group whose noise needed nothing added keeps its test
        if g == "hand turn":
            if turn <= 0.0:
                del model.reweighted[g]
            continue
        k = slice(0, 3) if g == "static accel" else slice(3, 6)
        if np.all(extra[k] <= base[k]):
            del model.reweighted[g]
        else:
            model.reweighted[g]["extra"] = (extra[k] - base[k]).tolist()
    return x, cov, r, reduced


def _ramp_names(model: Model) -> frozenset:
    """The rotations whose gyro integrals are the "ramp gyro" group: a recorded ramp whose angle
    carries a stated placement 1-sigma (RotationSummary.angle_sigma_deg > 0; noise_groups)."""
    return frozenset(getattr(model, "ramp_windows", None) or ())


RAMP_SOLVES = 3         # whole fits at most while the ramps' placement factor is estimated (_ramp_reweight)


def _ramp_reweight(model: Model, x, cov, r, reduced):
    """The recorded ramps' placement variance from their own scatter (issue 28, eighteenth session).

    A recorded ramp's angle carries the placement of the table's reads on the IMU's clock, stated
    per window as angle_sigma_deg: deliberately conservative (station/bench/ramp_angle.py:
    w / sqrt 12 per read, not divided by the reads; on the twins the windows' errors were 0.22-0.5
    of it in rms), and how the host's latencies spread them cannot be known beforehand.  So the
    windows' variance is taken as N_i + k^2 sigma_i^2 along the axis (N_i the gyro's white noise,
    bias instability and encoder: known) and k^2 is estimated from the windows' residuals
    (noise_groups.placement_component, Helmert/REML; up or down), the fit repeated from where it
    is until k^2 moves by less than noise_model.TURN_TOLERANCE, as _reweight does for the hand
    turns.  From residuals: what the model takes of the placement -- a part common to every
    window is the time offset's, when it is in the model -- is not counted as scatter.

    Only where the windows are enough to say: k^2's relative 1-sigma is sqrt(2 / f), f the
    estimate's degrees of freedom; with f below noise_groups.RAMP_MIN_DOF (at the stated 1-sigma,
    or at the estimate) the stated 1-sigma is kept (conservative) and the group is tested
    against it as any other; an estimated one is left out of the verdict's test (verdict_test:
    model.reweighted).  ``model.ramp_estimate``: {"k", "dof", "windows", "estimated", ...} (None
    without such windows)."""
    from station.estimate.noise_groups import RAMP_DRIFT_P, RAMP_MIN_DOF, placement_component

    model.ramp_estimate = None
    if not getattr(model, "ramp_windows", None):
        return x, cov, r, reduced
    old = getattr(model, "ramp_note", None)
    if old in model.notes:
        model.notes.remove(old)
    if model.is_large:          # (no dense Jacobian: no hat matrix to take the model's share out)
        model.ramp_estimate = {"windows": len(model.ramp_windows), "estimated": False, "k": 1.0}
        model.ramp_note = (f"the {len(model.ramp_windows)} recorded ramps' angles keep their stated placement "
                           "1-sigma (angle_sigma_deg, conservative): a model this large is not reweighted")
        model.notes.append(model.ramp_note)
        return x, cov, r, reduced

    def component(x, J=None, drift=False):
        J = np.asarray(model.jacobian(x)) if J is None else J
        return placement_component(model.row_labels(x), model.residuals(x), J, model.ramp_windows,
                                   signs=getattr(model, "ramp_signs", None),
                                   svd=_solution_svd(model, J), drift=drift)

    def set_k2(k2):
        model.ramp_k2 = float(k2)
        model._gyro_integral_whitening()
        model._prepare()
        model.refresh()

    stated = component(x)
    if stated is None:
        return x, cov, r, reduced
    first = (x, cov, r, reduced)
    entry = {"windows": stated["windows"], "dof_stated": stated["dof"],
             "scatter_before": float(np.sqrt(stated["ratio"] * model.ramp_k2))}
    comp, estimated = stated, stated["dof"] >= RAMP_MIN_DOF
    wider = correlated = False
    if not estimated and model.ramp_k2 != 1.0:
        # entered at an earlier estimate (_revealed_by_ramps: a released parameter took a degree of
        # freedom from the windows): back to the stated 1-sigma the note says
        set_k2(1.0)
        x, cov, r, reduced = _solve(model, x)
    if estimated:
        # k^2 and the parameters together: each new k^2 followed by a Gauss-Newton step from where
        # the fit is (the residuals move little with the weights), then the fit itself from there
        # (a whole _solve per step took 0.7 s of CPU on 24 windows, 5-6 of them)
        for _ in range(RAMP_SOLVES):
            if abs(comp["ratio"] - 1.0) < noise_model.TURN_TOLERANCE:
                break
            for _ in range(noise_model.TURN_ITERATIONS):
                set_k2(model.ramp_k2 * comp["ratio"])
                J = np.asarray(model.jacobian(x))
                x = x + _gauss_newton_step(J, model.residuals(x))
                comp = component(x)
                if abs(comp["ratio"] - 1.0) < noise_model.TURN_TOLERANCE:
                    break
            x, cov, r, reduced = _solve(model, x)
            comp = component(x)
        estimated = comp["dof"] >= RAMP_MIN_DOF
        k2_found = model.ramp_k2
        wider = estimated and k2_found >= 1.0
        if estimated and not wider:
            # the windows' residuals tested for a drift along the session (noise_groups.drift_test:
            # a host whose latency wanders; the lag-1 correlation before, with less power)
            comp = component(x, drift=True)
        correlated = estimated and not wider and comp.get("drift_p", 1.0) < RAMP_DRIFT_P
        if estimated and not wider and not correlated:
            # k^2 estimated from f degrees of freedom: the parameters resting on the windows carry
            # its sampling error too; weighted at f / (f - 2) of it (the variance of a t with f
            # degrees of freedom), capped at the stated 1-sigma (review of the eighteenth session:
            # a parameter resting on the windows alone came out at rms z 1.12 at f = 10, 1.05 at 23)
            inflated = min(1.0, k2_found * comp["dof"] / (comp["dof"] - 2.0))
            if inflated != k2_found:
                set_k2(inflated)
                x, cov, r, reduced = _solve(model, x)
        if not estimated or wider or correlated:
            # so little placement beside the white noise that k says too little; or the windows
            # scatter beyond the stated placement, which already holds every read anywhere in its
            # bracket: not the placement's doing (an encoder angle off, a table that slipped, a
            # missing effect), so not absorbed into it -- the group is tested against its stated
            # noise and the verdict names it (review of the eighteenth session)
            set_k2(1.0)
            x, cov, r, reduced = _solve(model, first[0])
            estimated = False
    k = float(np.sqrt(model.ramp_k2))
    model.ramp_estimate = dict(entry, k=k, dof=float(comp["dof"]), estimated=estimated,
                               lag1=float(comp.get("lag1", 0.0)))
    if "drift_p" in comp:
        model.ramp_estimate.update(drift_lr=float(comp["drift_lr"]), drift_p=float(comp["drift_p"]))
    n = entry["windows"]
    if estimated:
        model.reweighted["ramp gyro"] = {"scatter_before": entry["scatter_before"], "k": k, "dof": comp["dof"]}
        model.ramp_note = (f"the {n} recorded ramps scatter {np.sqrt(k2_found):.3g} of their stated placement "
                           f"1-sigma (angle_sigma_deg), estimated from their {comp['dof']:.1f} degrees of freedom "
                           f"(k^2 to +/- {100 * np.sqrt(2 / comp['dof']):.0f} %): their angles are weighted at "
                           f"{k:.3g} of it (the estimate's own uncertainty, f / (f - 2), included)")
    elif correlated:
        model.reweighted.pop("ramp gyro", None)
        model.ramp_note = (f"the {n} recorded ramps' angles keep their stated placement 1-sigma "
                           f"(angle_sigma_deg, conservative): their residuals drift along the session (the "
                           f"likelihood ratio of a drifting placement {comp['drift_lr']:.3g}, p = {comp['drift_p']:.2g} "
                           f"for independent windows; lag-1 {comp['lag1']:.2f}), so their scatter about the fit "
                           "would understate it")
    elif wider:
        model.reweighted.pop("ramp gyro", None)
        model.ramp_note = (f"the {n} recorded ramps' angles keep their stated placement 1-sigma "
                           f"(angle_sigma_deg): they scatter {np.sqrt(k2_found):.3g} of it, and the stated "
                           "one already places every read anywhere in its bracket; what is beyond it is tested "
                           "against the noise (the verdict names it), not taken for the placement")
    else:
        model.reweighted.pop("ramp gyro", None)
        model.ramp_note = (f"the {n} recorded ramps' angles keep their stated placement 1-sigma "
                           f"(angle_sigma_deg, conservative: their scatter is {entry['scatter_before']:.3g} of it): "
                           f"{comp['dof']:.1f} degrees of freedom say too little to estimate it (at least "
                           f"{RAMP_MIN_DOF:g}: more recorded ramps)")
    model.notes.append(model.ramp_note)
    return x, cov, r, reduced


def _revealed_by_ramps(model: Model, x, cov, r, reduced):
    """Effect parameters held by their prior (model.unobservable) that the ramps reveal once their
    placement 1-sigma is estimated (_ramp_reweight: the stated one is conservative, and a time
    offset informed by the ramps came out 1-sigma above its typical size): each is examined
    again without its prior (_blind_effect_parameters at the solution); those revealed are
    released, the fit repeated and the placement estimated again (the time offset then takes
    the part of the placement common to every window)."""
    held = _held(model)
    if not held:
        return x, cov, r, reduced
    # (the priors and the data rows as they were, in their order: r, cov and reduced are theirs)
    priors, data_rows = dict(model.priors), model.data_rows
    saved = {c: model.priors.pop(c) for c, _ in held}
    model.refresh()
    blind = {c for c, _ in _blind_effect_parameters(model, _Reduced(model, model.jacobian(x)))}
    released = [(c, p) for c, p in held if c not in blind]
    if not released:
        model.priors.clear()
        model.priors.update(priors)
        model.refresh()
        model.data_rows = data_rows
        return x, cov, r, reduced
    for c, _ in held:
        if c in blind:
            model.priors[c] = saved[c]
    model.refresh()
    for _, p in released:
        model.unobservable.remove(p.name)
    x, cov, r, reduced = _solve(model, x)
    x, cov, r, reduced = _ramp_reweight(model, x, cov, r, reduced)
    if not model.ramp_estimate["estimated"]:
        # the placement estimated again says too little (or beyond the stated one): the windows are
        # back at their stated 1-sigma, where these parameters were held: held again
        for c, p in released:
            model.priors[c] = saved[c]
            model.unobservable.append(p.name)
        model.refresh()
        return _solve(model, x)
    model.notes.append("revealed once the recorded ramps' placement 1-sigma was estimated from their scatter: "
                       + ", ".join(p.name for _, p in released))
    return x, cov, r, reduced


def _with_placement(model: Model, components: list) -> list:
    """The "ramp gyro" group's entry with the ramps' placement factor (placement_k, the factor k on
    their stated angle_sigma_deg; 1: kept as stated), its degrees of freedom and whether it was
    estimated (_ramp_reweight)."""
    est = getattr(model, "ramp_estimate", None)
    if not est:
        return components
    out = []
    for c in components:
        if c["group"] == "ramp gyro":
            c = dict(c, placement_k=est["k"], placement_estimated=est["estimated"])
            if "dof" in est:
                c["placement_dof"] = est["dof"]
        out.append(c)
    return out


def _scatters(component: dict, p_named: float) -> bool:
    """Whether a group scatters beyond its stated noise: as a whole, or on one of its sensor axes
    (Bonferroni over the three: a bias that wanders on one axis is diluted in the group's sum)."""
    parts = [component] + [dict(c, p_value=min(1.0, 3.0 * c.get("p_value", 1.0)))
                           for c in component.get("axes", {}).values()]
    return any(c.get("p_value", 1.0) < p_named and c.get("scatter", 0.0) > 1.0 for c in parts)


def reported(result: FitResult, accel_unit: str, gyro_unit: str):
    """Names, reported values, units, and the covariance in reported units, in the order of
    Calibration.parameters() followed by the effects' parameters."""
    names, index, factors, units_ = _reported_index(result, accel_unit, gyro_unit)
    values = result.x[index] * factors
    cov = result.covariance_of(index) * np.outer(factors, factors)
    return names, values, units_, cov


def _reported_index(result: FitResult, accel_unit: str, gyro_unit: str):
    """Names, parameter-vector columns, factors to the reported units, and units of the
    reported parameters (reported()'s order)."""
    L = result.model.layout
    scale = {name: (sc, unit) for name, sc, unit in GLOBAL}
    if accel_unit == "raw":
        scale["accel_bias"] = (1.0, "raw")
        scale["accel_scale"] = (1.0, "raw/(m/s^2)")
    if gyro_unit == "raw":
        scale["gyro_bias"] = (1.0, "raw")
        scale["gyro_scale"] = (1.0, "raw/(deg/s)")
    order = ["accel_scale", "accel_misalignment", "gyro_scale", "gyro_misalignment",
             "accel_bias", "gyro_bias", "inter_triad"]
    names, index, factors, units_ = [], [], [], []
    for block in order:
        sc, unit = scale[block]
        for k, suffix in enumerate(SUFFIX.get(block, "xyz")):
            names.append(f"{block}_{suffix}")
            index.append(L[block].start + k)
            factors.append(sc)
            units_.append(unit)
    for e in result.model.effects:
        sl = L[f"effect:{e.id}"]
        for k, p in enumerate(e.params):
            names.append(p.name)
            index.append(sl.start + k)
            factors.append(p.scale)
            units_.append(p.unit)
    return names, np.array(index, dtype=int), np.array(factors), units_


def _reported_columns(result: FitResult) -> np.ndarray:
    """The parameter-vector column of every reported parameter, in the order of reported()."""
    L = result.model.layout
    order = ["accel_scale", "accel_misalignment", "gyro_scale", "gyro_misalignment",
             "accel_bias", "gyro_bias", "inter_triad"]
    cols = [L[block].start + k for block in order for k in range(3)]
    for e in result.model.effects:
        cols += list(range(L[f"effect:{e.id}"].start, L[f"effect:{e.id}"].stop))
    return np.array(cols, dtype=int)


def verdict_test(result: FitResult, components: list | None = None) -> dict | None:
    """The chi-square test a fit's verdict is taken on, the same for every surface (the
    calibration file's verdict, station/estimate/verdict.py; station diagnose, report and batch
    diagnose, station/diagnose/core.py): the data's chi2 on the data's own redundancy (issue 29).

    A fit with priors minimises chi2_data + chi2_priors; under the noise model the first has the
    expectation sum over the data rows of (1 - h_ii), the data's redundancy (h the leverages of
    the whitened Jacobian; Forstner 1979), the second the rest of n - p.  Each is tested on its
    own count: the counted degrees of freedom n - p belong to the whole chi2, the redundancy to
    the data's.  Before, the calibration's verdict divided the whole chi2 (priors' share included)
    by the data's redundancy -- biased up by about (n - p) / redundancy, 108 / 98.8 = 1.09 on the
    flake's 12-segment captures -- while diagnose divided it by n - p: one capture was "fails"
    (1.55) in the file and "explains" (1.42) in diagnose.  The groups whose noise was estimated
    from their own scatter (the hand turns, noise_model) are left out: they test nothing.
    ``components``: noise_groups' (computed if None).  None for a model whose Jacobian is not
    taken dense (no leverages): the counted chi2 and dof then, on every surface alike."""
    if components is None:
        components = _noise_groups(result)
    if not components:
        return None
    estimated = set(getattr(result.model, "reweighted", None) or {})
    kept = [c for c in components if c["group"] not in estimated]
    return {"chi2": float(sum(c["chi2"] for c in kept)), "redundancy": float(sum(c["redundancy"] for c in kept)),
            "left_out": [c["group"] for c in components if c["group"] in estimated]}


def _noise_groups(result: FitResult) -> list:
    """Each data group's scatter against its stated noise (station/estimate/noise_groups.py);
    [] for a large model (its Jacobian is not taken dense)."""
    model = result.model
    if model.is_large:
        return []
    kept = getattr(model, "components_at", None)
    if kept is not None and np.array_equal(kept[0], result.x):      # computed while reweighting
        return _with_placement(model, kept[1])
    from station.estimate.noise_groups import variance_components

    labels = model.row_labels(result.x)
    r = model.residuals(result.x)
    J = model.jacobian(result.x)
    if len(labels) != len(r) or J.shape[0] != len(r):
        return []
    return _with_placement(model, variance_components(labels, r, np.asarray(J), parameters=model.layout.size,
                                                      svd=_solution_svd(model, np.asarray(J)),
                                                      ramps=_ramp_names(model)))


def _solution_svd(model: Model, J) -> tuple | None:
    """(U, singular values) of J scaled by its column norms when _solve factorised that very
    matrix at the solution (model.solution_svd), for noise_groups.leverages; None otherwise."""
    svd = getattr(model, "solution_svd", None)
    if J is None or svd is None or svd.u is None or not np.array_equal(svd.J, J):
        return None
    return svd.u, svd.sv


def _to_reported(model: Model, x: np.ndarray):
    """(accel (3,), gyro (3,) or None): factors from the summaries' units to µg and °/h, raw
    counts through the fitted scale factors, or the gyro's nominal scale when the capture cannot
    calibrate it; the gyro None where neither exists."""
    s, L = model.s, model.layout
    accel = np.full(3, 1.0 / units.UG_MPS2)
    if getattr(s, "accel_raw", False):
        accel = accel / np.abs(x[L["accel_scale"]])
    gyro = np.full(3, 3600.0)
    if getattr(s, "gyro_raw", False):
        if s.rotations or model.hands:
            gyro = gyro / np.abs(x[L["gyro_scale"]])
        elif getattr(s, "gyro_nominal", None):
            gyro = gyro / s.gyro_nominal
        else:
            gyro = None
    return accel, gyro


def _noise_model_block(model: Model, x: np.ndarray, tested: dict | None) -> dict:
    """fit.noise_model (station/estimate/noise_model.py) in µg, °/h and degrees."""
    s = model.s
    accel, gyro = _to_reported(model, x)
    turn = None
    if model.hands and getattr(model, "turn_source", None) is not None:
        turn = {"sigma": model.turn_sigma_deg, "source": model.turn_source,
                "scatter_before": model.turn_scatter_before}
    seconds = float(arrays.median([st.duration_s for st in s.statics])) if s.statics else 0.0
    between = {}
    for group, entry in getattr(model, "reweighted", {}).items():
        if "extra" in entry:
            factor = accel if group == "static accel" else (gyro if gyro is not None else np.ones(3))
            between[group] = {"scatter_before": entry["scatter_before"],
                              "sigma": (np.sqrt(np.maximum(entry["extra"], 0.0)) * factor).tolist()}
    return noise_model.describe(model.noise, accel, gyro, seconds, turn, tested, between)


def _noise_per_sample(model: Model, x: np.ndarray) -> dict:
    """The white noise per sample the fit was weighted with, in micro-g and deg/h whatever the
    capture's units: raw counts through the fitted scale factors (counts per m/s^2, per deg/s),
    or the nominal scale of a gyro the capture cannot calibrate; None where neither exists."""
    accel, gyro = _to_reported(model, x)
    return {"accel_ug": (model.s.accel_sigma.astype(float) * accel).tolist(),
            "gyro_dph": None if gyro is None else (model.s.gyro_sigma.astype(float) * gyro).tolist()}


def to_calibration(result: FitResult, accel_unit: str, gyro_unit: str, notes=()) -> Calibration:
    """The calibration of a fit.  An effect parameter the capture does not reveal (held by its
    prior 0 +/- its typical size: ``model.unobservable``) is not written (issue 28, eighteenth
    session): it is left out of the parameters, their 1-sigma and correlation, named in
    ``fit.not_determined``, and its effect's compensation uses the prior's mean, 0 (the effect's
    nominal: no correction for it), listed in that entry's ``not_determined``.  The fit is not
    changed: the other parameters' 1-sigma carry its uncertainty (what the prior is for).  Its
    posterior stays in memory only (``Calibration.held``: value, unit, 1-sigma)."""
    model, x = result.model, result.x
    L, s = model.layout, model.s
    names, values, units_, cov = reported(result, accel_unit, gyro_unit)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # a parameter in the null space has no finite 1-sigma (the pseudo-inverse would say zero)
    sigma[np.isin(_reported_columns(result), result.rank_deficient)] = np.inf
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sigma, sigma)
    held_names = set(model.unobservable)
    extra, effect_compensation = {}, []
    for e in model.effects:
        xe = x[L[f"effect:{e.id}"]]
        held_here = [p.name for p in e.params if p.name in held_names]
        nominal = np.where([p.name in held_names for p in e.params], 0.0, xe) if held_here else xe
        extra.update(e.report(nominal, None))
        effect_compensation.append({
            "id": e.id, "source": getattr(e, "_station_source", "library"), "state": e.state(),
            "parameters": {p.name: float(v * p.scale) for p, v in zip(e.params, nominal)},
            **({"not_determined": held_here} if held_here else {})})
    fit_stats = {
        "method": "lsq",
        "chi2": result.chi2,
        "dof": result.dof,
        "reduced_chi2": result.chi2 / result.dof if result.dof > 0 else float("nan"),
        "static_segments": len(s.statics),
        "rotation_segments": len(s.rotations),
        "static_attitudes": model.attitudes,
        "hand_rotations": len(model.hands),
        "noise_per_sample": _noise_per_sample(model, x),
        "notes": list(model.notes) + list(s.skipped) + list(notes),
        "converged": bool(getattr(model, "converged", True)),
    }
    if getattr(model, "stopped_short", False):
        fit_stats["stopped_short"] = True         # on its tolerances, short of a minimum (_solve)
    if getattr(model, "settled", False):
        fit_stats["settled"] = True               # where its last phase crept (_last_phase; verdict.py reads it)
    components = _noise_groups(result)
    tested = None
    if components:
        from station.estimate.noise_groups import words

        fit_stats["noise_groups"] = components
        fit_stats["notes"] += words(components)
        redundancy = sum(c["redundancy"] for c in components)
        fit_stats["data_redundancy"] = redundancy
        if result.dof - redundancy > 0.5:
            fit_stats["notes"].append(
                f"the fit counts {result.dof} degrees of freedom, the data's own redundancy is "
                f"{redundancy:.1f} (the rest is taken by priors): the chi-square verdict is taken "
                "on the data's (their chi2 on their redundancy)")
        tested = verdict_test(result, components)
    fit_stats["noise_model"] = _noise_model_block(model, x, tested)
    fit_stats["notes"] += noise_model.words(model.noise, fit_stats["noise_model"])
    if getattr(model, "remaining_step", None) is not None:      # where the solver stopped short
        _, index, factors, _ = _reported_index(result, accel_unit, gyro_unit)
        with np.errstate(invalid="ignore", divide="ignore"):
            steps = np.abs(model.remaining_step[index] * factors) / sigma
        fit_stats["remaining_step_sigma"] = {n: float(v) for n, v in zip(names, steps)
                                             if np.isfinite(v) and n not in held_names}
    if model.unobservable:
        fit_stats["notes"].append(
            f"not revealed by this capture (1-sigma above the typical size), held at 0 +/- the "
            f"typical size by a prior in the fit (the other parameters' 1-sigma carry its uncertainty), "
            f"not written, and not compensated (its nominal 0 is used): "
            f"{', '.join(model.unobservable)}")
        pulled, limit = contradicted_held(result)
        if pulled:
            # a disagreement is a finding: the prior is kept (the loop's candidates are judged held,
            # _contradicted_priors), the file and the verdict say it (docs/calibration-file.md)
            fit_stats["held_contradicted"] = {n: round(w, 2) for n, w in pulled.items()}
            fit_stats["notes"].append(
                "the data pull held parameters beyond their prior 0 +/- the typical size ("
                + ", ".join(f"{n} {w:+.1f} sigma" for n, w in pulled.items())
                + f"; beyond {limit:.2f}, the {HELD_PULL_P:g} false-alarm point of the prior's own "
                "check): the capture contradicts the model that holds them -- they exceed their typical size "
                "(the prior is then wrong for them, and what is correlated with them rests on it) or the model "
                "misses what pulls on them (an effect not added) --, and they are compensated at their nominal 0 "
                "all the same; add segments that reveal them (station design --from CAPTURE --reveal NAMES) or "
                "an effect that explains what pulls")
    for e in model.effects:       # what an effect's own convention fixes (not the capture's doing)
        fit_stats["notes"] += list(e.notes()) if hasattr(e, "notes") else []
        if getattr(e, "bench", False) and callable(getattr(e, "words", None)):
            # a fault of the bench found, with its size (a finding for the lab: apply compensates nothing);
            # a held parameter is no finding (its 1-sigma taken as infinite)
            own = [names.index(p.name) for p in e.params if p.name in names]
            own_sigma = np.where([names[i] in held_names for i in own], np.inf, sigma[own])
            fit_stats["notes"] += list(e.words(np.asarray(values, float)[own], own_sigma))
    if model.geometry.describe(s.rotations):
        fit_stats["notes"].append(model.geometry.describe(s.rotations))
    if "mounting_offset" in L.blocks:
        fit_stats["mounting_offset_mm"] = (x[L["mounting_offset"]] * 1e3).tolist()
    elif model.s.rotations and model.s.mounting_offset_m is None:
        # per mounting or per axis (an offset seen about one axis only: its part across it)
        fit_stats["mounting_offsets_mm"] = [
            (x[L[f"mounting_offset{m}"]] @ (np.eye(3) if k is None else model.axis_basis[k]) * 1e3).tolist()
            for m, k in enumerate(model.offset_axis)]
    held = [(n, float(v), u, float(sg)) for n, v, u, sg in zip(names, values, units_, sigma) if n in held_names]
    if held:
        fit_stats["not_determined"] = [n for n, _, _, _ in held]
    keep = [i for i, n in enumerate(names) if n not in held_names]
    names, values, units_, sigma = ([names[i] for i in keep], np.asarray(values)[keep],
                                    [units_[i] for i in keep], sigma[keep])
    corr = corr[np.ix_(keep, keep)]
    return Calibration(
        accel_unit=accel_unit, gyro_unit=gyro_unit,
        accel_scale=x[L["accel_scale"]].copy(), accel_T=lower_unit_rows(x[L["accel_misalignment"]]),
        accel_bias=x[L["accel_bias"]] / s.accel_factor,
        gyro_scale=x[L["gyro_scale"]].copy(), gyro_T=lower_unit_rows(x[L["gyro_misalignment"]]),
        gyro_bias=x[L["gyro_bias"]] / s.gyro_factor,
        R_po=matrix_from_rotvec(x[L["inter_triad"]]),
        effects=["base_triads", "inter_triad"] + [e.id for e in model.effects],
        fit=fit_stats, sigma=dict(zip(names, sigma.tolist())), correlation=(names, corr),
        extra_parameters=[(n, float(v), u) for n, v, u in zip(names[21:], values[21:], units_[21:])],
        compensation_extra=extra, effect_compensation=effect_compensation, held=held)


def estimate(capture, effects: list[Effect] | None = None, attitudes: str = "auto",
             table_angle_arcsec: float | None = None) -> Calibration:
    s = summarise(capture, table_angle_arcsec=table_angle_arcsec)
    result = fit(s, effects, attitudes)
    return to_calibration(result, capture.imu.accel_unit, capture.imu.gyro_unit)
