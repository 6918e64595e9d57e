"""Linear blend skinning of a triangulated skin to a Body's segments: the weights and the posed vertices.

Posing ([MagnenatThalmann1988], linear blend skinning): each segment k of the body has a rigid frame, its centre
c_k(t) [m] and rotation R_k(t) = [e1 e2 e3] from its joints and marker (`fabricfem.body.pose.segment_frame`). A skin
vertex v [m], given in the mesh's rest pose, where segment k has the frame (c_k^0, R_k^0), is posed at time t [s] as

    v(t) = sum_k w_k (R_k(t) (R_k^0)^T (v - c_k^0) + c_k(t))          (weights w_k >= 0, sum_k w_k = 1)

so a vertex of weight 1 on one segment moves rigidly with it; the rest frames come from the joint and marker
positions in the mesh's rest pose (by default the body's own pose at its first time).

Weights: bone heat diffusion ([Baran2007, sec. 4]): every segment is a bone, the line J1-J2 between its joints;
with d_j [m] the distance of vertex j to its nearest bone and p^k_j = 1 where bone k is that nearest bone (ties
shared), the weights of bone k solve the screened Poisson problem on the surface

    (-L + M H) w^k = M H p^k,      H = diag(c / d_j^2),  c = `heat` (default 4; 1 in [Baran2007])

with L the cotangent Laplacian and M the Voronoi mass matrix of the mesh ([Meyer2003]; libigl `cotmatrix`,
`massmatrix`), factorised once (scipy splu) for the K right-hand sides. Departure: Baran and Popovic attach a
vertex only to bones it sees along a ray inside the mesh; here the nearest bone is taken without that visibility
test (the segments of the project's bodies are convex-ish limbs seen from their own skin); and c = 4 instead of 1:
the blend decays over ~ d / sqrt(c) from a joint, and with c = 1 the middle of the Debian human's thighs (0.36 m
long, 0.08 m thick) carries only a median weight 0.93 of its thigh, with c = 4 it is 1.000 (rigid; the shanks 0.998
and 1.000). The weights sum to 1
(the constant solves the summed system); small values are cut continuously, w <- max(w - cutoff, 0), and the rows
renormalised, so a segment's middle moves exactly rigidly (weights 1) and only bands around the joints blend.
"""
from __future__ import annotations

from typing import Mapping

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

HEAT = 4.0                  # c of H = c / d^2 (1 in [Baran2007]; 4 measured: module docstring)
WEIGHT_CUTOFF = 0.01        # weights below this are cut (continuously) and the rows renormalised
MIN_BONE_DISTANCE = 1e-4    # m: the distance to the nearest bone is floored here (a vertex on a bone)


def segment_points(body) -> list[str]:
    """The joint and marker names the body's segments are posed from (each once, in segment order)."""
    names: dict[str, None] = {}
    for s in body.segments.values():
        for n in (s.proximal, s.distal, s.marker):
            names.setdefault(n)
    return list(names)


def check_rest_positions(body, rest_positions: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The rest positions (name -> (3,) [m]) as float arrays; ValueError naming `rest_positions` and the missing
    or non-finite joints and markers."""
    missing = [n for n in segment_points(body) if n not in rest_positions]
    if missing:
        raise ValueError(f"rest_positions: missing the joints/markers {missing} (the segments need "
                         f"{segment_points(body)})")
    out = {n: np.asarray(rest_positions[n], dtype=float) for n in segment_points(body)}
    bad = [n for n, p in out.items() if p.shape != (3,) or not np.all(np.isfinite(p))]
    if bad:
        raise ValueError(f"rest_positions: {bad} must be finite points of shape (3,) [m]")
    return out


def frames(body, positions: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Centres (K, 3) [m] and rotations (K, 3, 3) of the body's segments (in `Body.segments` order) posed from
    the joint and marker `positions` (`Segment.pose`)."""
    posed = [s.pose(positions) for s in body.segments.values()]
    return np.array([e.center for e in posed]), np.array([e.rotation for e in posed])


def bones(body, positions: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The bones' ends J1 (K, 3), J2 (K, 3) [m] from the joint positions."""
    segs = list(body.segments.values())
    return (np.array([positions[s.proximal] for s in segs], dtype=float),
            np.array([positions[s.distal] for s in segs], dtype=float))


def bone_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, K) distances [m] of the points (N, 3) to the K line segments a_k-b_k."""
    ab = b - a                                                     # (K, 3)
    ap = points[:, None, :] - a[None, :, :]                        # (N, K, 3)
    s = np.clip(np.einsum("nki,ki->nk", ap, ab) / np.maximum(np.einsum("ki,ki->k", ab, ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(ap - s[:, :, None] * ab[None], axis=2)


def bone_heat_weights(vertices: np.ndarray, faces: np.ndarray, a: np.ndarray, b: np.ndarray, heat: float = HEAT,
                      cutoff: float = WEIGHT_CUTOFF) -> np.ndarray:
    """(V, K) skinning weights of the vertices (V, 3) [m] of a closed triangulation `faces` (F, 3) for the K bones
    a_k-b_k [m] by bone heat diffusion ([Baran2007, sec. 4], module docstring): non-negative, rows summing to 1,
    cut below `cutoff`."""
    v = np.ascontiguousarray(vertices, dtype=float)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    d = bone_distances(v, a, b)
    nearest = d.min(axis=1)
    p = (d <= nearest[:, None] * (1.0 + 1e-9)).astype(float)
    p /= p.sum(axis=1, keepdims=True)
    h = heat / np.maximum(nearest, MIN_BONE_DISTANCE) ** 2
    L = igl.cotmatrix(v, f)
    M = igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_VORONOI)
    mh = M.diagonal() * h
    system = (-L + sp.diags(mh)).tocsc()
    w = splu(system).solve(mh[:, None] * p)
    w = np.maximum(w - cutoff, 0.0)
    total = w.sum(axis=1, keepdims=True)
    lost = total[:, 0] <= 0.0                 # no weight left after the cut: the nearest bone alone
    w[lost] = p[lost]
    return w / np.where(lost[:, None], 1.0, total)


def blend_transforms(rest_centers: np.ndarray, rest_rotations: np.ndarray, centers: np.ndarray,
                     rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The segments' rigid maps from rest to pose, v -> A_k v + b_k with A_k = R_k (R_k^0)^T and
    b_k = c_k - A_k c_k^0 [m]: (K, 3, 3), (K, 3)."""
    A = np.einsum("kij,klj->kil", rotations, rest_rotations)
    return A, centers - np.einsum("kij,kj->ki", A, rest_centers)


def pose_vertices(vertices: np.ndarray, weights: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Posed vertices (V, 3) [m]: sum_k w_k (A_k v + b_k) ([MagnenatThalmann1988]); the weighted maps are summed
    first, so the cost is one 3x4 affine map per vertex."""
    blended_A = np.einsum("vk,kij->vij", weights, A)
    return np.einsum("vij,vj->vi", blended_A, vertices) + weights @ b
