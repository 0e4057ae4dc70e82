"""Where the model fails, in plain words, from the pattern of the whitened residuals."""
from __future__ import annotations

import numpy as np

FAIL_RMS = 2.0           # a group of residuals whose RMS exceeds this is not noise


def _corr(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 3 or np.std(a) == 0 or np.std(b) == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def describe_failures(result, labels, segs) -> list[str]:
    """Sentences naming the sensor, the segment kind, the worst segments and the pattern."""
    s = result.model.s
    out = []
    groups = {}
    for seg in segs:
        for (q, axis), v in seg.values.items():
            sensor = "accelerometer" if q.startswith("accel") else "gyro"
            groups.setdefault((sensor, seg.kind), []).append((seg.name, q, axis, v))
    failing = {k: v for k, v in groups.items()
               if np.sqrt(np.mean([x[3] ** 2 for x in v])) > FAIL_RMS}
    if not failing:
        return out
    for (sensor, kind), rows in sorted(failing.items()):
        rms = np.sqrt(np.mean([x[3] ** 2 for x in rows]))
        worst = sorted(rows, key=lambda x: -abs(x[3]))[:3]
        where = ", ".join(f"{n} {q} {a} ({v:+.1f} sigma)" for n, q, a, v in worst)
        other_kinds = [k for (sn, k) in failing if sn == sensor and k != kind]
        only = "only" if not other_kinds else f"and {', '.join(other_kinds)}"
        pattern = _pattern(sensor, kind, rows, s)
        out.append(f"{sensor}, {kind} segments {only}: residuals {rms:.1f} times the noise"
                   f"{'; ' + pattern if pattern else ''}; worst: {where}")
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
                words.append("mostly at the rotation frequency (the gravity turning in the body)")
            if second and np.sqrt(np.mean(np.square(second))) > 2 * max(
                    np.sqrt(np.mean(np.square(harmonics))), np.sqrt(np.mean(np.square(dc)))):
                words.append("mostly at twice the rotation frequency")
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
