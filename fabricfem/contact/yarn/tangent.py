"""The tangent of the yarn contact forces, K = -dF/dx (the contact's part of dR/dx, R = internal - contact
forces): the closed form of [Man2006, Box 7] and the one central-difference helper that differentiates the
exact nodal forces of a contact element (fabricfem.contact.yarn.law) over its stencil. Units: N, m.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

__all__ = ["closed_form", "central_difference"]


def closed_form(area: np.ndarray, penalty: float, slope: np.ndarray, normal: np.ndarray, D: np.ndarray,
                G: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Closed-form tangent (m, 27, 27) [N/m] of m active slaves over their stencils (slave, 4 current master
    vertices, 4 reference master vertices; 3 dofs each) ([Man2006, Box 7], lambda_N fixed, so symmetric):

        K_jk = A eps_N p' G_j G_k n n^T - A H_j H_k D

    area: A (m,) [m^2]; penalty: eps_N [Pa/m]; slope: p' (m,) of the (smoothed) Macaulay bracket; normal: n
    (m, 3); D: dt_T/d(slip) (m, 3, 3) [Pa/m] (law.symmetric_return_map); G, H: (m, 9) stencil weights
    [1, -N_i] at the projection and [1, -N_i(xi_n)] at the reference point. It neglects the variation of n
    and of the projection xi (terms of relative size |g| / h and of the curvature): approximately consistent."""
    KN = (area * penalty * slope)[:, None, None] * normal[:, :, None] * normal[:, None, :]
    KT = -area[:, None, None] * D
    K = np.einsum("mj,mk,mab->mjakb", G, G, KN) + np.einsum("mj,mk,mab->mjakb", H, H, KT)
    return K.reshape(len(area), 27, 27)


def central_difference(forces: Callable[..., np.ndarray], positions: Sequence[np.ndarray],
                       fixed: Sequence[np.ndarray], h: float) -> np.ndarray:
    """K = -dF/dx (m, r, d) [N/m] by central differences with step h [m], vectorized over m elements.

    positions: the stencil blocks, each (m, 3) or (m, k, 3) [m]; their d = sum of 3 k coordinates are
    perturbed one at a time, in the order of the blocks, nodes and components (column j of K). fixed:
    per-element arrays (m, ...) held fixed. forces(*perturbed blocks, *fixed) is called once with all 2 d
    perturbed states stacked (the blocks (2 d m, ...), fixed tiled to match) and returns the forces
    (2 d m, ...) with r entries per element. Truncation O(h^2); round-off ~1e-16 |x| / h."""
    m = len(positions[0])
    sizes = [block[0].size for block in positions]
    n_dir = sum(sizes)
    perturbed, start = [], 0
    for block, size in zip(positions, sizes):
        k = size // 3
        step = np.zeros((n_dir, 1, k, 3))
        step[start + np.arange(size), 0, np.repeat(np.arange(k), 3), np.tile(np.arange(3), k)] = h
        step = step.reshape((n_dir, 1) + block.shape[1:])
        perturbed.append(np.concatenate([block[None] + step, block[None] - step]).reshape((-1,) + block.shape[1:]))
        start += size
    tiled = [np.tile(a, (2 * n_dir,) + (1,) * (a.ndim - 1)) for a in fixed]
    F = forces(*perturbed, *tiled).reshape(2, n_dir, m, -1)
    return np.transpose(-(F[0] - F[1]) / (2.0 * h), (1, 2, 0))
