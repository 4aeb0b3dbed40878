"""The compiled measurement update of the raw-sensor filter (raw.py): one message's m channels
(m <= 6) fused jointly, Joseph form, in one call (the numpy version of these few lines cost
about ten times the arithmetic in call overhead at 100 Hz).

Kept apart from raw.py so that the numba cache's group of compiled sources
(core/__init__.py COMPILED_SOURCES) holds only this file and what it imports.
"""
import math

import numpy as np

from auv_ident.core.compiled_cache import cached_njit

OK = 0
ERR_NOT_PD = 1


@cached_njit()
def joseph_update(xf, P, nu, H, Rm, P_out, w, gain):  # noqa: C901
    """x_f += K nu and P_out = (I - K H) P (I - K H)^T + K Rm K^T with K = P H^T S^-1,
    S = H P H^T + Rm; xf (n,) in place, P (n, n), nu (m,), H (m, n), Rm (m, m). w (m,) gets the
    innovation whitened by the Cholesky factor of S, gain (n,) 1/P_out_ii - 1/P_ii (the
    information the update gave each state). Returns (status, NIS)."""
    n = xf.shape[0]
    m = nu.shape[0]
    PHt = np.dot(P, H.T)
    S = np.dot(H, PHt) + Rm
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            s = 0.5 * (S[i, j] + S[j, i])
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not (s > 0.0) or not math.isfinite(s):
                    return ERR_NOT_PD, np.nan
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    # K^T = S^-1 H P: forward and back substitution per column
    Kt = np.empty((m, n))
    z = np.empty(m)
    for col in range(n):
        for i in range(m):
            s = PHt[col, i]
            for k in range(i):
                s -= L[i, k] * z[k]
            z[i] = s / L[i, i]
        for i in range(m - 1, -1, -1):
            s = z[i]
            for k in range(i + 1, m):
                s -= L[k, i] * Kt[k, col]
            Kt[i, col] = s / L[i, i]
    nis = 0.0
    for i in range(m):
        s = nu[i]
        for k in range(i):
            s -= L[i, k] * w[k]
        w[i] = s / L[i, i]
        nis += w[i] * w[i]
    for i in range(n):
        s = 0.0
        for a in range(m):
            s += Kt[a, i] * nu[a]
        xf[i] += s
    A = -np.dot(Kt.T, H)
    for i in range(n):
        A[i, i] += 1.0
    KR = np.dot(Kt.T, Rm)
    Pn = np.dot(np.dot(A, P), A.T) + np.dot(KR, Kt)
    for i in range(n):
        for j in range(i + 1):
            v = 0.5 * (Pn[i, j] + Pn[j, i])
            P_out[i, j] = v
            P_out[j, i] = v
        if not (P_out[i, i] > 0.0) or not math.isfinite(xf[i]):
            return ERR_NOT_PD, nis
        gain[i] = 1.0 / P_out[i, i] - 1.0 / P[i, i]
    return OK, nis
