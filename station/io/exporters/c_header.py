"""A C header for firmware: the compensation matrices and biases in double, float and fixed
point (Q format, int32), with inline functions that apply them.

Convention (station's, unchanged): out = M (raw - b), accelerometers into m/s^2, gyros into
deg/s, frame p; b in the raw units.  Fixed point: every matrix element is round(M 2^MF) in an
int32 (MF the largest number of fraction bits that keeps every element in range), inputs and
biases are Q numbers with IF fraction bits chosen for the full scale below; the product is
accumulated in int64 and shifted right by MF (rounding), so the output has IF fraction bits.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from station.core.errors import UserError
from station.io.exporters.source import ExportSource, fmt, safe_comment, write_text

TITLE = "C header (double, float and Q31 fixed point matrices and biases, inline functions)"
SUFFIX = ".h"
CONVENTION = ("station: out = M (raw - b); accelerometers into m/s^2, gyros into deg/s, frame p "
              "(accelerometer-defined); b in the raw units; row-major [row][column]; fixed point: "
              "M_q = round(M 2^MATRIX_FRAC_BITS), raw_q and b_q with INPUT_FRAC_BITS, out_q with "
              "INPUT_FRAC_BITS")
# the largest raw input the fixed-point form must hold, per raw unit (with the bias added)
FULL_SCALE = {"m/s^2": 400.0, "g": 40.0, "deg/s": 4000.0, "rad/s": 70.0, "raw": 65536.0}
INT32_MAX = 2**31 - 1


def matrix_frac_bits(matrix: np.ndarray) -> int:
    """Fraction bits so that every element times 2^bits fits an int32."""
    largest = float(np.max(np.abs(matrix)))
    bits = int(30 - max(0, math.ceil(math.log2(largest + 1e-300))) if largest > 0 else 30)
    if bits < 0:
        raise ValueError(f"a matrix element of {largest:.3g} leaves no fraction bits")
    return bits


def input_frac_bits(unit: str, bias: np.ndarray) -> int:
    scale = FULL_SCALE[unit] + float(np.max(np.abs(bias)))
    bits = 30 - math.ceil(math.log2(scale))
    if bits < 0:
        raise ValueError(f"a bias of {float(np.max(np.abs(bias))):.3g} leaves no fraction bits")
    return bits


def quantise(a: np.ndarray, bits: int) -> np.ndarray:
    q = np.round(np.asarray(a, float) * 2.0**bits)
    if np.any(np.abs(q) > INT32_MAX):
        raise ValueError("fixed-point value out of int32 range")
    return q.astype(np.int64)


def _c_array(kind: str, name: str, a, cfmt) -> str:
    a = np.asarray(a)
    if a.ndim == 2:
        body = ",\n    ".join("{" + ", ".join(cfmt(v) for v in row) + "}" for row in a)
        return f"static const {kind} {name}[3][3] = {{\n    {body}\n}};"
    return f"static const {kind} {name}[3] = {{" + ", ".join(cfmt(v) for v in a) + "};"


def _triad(prefix: str, matrix, bias, unit: str, out_unit: str) -> str:
    P = prefix.upper()
    mf, inf = matrix_frac_bits(matrix), input_frac_bits(unit, bias)
    dbl = lambda v: fmt(v)                          # noqa: E731 - shortest round-trip double
    flt = lambda v: f"{float(np.float32(v))!r}f"    # noqa: E731 - the float the compiler stores
    i32 = lambda v: f"INT32_C({int(v)})"            # noqa: E731
    return "\n".join([
        f"/* {prefix}: raw {safe_comment(unit)} -> {out_unit}: out = M (raw - b) */",
        f"#define {P}_MATRIX_FRAC_BITS {mf}",
        f"#define {P}_INPUT_FRAC_BITS {inf}",
        _c_array("double", f"{prefix}_matrix", matrix, dbl),
        _c_array("double", f"{prefix}_bias", bias, dbl),
        _c_array("float", f"{prefix}_matrix_f", matrix, flt),
        _c_array("float", f"{prefix}_bias_f", bias, flt),
        _c_array("int32_t", f"{prefix}_matrix_q", quantise(matrix, mf), i32),
        _c_array("int32_t", f"{prefix}_bias_q", quantise(bias, inf), i32),
        f"static inline void {prefix}_compensate(const double raw[3], double out[3]) {{",
        "    for (int i = 0; i < 3; ++i) {",
        f"        out[i] = {prefix}_matrix[i][0] * (raw[0] - {prefix}_bias[0])"
        f" + {prefix}_matrix[i][1] * (raw[1] - {prefix}_bias[1])"
        f" + {prefix}_matrix[i][2] * (raw[2] - {prefix}_bias[2]);",
        "    }",
        "}",
        f"static inline void {prefix}_compensate_f(const float raw[3], float out[3]) {{",
        "    for (int i = 0; i < 3; ++i) {",
        f"        out[i] = {prefix}_matrix_f[i][0] * (raw[0] - {prefix}_bias_f[0])"
        f" + {prefix}_matrix_f[i][1] * (raw[1] - {prefix}_bias_f[1])"
        f" + {prefix}_matrix_f[i][2] * (raw[2] - {prefix}_bias_f[2]);",
        "    }",
        "}",
        f"/* raw_q, out_q: Q numbers with {P}_INPUT_FRAC_BITS fraction bits */",
        f"static inline void {prefix}_compensate_q(const int32_t raw_q[3], int32_t out_q[3]) {{",
        "    for (int i = 0; i < 3; ++i) {",
        "        int64_t acc = 0;",
        "        for (int j = 0; j < 3; ++j)",
        f"            acc += (int64_t){prefix}_matrix_q[i][j] * ((int64_t)raw_q[j] - {prefix}_bias_q[j]);",
        f"        acc += (int64_t)1 << ({P}_MATRIX_FRAC_BITS - 1);",
        f"        out_q[i] = (int32_t)(acc >> {P}_MATRIX_FRAC_BITS);",
        "    }",
        "}",
    ])


def header_text(source: ExportSource, guard: str = "STATION_CALIBRATION_H") -> str:
    parts = ["/*"] + [f" * {safe_comment(line)}" for line in
                      [*source.header_lines(), "convention: " + CONVENTION]] + [" */",
             f"#ifndef {guard}", f"#define {guard}", "", "#include <stdint.h>", "",
             _triad("station_accel", source.accel_matrix, source.accel_bias, source.accel_unit, "m/s^2")]
    if source.has_gyro:
        parts += ["", "#define STATION_HAS_GYRO 1",
                  _triad("station_gyro", source.gyro_matrix, source.gyro_bias, source.gyro_unit, "deg/s")]
    else:
        parts += ["", "#define STATION_HAS_GYRO 0 /* accelerometer-only calibration */"]
    return "\n".join(parts + ["", f"#endif /* {guard} */", ""])


def write(source: ExportSource, path) -> list[Path]:
    try:
        text = header_text(source)
    except ValueError as e:
        raise UserError(f"{source.origin}: cannot be written in fixed point: {e}") from None
    return [write_text(path, text)]
