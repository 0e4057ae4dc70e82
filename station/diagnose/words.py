"""Where the model fails, in plain words, from the pattern of the whitened residuals."""
from __future__ import annotations

import numpy as np

FAIL_RMS = 2.0           # a group of residuals whose RMS exceeds this is not noise


def _corr(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 3 or np.std(a) == 0 or np.std(b) == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def describe_failures(result, labels, segs, fails: bool = False) -> list[str]:
    """Sentences naming the sensor, the segment kind, the worst segments and the pattern; when
    the fit fails (``fails``) there is always at least one."""
    s = result.model.s
    out = []
    groups = {}
    for seg in segs:
        for (q, axis), v in seg.values.items():
            sensor = "accelerometer" if q.startswith("accel") else "gyro"
            groups.setdefault((sensor, seg.kind), []).append((seg.name, q, axis, v))
    failing = {k: v for k, v in groups.items()
               if np.sqrt(np.mean([x[3] ** 2 for x in v])) > FAIL_RMS}
    for (sensor, kind), rows in sorted(failing.items()):
        rms = np.sqrt(np.mean([x[3] ** 2 for x in rows]))
        worst = sorted(rows, key=lambda x: -abs(x[3]))[:3]
        where = ", ".join(f"{n} {q} {a} ({v:+.1f} sigma)" for n, q, a, v in worst)
        other_kinds = [k for (sn, k) in failing if sn == sensor and k != kind]
        only = "only" if not other_kinds else f"and {', '.join(other_kinds)}"
        pattern = _pattern(sensor, kind, rows, s)
        out.append(f"{sensor}, {kind} segments {only}: residuals {rms:.1f} times the noise"
                   f"{'; ' + pattern if pattern else ''}; worst: {where}")
    moved = _moved_axes(result)
    # a rotation axis that moved between a ± pair also leaves gravity turning along the shared axis
    # the model fits (a first harmonic there): the vibration is named only when the axes agree
    out = (moved + _time_patterns(result, segs) + _bench_patterns(result, segs)
           + ([] if moved else _once_per_revolution(result, segs)) + out)   # specific causes first
    if fails and not out:
        out.append(_spread_everywhere(groups))
    return out


def _spread_everywhere(groups) -> str:
    """No group stands out although the fit fails: say how the excess is spread."""
    rms = {k: float(np.sqrt(np.mean([x[3] ** 2 for x in v]))) for k, v in groups.items()}
    parts = ", ".join(f"{sensor} {kind} {r:.2f}" for (sensor, kind), r in sorted(rms.items(), key=lambda kv: -kv[1]))
    return ("no single segment kind stands out: residuals (RMS in units of the noise, 1 expected) "
            f"{parts}; the scatter is larger than the static segments' sample-to-sample noise "
            "predicts everywhere: noise that is not white (vibration, a table that does not hold "
            "still, correlated drift), sample-time jitter, or an error model slightly wrong on "
            "every segment; compare the noise with `station noise` and look at the residuals per "
            "segment (--report)")


# per segment kind, the residual quantities that carry a bias: a static's means, a rotation's
# accelerometer mean and gyro integral (its whitened residual is about the bias times sqrt(samples)
# in units of the per-sample noise, like a static's)
BIAS_QUANTITIES = {"accelerometer": ("accel", "accel_dc"), "gyro": ("gyro", "gyro_integral")}


def _time_patterns(result, segs) -> list[str]:
    """Residuals that follow time over every segment in time order, statics and rotations alike:
    a step (a bias jump, a knock; also when the table starts turning) or a drift.  Each segment
    gives a bias-like 3-vector in units of the per-sample noise, u = r / sqrt(N), weighted by N
    (its inverse variance), so the sums of squares below are chi2-like whatever the segments'
    lengths."""
    s = result.model.s
    info = {st.name: ("static", st.t_mid_s, st.samples) for st in s.statics}
    info.update({r.name: ("rotation", r.t_mid_s, r.samples) for r in s.rotations if r.steady})
    raw = {"accelerometer": getattr(s, "accel_raw", False), "gyro": getattr(s, "gyro_raw", False)}
    out = []
    for sensor, quantities in BIAS_QUANTITIES.items():
        rows = []
        for seg in segs:
            kind, t_mid, n = info.get(seg.name, (None, float("nan"), 0))
            if kind is None or not np.isfinite(t_mid) or n <= 0:
                continue
            v = [seg.values.get((q, a)) for q in quantities for a in "xyz"]
            v = [x for x in v if x is not None]
            if len(v) == 3:
                rows.append((t_mid, seg.name, kind, np.array(v) / np.sqrt(n), float(n)))
        if len(rows) < 5:
            continue
        rows.sort(key=lambda r: r[0])
        t = np.array([r[0] for r in rows])
        U = np.array([r[3] for r in rows])
        w = np.array([r[4] for r in rows])[:, None]

        def ss(u, wt):
            mean = (wt * u).sum(axis=0) / wt.sum()
            return float(np.sum(wt * (u - mean) ** 2)), mean

        # the baseline is a constant offset over the run (a bias the fit got wrong is not a
        # function of time): a step or a drift must explain most of what varies around it
        ss0, _ = ss(U, w)
        if ss0 < FAIL_RMS**2 * U.size:
            continue
        best = (ss0, None)
        for k in range(2, len(rows) - 1):
            total = ss(U[:k], w[:k])[0] + ss(U[k:], w[k:])[0]
            if total < best[0]:
                best = (total, k)
        tc = t - (w[:, 0] @ t) / w.sum()
        mean = (w * U).sum(axis=0) / w.sum()
        slope = ((w[:, 0] * tc) @ (U - mean)) / (w[:, 0] @ tc**2)
        ss_drift = float(np.sum(w * (U - mean - np.outer(tc, slope)) ** 2))
        ss_step, k = best
        sigma = s.accel_sigma if sensor == "accelerometer" else s.gyro_sigma
        if k is not None and ss_step < 0.3 * ss0 and ss_step < 0.7 * ss_drift:
            jump = (ss(U[k:], w[k:])[1] - ss(U[:k], w[:k])[1]) * sigma
            i = int(np.argmax(np.abs(jump)))
            size = _bias_words(sensor, jump[i], raw[sensor])
            kinds = sorted({r[2] for r in rows})
            where = "every segment kind" if len(kinds) > 1 else f"{kinds[0]} segments"
            before, after = rows[k - 1], rows[k]
            words = (f"{sensor}, {where} in time order: the residuals jump between {before[1]} and {after[1]} "
                     f"(t ≈ {0.5 * (t[k - 1] + t[k]):.0f} s) by {size} on {'xyz'[i]} and stay: a step in "
                     "time (a bias jump, a knock, a changed mounting), not a function of the attitude")
            if before[2] != after[2] and all(r[2] == after[2] for r in rows[k:]) and all(
                    r[2] == before[2] for r in rows[:k]):
                first = "the table started turning" if after[2] == "rotation" else "the table stopped"
                words += (f"; it falls where {first} ({before[2]} segments before, {after[2]} after): a bias "
                          f"that jumped then, or an offset every {after[2]} segment shares; record a static "
                          f"after the {after[2]}s (or interleave them) to tell them apart")
            else:
                words += "; repeat an attitude at the end of the run to confirm"
            out.append(words)
        elif ss_drift < 0.3 * ss0:
            i = int(np.argmax(np.abs(slope * sigma)))
            out.append(f"{sensor}, segments in time order: the residuals drift steadily with time "
                       f"({_bias_words(sensor, slope[i] * sigma[i] * 3600, raw[sensor])} per hour on "
                       f"{'xyz'[i]}): a slow bias drift (warm-up, temperature) rather than a function of the "
                       "attitude; warm the IMU up longer or record its temperature (temperature_bias)")
    return out


def _bias_words(sensor: str, value: float, raw: bool) -> str:
    """A bias change in words and units (µg, °/h; output units for a raw capture)."""
    if raw:
        return f"{value:+.3g} output units"
    if sensor == "accelerometer":
        return f"{value / 9.80665e-6:+.3g} µg"
    return f"{value * 3600:+.3g} °/h"


JITTER_SCATTER = 0.3     # stamp jitter is named when the scatter it adds to a rotation's
                         #   accelerometer samples exceeds this fraction of their noise
WOBBLE_RMS = 1.5         # the rotations' second harmonic stands out: RMS above this (whitened) ...
WOBBLE_RATIO = 1.5       # ... and this many times the mean's and the first harmonic's


def _bench_patterns(result, segs) -> list[str]:
    """Bench causes with a signature of their own: time stamps that jitter (seen in the stamps
    themselves, and as extra scatter of the rotations' accelerometer harmonics), and a wobbling
    table axis (a second harmonic of the revolution in every rotation while the statics fit)."""
    s = result.model.s
    out = []
    steady = [r for r in s.rotations if r.steady]
    period = 1.0 / s.sample_rate_hz if s.sample_rate_hz else float("nan")
    jitter = float(getattr(s, "stamp_jitter_s", 0.0) or 0.0)
    if steady and jitter > 0 and np.isfinite(period):
        # a sample stamped dt late is taken for the attitude the table had dt later: gravity turning
        # at the rate w across the axis is then off by about g w dt (the accelerometer's noise is
        # the scale this is compared with; statics are unaffected)
        rate = max(abs(np.radians(r.rate_dps)) for r in steady)
        scatter = s.gravity_mps2 * rate * jitter          # m/s^2; the summaries' unit for a raw capture:
        if getattr(s, "accel_raw", False):
            scatter *= _counts_per_mps2(s)
        noise = float(np.mean(s.accel_sigma))
        if noise > 0 and scatter > JITTER_SCATTER * noise:
            stat = _rms([v for seg in segs if seg.kind == "static" for (q, _), v in seg.values.items()
                         if q == "accel"])
            rot = _rms([v for seg in segs if seg.kind == "rotation" for (q, _), v in seg.values.items()
                        if q.startswith("accel")])
            out.append(f"the time stamps jitter: {jitter * 1e3:.3g} ms (1 sigma, {100 * jitter / period:.0f} % of "
                       f"the sample period, from the intervals between stamps); a sample stamped late is "
                       f"taken for a later attitude, so at {np.degrees(rate):.0f} °/s gravity turning across "
                       f"the axis scatters the rotations' accelerometer samples by about {scatter / noise:.2g} "
                       f"times their noise (rotation residuals {rot:.2f}, statics {stat:.2f}; 1 expected), "
                       "statics are unaffected: stamp the samples with the IMU's own clock or a hardware "
                       "counter, or resample them on a uniform time base")
    if steady:
        second, rest = [], []
        per_segment = []
        for seg in segs:
            if seg.kind != "rotation":
                continue
            v2 = [v for (q, _), v in seg.values.items() if q in ("accel_cos2", "accel_sin2")]
            v01 = [v for (q, _), v in seg.values.items() if q in ("accel_dc", "accel_cos", "accel_sin")]
            second += v2
            rest += v01
            if v2:
                per_segment.append(_rms(v2))
        r2, r01 = _rms(second), _rms(rest)
        stat = _rms([v for seg in segs if seg.kind == "static" for (q, _), v in seg.values.items() if q == "accel"])
        consistent = per_segment and np.mean(np.array(per_segment) > 1.2) >= 0.75
        if r2 > WOBBLE_RMS and r2 > WOBBLE_RATIO * r01 and stat < FAIL_RMS and consistent:
            n = np.mean([r.samples for r in steady])
            amplitude = r2 * np.sqrt(2.0) * float(np.mean(s.accel_sigma)) / np.sqrt(n)   # per component
            size = (f"{amplitude / 9.80665e-6:.3g} µg" if not getattr(s, "accel_raw", False)
                    else f"{amplitude:.3g} output units")
            out.append(f"accelerometer, rotation segments: twice per revolution in {np.mean(np.array(per_segment) > 1.2):.0%} "
                       f"of the rotations (second harmonic {r2:.2f} times the noise, against {r01:.2f} for the "
                       f"mean and the first harmonic and {stat:.2f} at the statics; about {size} per component): "
                       "a wobbling or tilted table platter (gravity seen through an axis that nods as it turns), "
                       "or an accelerometer error even in its input (a nonlinearity, or a scale factor that "
                       "differs between positive and negative inputs: |a| has a second harmonic too); an even "
                       "accelerometer error also shows at the ±1 g and 45° statics, which fit here, so long "
                       "45° statics tell them apart, and so does turning the IMU by 90° on the platter (a "
                       "table wobble stays with the table, an accelerometer error moves with the IMU); "
                       "check the table's axis wobble against its specification")
    return out


ONCE_RMS = 3.0           # the rotations' first harmonic along their own axis stands out: RMS above
                         #   this (whitened; 1 expected) in at least ONCE_SHARE of the rotations
ONCE_SHARE = 0.75


def _once_per_revolution(result, segs) -> list[str]:
    """An acceleration at the rotation frequency along the rotation's own axis, about axes near
    horizontal: gravity has no part there that turns (its component along the axis is constant),
    nor has any error of the accelerometers' scale or misalignment the model does not already take
    (those mix gravity's turning part, across the axis, into the axis' harmonic only through
    parameters the fit has), nor, with no gravity along the axis, a product of gravity's parts.  What is left there is a vibration or an imbalance of the table fixed to its rotation
    (or a platter whose axis wobbles once per turn)."""
    s = result.model.s
    steady = {r.name: r for r in s.rotations if r.steady}
    along, names = [], []
    for seg in segs:
        r = steady.get(seg.name)
        if r is None or seg.kind != "rotation" or not _horizontal(result, r.group):
            continue
        c = [seg.values.get(("accel_cos", a)) for a in "xyz"]
        sn = [seg.values.get(("accel_sin", a)) for a in "xyz"]
        if None in c or None in sn:
            continue
        axis = np.asarray(r.axis_body, float)
        axis = axis / np.linalg.norm(axis)
        along.append(float(np.hypot(axis @ np.array(c), axis @ np.array(sn)) / np.sqrt(2.0)))
        names.append((seg.name, r))
    if len(along) < 2:
        return []
    along = np.array(along)
    share = float(np.mean(along > ONCE_RMS))
    # the statics must fit: an error of the accelerometers themselves (cubic, cross-axis) that the
    # fit shares out between statics and rotations leaves the statics failing too
    stat = _rms([v for seg in segs if seg.kind == "static" for (q, _), v in seg.values.items() if q == "accel"])
    if share < ONCE_SHARE or stat >= FAIL_RMS:
        return []
    # whitened first-harmonic component -> m/s^2: its noise is sigma sqrt(2 / N) over whole revolutions
    n = np.array([r.samples for _, r in names], float)
    amp = along * np.sqrt(2.0) * float(np.mean(s.accel_sigma)) * np.sqrt(2.0 / n)
    size = (f"{np.median(amp) / 9.80665e-6:.3g} µg" if not getattr(s, "accel_raw", False)
            else f"{np.median(amp):.3g} output units")
    return [f"accelerometer, rotation segments: once per revolution along the rotation's own axis in {share:.0%} of "
            f"the rotations (first harmonic along the axis {np.sqrt(np.mean(along ** 2)):.1f} times the noise; about "
            f"{size}; the ± pairs' axes agree, the statics fit: {stat:.2f}): gravity has no turning part along the axis, so this is an acceleration "
            "of the table at the "
            "rotation frequency, a vibration or imbalance of the table fixed to its rotation (a rotor out of balance, "
            "a bearing, a belt); not an error of the IMU, and not compensated: balance the platter or load it "
            "symmetrically, or check the table's vibration at the rotation rate"]


HORIZONTAL_COS = 0.5     # an axis within 30° of horizontal: gravity along it below g/2


def _horizontal(result, group: int) -> bool:
    """Whether the fitted axis of ``group`` is near horizontal.  Only there is the first harmonic
    along the axis free of the accelerometers' own nonlinear errors: about a tilted axis gravity's
    constant part along it times its turning part across it (a cross-axis or cubic term) has one."""
    try:
        alpha = result.x[result.model.layout[f"axis{group}"].start + 2]
    except (KeyError, AttributeError, IndexError, TypeError):
        return False
    return abs(np.cos(alpha)) < HORIZONTAL_COS


def _rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else 0.0


def _counts_per_mps2(s) -> float:
    from station.model.raw_counts import counts_per_unit

    return counts_per_unit(s)[0]


MOVED_AXIS_DEG = 0.05     # the least move of a ± pair's axis said as a remount: a gyro bias error b
                          #   tilts the two directions' integrals apart by 2 b / rate (a bias step of
                          #   100 °/h at 100 °/s: 0.0066°, taken for a remount at 0.005°); 0.05° is a
                          #   bias error of 160 °/h at 100 °/s, 16 °/h at 10 °/s


ACCEL_AXIS_SHARE = 0.5    # of the gyros' move, the least the accelerometers' axis must move too


def _accelerometers_agree(p, m, La, s, gyro_angle_deg: float) -> bool:
    """Whether the accelerometers saw the axis move too (True where they cannot tell): a remount
    turns the whole IMU, so the plane in which gravity turns (the first harmonic's cos and sin
    parts, across the axis) tilts with the gyros' axis; a gyro bias that changed between the two
    directions (a quadratic temperature bias over a warm-up: 160 °/h, 0.05° at 100 °/s) tilts the
    gyros' axis alone.  Needs gravity across the axis (a third of g at least)."""
    normals = []
    for r in (p, m):
        c, sn = La @ np.asarray(r.accel_cos, float), La @ np.asarray(r.accel_sin, float)
        if min(np.linalg.norm(c), np.linalg.norm(sn)) < s.gravity_mps2 / 3.0:
            return True
        n = np.cross(c, sn)
        normals.append(n / np.linalg.norm(n))
    accel = float(np.degrees(np.arccos(np.clip(abs(normals[0] @ normals[1]), -1.0, 1.0))))
    return accel > ACCEL_AXIS_SHARE * gyro_angle_deg


def _moved_axes(result) -> list[str]:
    """± rotations about one table axis whose axes, seen by the calibrated gyros, differ by more
    than the noise allows: the IMU moved between them (a remount or placement error)."""
    model, x = result.model, result.x
    s = model.s
    if any(e.id == "remount_per_segment" for e in model.effects):
        return []           # each rotation's placement is in the model (station/model/remount.py)
    try:
        Ma, Mg = model._matrices(x)
        La, Lg = np.linalg.inv(Ma), np.linalg.inv(Mg)
    except (np.linalg.LinAlgError, AttributeError):
        return []
    bias = x[model.layout["gyro_bias"]]
    out = []
    for g in range(s.groups):
        segs = [r for r in s.rotations if r.group == g and r.steady]
        plus = [r for r in segs if r.angle_deg > 0]
        minus = [r for r in segs if r.angle_deg < 0]
        for p, m in zip(plus, minus):
            axes = []
            for r in (p, m):
                v = Lg @ (r.gyro_integral - bias * r.duration_s) * np.sign(r.angle_deg)
                axes.append(v / np.linalg.norm(v))
            angle = float(np.degrees(np.arccos(np.clip(axes[0] @ axes[1], -1.0, 1.0))))
            # the integrals' white noise (deg) over the angle turned (deg): rad, in degrees (it was
            # divided by the angle in radians, 57.3 times too large: 0.45° moves over two
            # revolutions at 100 °/s went unsaid, and were taken for a vibration once per revolution)
            noise = float(np.degrees(np.max(s.gyro_sigma) * np.sqrt(
                (p.duration_s + m.duration_s) / s.sample_rate_hz) / min(abs(p.angle_deg), abs(m.angle_deg))))
            noise = max(noise, 2 * s.table_angle_sigma_deg / min(abs(p.angle_deg), abs(m.angle_deg)) * 57.3)
            if angle > 5 * noise and angle > MOVED_AXIS_DEG and _accelerometers_agree(p, m, La, s, angle):
                out.append(f"rotations {p.name} and {m.name}: the axis the gyros saw moved by {angle:.3g}° "
                           f"between them (noise {noise:.1g}°): the IMU was moved or remounted between the "
                           "two directions; record each ± pair without touching the IMU")
    return out


def caveats(summaries, effect_id: str) -> list[str]:
    """What the capture cannot tell apart from ``effect_id``, and the segment that would."""
    return [text for _, text in aliases(summaries, effect_id)]


def aliases(summaries, effect_id: str) -> list[tuple]:
    """(rival, words) for each thing the capture cannot tell apart from ``effect_id``: rival the
    library effect it cannot be told from (station design --from CAPTURE --separate EFFECT,RIVAL
    designs the segments that would: station/diagnose/suggest.py), or None where the rival is no
    effect (the mounting offset the base model fits)."""
    rates = sorted({round(abs(r.rate_dps), 1) for r in summaries.rotations if r.steady})
    out = []
    asym_rival = {"gyro_scale_asymmetry": "gyro_rate_nonlinearity", "gyro_rate_nonlinearity": "gyro_scale_asymmetry",
                  "gyro_rate_squared": "gyro_scale_asymmetry"}
    if effect_id in asym_rival and len(rates) == 1:
        out.append((asym_rival[effect_id],
                    f"every rotation is at one rate ({rates[0]:g} °/s): a scale asymmetry (|w|) and a "
                    "term in the square of the rate (w|w|) act alike there; turn at two rates to tell "
                    "them apart"))
    ramps = any(getattr(r, "record_ramp", None) for r in summaries.rotations)
    if effect_id == "time_offset" and summaries.mounting_offset_m is None and not ramps:
        out.append((None, "a time offset and the tangential acceleration of a varying rate at an unknown "
                    "mounting offset both follow the rate's changes; centre the IMU on the axis, or vary "
                    "the rate with the IMU centred, to tell them apart"))
    if effect_id == "time_offset" and summaries.rotations and not ramps:
        # (suggest.separations prints the command: turns whose ramp up is recorded, issue 28 item 3)
        out.append((None, "a time offset is seen only where the rate changes within a segment (here: only the "
                    "turns' rate ripple: every turn of this capture was recorded at one steady rate, after its "
                    "ramp); turns whose ramp up is recorded (record_ramp: start) change the rate within the "
                    "window and separate it from the gyro scale"))
    if effect_id == "accel_lever_arm" and len(rates) == 1:
        out.append((None, f"every rotation is at one rate ({rates[0]:g} °/s): the size effect and any other "
                    "term in the square of the rate act alike; turn at two rates to confirm it grows "
                    "with the square of the rate"))
    vertical = _vertical_turns(summaries)
    # a turn about a vertical axis off every body axis separates the size effect from a vibration (measured, docs/design.md
    # sixteenth session): gravity along such an axis is g itself (no part across it to trade against),
    # so the constant along the axis that the size effect leaves (each accelerometer at its own point
    # sees its own centripetal acceleration, not one vector across the axis) is measured there, and a
    # vibration makes none (its part along the axis is once per revolution; since the sixteenth session
    # it is modelled about a vertical axis too, its part across it per rotation group)
    if effect_id == "accel_lever_arm" and len(rates) == 1 and not vertical:
        out.append(("table_vibration_once_per_rev",
                    f"every rotation is at one rate ({rates[0]:g} °/s): an offset of the rotations' accelerometer "
                    "mean is also what a table vibrating once per revolution leaves (its part across the axis); "
                    "a turn about a vertical axis off the IMU's axes (the size effect's constant along the axis, "
                    "which no vibration makes) or at a second rate tells them apart"))
    if effect_id == "rotation_axis_offsets" and rates:
        # no command (suggest.NOT_SEPARABLE since the sixteenth session): a vibration's part turning
        # with the platter is a constant across the axis in the case's frame, as an offset's w^2 d is;
        # the vibration has its own parameters at every rate (and about a vertical axis for every
        # rotation group), so offsets that look alike in the table's frame for every axis are a
        # vibration at every rate and elevation (station/model/table_vibration.py); a recorded ramp
        # does not separate them either (twenty-first session: an imbalance's tangential force is the
        # offset's dw/dt x d as its centripetal one is w^2 d; sim_devices/world.py, the twins)
        out.append(("table_vibration_once_per_rev",
                    "an offset of the rotations' accelerometer mean for each rotation axis is also what a table "
                    "vibrating once per revolution leaves: its part turning with the platter is a constant across "
                    "the axis, as the centripetal acceleration w² d of an offset is, at any rate and about a "
                    "vertical axis too, and through a recorded ramp (an imbalance's force on the base is "
                    "m r (w² e - dw/dt a x e), what an offset d fixed to the platter gives); no segment tells them "
                    "apart. Where the table's axes meet and the IMU stayed mounted, the model's one mounting offset "
                    "holds (leave rotation_axis_offsets out); otherwise check the table's vibration with an "
                    "accelerometer on its base, or turn the IMU on the platter by a known angle about the axis "
                    "between runs (the offset turns with the IMU, an imbalance stays with the platter)"))
    if effect_id == "table_vibration_once_per_rev" and len(rates) == 1 and not vertical:
        out.append(("accel_lever_arm", f"every rotation is at one rate ({rates[0]:g} °/s): the part of a "
                    "vibration across the axis is a constant in the rotations' accelerometer mean, as the "
                    "accelerometers' size effect is; turns about a vertical axis off the IMU's axes (the size "
                    "effect's constant along the axis, which no vibration makes) or at another rate separate the two"))
    # (an even accelerometer error and a wobbling table axis are not named from the words: wobble
    # leaves its second harmonic along the rotation's axis, an even error across it, and the
    # estimator's information tells them apart on every capture measured -- nine statics or the six
    # faces, turns about six axes at one rate: correlation 0.10-0.15, both revealed (docs/design.md,
    # fourteenth session); where the data cannot tell them, suggest.alike_candidates names them)
    return out


OFF_BODY_AXES = 0.985      # a rotation axis whose largest body component is below this (10 deg off each)


def _vertical_turns(summaries) -> bool:
    """Whether a steady rotation is about an axis near the vertical (table_revolution.VERTICAL_DEG)
    and off every body axis: gravity along it is g itself, so such a turn measures the constant
    along the axis that the accelerometers' size effect leaves and a vibration once per revolution
    does not (aliases).  About a body axis the size effect leaves nothing along it (the
    centripetal acceleration is across the axis, and the accelerometer along it is the only one
    whose reading the axis takes), and its constant across the axis is the vertical vibration's
    too (four parameters per rotation group since the sixteenth session): such a turn separates
    nothing (this session's review: level pairs about x, y, [1,1,0] and a vertical pair about z
    left every accelerometer position undetermined with no alias named)."""
    from station.model import table_revolution as rev

    steady = [r for r in summaries.rotations if r.steady and r.accel_cos is not None]
    framed = rev.frames(summaries)
    return any(int(r.index) not in framed and float(np.max(np.abs(r.axis_body))) < OFF_BODY_AXES
               for r in steady)


def _pattern(sensor, kind, rows, s) -> str:
    words = []
    if kind == "rotation":
        rot = {r.name: r for r in s.rotations}
        quantity = "accel_dc" if sensor == "accelerometer" else "gyro_integral"
        per_seg = {}
        for name, q, axis, v in rows:
            if q == quantity and name in rot:
                per_seg.setdefault(name, []).append(v)
        if per_seg:
            names = list(per_seg)
            mag = [np.linalg.norm(per_seg[n]) for n in names]
            rates = [rot[n].rate_dps for n in names]
            c2 = _corr(mag, np.square(rates))
            c1 = _corr(mag, np.abs(rates))
            if quantity == "accel_dc":
                words.append("a constant offset")
            else:
                words.append("an error in the integrated rate")
            if max(c2, c1) > 0.7:
                words.append("growing with the square of the rate" if c2 >= c1 else "growing with the rate")
            signs = []
            for g in {r.group for r in s.rotations}:
                plus = [n for n in names if rot[n].group == g and rot[n].angle_deg > 0]
                minus = [n for n in names if rot[n].group == g and rot[n].angle_deg < 0]
                for p, m in zip(plus, minus):
                    a, b = np.array(per_seg[p]), np.array(per_seg[m])
                    signs.append(float(a @ b) / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300))
            if signs:
                mean = float(np.mean(signs))
                if mean > 0.5:
                    words.append("the same sign in both directions")
                elif mean < -0.5:
                    words.append("opposite signs in the two directions")
        second = [v for _, q, _, v in rows if q in ("accel_cos2", "accel_sin2")]
        harmonics = [v for _, q, _, v in rows if q in ("accel_cos", "accel_sin")]
        dc = [v for _, q, _, v in rows if q == "accel_dc"]
        if sensor == "accelerometer" and harmonics and dc:
            if np.sqrt(np.mean(np.square(harmonics))) > 2 * np.sqrt(np.mean(np.square(dc))):
                words.append("mostly at the rotation frequency (once per revolution: gravity turning "
                             "in the body seen with a wrong scale or misalignment, or a vibration or "
                             "imbalance of the table fixed to its rotation)")
            if second and np.sqrt(np.mean(np.square(second))) > 2 * max(
                    np.sqrt(np.mean(np.square(harmonics))), np.sqrt(np.mean(np.square(dc)))):
                words.append("mostly at twice the rotation frequency (twice per revolution: a wobbling "
                             "table axis, or a nonlinearity)")
    else:
        stat = {st.name: st for st in s.statics}
        temps = [stat[n].temp_c for n, _, _, _ in rows if n in stat and stat[n].temp_c is not None]
        vals = [v for n, _, _, v in rows if n in stat and stat[n].temp_c is not None]
        if temps and abs(_corr(np.abs(vals), temps)) > 0.7:
            words.append("following the temperature")
        ups = [(stat[n].up_body, axis, v) for n, _, axis, v in rows if n in stat and stat[n].up_body is not None]
        if ups:
            along = [abs(u["xyz".index(a)]) if a in "xyz" else 0.0 for u, a, _ in ups]
            c = _corr(np.abs([v for _, _, v in ups]), along)
            if c > 0.6:
                words.append("largest on the axis that gravity lies along")
            elif c < -0.6:
                words.append("largest on the axes across gravity")
    return ", ".join(words)


# ---------------------------------------------------------------------------------------------
# words for a failure that --auto could not mend (issue 25 item 5): what was tried, what each
# candidate explained, and what the residuals look like

PATTERN_SHARE = 0.5      # a variable is named when a straight line in it explains this share of
                         #   an axis' misfit in the segment means ...
PATTERN_GAIN = 0.25      # ... and this much more than a constant offset over the same segments
AXIS_SHARE = 0.1         # an axis (or segment kind) is named when it holds this share of the misfit

_VARIABLES = (   # name, words, unit of the variable, per-unit words for the slope
    ("rate", "grows with rate", "°/s", "per °/s"),
    ("abs_rate", "grows with the size of the rate, the same sign both ways", "°/s", "per °/s of |rate|"),
    ("temp", "follows temperature", "°C", "per °C"),
    ("time", "drifts with time", "h", "per hour"),
)


def _share(ss0: float, ss1: float) -> float:
    return 0.0 if ss0 <= 0 else max(0.0, (ss0 - ss1) / ss0)


def _wls(u, w, columns) -> float:
    """Weighted sum of squares left after fitting u (weights w) with the given columns."""
    A = np.column_stack(columns) * np.sqrt(w)[:, None]
    b = u * np.sqrt(w)
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    r = b - A @ coef
    return float(r @ r), coef


def segment_means(result, segs) -> list[dict]:
    """The bias-like residual of every static and steady rotation, per sensor and axis: the
    whitened residual r and the same in the summaries' units u (m/s², deg/s: a static's mean less
    the model's, a rotation's accelerometer mean and mean gyro rate error), u = r sigma / sqrt(N)
    (the per-sample noise over the segment's samples; the noise model's pose terms left out),
    with the variables a missing term could follow: time, temperature, the signed rate."""
    s = result.model.s
    info = {st.name: ("static", st, 0.0) for st in s.statics}
    info.update({r.name: ("rotation", r, r.rate_dps) for r in s.rotations if r.steady})
    t0 = min([x.t_mid_s for _, x, _ in info.values() if np.isfinite(x.t_mid_s)], default=0.0)
    rows = []
    for seg in segs:
        kind, summ, rate = info.get(seg.name, (None, None, 0.0))
        if kind is None or summ.samples <= 0:
            continue
        for sensor, quantities in BIAS_QUANTITIES.items():
            sigma = s.accel_sigma if sensor == "accelerometer" else s.gyro_sigma
            for i, a in enumerate("xyz"):
                r = next((seg.values[(q, a)] for q in quantities if (q, a) in seg.values), None)
                if r is None:
                    continue
                rows.append({"segment": seg.name, "kind": kind, "sensor": sensor, "axis": a, "r": float(r),
                             "u": float(r) * float(sigma[i]) / np.sqrt(summ.samples),
                             "w": summ.samples / float(sigma[i]) ** 2,
                             "time": (summ.t_mid_s - t0) / 3600.0 if np.isfinite(summ.t_mid_s) else np.nan,
                             "temp": np.nan if summ.temp_c is None else float(summ.temp_c),
                             "rate": float(rate), "abs_rate": abs(float(rate))})
    return rows


def _slope_words(sensor: str, slope: float, raw: bool, per: str) -> str:
    if raw:
        return f"{slope:+.3g} output units {per}"
    if sensor == "accelerometer":
        return f"{slope / 9.80665e-6:+.3g} µg {per}"
    return f"{slope * 3600:+.3g} °/h {per}"


def axis_patterns(result, segs) -> list[dict]:
    """Per sensor and axis whose segment means misfit (sum of r² above twice their count): the
    variable a straight line in which explains most of it, its slope in units, and its share."""
    s = result.model.s
    raw = {"accelerometer": getattr(s, "accel_raw", False), "gyro": getattr(s, "gyro_raw", False)}
    rows = segment_means(result, segs)
    out = []
    for sensor in BIAS_QUANTITIES:
        for a in "xyz":
            sel = [x for x in rows if x["sensor"] == sensor and x["axis"] == a]
            if len(sel) < 4:
                continue
            u = np.array([x["u"] for x in sel])
            w = np.array([x["w"] for x in sel])
            ss0 = float(np.sum(w * u * u))
            if ss0 < FAIL_RMS**2 * len(sel):
                continue
            ss_c, _ = _wls(u, w, [np.ones(len(u))])
            best = None
            for name, words, unit, per in _VARIABLES:
                v = np.array([x[name] for x in sel])
                if not np.all(np.isfinite(v)) or np.ptp(v) == 0:
                    continue
                ss1, coef = _wls(u, w, [np.ones(len(u)), v])
                gain = _share(ss0, ss1) - _share(ss0, ss_c)
                if best is None or gain > best[0]:
                    best = (gain, name, words, unit, per, float(coef[1]), _share(ss0, ss1))
            item = {"sensor": sensor, "axis": a, "misfit": ss0, "segments": len(sel),
                    "constant_share": _share(ss0, ss_c), "variable": None}
            if best is not None and best[0] >= PATTERN_GAIN and best[6] >= PATTERN_SHARE:
                gain, name, words, unit, per, slope, share = best
                item.update(variable=name, slope=slope, share=share,
                            words=f"the residual of {sensor} {a} {words}: "
                                  f"{_slope_words(sensor, slope, raw[sensor], per)}, {100 * share:.0f} % of its "
                                  f"misfit in the segment means")
            elif item["constant_share"] >= PATTERN_SHARE:
                kinds = sorted({x["kind"] for x in sel if abs(x["r"]) > FAIL_RMS})
                item["words"] = (f"the residual of {sensor} {a} is about the same offset on every segment "
                                 f"({100 * item['constant_share']:.0f} % of its misfit in the segment means, largest on "
                                 f"the {' and '.join(kinds) or 'segments'}): not a straight line in rate, "
                                 "temperature or time; an offset the segments share that the model's bias does not take "
                                 "(statics against rotations: a bias that changed when the table turned)")
            else:
                worst = sorted(sel, key=lambda x: -abs(x["r"]))[:3]
                item["words"] = (f"the residual of {sensor} {a} follows neither rate, temperature nor time "
                                 f"(a straight line in any explains < {100 * PATTERN_SHARE:.0f} % of its misfit): "
                                 "largest on " + ", ".join(f"{x['segment']} ({x['r']:+.1f} sigma)" for x in worst)
                                 + "; a function of the attitude or of the segment, not of a variable that is recorded")
            out.append(item)
    return out


def where_misfit(segs) -> list[str]:
    """How the misfit (sum of the squared whitened residuals) is shared between the sensors' axes,
    the segment kinds and, in the rotations, the mean and the harmonics of the revolution."""
    total = 0.0
    per_axis, per_kind, per_harmonic = {}, {}, {}
    for seg in segs:
        for (q, a), v in seg.values.items():
            sensor = "accelerometer" if q.startswith("accel") else "gyro"
            total += v * v
            per_axis[(sensor, a)] = per_axis.get((sensor, a), 0.0) + v * v
            per_kind[seg.kind] = per_kind.get(seg.kind, 0.0) + v * v
            if seg.kind == "rotation" and q.startswith("accel"):
                h = {"accel_dc": "the mean", "accel_cos": "once per revolution", "accel_sin": "once per revolution",
                     "accel_cos2": "twice per revolution", "accel_sin2": "twice per revolution"}.get(q)
                if h:
                    per_harmonic[h] = per_harmonic.get(h, 0.0) + v * v
    if total <= 0:
        return []
    out = []
    axes = sorted(per_axis.items(), key=lambda kv: -kv[1])
    named = [f"{s} {a} {100 * v / total:.0f} %" for (s, a), v in axes if v / total >= AXIS_SHARE]
    out.append("the misfit per axis: " + ", ".join(named or [f"{s} {a} {100 * v / total:.0f} %"
                                                           for (s, a), v in axes[:3]])
               + (" (the rest spread over the other axes)" if len(named) < len(axes) else ""))
    kinds = ", ".join(f"{k} segments {100 * v / total:.0f} %" for k, v in sorted(per_kind.items(), key=lambda kv: -kv[1]))
    out.append(f"the misfit per segment kind: {kinds}")
    rot = sum(per_harmonic.values())
    if rot > 0.1 * total:
        parts = ", ".join(f"{h} {100 * v / rot:.0f} %" for h, v in sorted(per_harmonic.items(), key=lambda kv: -kv[1]))
        top = max(per_harmonic, key=per_harmonic.get)
        meaning = {"once per revolution": "a vibration or imbalance fixed to the table's rotation, or gravity turning "
                                          "in the body seen with a wrong scale, misalignment or angle (a table that "
                                          "turns more than its encoder says)",
                   "twice per revolution": "a wobbling or tilted platter, or an accelerometer error even in its "
                                           "input (nonlinearity)",
                   "the mean": "an offset of the accelerometers while turning (centripetal: size effect, "
                               "mounting offset; or a bias that changed)"}[top]
        out.append(f"per revolution, the rotations' accelerometer misfit is {parts}: mostly {top}, the signature "
                   f"of {meaning}")
    return out


def tried_lines(d, steps=()) -> list[str]:
    """What --auto tried and what each explained, as a share of the excess chi2 (chi2 - dof) of
    the fit it was tried on; the library candidates left untried with the share their score test
    predicts; the terms of the dictionary."""
    out = []
    for st in steps:
        excess = max(st.before.chi2 - st.before.dof, 1e-300)
        kind = "terms found outside the library" if st.discovered else st.added
        out.append(f"added {kind}: it explained {100 * st.actual_drop / excess:.0f} % of the excess chi2 "
                   f"({st.before.chi2:.1f} -> {st.after.chi2:.1f})")
    excess_now = max(d.chi2 - d.dof, 1e-300)
    for r in d.rejected:
        share = r.share if r.share is not None else r.actual_drop / excess_now
        out.append(f"tried {r.effect} and did not keep it: it explained {100 * share:.0f} % of the excess chi2 "
                   f"({r.reason})")
    rejected = {r.effect for r in d.rejected}
    untried = [c for c in d.candidates if c.effect not in rejected and c.dof > 0]
    top = sorted(untried, key=lambda c: -c.predicted_chi2_drop)[:3]
    if top:
        out.append("the library's other candidates would explain at most: " + ", ".join(
            f"{c.effect} {100 * min(c.predicted_chi2_drop / excess_now, 1.0):.0f} %"
            f"{'' if c.significant else ' (not significant)'}" for c in top)
            + f" of the excess chi2 left ({d.chi2 - d.dof:.1f}; score test)")
    untestable = [c.effect for c in d.candidates if c.dof == 0]
    if untestable:
        out.append(f"not testable on this capture: {', '.join(untestable)}")
    prop = getattr(d, "proposal", None)
    if prop is not None:
        share = (d.chi2 - prop.chi2_after) / excess_now
        out.append(f"terms outside the library ({'; '.join(prop.lines())}) would explain {100 * share:.0f} % of it "
                   f"(reduced chi2 {prop.reduced_after:.3g}); {'kept' if prop.kept else 'not kept: ' + prop.reason}")
    return out


def failure_account(d, steps=()) -> list[str]:
    """Words for a fit that still fails: what was tried and explained what, where the misfit is
    (per axis, per segment kind, per revolution) and what the residuals follow (rate,
    temperature, time), so that no failure ends with "no significant candidate" alone."""
    result = d.result
    lines = tried_lines(d, steps)
    lines += where_misfit(d.segments)
    lines += [p["words"] for p in axis_patterns(result, d.segments)]
    return lines
