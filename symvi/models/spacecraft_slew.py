"""A torque-limited spacecraft slew on SO(3) (issue 21): the rigid-body optimal control of
:mod:`symvi.models.rigid_body_oc` — rest to rest through a quarter turn about
(1, 1, 1)/√3 in T = 1, min ½∫|τ/I|² dt — with reaction-wheel limits |τ_i| ≤ τ_max on
every axis. The unbounded optimum needs peak torques of 6.9, 14.3 and 16.7 on the three
axes (I = diag(1, 2, 3)); τ_max = 11 saturates the second and third on about a fifth to
a third of the windows, at the start and at the end of the slew. Below about 8.99
(N = 40) no rest-to-rest quarter turn in T = 1 exists (tests/test_bounded_oc.py). The
body rates are bounded too, |Ω_i| ≤ ω_max at every window's quadrature point; the default
ω_max = 10 lies above the slew's peak rate 1.52, and ω_max = 1.45 makes it bind
(``params=dict(omega_max=1.45)``).
"""
import sympy as sp

from symvi.models.rigid_body_oc import slew


def build(retraction: str = "cayley"):
    tau_max, omega_max = sp.symbols("tau_max omega_max", positive=True)
    rates = sp.symbols("Omega1 Omega2 Omega3", real=True)      # SO3's fibre symbols G.xi
    return slew("spacecraft_slew", retraction,
                "Torque-limited slew of a rigid spacecraft on SO(3): min ½∫|τ/I|², "
                "|τ_i| ≤ τ_max, |Ω_i| ≤ ω_max (issue 21)",
                parameters={tau_max: 11.0, omega_max: 10.0},
                bounds=lambda u: {ui: (-tau_max, tau_max) for ui in u}
                | {w: (-omega_max, omega_max) for w in rates})


model = build()
