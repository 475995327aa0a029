"""Radau collocation points and Lagrange bases on the unit element (7.3).

Each element ``[t_{i-1}, t_i]`` is mapped to ``tau in [0, 1]``. States use
the Lagrange polynomial through ``tau_0 = 0`` and the ``K`` Radau IIA points
``tau_1 < ... < tau_K = 1``:

    l_j(tau) = prod_{k != j} (tau - tau_k) / (tau_j - tau_k)

(the chapter prints the basis with a summation sign; it is this product).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.polynomial import legendre

from ..errors import SettingsError

__all__ = ["radau_points", "lagrange_basis", "differentiation_matrix", "MAX_DEGREE"]

MAX_DEGREE = 5


@lru_cache(maxsize=None)
def _radau(K: int) -> tuple[float, ...]:
    # right Radau points on [-1, 1]: roots of P_K(x) - P_{K-1}(x) (x = 1 is one of them)
    c = np.zeros(K + 1)
    c[K] = 1.0
    c[K - 1] -= 1.0
    x = np.sort(np.real(legendre.legroots(c)))
    x[-1] = 1.0
    return tuple((1.0 + x) / 2.0)


def radau_points(K: int) -> np.ndarray:
    """The K Radau IIA collocation points on [0, 1] (the last is 1).

    Parameters
    ----------
    K : int
        Number of collocation points, 1 to 5.

    Returns
    -------
    ndarray, shape (K,)

    Examples
    --------
    >>> radau_points(2)
    array([0.33333333, 1.        ])
    """
    if not isinstance(K, (int, np.integer)) or not 1 <= K <= MAX_DEGREE:
        raise SettingsError(f"the number of collocation points K must be an integer from 1 to {MAX_DEGREE}, got {K!r}")
    return np.array(_radau(int(K)))


def element_nodes(K: int) -> np.ndarray:
    """``(0, tau_1, ..., tau_K)``: the state nodes of one element, shape (K+1,)."""
    return np.concatenate([[0.0], radau_points(K)])


def lagrange_basis(nodes: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives of the Lagrange basis through ``nodes`` at ``tau``.

    Parameters
    ----------
    nodes : ndarray, shape (m,)
    tau : ndarray, shape (n,)

    Returns
    -------
    values, derivatives : ndarray, shape (n, m)
        ``values[i, j] = l_j(tau_i)``, ``derivatives[i, j] = l_j'(tau_i)``.
    """
    nodes = np.asarray(nodes, dtype=float)
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    m = nodes.size
    vals = np.ones((tau.size, m))
    ders = np.zeros((tau.size, m))
    for j in range(m):
        others = [k for k in range(m) if k != j]
        denom = np.prod([nodes[j] - nodes[k] for k in others])
        factors = np.stack([tau - nodes[k] for k in others], axis=1) if others else np.ones((tau.size, 0))
        vals[:, j] = np.prod(factors, axis=1) / denom
        for i_skip in range(len(others)):
            keep = [i for i in range(len(others)) if i != i_skip]
            ders[:, j] += np.prod(factors[:, keep], axis=1) / denom
    return vals, ders


def differentiation_matrix(K: int) -> np.ndarray:
    """``D[j, l] = l_l'(tau_j)`` for the K collocation points, shape (K, K+1).

    With element length ``h``, ``ds/dt`` at collocation point ``j`` is
    ``(1/h) sum_l D[j, l] s_l`` where ``s_0`` is the element-start value.
    """
    nodes = element_nodes(K)
    _, ders = lagrange_basis(nodes, nodes[1:])
    return ders
