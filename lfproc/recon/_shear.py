"""The shear of a Lambertian patch: every view of a patch from its centre view's extended patch at one disparity.

Used by the Gaussian patch prior (:mod:`._gmm`) and the lights refit (:mod:`._lights`), which imports it from here
because :mod:`._gmm` imports the refit.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError


def shear_matrix(views: tuple[int, int], patch: int, margin: int, disparity: float) -> np.ndarray:
    """``S_d``: ``(V U P P, E E)``, view pixel ``(v, u, y, x)`` from the extended centre patch (bilinear).

    View ``(v, u)`` pixel ``(y, x)`` shows centre-view pixel ``(y - dv d, x - du d)`` (module notes),
    i.e. extended-patch pixel ``(y + R - dv d, x + R - du d)``; a translation beyond the margin
    raises :class:`~lfproc.errors.InputError`.
    """
    nv, nu = views
    e = patch + 2 * margin
    if abs(disparity) * max(nv // 2, nu // 2) > margin:
        raise InputError(f"disparity {disparity:g}: translations of {abs(disparity) * max(nv // 2, nu // 2):g} pixels "
                         f"exceed the model's margin of {margin} pixels")
    out = np.zeros((nv, nu, patch, patch, e, e))
    ii = np.arange(patch)
    for v in range(nv):
        for u in range(nu):
            sy, sx = margin - (v - nv // 2) * disparity, margin - (u - nu // 2) * disparity
            y0, x0 = math.floor(sy), math.floor(sx)
            fy, fx = sy - y0, sx - x0
            for oy, wy in ((0, 1.0 - fy), (1, fy)):
                for ox, wx in ((0, 1.0 - fx), (1, fx)):
                    if wy * wx < 1e-12:
                        continue
                    rows = (ii + y0 + oy)[:, None]
                    cols = (ii + x0 + ox)[None, :]
                    out[v, u, ii[:, None], ii[None, :], rows, cols] += wy * wx
    return out.reshape(nv * nu * patch * patch, e * e)
