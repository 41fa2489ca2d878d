"""Jacobian health: singular values, condition number, manipulability, and Jᵀ statics.

Manipulability measures follow Yoshikawa and Sciavicco & Siciliano, for a Jacobian J (m × n,
m ≤ n) with singular values σ₁ ≥ … ≥ σₘ:

- w1 = sqrt(det(J Jᵀ)) = Π σᵢ (volume of the velocity ellipsoid),
- w2 = σmin / σmax (inverse condition number, isotropy),
- w3 = σmin (the worst direction),
- w4 = (Π σᵢ)^(1/m) (geometric mean, independent of m).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

GRAVITY_W = np.array([0.0, 0.0, -9.81])


def manipulability_measures(sigma: np.ndarray) -> tuple[np.ndarray, ...]:
    """(condition, w1, w2, w3, w4) of singular values sorted in decreasing order.

    Args:
        sigma: Singular values, shape (..., m), each row sorted in decreasing order; a stack
            of rows (e.g. one per control tick) gives one measure per row.

    Returns:
        Five arrays of shape ``sigma.shape[:-1]`` (0-d for a single row): the condition number
        σmax/σmin (inf where σmin = 0), w1 = Π σ, w2 = σmin/σmax (0 where σmax = 0),
        w3 = σmin and w4 = (Π σ)^(1/m).
    """
    s = np.asarray(sigma, dtype=float)
    smax, smin = s[..., 0], s[..., -1]
    prod = np.prod(s, axis=-1)
    condition = np.full(smin.shape, np.inf)
    np.divide(smax, smin, out=condition, where=smin > 0.0)
    w2 = np.zeros(smin.shape)
    np.divide(smin, smax, out=w2, where=smax > 0.0)
    return condition, prod, w2, smin.copy(), prod ** (1.0 / s.shape[-1])


@dataclass(frozen=True)
class Manipulability:
    """Manipulability measures of one Jacobian.

    Attributes:
        singular_values: σ₁ ≥ … ≥ σₘ.
        condition: σmax / σmin (inf at a singularity).
        w1: sqrt(det J Jᵀ).
        w2: σmin / σmax.
        w3: σmin.
        w4: (Π σ)^(1/m).
    """

    singular_values: np.ndarray
    condition: float
    w1: float
    w2: float
    w3: float
    w4: float

    @classmethod
    def from_singular_values(cls, sigma: np.ndarray) -> Manipulability:
        """Compute every measure from singular values (any order)."""
        s = np.sort(np.asarray(sigma, dtype=float))[::-1]
        condition, w1, w2, w3, w4 = (float(x) for x in manipulability_measures(s))
        return cls(singular_values=s, condition=condition, w1=w1, w2=w2, w3=w3, w4=w4)

    def as_array(self) -> np.ndarray:
        """[w1, w2, w3, w4]."""
        return np.array([self.w1, self.w2, self.w3, self.w4])


@dataclass(frozen=True)
class JacobianHealthRows:
    """Jacobian health of a stack of Jacobians (one row per control tick).

    Attributes:
        sigma: Singular values (n, m) of the full Jacobians, decreasing.
        sigma_t: Singular values (n, 3) of the translational rows J_v, decreasing.
        U_t: Axes (n, 3, 3) of the translational velocity ellipsoid: eigenvectors of J_v J_vᵀ
            as columns, ordered like ``sigma_t``, forming a proper rotation (det = +1).
        quat_t: The same rotations as wxyz quaternions (n, 4).
        condition: σmax/σmin of the full Jacobians (n,) (inf at a singularity).
        manipulability: w1..w4 of the full Jacobians (n, 4).
        condition_t: The same for the translational rows (n,).
        manipulability_t: w1..w4 of the translational rows (n, 4).
    """

    sigma: np.ndarray
    sigma_t: np.ndarray
    U_t: np.ndarray
    quat_t: np.ndarray
    condition: np.ndarray
    manipulability: np.ndarray
    condition_t: np.ndarray
    manipulability_t: np.ndarray


def jacobian_health_rows(J: np.ndarray) -> JacobianHealthRows:
    """Singular values, ellipsoid axes, condition and manipulability of each Jacobian.

    The full Jacobian's singular values come from one batched SVD; the translational
    ellipsoid from MuJoCo's ``mju_eig3`` on J_v J_vᵀ = U Σ² Uᵀ, which returns the
    eigenvalues in decreasing order and U as a proper rotation with its quaternion.

    Args:
        J: Spatial Jacobians [v; ω] in world, shape (n, 6, nv).
    """
    J = np.asarray(J, dtype=np.float64)
    n = J.shape[0]
    sigma = np.linalg.svd(J, compute_uv=False)
    Jv = J[:, :3]
    JJt = Jv @ Jv.transpose(0, 2, 1)
    eig = np.zeros((n, 3))
    U = np.zeros((n, 9))
    quat = np.zeros((n, 4))
    for i in range(n):
        mujoco.mju_eig3(eig[i], U[i], quat[i], JJt[i].reshape(9))
    np.sqrt(np.maximum(eig, 0.0), out=eig)
    c, *w = manipulability_measures(sigma)
    c_t, *w_t = manipulability_measures(eig)
    return JacobianHealthRows(
        sigma=sigma,
        sigma_t=eig,
        U_t=U.reshape(n, 3, 3),
        quat_t=quat,
        condition=c,
        manipulability=np.stack(w, axis=-1),
        condition_t=c_t,
        manipulability_t=np.stack(w_t, axis=-1),
    )


@dataclass(frozen=True)
class JacobianHealth:
    """Health of the tool-site Jacobian at one configuration.

    Attributes:
        full: Measures of the 6 × n Jacobian [v; ω].
        translational: Measures of its 3 × n translational rows.
        U_translational: Axes (3, 3) of the translational velocity ellipsoid (columns ordered
            like ``translational.singular_values``).
    """

    full: Manipulability
    translational: Manipulability
    U_translational: np.ndarray


def jacobian_health(J: np.ndarray) -> JacobianHealth:
    """The SVD-based health of one 6 × n spatial Jacobian [v; ω] (see
    :func:`jacobian_health_rows`, which this evaluates on a stack of one)."""
    rows = jacobian_health_rows(np.asarray(J)[None])
    return JacobianHealth(
        full=Manipulability.from_singular_values(rows.sigma[0]),
        translational=Manipulability.from_singular_values(rows.sigma_t[0]),
        U_translational=rows.U_t[0],
    )


def holding_torques(J: np.ndarray, mass: float, gravity_W: np.ndarray = GRAVITY_W) -> np.ndarray:
    """Joint torques [N m] that hold a load of ``mass`` [kg] at the Jacobian's point (Jᵀ statics).

    The load pulls on the tool with f = mass · g; the arm must push back with −f, so
    τ = Jᵥᵀ (−mass · g) (the statics relation τ = Jᵀ F).

    Args:
        J: Spatial Jacobian [v; ω] in world, shape (6, n), or a stack (..., 6, n).
        mass: Load [kg].
        gravity_W: Gravity in world [m/s²].

    Returns:
        Torques, shape (n,) or (..., n) [N m].
    """
    return (-mass * np.asarray(gravity_W)) @ J[..., :3, :]
