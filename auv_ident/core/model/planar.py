"""Vehicles with fewer than six degrees of freedom, and the ship's speed factor: the parts of
the compiled model (core/model/hydrodynamics.py calls them) that only such vehicles use.

A vehicle file may declare its degrees of freedom (``dofs: [surge, sway, yaw]``, a surface
ship manoeuvring in the horizontal plane; core/model/vehicle.py). The state keeps its 12-entry
layout (core/model/state.py) and the other states are HELD: the model reads them as 0 (level, no
heave, roll or pitch rate), their rates are zero, and so are their rows and columns of df/dx and
their rows of df/dtheta. So a held state never moves in the model, the
simulator or the EKF, and it is decoupled from the others in the EKF's covariance (its row of
the transition Jacobian is an identity row, its column an identity column), so no measurement
update can move it either; core/filter/augmented.py gives it no process noise and reads no
measurement of it. The free accelerations solve M_ff nu_f_dot = F_f (the constraint takes the held
equations' forces; vehicle.py builds M with identity rows and columns there). Why keep the 12
states rather than a 6-state model: one compiled model, filter, refinement and message layer for
every vehicle; the held states cost a few exact zeros in a 12 x 12 product, and nothing at all for
a 6-DOF vehicle (its list of held states is empty).

Restoring forces: with phi = theta = 0 held, g(eta) adds nothing to surge, sway and yaw, and
the heave, roll and pitch rows are zeroed, so a planar vehicle has none (a floating ship has
W = B anyway).

The speed U = sqrt(u^2 + v^2) (m/s) is the factor a ship's prime system scales with (U v, U r,
U^2 delta; SNAME 1950, Clarke et al. 1983): it is evaluated only for vehicles whose terms use it.
"""
import math

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.model.monomials import NZ, Z_SPEED, ZZ_DU_DV
from auv_ident.core.model.state import N_STATE

kernel = cached_njit(_nrt=False)     # as hydrodynamics.kernel (no reference counting)


@kernel
def speed_factor(u, v, zz):
    """zz[Z_SPEED] = U = sqrt(u^2 + v^2) (m/s), its derivatives u/U and v/U into
    zz[NZ + Z_SPEED] and zz[ZZ_DU_DV]; at U = 0 (no direction) the derivatives are taken as 0,
    where every term U x (something of u, v) has a zero derivative anyway."""
    U = math.sqrt(u * u + v * v)
    zz[Z_SPEED] = U
    if U > 0.0:
        zz[NZ + Z_SPEED] = u / U
        zz[ZZ_DU_DV] = v / U
    else:
        zz[NZ + Z_SPEED] = 0.0
        zz[ZZ_DU_DV] = 0.0


@kernel
def held_at_zero(x, held, xh):
    """xh (12,) <- the state the model reads: x (12,) with every held state at 0, its hold
    value (level, no heave, roll or pitch rate). So f does not depend on the held states at
    all, whatever a caller holds them at (a depth, say), and their zero columns of df/dx are
    exact derivatives."""
    for i in range(N_STATE):
        xh[i] = x[i]
    for a_ in range(held.shape[0]):
        xh[held[a_]] = 0.0


@kernel
def hold_states(held, want_jac, p, xdot, A, Bt):
    """Zero the rate of each held state (held: int indices into x), and with want_jac its row
    and column of A = df/dx (12 x 12) and its row of Bt = df/dtheta (12 x p)."""
    n = xdot.shape[0]
    for a_ in range(held.shape[0]):
        h = held[a_]
        xdot[h] = 0.0
        if want_jac:
            for j in range(n):
                A[h, j] = 0.0
                A[j, h] = 0.0
            for j in range(p):
                Bt[h, j] = 0.0
