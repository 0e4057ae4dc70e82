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
    out = _moved_axes(result) + _time_patterns(result, segs) + out      # specific causes first
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


def _time_patterns(result, segs) -> list[str]:
    """Static residuals that follow time: a step (a bias jump, a knock) or a drift."""
    s = result.model.s
    stat = {st.name: st for st in s.statics}
    out = []
    for sensor, prefix in (("accelerometer", "accel"), ("gyro", "gyro")):
        rows = []
        for seg in segs:
            if seg.name not in stat or not np.isfinite(stat[seg.name].t_mid_s):
                continue
            v = [val for (q, _), val in seg.values.items() if q.startswith(prefix)]
            if v:
                rows.append((stat[seg.name].t_mid_s, seg.name, np.array(v)))
        if len(rows) < 5 or len({len(r[2]) for r in rows}) != 1:
            continue
        rows.sort(key=lambda r: r[0])
        t = np.array([r[0] for r in rows])
        V = np.array([r[2] for r in rows])
        # the baseline is a constant offset over the run (a bias the fit got wrong is not a
        # function of time): a step or a drift must explain most of what varies around it
        ss0 = float(np.sum((V - V.mean(axis=0)) ** 2))
        if ss0 < FAIL_RMS**2 * V.size:
            continue
        best = (ss0, None)
        for k in range(2, len(rows) - 1):
            a, b = V[:k], V[k:]
            ss = float(np.sum((a - a.mean(axis=0)) ** 2) + np.sum((b - b.mean(axis=0)) ** 2))
            if ss < best[0]:
                best = (ss, k)
        tc = t - t.mean()
        slope = (tc @ V) / (tc @ tc)
        ss_drift = float(np.sum((V - V.mean(axis=0) - np.outer(tc, slope)) ** 2))
        ss_step, k = best
        if k is not None and ss_step < 0.3 * ss0 and ss_step < 0.7 * ss_drift:
            jump = V[k:].mean(axis=0) - V[:k].mean(axis=0)
            out.append(f"{sensor}, static segments: the residuals jump between {rows[k - 1][1]} and "
                       f"{rows[k][1]} (t ≈ {0.5 * (t[k - 1] + t[k]):.0f} s) by up to "
                       f"{np.max(np.abs(jump)):.1f} sigma and stay: a step in time (a bias jump, a knock, "
                       "a changed mounting), not a function of the attitude; repeat an attitude at the "
                       "end of the run to confirm")
        elif ss_drift < 0.3 * ss0:
            out.append(f"{sensor}, static segments: the residuals drift steadily with time "
                       f"({np.max(np.abs(slope)) * 3600:.2g} sigma per hour): a slow bias drift (warm-up, "
                       "temperature) rather than a function of the attitude; warm the IMU up longer or "
                       "record its temperature (temperature_bias)")
    return out


def _moved_axes(result) -> list[str]:
    """± rotations about one table axis whose axes, seen by the calibrated gyros, differ by more
    than the noise allows: the IMU moved between them (a remount or placement error)."""
    model, x = result.model, result.x
    s = model.s
    try:
        _, Mg = model._matrices(x)
        Lg = np.linalg.inv(Mg)
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
            noise = float(np.degrees(np.max(s.gyro_sigma) * np.sqrt(
                (p.duration_s + m.duration_s) / s.sample_rate_hz) / np.radians(min(abs(p.angle_deg), abs(m.angle_deg)))))
            noise = max(noise, 2 * s.table_angle_sigma_deg / min(abs(p.angle_deg), abs(m.angle_deg)) * 57.3)
            if angle > 5 * noise and angle > 0.005:
                out.append(f"rotations {p.name} and {m.name}: the axis the gyros saw moved by {angle:.3g}° "
                           f"between them (noise {noise:.1g}°): the IMU was moved or remounted between the "
                           "two directions; record each ± pair without touching the IMU")
    return out


def caveats(summaries, effect_id: str) -> list[str]:
    """What the capture cannot tell apart from ``effect_id``, and the segment that would."""
    rates = sorted({round(abs(r.rate_dps), 1) for r in summaries.rotations if r.steady})
    out = []
    if effect_id in ("gyro_scale_asymmetry", "gyro_rate_squared") and len(rates) == 1:
        out.append(f"every rotation is at one rate ({rates[0]:g} °/s): a scale asymmetry (|w|) and a "
                   "term in the square of the rate (w|w|) act alike there; turn at two rates to tell "
                   "them apart")
    if effect_id == "time_offset" and summaries.mounting_offset_m is None:
        out.append("a time offset and the tangential acceleration of a varying rate at an unknown "
                   "mounting offset both follow the rate's changes; centre the IMU on the axis, or vary "
                   "the rate with the IMU centred, to tell them apart")
    if effect_id == "accel_lever_arm" and len(rates) == 1:
        out.append(f"every rotation is at one rate ({rates[0]:g} °/s): the size effect and any other "
                   "term in the square of the rate act alike; turn at two rates to confirm it grows "
                   "with the square of the rate")
    if effect_id == "accel_nonlinearity" and summaries.rotations and len(rates) == 1:
        out.append("a second harmonic in the rotations can also come from a wobbling table axis; "
                   "statics at ±1 g and 45° separate the two")
    return out


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
