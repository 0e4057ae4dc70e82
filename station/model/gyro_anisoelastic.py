"""gyro_anisoelastic: gyro output in the products of the specific force's components."""
from __future__ import annotations

import numpy as np

from station.core import units
from station.model.effect import Effect, Param

# (j, k) of the products F_j F_k each gyro takes, frame p.  F_z^2 is not among them: at rest
# F_x^2 + F_y^2 + F_z^2 = (g/g0)^2, so a coefficient of F_z^2 is a bias there (and N_xx, N_yy are
# the differences N_xx - N_zz, N_yy - N_zz of a model that has all three squares).
PRODUCTS = ((0, 0), (1, 1), (0, 1), (0, 2), (1, 2))
NAMES = ("xx", "yy", "xy", "xz", "yz")


class GyroAnisoelastic(Effect):
    id = "gyro_anisoelastic"
    title = "Gyro anisoelastic term: rate error in products of the specific force (per gyro)"
    physics = ("A proof mass (or a fibre coil) that is not equally stiff in every direction deflects "
               "under the specific force along one axis and is then driven by the force along "
               "another: a false rate in the product of two force components, second order in g.")
    term = ("gyro_raw_i += sum N_i,jk (f_j / g0)(f_k / g0) (°/h/g²), jk in xx, yy, xy, xz, yz, "
            "f in frame p (F_z² is a bias at rest: N_xx and N_yy are relative to N_zz)")
    excited_by = ("static attitudes with gravity at 45° between two axes (the cross products) and "
                  "along each axis (the squares against g-sensitivity, which is odd); rotations "
                  "about horizontal axes add the mean of the products over a revolution")
    magnitudes = ("1-50 °/h/g² (MEMS), 0.01-1 °/h/g² (FOG), < 0.01 °/h/g² (ring laser)")
    signature = ("gyro, static segments: a bias that depends on the attitude evenly (the same at "
                 "+1 g and -1 g, unlike g-sensitivity), largest at the 45° attitudes for the cross "
                 "products.  The squares at ±1 g look like a bias per attitude pair and are told "
                 "from g-sensitivity only by that evenness")
    signature_variable = "gravity_along_axis"
    complex_step = True

    @property
    def params(self):
        return tuple(Param(f"gyro_aniso_{'xyz'[i]}_{n}", "deg/h/g^2", 1.0, 10.0, 3000.0)
                     for i in range(3) for n in NAMES)

    def gyro(self, x, ctx):
        # x (15,), or a batch X (B, 15) with a batch context (gyro_batch): the points' axis second to last
        F = ctx.f_p / units.STANDARD_GRAVITY
        products = np.stack([F[..., j] * F[..., k] for j, k in PRODUCTS], axis=-1)  # (N, 5)
        return products @ x.reshape(*x.shape[:-1], 3, len(PRODUCTS)).mT / 3600.0

    gyro_batch = gyro
