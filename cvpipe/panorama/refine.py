"""Joint refinement of the global homographies over the inliers of every accepted pair (Levenberg-Marquardt).

:func:`refine_homographies` frees 8 parameters per image; :func:`refine_rotations` fits a rotating camera (one
focal length, 3 rotation parameters per image). Both minimise the symmetric transfer error with
:func:`levenberg_marquardt`, whose damped normal equations are solved by :func:`cvpipe.linalg.solve_spd`.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import EstimationError
from ..geometry import apply_homography
from ..linalg import solve_spd
from .features import normalize_det


def _transfer_rms(G: dict, edges: dict) -> float:
    err, cnt = 0.0, 0
    for (i, j), e in edges.items():
        if i in G and j in G:
            Hij = np.linalg.inv(G[j]) @ G[i]
            p = apply_homography(Hij, e.src)
            err += float(np.sum((p - e.dst) ** 2))
            cnt += len(e.src)
    return float(np.sqrt(err / max(cnt, 1)))


def _blocks(G: dict, edges: dict, max_points_per_pair: int, rng) -> list:
    """(i, j, src, dst) per accepted pair inside ``G``, at most ``max_points_per_pair`` random inliers each."""
    blocks = []
    for (i, j), e in edges.items():
        if i not in G or j not in G:
            continue
        k = len(e.src)
        sel = np.sort(rng.choice(k, max_points_per_pair, replace=False)) if k > max_points_per_pair else np.arange(k)
        blocks.append((i, j, e.src[sel], e.dst[sel]))
    return blocks


def _solve(blocks: list, homs, x0: np.ndarray, columns, T: dict | None = None,
           Tr_inv: np.ndarray | None = None) -> np.ndarray:
    """Least squares over the symmetric transfer error of all ``blocks``; ``homs(x)`` gives the homographies,
    ``columns(a)`` the parameter columns image ``a`` depends on (for the sparse Jacobian).

    With ``T`` and ``Tr_inv`` the parameters are the 8 free entries of ``Hn_a`` in ``H_a = Tr_inv Hn_a T_a`` and the
    Jacobian is analytic; otherwise it is estimated by grouped finite differences."""
    keys = sorted({a for blk in blocks for a in blk[:2]})
    pos = {a: k for k, a in enumerate(keys)}
    e_i = np.array([pos[blk[0]] for blk in blocks])
    e_j = np.array([pos[blk[1]] for blk in blocks])
    edge = np.concatenate([np.full(len(blk[2]), k) for k, blk in enumerate(blocks)])
    src = np.concatenate([blk[2] for blk in blocks]).astype(np.float64)
    dst = np.concatenate([blk[3] for blk in blocks]).astype(np.float64)
    src_h = np.column_stack([src, np.ones(len(src))])
    dst_h = np.column_stack([dst, np.ones(len(dst))])
    n = len(src)

    def residuals(x):
        H = homs(x)
        Hs = np.stack([H[a] for a in keys])
        Hinv = np.linalg.inv(Hs)
        fwd = np.einsum("nij,nj->ni", (Hinv[e_j] @ Hs[e_i])[edge], src_h)
        bwd = np.einsum("nij,nj->ni", (Hinv[e_i] @ Hs[e_j])[edge], dst_h)
        return np.concatenate([(fwd[:, :2] / fwd[:, 2:] - dst).ravel(), (bwd[:, :2] / bwd[:, 2:] - src).ravel()])

    if T is None:
        from scipy.sparse import coo_matrix  # here: its import costs the command ~0.2 s

        # residual rows of edge k: forward 2p, 2p+1 and backward 2n + 2p, 2n + 2p + 1
        rows, cols = [], []
        for k, blk in enumerate(blocks):
            pts = np.nonzero(edge == k)[0]
            r = np.concatenate([2 * pts, 2 * pts + 1, 2 * n + 2 * pts, 2 * n + 2 * pts + 1])
            for a in blk[:2]:
                c = columns(a)
                if len(c):
                    rows.append(np.repeat(r, len(c)))
                    cols.append(np.tile(np.asarray(c), len(r)))
        sparsity = coo_matrix((np.ones(sum(len(r) for r in rows), np.int8),
                               (np.concatenate(rows), np.concatenate(cols))), shape=(4 * n, len(x0))).tocsr()
        sparsity.data[:] = 1
        sp = sparsity.tocsc()

        def jac(x):  # forward differences, one column at a time (used for the few rotation parameters)
            r0 = residuals(x)
            cols = []
            for k in range(len(x)):
                h = 1e-7 * max(1.0, abs(x[k]))
                xk = x.copy()
                xk[k] += h
                rows = sp.indices[sp.indptr[k]:sp.indptr[k + 1]]
                cols.append((rows, np.full(len(rows), k), (residuals(xk)[rows] - r0[rows]) / h))
            r, c, v = (np.concatenate([t[m] for t in cols]) for m in range(3))
            return coo_matrix((v, (r, c)), shape=(4 * n, len(x))).tocsr()
    else:
        col0 = {a: (columns(a)[0] if len(columns(a)) else -1) for a in keys}
        bounds = np.searchsorted(edge, np.arange(len(blocks) + 1))  # points are stored edge by edge
        C_ref = Tr_inv

        def derivatives(Ha, Hb_inv, Ta, Tb, pts_h):
            # residual proj(H_b^-1 H_a p) - q of one edge: (2m, 8) derivatives w.r.t. Hn_a (source), Hn_b (target)
            u = pts_h @ (Hb_inv @ Ha).T
            iw = 1.0 / u[:, 2:]
            C = Hb_inv @ C_ref
            B = np.stack([(C[0] - u[:, :1] * iw * C[2]) * iw, (C[1] - u[:, 1:2] * iw * C[2]) * iw], axis=1)
            q, w = pts_h @ Ta.T, u @ Tb.T
            Ja = (B[:, :, :, None] * q[:, None, None, :]).reshape(-1, 9)[:, :8]
            Jb = -(B[:, :, :, None] * w[:, None, None, :]).reshape(-1, 9)[:, :8]
            return Ja, Jb

        def normal(x, r):
            # J^T J and J^T r accumulated edge by edge in dense (8, 8) blocks: a residual touches two images only
            H = homs(x)
            Hinv = {a: np.linalg.inv(H[a]) for a in keys}
            A = np.zeros((len(x0), len(x0)))
            g = np.zeros(len(x0))
            fwd, bwd = r[:2 * n], r[2 * n:]
            for k, blk in enumerate(blocks):
                lo, hi = bounds[k], bounds[k + 1]
                for a, b, pts_h, res in ((blk[0], blk[1], src_h[lo:hi], fwd[2 * lo:2 * hi]),
                                         (blk[1], blk[0], dst_h[lo:hi], bwd[2 * lo:2 * hi])):
                    Ja, Jb = derivatives(H[a], Hinv[b], T[a], T[b], pts_h)
                    ca, cb = col0[a], col0[b]
                    if ca >= 0:
                        A[ca:ca + 8, ca:ca + 8] += Ja.T @ Ja
                        g[ca:ca + 8] += Ja.T @ res
                    if cb >= 0:
                        A[cb:cb + 8, cb:cb + 8] += Jb.T @ Jb
                        g[cb:cb + 8] += Jb.T @ res
                    if ca >= 0 and cb >= 0:
                        cross = Ja.T @ Jb
                        A[ca:ca + 8, cb:cb + 8] += cross
                        A[cb:cb + 8, ca:ca + 8] += cross.T
            return A, g

        x = levenberg_marquardt(residuals, None, x0, normal=normal)
        if not np.all(np.isfinite(x)):
            raise EstimationError("homography refinement diverged; set `refine: none` or raise `min_inliers`")
        return x

    x = levenberg_marquardt(residuals, jac, x0)
    if not np.all(np.isfinite(x)):
        raise EstimationError("homography refinement diverged; set `refine: none` or raise `min_inliers`")
    return x


def _sum_squares(r: np.ndarray) -> float:
    """``r @ r`` without BLAS: OpenBLAS threads a dot product of more than about 32k elements, which took 9 ms
    instead of 40 us on the loaded 2-core machine (halfdome-14's 40k residuals, twice per LM step)."""
    return float(np.einsum("i,i->", r, r))


def levenberg_marquardt(fun, jac, x0: np.ndarray, max_iter: int = 30, ftol: float = 1e-7,
                        normal=None) -> np.ndarray:
    """Minimise ``|fun(x)|^2`` by Levenberg-Marquardt on the normal equations.

    ``jac(x)`` returns the sparse (m, n) Jacobian; alternatively ``normal(x, r)`` returns ``(J^T J, J^T r)``
    directly (dense (n, n) and (n,)), for problems whose structure gives them without forming ``J``. With n in
    the hundreds and m in the tens of thousands, forming ``J^T J`` once per iteration is far cheaper than an
    iterative trust-region solver (``least_squares``' LSMR does hundreds of length-m vector operations per step,
    which thread-contended BLAS makes slow on a shared machine).
    Marquardt's scaling by ``diag(J^T J)`` makes the step invariant to the parameter units.

    Returns
    -------
    (n,) float64
        The parameters where the cost stopped decreasing by more than ``ftol`` (relative).
    """
    x = np.asarray(x0, np.float64).copy()
    r = fun(x)
    cost = _sum_squares(r)
    lam = 1e-4
    for _ in range(max_iter):
        if normal is not None:
            A, g = normal(x, r)
        else:
            J = jac(x)
            A, g = (J.T @ J).toarray(), J.T @ r
        d = np.diag(A).copy()
        d[d <= 0] = 1.0
        while lam < 1e10:
            step = solve_spd(A + lam * np.diag(d), -g)
            if step is None:
                lam *= 10
                continue
            r_new = fun(x + step)
            c_new = _sum_squares(r_new)
            if np.isfinite(c_new) and c_new < cost:
                break
            lam *= 10
        else:
            return x  # no step lowers the cost: at a minimum
        x, r, decrease, cost = x + step, r_new, cost - c_new, c_new
        lam = max(lam / 10, 1e-12)
        if decrease <= ftol * cost:
            break
    return x


def refine_homographies(G: dict, edges: dict, sizes: Sequence[tuple[int, int]], reference: int,
                        max_points_per_pair: int, rng=None) -> dict:
    """Jointly refine the global homographies (8 parameters per image) over the inliers of all accepted pairs.

    Minimises, for every accepted pair (i, j) and inlier (p, q), the symmetric transfer error
    ``|G_j^-1 G_i p - q|^2 + |G_i^-1 G_j q - p|^2`` in pixels; the reference stays the identity. Coordinates are
    centred and scaled per image so the parameters are well conditioned; the Jacobian is sparse (a residual
    depends on two images only).

    Parameters
    ----------
    G : dict int -> (3, 3)
        Chained initial homographies (image -> reference pixels).
    edges : dict (i, j) -> Edge
    sizes : sequence of (w, h)
        Image sizes (indexed by input position).
    reference : int
    max_points_per_pair : int
        Inliers used per pair at most (a random subset; the rest add time, not accuracy).
    rng : seed or Generator

    Returns
    -------
    dict int -> (3, 3)
        Refined homographies, ``det = 1``.
    """
    rng = np.random.default_rng(rng)
    nodes = [a for a in sorted(G) if a != reference]
    if not nodes:
        return dict(G)
    slot = {a: k for k, a in enumerate(nodes)}
    T = {}
    for a in G:
        w, h = sizes[a]
        s = 2.0 / max(w, h)
        T[a] = np.array([[s, 0, -s * (w - 1) / 2], [0, s, -s * (h - 1) / 2], [0, 0, 1.0]])
    Tr, Tr_inv = T[reference], np.linalg.inv(T[reference])
    x0 = np.zeros(8 * len(nodes))
    for a in nodes:
        Hn = Tr @ G[a] @ np.linalg.inv(T[a])
        x0[8 * slot[a]: 8 * slot[a] + 8] = (Hn / Hn[2, 2]).ravel()[:8]

    def homs(x):
        H = {reference: np.eye(3)}
        for a in nodes:
            H[a] = Tr_inv @ np.append(x[8 * slot[a]: 8 * slot[a] + 8], 1.0).reshape(3, 3) @ T[a]
        return H

    def columns(a):
        return [] if a == reference else list(range(8 * slot[a], 8 * slot[a] + 8))

    x = _solve(_blocks(G, edges, max_points_per_pair, rng), homs, x0, columns, T, Tr_inv)
    return {a: normalize_det(H) for a, H in homs(x).items()}


def _intrinsics(f: float, size: tuple[int, int]) -> np.ndarray:
    w, h = size
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation matrix closest to ``M`` in the Frobenius norm (SVD, determinant +1)."""
    U, _, Vt = np.linalg.svd(M)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1, 1, -1.0]) @ Vt
    return R


def refine_rotations(G: dict, edges: dict, sizes: Sequence[tuple[int, int]], reference: int, focal: float,
                     max_points_per_pair: int, rng=None) -> tuple[dict, float]:
    """Jointly refine a rotating-camera model ``G_i = K_ref R_i K_i^-1`` over the inliers of all accepted pairs.

    One shared focal length (pixels, principal points at the image centres) and three rotation parameters per
    non-reference image, the same symmetric transfer error as :func:`refine_homographies`. With 3 instead of 8
    degrees of freedom per image, the homographies extrapolate correctly far from the overlaps when the photos
    were taken by turning the camera (the usual panorama); views of a flat scene from moving positions do not fit
    it, which :func:`register` detects from the residuals.

    Returns
    -------
    G : dict int -> (3, 3)
        Refined homographies, ``det = 1``.
    focal : float
        Refined focal length in pixels.
    """
    from scipy.spatial.transform import Rotation  # here: its import costs the command ~0.3 s

    rng = np.random.default_rng(rng)
    nodes = [a for a in sorted(G) if a != reference]
    slot = {a: k for k, a in enumerate(nodes)}
    Kr_inv = np.linalg.inv(_intrinsics(focal, sizes[reference]))
    x0 = np.zeros(1 + 3 * len(nodes))
    x0[0] = np.log(focal)
    for a in nodes:
        R = nearest_rotation(Kr_inv @ G[a] @ _intrinsics(focal, sizes[a]))
        x0[1 + 3 * slot[a]: 4 + 3 * slot[a]] = Rotation.from_matrix(R).as_rotvec()

    def homs(x):
        f = np.exp(x[0])
        Kr = _intrinsics(f, sizes[reference])
        H = {reference: np.eye(3)}
        for a in nodes:
            R = Rotation.from_rotvec(x[1 + 3 * slot[a]: 4 + 3 * slot[a]]).as_matrix()
            H[a] = Kr @ R @ np.linalg.inv(_intrinsics(f, sizes[a]))
        return H

    def columns(a):
        return [0] if a == reference else [0] + list(range(1 + 3 * slot[a], 4 + 3 * slot[a]))

    x = _solve(_blocks(G, edges, max_points_per_pair, rng), homs, x0, columns)
    return {a: normalize_det(H) for a, H in homs(x).items()}, float(np.exp(x[0]))
