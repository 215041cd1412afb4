#!/usr/bin/env python3
"""Reference solution of the window-update benchmark with scipy.optimize.least_squares.

Run after the Rust bench entry wrote the problem and its solution:

    cargo bench -p phototraverse-core --bench adjust_window
    python3 bench/adjust/compare.py            # bench/adjust/out/{problem,solution}.json

The model is the window's: left camera EOP per epoch (omega, phi, kappa, X, Y, Z),
right camera through the fixed rig (M_R = Mrel M_L, C_R = C_L + M_L^T b), tie points,
observations weighted by p = 1/sigma^2, and the datum prior on epoch 0. scipy gets the
same start values, an analytic Jacobian (checked against central differences)
and tight tolerances (method 'lm', MINPACK); we compare the
solutions (relative difference with a floor of 1 m / 1 rad) and the times.
Needs numpy and scipy (benchmark only: pip install scipy numpy).
"""
import json
import pathlib
import sys
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

OUT = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else pathlib.Path(__file__).parent / "out"


def rot(w, p, k):
    """M = Rk Rp Rw (docs/conventions.md, "Rotation and collinearity"), vectorised over the leading axis."""
    cw, sw, cp, sp, ck, sk = np.cos(w), np.sin(w), np.cos(p), np.sin(p), np.cos(k), np.sin(k)
    one, zero = np.ones_like(w), np.zeros_like(w)
    rw = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cw, sw], -1), np.stack([zero, -sw, cw], -1)], -2)
    rp = np.stack([np.stack([cp, zero, -sp], -1), np.stack([zero, one, zero], -1), np.stack([sp, zero, cp], -1)], -2)
    rk = np.stack([np.stack([ck, sk, zero], -1), np.stack([-sk, ck, zero], -1), np.stack([zero, zero, one], -1)], -2)
    return rk @ rp @ rw


def rot_derivs(w, p, k):
    """M and dM/d(omega, phi, kappa), vectorised."""
    cw, sw, cp, sp, ck, sk = np.cos(w), np.sin(w), np.cos(p), np.sin(p), np.cos(k), np.sin(k)
    one, zero = np.ones_like(w), np.zeros_like(w)

    def mat(rows):
        return np.stack([np.stack(r, -1) for r in rows], -2)

    rw = mat([[one, zero, zero], [zero, cw, sw], [zero, -sw, cw]])
    drw = mat([[zero, zero, zero], [zero, -sw, cw], [zero, -cw, -sw]])
    rp = mat([[cp, zero, -sp], [zero, one, zero], [sp, zero, cp]])
    drp = mat([[-sp, zero, -cp], [zero, zero, zero], [cp, zero, -sp]])
    rk = mat([[ck, sk, zero], [-sk, ck, zero], [zero, zero, one]])
    drk = mat([[-sk, ck, zero], [-ck, -sk, zero], [zero, zero, zero]])
    return rk @ rp @ rw, [rk @ rp @ drw, rk @ drp @ rw, drk @ rp @ rw]


def main():
    prob = json.loads((OUT / "problem.json").read_text())
    sol = json.loads((OUT / "solution.json").read_text())
    e0 = np.array(prob["epochs"]).reshape(-1, 6)
    p0 = np.array(prob["points"]).reshape(-1, 3)
    obs = np.array(prob["observations"]).reshape(-1, 7)
    ne, npt, no = len(e0), len(p0), len(obs)
    ep, cam, pt = obs[:, 0].astype(int), obs[:, 1].astype(int), obs[:, 2].astype(int)
    xy, sw = obs[:, 3:5], np.sqrt(obs[:, 5:7])
    f = np.array(prob["focal_mm"])[cam]
    mrel = rot(*np.array(prob["rig_angles"]))
    base = np.array(prob["rig_base"])
    ds = prob["datum_sigma"]
    prior = e0[0].copy()
    prior_w = np.array([1 / ds[0]] * 3 + [1 / ds[1]] * 3)
    right = cam == 1

    def residuals(x):
        e = x[: 6 * ne].reshape(-1, 6)
        p = x[6 * ne :].reshape(-1, 3)
        m = rot(e[:, 0], e[:, 1], e[:, 2])
        q = np.einsum("nij,nj->ni", m[ep], p[pt] - e[ep, 3:])
        qr = (q - base) @ mrel.T
        q = np.where(right[:, None], qr, q)
        proj = np.stack([-f * q[:, 0] / q[:, 2], -f * q[:, 1] / q[:, 2]], -1)
        r_obs = (sw * (proj - xy)).ravel()
        r_prior = prior_w * (e[0] - prior)
        return np.concatenate([r_obs, r_prior])

    n = 6 * ne + 3 * npt
    rows = np.arange(no)

    def jacobian(x):
        """Analytic Jacobian (dense): chain rule through the rig, as in the core."""
        e = x[: 6 * ne].reshape(-1, 6)
        p = x[6 * ne :].reshape(-1, 3)
        m, dm = rot_derivs(e[:, 0], e[:, 1], e[:, 2])
        d = p[pt] - e[ep, 3:]
        q = np.einsum("nij,nj->ni", m[ep], d)
        dq_ang = [np.einsum("nij,nj->ni", dmk[ep], d) for dmk in dm]
        dq_pt = m[ep]
        qr = (q - base) @ mrel.T
        q = np.where(right[:, None], qr, q)
        dq_ang = [np.where(right[:, None], v @ mrel.T, v) for v in dq_ang]
        dq_pt = np.where(right[:, None, None], mrel @ dq_pt, dq_pt)
        u, v, w = q[:, 0], q[:, 1], q[:, 2]
        gx = np.stack([-f / w, np.zeros_like(w), f * u / w**2], -1) * sw[:, :1]
        gy = np.stack([np.zeros_like(w), -f / w, f * v / w**2], -1) * sw[:, 1:]
        jac = np.zeros((2 * no + 6, n))
        for c, g in ((0, gx), (1, gy)):
            r = 2 * rows + c
            for a in range(3):
                jac[r, 6 * ep + a] = np.sum(g * dq_ang[a], -1)
            jp = np.einsum("ni,nij->nj", g, dq_pt)
            for a in range(3):
                jac[r, 6 * ne + 3 * pt + a] = jp[:, a]
                jac[r, 6 * ep + 3 + a] = -jp[:, a]
        jac[2 * no + np.arange(6), np.arange(6)] = prior_w
        return jac

    x0 = np.concatenate([e0.ravel(), p0.ravel()])
    # Analytic Jacobian checked against central differences at the start.
    j0 = jacobian(x0)
    h = 1e-6
    for k in (0, 3, 6 * ne - 1, 6 * ne, n - 1):
        dx = np.zeros(n)
        dx[k] = h
        num = (residuals(x0 + dx) - residuals(x0 - dx)) / (2 * h)
        assert np.allclose(num, j0[:, k], rtol=1e-5, atol=1e-3 * np.abs(num).max()), k

    t0 = time.perf_counter()
    res = least_squares(residuals, x0, jac=jacobian, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    t_scipy = time.perf_counter() - t0
    # A second reference: trust-region reflective on the sparse Jacobian (LSMR), the
    # faster scipy configuration for bundle adjustment (it stops at a looser optimum).
    t1 = time.perf_counter()
    res_trf = least_squares(residuals, x0, jac=lambda x: csr_matrix(jacobian(x)), method="trf",
                            tr_solver="lsmr", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=100)
    t_trf = time.perf_counter() - t1

    x_rust = np.concatenate([np.array(sol["epochs"]), np.array(sol["points"])])
    diff = np.abs(res.x - x_rust)
    rel = diff / np.maximum(np.abs(res.x), 1.0)
    cost_scipy = float(np.sum(residuals(res.x) ** 2))
    cost_rust = float(np.sum(residuals(x_rust) ** 2))
    t_rust = sol["seconds_median"]
    print(f"problem: {ne} epochs, {npt} points, {no} observations ({2 * no} equations + 6 datum)")
    print(f"scipy least_squares (lm, analytic Jacobian): {t_scipy * 1e3:.1f} ms, {res.nfev} evaluations, status {res.status}")
    print(f"rust window solve (median of {sol['reps']}):        {t_rust * 1e3:.3f} ms (min {sol['seconds_min'] * 1e3:.3f} ms), "
          f"{sol['iterations']} iterations")
    rel_trf = (np.abs(res_trf.x - x_rust) / np.maximum(np.abs(res_trf.x), 1.0)).max()
    print(f"scipy least_squares (trf, sparse analytic Jacobian, lsmr): {t_trf * 1e3:.1f} ms, "
          f"{res_trf.nfev} evaluations, max relative difference {rel_trf:.3e}")
    print(f"speed-up: {t_scipy / t_rust:.1f}x vs lm, {t_trf / t_rust:.1f}x vs trf   (bar: >= 10x)")
    print(f"vTPv: scipy {cost_scipy:.9f}  rust {cost_rust:.9f}")
    print(f"max |difference|: {diff.max():.3e}   max relative (floor 1): {rel.max():.3e}   (bar: <= 1e-6)")
    print(f"memory per update (budget): {sol['budget_bytes']} B predicted, {sol['arena_used_bytes']} B used")
    ok = rel.max() <= 1e-6 and min(t_scipy, t_trf) / t_rust >= 10
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
