"""A near-minimum-time slew with torque limits (issue 21): the torque-limited slew of
:mod:`symvi.models.spacecraft_slew` with a free horizon T, min ½∫|τ/I|² dt + ρ·T.

The time cost ρ = 100 outweighs the control cost, so the optimal horizon lies just above
the shortest one the limits allow (T* = 0.959 at N = 400 with τ_max = 11, 0.851 with 16):
the third axis's torque sits on its bound for two thirds of the horizon, switching from
+τ_max to −τ_max in a linear ramp between (bang–bang-like), the second's for a third;
the control cost keeps the optimality system regular. ``solve_bvp``'s h is the first guess of T/N. The example takes N = 200: at
N = 1000 the KKT corrections stall near 5e-8 (rounding, the torques saturated on 70 % of
the windows), above the default tolerance, and the solve says ILL_CONDITIONED.
"""
import sympy as sp

from symvi.models.rigid_body_oc import slew


def build(retraction: str = "cayley"):
    tau_max, rho = sp.symbols("tau_max rho", positive=True)
    return slew("minimum_time_slew", retraction,
                "Near-minimum-time slew of a rigid spacecraft on SO(3): min ½∫|τ/I|² + ρT, "
                "|τ_i| ≤ τ_max, free horizon T (issue 21)",
                parameters={tau_max: 11.0, rho: 100.0},
                steps=200, bounds=lambda u: {ui: (-tau_max, tau_max) for ui in u},
                time_cost=rho)


model = build()
