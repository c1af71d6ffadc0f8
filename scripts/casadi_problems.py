"""symvi's bounded discrete optimal-control problems written again in CasADi SX, for
``bench_bounded_oc.py``: each in a compact form (for IPOPT) and in a stage-wise form (for
FATROP, whose structure detection needs the variables and constraints stage by stage).

Both forms of one problem have the same cost Σ_w L_d over the same windows and the same
feasible set in symvi's unknowns: they are the same discrete problem, the stage-wise form
carrying copies of the nodes (or of the configurations) as states. The cart-pole's
stage-wise rows u and Φ are multiplied by h² (bounds too): FATROP does no automatic
scaling, and unscaled (Jacobian entries ~1/h²) it hangs inside an iteration at N = 1000;
IPOPT, which scales rows by their gradients, gets the rows of the NumPy problem (h·Φ, u)
— given the h²-scaled rows it had not finished after 200 s at N = 10⁴ (MUMPS kept
reallocating memory).

Every :class:`Nlp` maps a symvi result and symvi's initial path to its variables (``at``,
``x0``), so that its cost can be checked at symvi's optimum and both peers start from
symvi's initial path.

Stage-wise layout (CasADi's FATROP interface, ``structure_detection="auto"``): variables
x_0 u_0 x_1 u_1 … x_K; constraint rows per stage k: first the gap-closing rows
x_{k+1} − F(x_k, u_k) (coefficient +1 on x_{k+1}), then the stage's own rows in (x_k, u_k);
the last stage's rows (x_K only) at the end. Cost and constraints are sums of stage terms,
so the Lagrangian's Hessian is block diagonal by stage. Fixed ends are bounds lbx = ubx.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np

from bench_bvp import casadi_functions, increment, timed_casadi_functions


@dataclass
class Nlp:
    """An NLP min f(x) s.t. lbg ≤ g(x) ≤ ubg, lbx ≤ x ≤ ubx, with its start and the map
    from a symvi result to x."""

    form: str
    x: ca.SX
    f: ca.SX
    g: ca.SX
    lbg: np.ndarray
    ubg: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    x0: np.ndarray
    equality: list
    at: Callable[[object], np.ndarray]

    def cost_and_violation(self, x: np.ndarray) -> tuple[float, float]:
        """(f(x), largest violation of the constraints and bounds) at x."""
        fg = ca.Function("fg", [self.x], [self.f, self.g])
        f, g = (np.asarray(v, float).ravel() for v in fg(x))
        worst = max(np.max(self.lbg - g, initial=0.0), np.max(g - self.ubg, initial=0.0),
                    np.max(self.lbx - x, initial=0.0), np.max(x - self.ubx, initial=0.0))
        return float(f[0]), float(worst)

    def dual_infeasibility(self, x: np.ndarray, lam_g: np.ndarray, lam_x: np.ndarray) -> float:
        """|∇f + Jᵀλ_g + λ_x|_∞ / max(1, |∇f|_∞) at (x, λ) (CasADi's sign convention: the
        Lagrangian f + λ_gᵀg + λ_xᵀx), by a reverse-mode product: no Jacobian is formed."""
        lam = ca.SX.sym("lam", self.g.shape[0])
        grad = ca.gradient(self.f, self.x)
        kkt = ca.Function("kkt", [self.x, lam], [grad, grad + ca.jtimes(self.g, self.x, lam, True)])
        gradient, residual = (np.asarray(v, float).ravel() for v in kkt(x, lam_g))
        return float(np.max(np.abs(residual + lam_x)) / max(1.0, np.max(np.abs(gradient))))


def _column_major(g: np.ndarray) -> np.ndarray:
    """(count, 3, 3) or (count, 9) row-major configurations → (count, 9) column-major."""
    return np.asarray(g, float).reshape(-1, 3, 3).transpose(0, 2, 1).reshape(-1, 9)


# ---------------------------------------------------------------------------------------
# spacecraft_slew: increments ξ_0 … ξ_{N−1} on SO(3), g_{k+1} = g_k cay(hξ̂_k)
# ---------------------------------------------------------------------------------------
def slew_compact(path, start, end, N, h, inertia, tau_max, omega_max) -> Nlp:
    """Unknowns ξ_1 … ξ_{N−2} (ξ_0, ξ_{N−1} fixed by g_0, g_1 and g_{N−1}, g_N) and, lifted
    as in multiple shooting, g_2 … g_{N−2} with g_{k+1} = g_k cay(hξ̂_k) and the end defect
    vee cay⁻¹(g_{N−1}ᵀ g_{N−2} cay(hξ̂_{N−2})) = 0; cost Σ_{w=0}^{N−2} L_d(ξ_w, ξ_{w+1});
    |τ_w| ≤ τ_max and |(ξ_w+ξ_{w+1})/2| ≤ ω_max per window (the script's earlier form)."""
    L_d, step, end_defect, torque = casadi_functions(h, inertia, end[0])
    X, G = ca.SX.sym("xi", 3, N - 2), ca.SX.sym("g", 9, N - 3)
    xi = ca.horzcat(ca.DM(increment(*start, h)), X, ca.DM(increment(*end, h)))
    cost = ca.sum2(L_d.map(N - 1)(xi[:, :-1], xi[:, 1:]))
    torques = ca.vec(torque.map(N - 1)(xi[:, :-1], xi[:, 1:]))
    rates = ca.vec((xi[:, :-1] + xi[:, 1:]) / 2)
    following = step.map(N - 2)(ca.horzcat(ca.DM(start[1].flatten(order="F")), G), X)
    equalities = ca.vertcat(ca.vec(following[:, :-1] - G), end_defect(following[:, -1]))
    count = equalities.shape[0]
    limits = np.r_[tau_max * np.ones(torques.shape[0]), omega_max * np.ones(rates.shape[0])]
    x = ca.vertcat(ca.vec(X), ca.vec(G))
    free = np.full(x.shape[0], np.inf)
    x0 = np.concatenate([path.f[1:-1].reshape(-1), _column_major(path.g[2:-2]).reshape(-1)])
    return Nlp("compact", x, cost, ca.vertcat(equalities, torques, rates),
               np.r_[np.zeros(count), -limits], np.r_[np.zeros(count), limits], -free, free,
               x0, [True] * count + [False] * limits.size,
               lambda r: np.concatenate([np.asarray(r.f)[1:-1].reshape(-1),
                                         _column_major(r.g[2:-2]).reshape(-1)]))


def slew_stagewise(path, start, end, N, h, inertia, tau_max, omega_max) -> Nlp:
    """Stage k = 0 … N−3: state (ξ_k, g_{k+1}) (12), control ξ_{k+1} (3), dynamics
    (ξ_{k+1}, g_{k+2}) = (u_k, g_{k+1} cay(hû_k)), stage cost L_d(ξ_k, ξ_{k+1}), stage rows
    τ_k and (ξ_k+ξ_{k+1})/2; last stage N−2: state (ξ_{N−2}, g_{N−1}), rows: the end defect
    vee cay⁻¹(g_{N−1}ᵀ ·) = 0 and window N−2's τ and rate with ξ_{N−1} fixed, cost
    L_d(ξ_{N−2}, ξ_{N−1}). The first state (ξ_0, g_1) is fixed by its bounds."""
    L_d, step, end_defect, torque = casadi_functions(h, inertia, end[0])
    xi_first, xi_last = increment(*start, h), increment(*end, h)
    K = N - 2
    S = [ca.SX.sym(f"s{k}", 12) for k in range(K + 1)]
    U = [ca.SX.sym(f"u{k}", 3) for k in range(K)]
    variables, rows, lbg, ubg, equality, cost = [], [], [], [], [], 0
    ones = np.ones(3)

    def stage(a, b):
        nonlocal cost
        cost += L_d(a, b)
        rows.extend([torque(a, b), (a + b) / 2])
        lbg.extend([-tau_max * ones, -omega_max * ones])
        ubg.extend([tau_max * ones, omega_max * ones])
        equality.extend([False] * 6)

    for k in range(K):
        variables.extend([S[k], U[k]])
        rows.append(S[k + 1] - ca.vertcat(U[k], step(S[k][3:], U[k])))
        lbg.append(np.zeros(12)), ubg.append(np.zeros(12)), equality.extend([True] * 12)
        stage(S[k][:3], U[k])
    variables.append(S[K])
    rows.append(end_defect(S[K][3:]))
    lbg.append(np.zeros(3)), ubg.append(np.zeros(3)), equality.extend([True] * 3)
    stage(S[K][:3], ca.DM(xi_last))
    x = ca.vertcat(*variables)
    lbx, ubx = np.full(x.shape[0], -np.inf), np.full(x.shape[0], np.inf)
    fixed = np.r_[xi_first, start[1].flatten(order="F")]
    lbx[:12], ubx[:12] = fixed, fixed

    def layout(f, g):
        """x from ξ_0 … ξ_{N−1} (N, 3) and g_0 … g_N (N+1, 9 column-major)."""
        parts = []
        for k in range(K):
            parts.extend([f[k], g[k + 1], f[k + 1]])
        parts.extend([f[K], g[K + 1]])
        return np.concatenate(parts)

    x0 = layout(path.f, _column_major(path.g))
    x0[:12] = fixed
    return Nlp("stage-wise", x, cost, ca.vertcat(*rows), np.concatenate(lbg),
               np.concatenate(ubg), lbx, ubx, x0, equality,
               lambda r: layout(np.asarray(r.f), _column_major(r.g)))


# ---------------------------------------------------------------------------------------
# minimum_time_slew: spacecraft_slew's torque limits, min Σ L_d + ρT over the increments
# and T (h = T/N an unknown); rest to rest, so the end increments are 0 whatever h
# ---------------------------------------------------------------------------------------
def _at_rest(start, end) -> None:
    if not (np.array_equal(start[0], start[1]) and np.array_equal(end[0], end[1])):
        raise ValueError("the minimum-time slew's formulations assume rest-to-rest ends")


def timed_slew_compact(path, start, end, N, h, inertia, tau_max, rho) -> Nlp:
    """:func:`slew_compact`'s unknowns and T last; cost Σ_w L_d(·, T/N) + ρT; |τ_w| ≤ τ_max
    (the minimum-time slew bounds no rate)."""
    _at_rest(start, end)
    L_d, step, end_defect, torque = timed_casadi_functions(inertia, end[0])
    X, G, T = ca.SX.sym("xi", 3, N - 2), ca.SX.sym("g", 9, N - 3), ca.SX.sym("T")
    hh = T / N
    xi = ca.horzcat(ca.DM.zeros(3, 1), X, ca.DM.zeros(3, 1))
    cost = ca.sum2(L_d.map(N - 1)(xi[:, :-1], xi[:, 1:], hh)) + rho * T
    torques = ca.vec(torque.map(N - 1)(xi[:, :-1], xi[:, 1:], hh))
    following = step.map(N - 2)(ca.horzcat(ca.DM(start[1].flatten(order="F")), G), X, hh)
    equalities = ca.vertcat(ca.vec(following[:, :-1] - G), end_defect(following[:, -1]))
    count = equalities.shape[0]
    limits = tau_max * np.ones(torques.shape[0])
    x = ca.vertcat(ca.vec(X), ca.vec(G), T)
    lbx, ubx = np.full(x.shape[0], -np.inf), np.full(x.shape[0], np.inf)
    lbx[-1] = 1e-3
    x0 = np.concatenate([path.f[1:-1].reshape(-1), _column_major(path.g[2:-2]).reshape(-1),
                         [N * h]])
    return Nlp("compact", x, cost, ca.vertcat(equalities, torques),
               np.r_[np.zeros(count), -limits], np.r_[np.zeros(count), limits], lbx, ubx,
               x0, [True] * count + [False] * limits.size,
               lambda r: np.concatenate([np.asarray(r.f)[1:-1].reshape(-1),
                                         _column_major(r.g[2:-2]).reshape(-1), [r.T]]))


def timed_slew_stagewise(path, start, end, N, h, inertia, tau_max, rho) -> Nlp:
    """:func:`slew_stagewise` with T a state of every stage (T_{k+1} = T_k, the way
    FATROP takes a free horizon): state (ξ_k, g_{k+1}, T) (13), control ξ_{k+1}; ρT on
    the last stage; the first state's ξ_0 and g_1 fixed, its T free."""
    _at_rest(start, end)
    L_d, step, end_defect, torque = timed_casadi_functions(inertia, end[0])
    K = N - 2
    S = [ca.SX.sym(f"s{k}", 13) for k in range(K + 1)]
    U = [ca.SX.sym(f"u{k}", 3) for k in range(K)]
    variables, rows, lbg, ubg, equality, cost = [], [], [], [], [], 0
    ones = np.ones(3)

    def stage(a, b, T):
        nonlocal cost
        cost += L_d(a, b, T / N)
        rows.append(torque(a, b, T / N))
        lbg.append(-tau_max * ones), ubg.append(tau_max * ones)
        equality.extend([False] * 3)

    for k in range(K):
        variables.extend([S[k], U[k]])
        T = S[k][12]
        rows.append(S[k + 1] - ca.vertcat(U[k], step(S[k][3:12], U[k], T / N), T))
        lbg.append(np.zeros(13)), ubg.append(np.zeros(13)), equality.extend([True] * 13)
        stage(S[k][:3], U[k], T)
    variables.append(S[K])
    rows.append(end_defect(S[K][3:12]))
    lbg.append(np.zeros(3)), ubg.append(np.zeros(3)), equality.extend([True] * 3)
    stage(S[K][:3], ca.DM.zeros(3, 1), S[K][12])
    cost += rho * S[K][12]
    x = ca.vertcat(*variables)
    lbx, ubx = np.full(x.shape[0], -np.inf), np.full(x.shape[0], np.inf)
    fixed = np.r_[np.zeros(3), start[1].flatten(order="F")]
    lbx[:12], ubx[:12] = fixed, fixed

    def layout(f, g, T):
        parts = []
        for k in range(K):
            parts.extend([f[k], g[k + 1], [T], f[k + 1]])
        parts.extend([f[K], g[K + 1], [T]])
        return np.concatenate(parts)

    x0 = layout(path.f, _column_major(path.g), N * h)
    x0[:12] = fixed
    return Nlp("stage-wise", x, cost, ca.vertcat(*rows), np.concatenate(lbg),
               np.concatenate(ubg), lbx, ubx, x0, equality,
               lambda r: layout(np.asarray(r.f), _column_major(r.g), r.T))


# ---------------------------------------------------------------------------------------
# cart_pole_swing_up: nodes q_0 … q_N = (x, θ), three-point rule on windows (q_w, q_{w+1},
# q_{w+2}); q_0, q_1, q_{N−1}, q_N fixed
# ---------------------------------------------------------------------------------------
def cart_pole_window(h, p):
    """CasADi function (q_w, q_{w+1}, q_{w+2}) ↦ (L_d, u, Φ, x̄): q̄, q̇, q̈ by the
    three-point rule (tests/test_independent_optimum.pair_point), u = EL_x =
    (M+m)ẍ + mℓ(cos θ θ̈ − sin θ θ̇²), Φ = EL_θ = mℓ cos θ ẍ + mℓ²θ̈ − mgℓ sin θ at q̄, and
    L_d = h·½u² (symvi's cost: the midpoint of the window times h)."""
    M, m, ell, g = p["M"], p["m"], p["ell"], p["g"]
    a, b, c = ca.SX.sym("a", 2), ca.SX.sym("b", 2), ca.SX.sym("c", 2)
    q, v, acc = (a + b + c) / 3, (c - a) / (2 * h), (c - 2 * b + a) / h**2
    cos, sin = ca.cos(q[1]), ca.sin(q[1])
    u = (M + m) * acc[0] + m * ell * (cos * acc[1] - sin * v[1]**2)
    phi = m * ell * cos * acc[0] + m * ell**2 * acc[1] - m * g * ell * sin
    return ca.Function("window", [a, b, c], [h * u**2 / 2, u, phi, q[0]])


def cart_pole_compact(path, start, end, N, h, p, u_max, d) -> Nlp:
    """Unknowns q_2 … q_{N−2} (tests/test_independent_optimum.PairProblem); per window
    w = 0 … N−2 the rows h·Φ_w = 0, −u_max ≤ u_w ≤ u_max, −d ≤ x̄_w ≤ d; cost Σ_w L_d."""
    window = cart_pole_window(h, p)
    Q = ca.SX.sym("q", 2, N - 3)
    nodes = ca.horzcat(ca.DM(start[0]), ca.DM(start[1]), Q, ca.DM(end[0]), ca.DM(end[1]))
    L, u, phi, xbar = window.map(N - 1)(nodes[:, :-2], nodes[:, 1:-1], nodes[:, 2:])
    rows = ca.vec(ca.vertcat(h * phi, u, xbar))
    count = N - 1
    lbg = np.tile([0.0, -u_max, -d], count)
    ubg = np.tile([0.0, u_max, d], count)
    free = np.full(Q.numel(), np.inf)
    return Nlp("compact", ca.vec(Q), ca.sum2(L), rows, lbg, ubg, -free, free,
               path.x[2:-2].reshape(-1), [True, False, False] * count,
               lambda r: np.asarray(r.x)[2:-2].reshape(-1))


def cart_pole_stagewise(path, start, end, N, h, p, u_max, d) -> Nlp:
    """Stage k = 0 … N−2 (window k): state (q_k, q_{k+1}) (4), control q_{k+2} (2),
    dynamics (q_{k+1}, q_{k+2}) = (state[2:], u_k), stage cost L_d, stage rows h²·Φ_k = 0,
    −h²u_max ≤ h²·u_k ≤ h²u_max, −d ≤ x̄_k ≤ d; last stage N−1: state (q_{N−1}, q_N), no
    rows. The first and last states are fixed by their bounds."""
    window = cart_pole_window(h, p)
    K = N - 1
    S = [ca.SX.sym(f"s{k}", 4) for k in range(K + 1)]
    U = [ca.SX.sym(f"u{k}", 2) for k in range(K)]
    variables, rows, cost = [], [], 0
    for k in range(K):
        variables.extend([S[k], U[k]])
        L, u, phi, xbar = window(S[k][:2], S[k][2:], U[k])
        cost += L
        rows.extend([S[k + 1] - ca.vertcat(S[k][2:], U[k]), h**2 * phi, h**2 * u, xbar])
    variables.append(S[K])
    x = ca.vertcat(*variables)
    lbg = np.tile([0.0] * 5 + [-h**2 * u_max, -d], K)
    ubg = np.tile([0.0] * 5 + [h**2 * u_max, d], K)
    lbx, ubx = np.full(x.shape[0], -np.inf), np.full(x.shape[0], np.inf)
    first, last = np.r_[start[0], start[1]], np.r_[end[0], end[1]]
    lbx[:4], ubx[:4], lbx[-4:], ubx[-4:] = first, first, last, last

    def layout(q):
        parts = []
        for k in range(K):
            parts.extend([q[k], q[k + 1], q[k + 2]])
        parts.extend([q[K], q[K + 1]])
        return np.concatenate(parts)

    return Nlp("stage-wise", x, cost, ca.vertcat(*rows), lbg, ubg, lbx, ubx, layout(path.x),
               ([True] * 5 + [False] * 2) * K, lambda r: layout(np.asarray(r.x)))


def pure_time_compact(path, start, end, N, h, u_max) -> Nlp:
    """Pure minimum time of the double integrator ẍ = u from nodes: unknowns q_2 … q_{N−2}
    and T (h = T/N); per window w = 0 … N−2, u_w = (q_w − 2q_{w+1} + q_{w+2})/h² (the
    three-point rule's EL of ½ẋ²) with |u_w| ≤ u_max; cost T."""
    Q, T = ca.SX.sym("q", N - 3), ca.SX.sym("T")
    nodes = ca.vertcat(start[0, 0], start[1, 0], Q, end[0, 0], end[1, 0])
    u = (nodes[:-2] - 2 * nodes[1:-1] + nodes[2:]) / (T / N) ** 2
    x = ca.vertcat(Q, T)
    lbx, ubx = np.full(N - 2, -np.inf), np.full(N - 2, np.inf)
    lbx[-1] = 1e-3
    limits = u_max * np.ones(N - 1)
    return Nlp("compact", x, T, u, -limits, limits, lbx, ubx,
               np.r_[path.x[2:-2, 0], N * h], [False] * (N - 1),
               lambda r: np.r_[np.asarray(r.x)[2:-2, 0], r.T])


def pure_time_stagewise(path, start, end, N, h, u_max) -> Nlp:
    """:func:`pure_time_compact` stage-wise for FATROP: stage k = 0 … N−2 (window k): state
    (q_k, q_{k+1}, T) (3), control q_{k+2}, dynamics (q_{k+1}, q_{k+2}, T), and |u_k| ≤
    u_max as the rows N²(q_k − 2q_{k+1} + q_{k+2}) ∓ u_max T² of one sign each (T²u: rows
    of u's scale, not h²u's, since FATROP does no scaling: at h²'s, its tolerance 1e-8
    let u exceed its bound by 1e-4 at N = 100); cost T on the last stage; the first
    state's nodes and the last's fixed, T free."""
    K = N - 1
    S = [ca.SX.sym(f"s{k}", 3) for k in range(K + 1)]
    U = [ca.SX.sym(f"u{k}", 1) for k in range(K)]
    variables, rows, lbg, ubg = [], [], [], []
    for k in range(K):
        variables.extend([S[k], U[k]])
        second = N**2 * (S[k][0] - 2 * S[k][1] + U[k])     # T²u: FATROP does not scale
        step2 = u_max * S[k][2] ** 2
        rows.extend([S[k + 1] - ca.vertcat(S[k][1], U[k], S[k][2]),
                     second - step2, second + step2])
        lbg.extend([0.0, 0.0, 0.0, -np.inf, 0.0]), ubg.extend([0.0, 0.0, 0.0, 0.0, np.inf])
    variables.append(S[K])
    x = ca.vertcat(*variables)
    lbx, ubx = np.full(x.shape[0], -np.inf), np.full(x.shape[0], np.inf)
    lbx[:2], ubx[:2] = (start[0, 0], start[1, 0]), (start[0, 0], start[1, 0])
    lbx[-3:-1], ubx[-3:-1] = (end[0, 0], end[1, 0]), (end[0, 0], end[1, 0])
    lbx[2::4] = 1e-3

    def layout(q, T):
        parts = []
        for k in range(K):
            parts.append([q[k], q[k + 1], T, q[k + 2]])
        parts.append([q[K], q[K + 1], T])
        return np.concatenate(parts)

    return Nlp("stage-wise", x, S[K][2], ca.vertcat(*rows), np.array(lbg), np.array(ubg),
               lbx, ubx, layout(path.x[:, 0], N * h), ([True] * 3 + [False] * 2) * K,
               lambda r: layout(np.asarray(r.x)[:, 0], r.T))
