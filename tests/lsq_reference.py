"""The least-squares model's residual as it was written before it was vectorised: one static,
one rotation and one SampleContext at a time (station/estimate/lsq.py up to commit 1e2f926).
tests/test_lsq_vectorised.py checks the vectorised residual against it, row by row.  Since issue 24
the gravity along an axis is g cos(alpha), across it g sin(alpha), alpha the axis' angle from up."""
import numpy as np
from scipy.spatial.transform import Rotation

from station.estimate.lsq import PHASES, UP, WEAK_PRIOR_RAD, Model, _earth_rate_visible
from station.model.effect import SampleContext
from station.model.geometry import cross, tangent_basis
from station.model.table_encoder_scale import turned_time


class PerSegmentModel(Model):
    """Model with the per-segment residual of before (same parameters, same rows) and its
    forward-difference Jacobian (every hand turn integrated again for each gyro column)."""

    def jacobian_columns(self, x, columns) -> np.ndarray:
        """Forward-difference Jacobian of the given columns only."""
        r0 = self.residuals(x)
        J = np.empty((len(r0), len(columns)))
        for k, c in enumerate(columns):
            xp = x.copy()
            h = 1e-7 * max(abs(x[c]), 1e-2)
            xp[c] += h
            J[:, k] = (self.residuals(xp) - r0) / h
        return J

    def jacobian(self, x) -> np.ndarray:
        if not hasattr(self, "_groups"):
            self._groups, self._rows = self._column_groups()
        r0 = self.residuals(x)
        J = np.zeros((self._rows, len(x)))
        for members in self._groups:
            xp = x.copy()
            steps = []
            for c, _ in members:
                h = 1e-7 * max(abs(x[c]), 1e-2)
                xp[c] += h
                steps.append(h)
            d = self.residuals(xp) - r0
            for (c, owned), h in zip(members, steps):
                if owned is None:
                    J[:, c] = d / h
                else:
                    J[owned, c] = d[owned] / h
        return J

    def central_jacobian(self, x, relative=1e-4) -> tuple[np.ndarray, np.ndarray]:
        """(J, steps): central differences of every column, steps `relative` times each
        parameter's size (Model._sizes); the hand turns integrated anew for each."""
        h = relative * self._sizes(x)
        J = np.empty((len(self.residuals(x)), len(x)))
        for c in range(len(x)):
            xp, xm = x.copy(), x.copy()
            xp[c] += h[c]
            xm[c] -= h[c]
            J[:, c] = (self.residuals(xp) - self.residuals(xm)) / (2 * h[c])
        return J, h

    def _axis(self, x, k):
        p = x[self.layout[f"axis{k}"]]
        l0 = self.axis_ref[k]
        t1, t2 = self.axis_basis[k]
        l = l0 + p[0] * t1 + p[1] * t2
        # the axis' angle from up (alpha): gravity along it and across it; the Earth rate along it
        # (e, or from the Earth's axis' angle beta from it: Omega cos beta, Omega sin beta across)
        g, alpha = self.s.gravity_mps2, p[2]
        if self.earth_angle[k]:
            e, across = self.omega_dps * np.cos(p[3]), self.omega_dps * np.sin(p[3])
        else:
            e, across = p[3], np.sqrt(max(self.omega_dps**2 - p[3] * p[3], 0.0))
        return l / np.linalg.norm(l), (g * np.cos(alpha), g * np.sin(alpha)), (e, across)

    def _hand_residuals(self, x, Mg, ups, attitudes) -> np.ndarray:
        """(H, 2) whitened residuals: the up after each turn against the up before carried through it."""
        hands = self.hands
        dR = Rotation.from_matrix(self.integrator.turns(np.linalg.inv(Mg), x[self.layout["gyro_bias"]]))
        before = np.array([ups[h.before] for h in hands])
        if self.with_latitude:      # the Earth turns the up during the turn
            earth = np.array([attitudes[h.before].apply(self.omega_n) for h in hands])
            before = Rotation.from_rotvec(np.radians(earth) * self.hand_duration[:, None]).apply(before)
        d = np.array([ups[h.after] for h in hands]) - dR.apply(before, inverse=True)
        return np.einsum("hkc,hc->hk", self.hand_basis, d) / self.hand_sigma_rad[:, None]

    def _static_attitude(self, x, j):
        p = x[self.layout[f"static{j}"]]
        ref = self.static_ref[j]
        if self.with_latitude:
            return Rotation.from_rotvec(p) * Rotation.from_matrix(ref)    # (the model keeps matrices)
        if not hasattr(self, "_static_basis"):      # fixed: computed once
            self._static_basis = [tangent_basis(r) for r in self.static_ref]
        t1, t2 = self._static_basis[j]
        up = ref + p[0] * t1 + p[1] * t2
        return up / np.linalg.norm(up)

    def _predict(self, x, ctx: SampleContext, Ma, Mg):
        a = ctx.f_p @ Ma.T + x[self.layout["accel_bias"]]
        w = ctx.w_p @ Mg.T + x[self.layout["gyro_bias"]]
        for e in self.effects:
            px = x[self.layout[f"effect:{e.id}"]]
            da, dw = e.accel(px, ctx), e.gyro(px, ctx)
            if da is not None:
                a = a + da
            if dw is not None:
                w = w + dw
        return a, w

    def _context(self, f_p, w_p, w_table, temp, Ma, Mg, seg=None):
        n = len(f_p)
        extra = {}
        if seg is not None:
            extra = {"t_s": np.full(n, seg.t_mid_s - self.t0), "segment_index": np.full(n, float(seg.index)),
                     "temp_rate_c_per_s": np.full(n, seg.temp_rate_c_per_s)}
        return SampleContext(f_p=f_p, w_p=w_p, w_table=w_table, wdot_table=np.zeros((n, 3)),
                             temp_c=np.full(n, np.nan if temp is None else temp),
                             accel_matrix=Ma, gyro_matrix=Mg, **extra)

    def residuals(self, x) -> np.ndarray:
        return np.concatenate(self._pieces(x)[0])

    def _pieces(self, x):
        """The whitened residuals in pieces, and a (tag, length) per piece naming what owns it."""
        s, L = self.s, self.layout
        Ma, Mg = self._matrices(x)
        out, tags = [], []

        def put(tag, values, quantity):
            out.append(values)
            tags.append((tag, len(values), quantity))

        static_sigma_a = s.accel_sigma
        static_sigma_w = s.gyro_sigma
        C_mount = Rotation.from_rotvec(x[L["mounting_rotation"]]) if self.attitudes == "table" else None
        ups, attitudes = [], []
        for j, st in enumerate(s.statics):
            att = self._static_attitude(x, j)
            if self.with_latitude:
                f_p, w_p = att.apply(self.f_n)[None, :], att.apply(self.omega_n)[None, :]
                up_p = att.apply(UP)
            else:
                up_p = att
                f_p, w_p = (self.f_n[2] * att)[None, :], np.zeros((1, 3))
                if self.hand_earth_vertical:
                    w_p = (self.omega_n[2] * att)[None, :]
            a, w = self._predict(x, self._context(f_p, w_p, np.zeros((1, 3)), st.temp_c, Ma, Mg, st), Ma, Mg)
            root_n = np.sqrt(st.samples)
            ups.append(up_p)
            attitudes.append(att)
            put(("static", j), (st.accel - a[0]) * root_n / static_sigma_a, "accel")
            if self.with_latitude:
                put(("static", j), (st.gyro - w[0]) * root_n / static_sigma_w, "gyro")
            elif self.hands:    # the bias, the unmodelled Earth rate within the noise
                put(("static", j), self.static_gyro_whiten[j] @ (st.gyro - w[0]), "gyro")
            else:   # only |Omega_E| known: the norm of the compensated rate
                rate = np.linalg.norm(np.linalg.solve(Mg, st.gyro - x[L["gyro_bias"]]))
                put(("static", j), np.atleast_1d((rate - self.omega_dps) * root_n / np.mean(static_sigma_w)),
                    "gyro_norm")
            if C_mount is not None and st.up_body is not None:
                put(("static", j), cross(up_p, C_mount.apply(st.up_body)) / self.prior_sigma, "attitude_prior")
            if self.with_latitude:   # keeps the heading finite when the gyros cannot see the Earth turn
                put(("weak", j), x[L[f"static{j}"]] / WEAK_PRIOR_RAD, "weak_prior")
        if self.hands:
            for i, rows in enumerate(self._hand_residuals(x, Mg, ups, attitudes)):
                put(("hand", i), rows, "gravity_after_turn")
        offset = (x[L["mounting_offset"]] if "mounting_offset" in L.blocks
                  else (s.mounting_offset_m if s.mounting_offset_m is not None else np.zeros(3)))
        phases = 2 * np.pi * np.arange(PHASES) / PHASES
        cos_p, sin_p = np.cos(phases), np.sin(phases)
        cos_2p, sin_2p = np.cos(2 * phases), np.sin(2 * phases)
        grid = np.column_stack([np.ones(PHASES), cos_p, sin_p, cos_2p, sin_2p])
        axes = [self._axis(x, k) for k in range(s.groups)]
        if C_mount is not None:
            for k, (l, _, _) in enumerate(axes):
                axis_body = next(r.axis_body for r in s.rotations if r.group == k)
                put(("axis", k), cross(l, C_mount.apply(axis_body)) / self.prior_sigma, "axis_prior")
        g = s.gravity_mps2
        for k, (_, (kappa, _), (e, _)) in enumerate(axes):
            # the Earth rate along an axis lies within +/- Omega_E (uniform: sigma Omega_E/sqrt(3));
            # without this a single-direction turn could trade it against the scale factor
            put(("weak_axis", k), np.atleast_1d(e * np.sqrt(3.0) / self.omega_dps), "earth_prior")
            if not any(r.steady for r in s.rotations if r.group == k):
                # only unsteady turns about this axis: nothing sees the gravity along it
                put(("weak_axis", k), np.atleast_1d(kappa / g / WEAK_PRIOR_RAD), "weak_prior")
        for i, r in enumerate(s.rotations):
            l, (kappa, g_across), (e, across) = axes[r.group]
            e1 = self.axis_basis[r.group][0]
            e1 = e1 - (e1 @ l) * l
            e1 /= np.linalg.norm(e1)
            e2 = cross(l, e1)
            psi, chi = (list(x[L[f"phase{i}"]]) + [0.0, 0.0])[:2]
            v = g_across * (np.cos(psi) * e1 + np.sin(psi) * e2)
            # Earth rate across the axis turns with the body: over a whole number of turns it
            # integrates to zero, over the rest of a turn it does not
            earth_perp = across * (np.cos(chi) * e1 + np.sin(chi) * e2)
            A = np.radians(r.angle_deg)
            earth_integral = np.zeros(3) if not _earth_rate_visible(r, s) else (r.duration_s / A) * (
                np.sin(A) * earth_perp - (1.0 - np.cos(A)) * cross(l, earth_perp))
            if _earth_rate_visible(r, s) and r.earth_weights_s is not None:    # a recorded ramp: over its own phase
                earth_integral = r.earth_weights_s[0] * earth_perp - r.earth_weights_s[1] * cross(l, earth_perp)
            # at the mounting offset: centripetal w x (w x d) and tangential dw/dt x d, with the
            # rate's shape over the turn (its harmonics, from the summary): a steady rate gives a
            # constant centripetal force and no tangential one
            if r.rate_coef is not None:
                w_k, wsq_k, wdot_k = grid @ r.rate_coef, grid @ r.rate_sq_coef, grid @ r.rate_dot_coef
            else:
                w_k = np.full(PHASES, np.radians(r.rate_dps) * np.sqrt(r.rate_sq_factor))
                wsq_k, wdot_k = w_k**2, np.zeros(PHASES)
            # a window shifted by dt: the samples turned I (the gyro's own turn), the encoder I - dt dw,
            # and the rate's shape was scaled to the encoder's turn: the table's rate is I / (I - dt dw)
            # times it (dw: the measured rate's change along the turn)
            turn = np.linalg.norm(r.gyro_integral)
            phase_less_1 = 0.0     # c - 1, from dt dw (not c less 1: rounding)
            for eff in self.effects:
                dt = eff.window_shift_s(x[L[f"effect:{eff.id}"]])
                if dt is not None and turn > 0 and not r.rate_from_table:
                    dw = (np.asarray(r.gyro_end) - np.asarray(r.gyro_start)) @ (np.asarray(r.gyro_integral) / turn)
                    c = turn / (turn - dt * dw)
                    w_k, wsq_k, wdot_k = c * w_k, c * c * wsq_k, c * wdot_k
                    step = dt * dw / (turn - dt * dw)
                    phase_less_1 = phase_less_1 + step + phase_less_1 * step
            l_x_d = cross(l, offset)
            at_offset = np.outer(wsq_k, cross(l, l_x_d)) + np.outer(wdot_k, l_x_d)
            f_p = kappa * l + np.outer(cos_p, v) - np.outer(sin_p, cross(l, v)) + at_offset
            if r.duration_s > 0:    # the summary's phases at the encoder's scale, gravity's at c times them
                angle = turned_time(r.angle_deg, r.duration_s, PHASES) * (A / r.duration_s)
                f_p = f_p + phase_less_1 * angle[:, None] * (-np.outer(sin_p, v) - np.outer(cos_p, cross(l, v)))
            w_p = np.tile((r.rate_dps + e) * l, (PHASES, 1))
            ctx = self._context(f_p, w_p, np.outer(w_k, l), r.temp_c, Ma, Mg, r)
            ctx.wdot_table = np.outer(wdot_k, l)
            a, w = self._predict(x, ctx, Ma, Mg)
            dc, c, sn = a.mean(axis=0), 2 * cos_p @ a / PHASES, 2 * sin_p @ a / PHASES
            c2, s2 = 2 * cos_2p @ a / PHASES, 2 * sin_2p @ a / PHASES
            root_n = np.sqrt(r.samples)
            integral = w.mean(axis=0) * r.duration_s + Mg @ earth_integral
            for eff in self.effects:
                term = eff.integral(x[L[f"effect:{eff.id}"]], r)
                if term is not None:
                    integral = integral + term
                dt = eff.window_shift_s(x[L[f"effect:{eff.id}"]])
                if dt is not None:      # of the measured change, only the table rate's (along M_g l) is the shift's
                    m, d = Mg @ l, np.asarray(r.gyro_end) - np.asarray(r.gyro_start)
                    integral = integral - dt * (d - (m @ d) / (m @ m) * m)
            gyro_rows = self.gyro_whiten[i] @ (r.gyro_integral - integral)
            if not r.steady:        # a hand turn: its angle and axis only, through the gyro
                put(("rot", i), gyro_rows, "rotation_gyro")
                continue
            # the coefficients' covariance sigma^2 / n * G^-1 (G per sample, over the arc recorded):
            # whitened by G's symmetric square root (whole turns: 1, 1/sqrt 2, ...)
            G = np.diag([1.0, 0.5, 0.5, 0.5, 0.5]) if r.gram is None else np.asarray(r.gram)
            lam, V = np.linalg.eigh(G)
            root_G = V @ np.diag(np.sqrt(np.clip(lam, 0.0, None))) @ V.T
            diff = np.array([r.accel_dc - dc, r.accel_cos - c, r.accel_sin - sn, r.accel_cos2 - c2, r.accel_sin2 - s2])
            rows = root_G @ diff * root_n / s.accel_sigma
            put(("rot", i), np.concatenate([*rows, gyro_rows]), "rotation")
        for c, sigma in self.priors.items():
            put(("prior", c), np.atleast_1d(x[c] / sigma), "effect_prior")
        return out, tags


