"""The photogrammetric conventions the bench scripts share (docs/conventions.md): the
rotation `M = Rk Rp Rw` from omega, phi, kappa, its inverse, and the flip between KITTI
camera axes and photogrammetric ones. numpy only, so that scripts without OpenCV can
import it."""
import numpy as np

# KITTI camera axes (x right, y down, z forward) from photogrammetric ones (x right, y up,
# z backward) and back.
F = np.diag([1.0, -1.0, -1.0])


def rotation(omega, phi, kappa):
    """M = Rk Rp Rw (object to camera, photogrammetric axes), angles in radians."""
    cw, sw, cp, sp, ck, sk = (np.cos(omega), np.sin(omega), np.cos(phi), np.sin(phi),
                              np.cos(kappa), np.sin(kappa))
    rw = np.array([[1, 0, 0], [0, cw, sw], [0, -sw, cw]])
    rp = np.array([[cp, 0, -sp], [0, 1, 0], [sp, 0, cp]])
    rk = np.array([[ck, sk, 0], [-sk, ck, 0], [0, 0, 1]])
    return rk @ rp @ rw


def angles(m):
    """(omega, phi, kappa) in radians of `M = Rk Rp Rw`, phi in [-pi/2, pi/2]."""
    return np.array([np.arctan2(-m[2, 1], m[2, 2]), np.arcsin(np.clip(m[2, 0], -1, 1)),
                     np.arctan2(-m[1, 0], m[0, 0])])
