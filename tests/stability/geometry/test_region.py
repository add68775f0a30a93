"""Tests of margin_rl.stability.geometry.region: hand-solvable cases, an independent LP check,
invariants (hypothesis) and input validation."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from margin_rl.stability.geometry import region as fr
from margin_rl.stability.geometry import region_program
from margin_rl.stability.geometry.contact import (
    gravito_inertial_wrench,
    parse_friction,
    solver_settings,
    tangent_bases,
    validate_contact_arrays,
)
from margin_rl.stability.geometry.icp import stability_margin
from margin_rl.stability.geometry.polygon import convex_polygon
from margin_rl.stability.geometry.region import (
    DEFAULT_CONTACT_TORQUE_LIMIT,
    SUPPORT_FAILED,
    SUPPORT_INFEASIBLE,
    SUPPORT_OK,
    FeasibleRegion,
    feasible_region,
    halfspaces_from_polygon,
    iterative_projection,
    polygon_area,
)
from tests.stability import cases

C = cases  # short alias for the fixtures

G = C.G
WM = DEFAULT_CONTACT_TORQUE_LIMIT
HUGE = 1e6  # torque limit that never binds [N m]
TIGHT = dict(tol=1e-8, max_lps=200)  # converge polygonal regions completely
FAST_SETTINGS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def rect_kwargs(**over: Any) -> dict[str, Any]:
    """Flat 0.6 x 0.4 rectangle, CoM 0.5 m above the feet, non-binding limits, mu = 10."""
    kw: dict[str, Any] = dict(
        feet=C.rect_feet(0.6, 0.4, 0.5),
        normals=C.flat_normals(4),
        stance=np.ones(4, dtype=bool),
        mu=10.0,
        mass=C.MASS,
        jacobians=C.unit_jacobians(4),
        torque_limits=np.full((4, 3), HUGE),
    )
    kw.update(over)
    return kw


def assert_valid_polygon(region: FeasibleRegion) -> None:
    v, hs = region.vertices, region.halfspaces
    assert v.ndim == 2 and v.shape[1] == 2
    assert hs.ndim == 2 and hs.shape[1] == 3
    if v.shape[0] >= 3:
        assert hs.shape[0] == v.shape[0]
        assert polygon_area(v) > 0.0  # CCW
        assert region.area == pytest.approx(polygon_area(v))
        np.testing.assert_allclose(np.linalg.norm(hs[:, :2], axis=1), 1.0, atol=1e-12)
        # Every vertex satisfies every half-space; consecutive vertices are distinct.
        assert (v @ hs[:, :2].T - hs[:, 2]).min() >= -1e-9
        assert np.linalg.norm(np.diff(np.vstack([v, v[:1]]), axis=0), axis=1).min() > 1e-7


def assert_same_polygon(a: np.ndarray, b: np.ndarray, atol: float) -> None:
    """Same vertex sets up to ordering (both CCW)."""
    assert a.shape == b.shape, (a, b)
    for p in a:
        assert np.min(np.linalg.norm(b - p, axis=1)) <= atol, (p, b)


def contains(big: FeasibleRegion, small: FeasibleRegion, atol: float) -> bool:
    """Every vertex of `small` is inside `big` up to `atol` metres."""
    if small.vertices.shape[0] == 0:
        return True
    if big.vertices.shape[0] == 0:
        return False
    return bool(np.min(stability_margin(big, small.vertices)) >= -atol)


# ----------------------------------------------------------------------------------------------
# Independent check: equilibrium feasibility at a FIXED CoM, solved by HiGHS (scipy.linprog)
# with per-foot contact torques (no aggregation) and pyramids written out here.
# ----------------------------------------------------------------------------------------------


def equilibrium_feasible(
    c_xy: np.ndarray,
    kw: dict[str, Any],
    n_faces: int,
    circumscribed: bool = False,
    z_coupling: bool = True,
) -> bool:
    """Is there (f_i, w_i) balancing the robot with its CoM moved to c_xy?

    ``circumscribed=False``: the k-face pyramid inscribed in the cone (as the code's
    ``("pyramid", k)``); ``True``: the one circumscribed about it (contains the cone), so that
    infeasibility with it proves infeasibility with the exact cone.
    """
    stance = np.asarray(kw["stance"], dtype=bool)
    p = np.asarray(kw["feet"], float)[stance]
    nrm = np.asarray(kw["normals"], float)[stance]
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    jac = np.asarray(kw["jacobians"], float)[stance]
    lim = np.asarray(kw["torque_limits"], float)
    lo, hi = (lim[0], lim[1]) if lim.ndim == 3 else (-lim, lim)
    lo, hi = lo[stance], hi[stance]
    bias = np.zeros_like(lo) if kw.get("leg_bias") is None else np.asarray(kw["leg_bias"], float)[stance]
    n = p.shape[0]
    mass, mu = kw["mass"], kw["mu"]
    w_max = kw.get("contact_torque_limit", WM)
    acc = np.asarray(kw.get("com_acc", (0, 0, 0)), float)
    force = mass * (acc + np.array([0.0, 0.0, G])) - np.asarray(kw.get("ext_force", (0, 0, 0)), float)
    moment = np.asarray(kw.get("ang_momentum_rate", (0, 0, 0)), float) - np.asarray(
        kw.get("ext_torque", (0, 0, 0)), float
    )
    c = np.array([c_xy[0], c_xy[1], 0.0])
    c_cross_f = np.cross(c, force)
    if not z_coupling:
        c_cross_f[2] = 0.0
    nv = 5 * n  # f_i (3), w_i (2)
    a_eq = np.zeros((6, nv))
    b_eq = np.concatenate([force, moment + c_cross_f])
    rows, rhs = [], []
    angles = 2 * np.pi * np.arange(n_faces) / n_faces
    apothem = 1.0 if circumscribed else math.cos(math.pi / n_faces)
    for i in range(n):
        fi = slice(3 * i, 3 * i + 3)
        a_eq[0:3, fi] = np.eye(3)
        a_eq[3:6, fi] = np.cross(p[i], np.eye(3)).T  # column j is p x e_j
        a_eq[3:5, 3 * n + 2 * i : 3 * n + 2 * i + 2] = np.eye(2)
        t1 = np.array([1.0, 0.0, 0.0]) - nrm[i] * nrm[i, 0]
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(nrm[i], t1)
        for th in angles:
            row = np.zeros(nv)
            row[fi] = math.cos(th) * t1 + math.sin(th) * t2 - mu * apothem * nrm[i]
            rows.append(row)
            rhs.append(0.0)
        row = np.zeros(nv)
        row[fi] = -nrm[i]
        rows.append(row)
        rhs.append(0.0)
        for j in range(jac.shape[2]):
            # tau_j = bias_j - J[:, j] . f in [lo_j, hi_j]
            row = np.zeros(nv)
            row[fi] = jac[i][:, j]
            rows += [row, -row]
            rhs += [bias[i, j] - lo[i, j], hi[i, j] - bias[i, j]]
    bounds = [(None, None)] * (3 * n) + [(-w_max, w_max)] * (2 * n)
    res = linprog(
        np.zeros(nv),
        A_ub=np.array(rows),
        b_ub=np.array(rhs),
        A_eq=a_eq,
        b_eq=b_eq,
        bounds=bounds,
        method="highs",
    )
    assert res.status in (0, 2), res.message
    return res.status == 0


# ----------------------------------------------------------------------------------------------
# Hand-solvable cases
# ----------------------------------------------------------------------------------------------


def test_flat_rectangle_is_support_polygon_exactly_without_contact_torques() -> None:
    r = feasible_region(**rect_kwargs(), contact_torque_limit=0.0)
    assert r.status == "ok"
    assert r.n_lps == 8  # 4 diagonal corners + 4 edge certificates
    assert_valid_polygon(r)
    assert_same_polygon(r.vertices, C.support_rectangle(0.6, 0.4), atol=1e-6)
    assert r.area == pytest.approx(0.24, abs=1e-6)


def test_flat_rectangle_with_contact_torques_is_expanded_by_n_wm_over_fz() -> None:
    # Only W = sum w_i (|W_x|, |W_y| <= 4 w_M) is added to the moment rows: c = CoP + W x / F_z.
    r = feasible_region(**rect_kwargs())
    e = 4 * WM / (C.MASS * G)
    assert_same_polygon(r.vertices, C.support_rectangle(0.6, 0.4, expand=e), atol=1e-7)
    assert 0.0 < e < 1e-3  # the default keeps this effect negligible (sub-millimetre)


def test_margin_of_rectangle_centre_and_outside_point() -> None:
    r = feasible_region(**rect_kwargs(), contact_torque_limit=0.0)
    assert stability_margin(r, [0.0, 0.0]) == pytest.approx(0.2, abs=1e-6)  # min(L, W) / 2
    for d in (0.01, 0.05):
        assert stability_margin(r, [0.3 + d, 0.0]) == pytest.approx(-d, abs=1e-6)
        assert stability_margin(r, [0.0, -0.2 - d]) == pytest.approx(-d, abs=1e-6)
    assert stability_margin(r, [0.3, 0.1]) == pytest.approx(0.0, abs=1e-6)


def test_trot_region_is_thin_segment_along_the_diagonal() -> None:
    kw = rect_kwargs(stance=np.array([True, False, False, True]))  # LF + RH
    r = feasible_region(**kw)
    assert r.status == "ok"
    assert_valid_polygon(r)
    lf, rh = kw["feet"][0, :2], kw["feet"][3, :2]
    axis = (rh - lf) / np.linalg.norm(rh - lf)
    perp = np.array([-axis[1], axis[0]])
    # Half-width bound from the module docstring: |W . e_xy| <= 2 w_M sqrt(2) |e_xy| => d <= 2 sqrt2 wM/Fz.
    eps = 2 * math.sqrt(2) * WM / (C.MASS * G)
    assert np.abs((r.vertices - lf) @ perp).max() <= eps + 1e-9
    along = (r.vertices - lf) @ axis
    assert along.min() == pytest.approx(0.0, abs=1e-3)
    assert along.max() == pytest.approx(np.linalg.norm(rh - lf), abs=1e-3)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.4, 0.4, size=(500, 2))
    pts = np.vstack([pts, lf + np.outer(np.linspace(0, 1, 50), rh - lf)])  # points on the diagonal
    assert np.max(stability_margin(r, pts)) <= eps + 1e-9
    # Points off the diagonal by d have margin ~ -d (up to the tiny width).
    mid = 0.5 * (lf + rh)
    assert stability_margin(r, mid + 0.05 * perp) == pytest.approx(-0.05, abs=eps + 1e-9)


def test_trot_without_contact_torques_is_a_segment() -> None:
    kw = rect_kwargs(stance=np.array([True, False, False, True]))
    r = feasible_region(**kw, contact_torque_limit=0.0)
    assert r.vertices.shape == (2, 2)
    assert r.area == 0.0
    assert_same_polygon(r.vertices, kw["feet"][[0, 3], :2], atol=1e-5)
    assert r.halfspaces.shape == (4, 3)  # two sides and two end caps
    assert stability_margin(r, [0.0, 0.0]) == pytest.approx(0.0, abs=1e-6)
    assert stability_margin(r, [0.0, 0.1]) < -0.05


def test_three_feet_give_the_support_triangle() -> None:
    kw = rect_kwargs(stance=np.array([True, True, True, False]))
    r0 = feasible_region(**kw, contact_torque_limit=0.0)
    assert_same_polygon(r0.vertices, kw["feet"][:3, :2], atol=1e-6)
    r = feasible_region(**kw)
    e = 3 * WM / (C.MASS * G)
    assert contains(r, r0, atol=1e-9)
    assert contains(r0, r, atol=math.sqrt(2) * e + 1e-9)  # triangle (+) box of half-width e


def test_single_foot_region_is_a_tiny_square_around_the_foot() -> None:
    kw = rect_kwargs(stance=np.array([False, False, True, False]))
    r = feasible_region(**kw)
    e = WM / (C.MASS * G)
    foot = kw["feet"][2, :2]
    assert_same_polygon(r.vertices, foot + C.support_rectangle(0.0, 0.0, expand=e), atol=1e-7)
    point = feasible_region(**kw, contact_torque_limit=0.0)
    assert point.status == "ok" and point.vertices.shape == (1, 2) and point.area == 0.0
    np.testing.assert_allclose(point.vertices[0], foot, atol=1e-6)
    assert stability_margin(point, foot + np.array([0.0, 0.1])) == pytest.approx(-0.1, abs=1e-6)


@pytest.mark.parametrize("acc", [(2.0, 0.0, 0.0), (-1.5, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, -2.0, 0.0)])
def test_horizontal_com_acceleration_shifts_region_like_the_zmp(acc: tuple[float, float, float]) -> None:
    # ZMP = c - (h / g) c_ddot must lie in the support rectangle, so the set of feasible CoM
    # positions is the rectangle shifted by +h a / g (in the direction of the acceleration).
    h = 0.5
    r = feasible_region(**rect_kwargs(com_acc=acc), contact_torque_limit=0.0)
    shift = h * np.array(acc[:2]) / G
    assert_same_polygon(r.vertices, C.support_rectangle(0.6, 0.4) + shift, atol=1e-6)


def test_vertical_acceleration_and_external_force_are_equivalent() -> None:
    # F = m (c_ddot - g_vec) - f_ext: an external force -m a equals an acceleration a.
    acc = np.array([1.0, -0.5, 2.0])
    r1 = feasible_region(**rect_kwargs(com_acc=acc, mu=0.5), friction=("pyramid", 6), **TIGHT)
    r2 = feasible_region(**rect_kwargs(ext_force=-C.MASS * acc, mu=0.5), friction=("pyramid", 6), **TIGHT)
    assert_same_polygon(r1.vertices, r2.vertices, atol=1e-6)
    ld = np.array([0.5, -1.0, 2.0])
    r3 = feasible_region(**rect_kwargs(ang_momentum_rate=ld, mu=0.5), friction=("pyramid", 6), **TIGHT)
    r4 = feasible_region(**rect_kwargs(ext_torque=-ld, mu=0.5), friction=("pyramid", 6), **TIGHT)
    assert_same_polygon(r3.vertices, r4.vertices, atol=1e-6)
    assert not np.allclose(polygon_area(r1.vertices), polygon_area(r3.vertices))


def test_z_moment_coupling_changes_the_region() -> None:
    # Flat feet, low friction, horizontal acceleration: the yaw row sum p x f |_z = c_x F_y - c_y F_x
    # ties c to the tangential forces.  Points several mm inside our region need that term:
    # HiGHS finds them feasible with it and infeasible without it.
    kw = rect_kwargs(mu=0.3, com_acc=(2.5, 1.0, 0.0))
    r = feasible_region(**kw, friction=("pyramid", 8), **TIGHT)
    assert r.status == "ok"
    centre = r.vertices.mean(axis=0)
    inner = centre + 0.97 * (r.vertices - centre)
    assert np.min(stability_margin(r, inner)) > 3e-3  # several millimetres inside
    with_term = [equilibrium_feasible(p, kw, 8) for p in inner]
    without_term = [equilibrium_feasible(p, kw, 8, z_coupling=False) for p in inner]
    assert all(with_term)
    assert not all(without_term)


def test_leg_bias_sign_convention() -> None:
    # tau = delta - J^T f in [lo, hi]  <=>  -J^T f in [lo - delta, hi - delta].
    kw = C.quadruped_case(torque_limit=30.0)
    rng = np.random.default_rng(3)
    delta = rng.uniform(-8.0, 8.0, size=(4, 3))
    lim = kw.pop("torque_limits")
    r1 = feasible_region(**kw, torque_limits=(-lim, lim), leg_bias=delta, friction=("pyramid", 8), **TIGHT)
    r2 = feasible_region(**kw, torque_limits=(-lim - delta, lim - delta), friction=("pyramid", 8), **TIGHT)
    r0 = feasible_region(**kw, torque_limits=lim, friction=("pyramid", 8), **TIGHT)
    assert_same_polygon(r1.vertices, r2.vertices, atol=1e-5)
    assert abs(r1.area - r0.area) > 1e-3  # the bias does matter here


def test_swing_feet_are_ignored_entirely() -> None:
    kw = C.quadruped_case(stance=(True, True, False, True), torque_limit=35.0)
    r1 = feasible_region(**kw)
    for name in ("feet", "normals", "jacobians", "torque_limits"):
        kw[name] = np.array(kw[name], dtype=float)
        kw[name][2] = np.nan
    kw["leg_bias"] = np.zeros((4, 3))
    kw["leg_bias"][2] = np.inf
    r2 = feasible_region(**kw)
    np.testing.assert_allclose(r1.vertices, r2.vertices, atol=1e-9)
    sub = {
        k: (v[[0, 1, 3]] if k in ("feet", "normals", "jacobians", "torque_limits", "leg_bias", "stance") else v)
        for k, v in kw.items()
    }
    r3 = feasible_region(**sub)
    np.testing.assert_allclose(r1.vertices, r3.vertices, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# Torque limits, emptiness, unboundedness
# ----------------------------------------------------------------------------------------------


def test_large_torque_limits_with_leg_jacobians_give_support_polygon() -> None:
    kw = C.quadruped_case(torque_limit=1e3, mu=5.0)
    r = feasible_region(**kw, contact_torque_limit=0.0)
    assert_same_polygon(r.vertices, C.nominal_feet()[[0, 2, 3, 1], :2], atol=1e-6)


def test_torque_limits_shrink_region_strictly_inside_support_polygon() -> None:
    kw = C.quadruped_case(torque_limit=20.0)
    r = feasible_region(**kw)
    support = feasible_region(**C.quadruped_case(torque_limit=1e3))
    assert r.status == "ok"
    assert_valid_polygon(r)
    assert r.area < 0.5 * support.area
    assert contains(support, r, atol=1e-9)
    # No vertex touches the support polygon's boundary: torques, not geometry, limit the region.
    assert np.min(stability_margin(support, r.vertices)) > 0.02


def test_torque_limited_region_matches_independent_lp() -> None:
    kw = C.quadruped_case(torque_limit=25.0, mu=0.5)
    r = feasible_region(**kw, friction=("pyramid", 8), **TIGHT)
    assert r.status == "ok"
    v = r.vertices
    centre = v.mean(axis=0)
    for p in centre + (v - centre) * 0.99:
        assert equilibrium_feasible(p, kw, 8)
    hs = r.halfspaces
    for i in range(len(v)):
        mid = 0.5 * (v[i] + v[(i + 1) % len(v)])
        assert not equilibrium_feasible(mid - 3e-3 * hs[i, :2], kw, 8)


def test_empty_region_when_mass_exceeds_torque_limits() -> None:
    kw = C.quadruped_case(torque_limit=20.0)
    kw["mass"] = 400.0
    r = feasible_region(**kw)
    assert r.status == "empty"
    assert r.vertices.shape == (0, 2) and r.halfspaces.shape == (0, 3)
    assert r.area == 0.0 and r.n_lps >= 1
    assert not r.usable
    assert stability_margin(r, [0.0, 0.0]) == -math.inf


def test_no_stance_foot_gives_empty_status() -> None:
    r = feasible_region(**rect_kwargs(stance=np.zeros(4, dtype=bool)))
    assert r.status == "empty" and r.n_lps == 0 and "stance" in r.message


def test_free_fall_is_unbounded_and_clipped() -> None:
    r = feasible_region(**rect_kwargs(com_acc=(0.0, 0.0, -G)), extent=2.0)
    assert r.status == "unbounded"
    assert r.area == pytest.approx(16.0, rel=1e-6)


def test_max_lps_stops_early_with_a_valid_unconverged_region() -> None:
    kw = C.quadruped_case(torque_limit=30.0)
    r = feasible_region(**kw, tol=1e-9, max_lps=6)
    assert r.status == "ok" and not r.converged and "max_lps" in r.message
    assert r.n_lps == 6 and r.gap > 1e-9
    assert_valid_polygon(r)
    fine = feasible_region(**kw, tol=1e-6, max_lps=200)
    assert fine.converged and fine.gap <= 1e-6
    assert contains(fine, r, atol=1e-6)  # an inner approximation of the same region


def test_result_is_frozen() -> None:
    r = feasible_region(**rect_kwargs())
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.status = "x"  # type: ignore[misc]
    with pytest.raises(ValueError):
        r.vertices[0, 0] = 1.0


# ----------------------------------------------------------------------------------------------
# Independent check with random realistic cases (HiGHS, fixed c)
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 35])  # 35: once hit an AlmostSolved (inaccurate) support point
@pytest.mark.parametrize("stance", [(True, True, True, True), (True, False, True, True)])
def test_pyramid_region_agrees_with_fixed_com_lp(seed: int, stance: tuple[bool, ...]) -> None:
    rng = np.random.default_rng(seed)
    kw = C.random_quadruped_case(rng, stance)
    r = feasible_region(**kw, friction=("pyramid", 8), **TIGHT)
    if r.status == "empty":
        assert not equilibrium_feasible(np.zeros(2), kw, 8)
        return
    assert r.status == "ok"
    v, hs = r.vertices, r.halfspaces
    centre = v.mean(axis=0)
    # Vertices pulled 1 mm towards the centre, and interior samples, are feasible.
    pull = v + 1e-3 * (centre - v) / np.linalg.norm(centre - v, axis=1, keepdims=True)
    lam = rng.dirichlet(np.ones(len(v)), size=5)
    for p in np.vstack([pull, lam @ v]):
        assert equilibrium_feasible(p, kw, 8), p
    # Edge midpoints pushed 2 mm out along the outward normal are infeasible.
    for i in range(len(v)):
        mid = 0.5 * (v[i] + v[(i + 1) % len(v)])
        assert not equilibrium_feasible(mid - 2e-3 * hs[i, :2], kw, 8)


@pytest.mark.parametrize("seed", range(3))
def test_cone_region_is_bracketed_by_inscribed_and_circumscribed_pyramids(seed: int) -> None:
    # cone_k,inscribed  <=  exact cone  <=  cone_k,circumscribed, with k = 48 faces (~0.2 % of mu).
    rng = np.random.default_rng(100 + seed)
    kw = C.random_quadruped_case(rng, (True, True, True, True))
    r = feasible_region(**kw, friction="cone", tol=1e-7, max_lps=300)
    assert r.status == "ok", r.message
    v, hs = r.vertices, r.halfspaces
    centre = v.mean(axis=0)
    pull = v + 2e-3 * (centre - v) / np.linalg.norm(centre - v, axis=1, keepdims=True)
    for p in pull[:: max(1, len(v) // 12)]:
        assert equilibrium_feasible(p, kw, 48), p
    idx = range(0, len(v), max(1, len(v) // 12))
    for i in idx:
        mid = 0.5 * (v[i] + v[(i + 1) % len(v)])
        assert not equilibrium_feasible(mid - 2e-3 * hs[i, :2], kw, 48, circumscribed=True)


# ----------------------------------------------------------------------------------------------
# Invariants (hypothesis)
# ----------------------------------------------------------------------------------------------

stances = st.sampled_from([(True, True, True, True), (True, True, False, True), (False, True, True, True)])
seeds = st.integers(min_value=0, max_value=2**31 - 1)
INV = dict(tol=1e-6, max_lps=150)
ATOL = 5e-4  # containment slack [m]: convergence (tol 1e-6 m^2) and solver noise


@FAST_SETTINGS
@given(seed=seeds, stance=stances, dx=st.floats(-0.3, 0.3), dy=st.floats(-0.3, 0.3))
def test_translating_feet_translates_region(seed: int, stance: tuple[bool, ...], dx: float, dy: float) -> None:
    kw = C.random_quadruped_case(np.random.default_rng(seed), stance)
    r1 = feasible_region(**kw, **INV)
    kw["feet"] = kw["feet"] + np.array([dx, dy, 0.0])
    r2 = feasible_region(**kw, **INV)
    assert r1.status == r2.status
    assume(r1.usable)
    moved = r1.vertices + np.array([dx, dy])
    shifted = dataclasses.replace(r1, vertices=moved, halfspaces=halfspaces_from_polygon(moved))
    assert contains(r2, shifted, ATOL) and contains(shifted, r2, ATOL)
    assert r2.area == pytest.approx(r1.area, abs=1e-4)


@FAST_SETTINGS
@given(seed=seeds, stance=stances, scale=st.floats(1.05, 3.0), which=st.sampled_from(["torque", "mu"]))
# Regression: one refining direction stops at AlmostSolved in both solvers; the cap must still be refined.
@example(seed=432, stance=(True, True, False, True), scale=2.7307444161789842, which="mu")
def test_relaxing_limits_never_shrinks_region(seed: int, stance: tuple[bool, ...], scale: float, which: str) -> None:
    kw = C.random_quadruped_case(np.random.default_rng(seed), stance)
    r1 = feasible_region(**kw, **INV)
    if which == "torque":
        kw["torque_limits"] = kw["torque_limits"] * scale
    else:
        kw["mu"] = kw["mu"] * scale
    r2 = feasible_region(**kw, **INV)
    assert contains(r2, r1, ATOL)
    assert r2.area >= r1.area - 1e-4


@FAST_SETTINGS
@given(seed=seeds, stance=stances, k=st.integers(3, 12))
def test_inscribed_pyramid_region_is_inside_cone_region(seed: int, stance: tuple[bool, ...], k: int) -> None:
    kw = C.random_quadruped_case(np.random.default_rng(seed), stance)
    cone = feasible_region(**kw, **INV)
    pyr = feasible_region(**kw, friction=("pyramid", k), **INV)
    assert contains(cone, pyr, ATOL)
    assert pyr.area <= cone.area + 1e-4


def mirror(kw: dict[str, Any]) -> dict[str, Any]:
    """Reflect y -> -y: points and forces get M = diag(1, -1, 1), torques (pseudo-vectors) -M."""
    m = np.diag([1.0, -1.0, 1.0])
    out = dict(kw)
    out["feet"] = kw["feet"] @ m
    out["normals"] = kw["normals"] @ m
    out["jacobians"] = np.einsum("ab,nbk->nak", m, kw["jacobians"])  # J' = M J: J'^T (M f) = J^T f
    out["com_acc"] = np.asarray(kw["com_acc"]) @ m
    out["ext_force"] = np.asarray(kw["ext_force"]) @ m
    out["ang_momentum_rate"] = -(np.asarray(kw["ang_momentum_rate"]) @ m)
    out["ext_torque"] = -(np.asarray(kw["ext_torque"]) @ m)
    return out


@FAST_SETTINGS
@given(seed=seeds, stance=stances, friction=st.sampled_from(["cone", ("pyramid", 8)]))
def test_mirrored_stance_gives_mirrored_region(seed: int, stance: tuple[bool, ...], friction: Any) -> None:
    kw = C.random_quadruped_case(np.random.default_rng(seed), stance)
    r1 = feasible_region(**kw, friction=friction, **INV)
    r2 = feasible_region(**mirror(kw), friction=friction, **INV)
    assert r1.status == r2.status
    assume(r1.usable)
    flipped = r1.vertices[::-1] * [1.0, -1.0]  # reflection reverses orientation
    m1 = dataclasses.replace(r1, vertices=flipped, halfspaces=halfspaces_from_polygon(flipped))
    assert contains(r2, m1, ATOL) and contains(m1, r2, ATOL)
    assert r2.area == pytest.approx(r1.area, abs=1e-4)


# ----------------------------------------------------------------------------------------------
# The projection itself, on analytic support functions
# ----------------------------------------------------------------------------------------------


def test_projection_of_a_disc_converges_to_tolerance() -> None:
    centre, radius = np.array([0.3, -0.1]), 0.25

    def disc(ax: float, ay: float) -> tuple[int, float, float]:
        p = centre + radius * np.array([ax, ay])
        return SUPPORT_OK, float(p[0]), float(p[1])

    for tol in (1e-3, 1e-5):
        res = iterative_projection(disc, tol=tol, max_evals=500)
        assert res.status == "ok" and res.gap <= tol
        np.testing.assert_allclose(np.linalg.norm(res.points - centre, axis=1), radius, atol=1e-12)
        assert np.all(np.diff(res.angles) > 0)  # CCW
        inner = polygon_area(res.points)
        assert 0 < math.pi * radius**2 - inner <= tol
    # Area gap of an inscribed N-gon vs the circumscribed one ~ pi^3 R^2 / N^2.
    assert res.n_evals < 2 * math.sqrt(math.pi**3 * radius**2 / 1e-5)


def test_projection_of_a_square_needs_eight_evaluations() -> None:
    def square(ax: float, ay: float) -> tuple[int, float, float]:
        # Interior-point-like answer on a face: its midpoint.
        x = 0.0 if abs(ax) < 1e-12 else math.copysign(1.0, ax)
        y = 0.0 if abs(ay) < 1e-12 else math.copysign(1.0, ay)
        return SUPPORT_OK, x, y

    res = iterative_projection(square, tol=1e-9, max_evals=50)
    assert res.n_evals == 8 and res.gap == pytest.approx(0.0, abs=1e-12)


def test_projection_reports_empty_failures_and_budget() -> None:
    assert iterative_projection(lambda ax, ay: (SUPPORT_INFEASIBLE, math.nan, math.nan)).status == "empty"
    assert iterative_projection(lambda ax, ay: (SUPPORT_FAILED, math.nan, math.nan)).status == "solver_error"

    def flaky(ax: float, ay: float) -> tuple[int, float, float]:
        if ax < -0.5 and ay < -0.5:  # one initial diagonal fails
            return SUPPORT_FAILED, math.nan, math.nan
        return SUPPORT_OK, ax, ay

    res = iterative_projection(flaky, tol=1e-3, max_evals=200)
    assert res.status == "inaccurate" and len(res.points) > 3
    res = iterative_projection(lambda ax, ay: (SUPPORT_OK, ax, ay), tol=1e-12, max_evals=10)
    assert res.status == "max_lps" and res.n_evals == 10


def test_polygon_cleanup_is_robust_to_order_and_noise() -> None:
    rng = np.random.default_rng(0)
    corners = C.support_rectangle(0.6, 0.4)
    # Points along every edge (as an interior-point solver returns them), 1e-11 m noise, shuffled.
    pts = [corners[i] + t * (corners[(i + 1) % 4] - corners[i]) for i in range(4) for t in np.linspace(0, 1, 7)]
    pts = np.array(pts) + rng.normal(scale=1e-11, size=(28, 2))
    rng.shuffle(pts)
    out = np.array(convex_polygon([tuple(p) for p in pts]))
    assert_same_polygon(out, corners, atol=1e-9)
    assert polygon_area(out) > 0
    # A spike back along an edge (a sub-optimal point) never survives.
    spiky = [(0.0, 0.0), (1.0, 0.0), (0.5, 1e-3), (1.0 + 1e-7, 1e-7), (1.0, 1.0), (0.0, 1.0)]
    assert len(convex_polygon(spiky)) == 4
    # Nearly collinear points: the extreme pair.
    line = [(t, 2 * t + 1e-12 * math.sin(50 * t)) for t in rng.permutation(np.linspace(-1, 1, 9))]
    assert_same_polygon(np.array(convex_polygon(line)), np.array([[-1.0, -2.0], [1.0, 2.0]]), atol=1e-9)
    assert len(convex_polygon([(0.1, 0.2), (0.1 + 1e-9, 0.2)])) == 1


def test_failed_fast_solves_are_retried_with_the_robust_solver(monkeypatch: pytest.MonkeyPatch) -> None:
    kw = C.quadruped_case(torque_limit=30.0)
    ref = feasible_region(**kw)
    crippled = solver_settings(robust=False)
    crippled.max_iter = 2  # every fast solve stops with MaxIterations
    monkeypatch.setattr(region_program, "FAST_SETTINGS", crippled)
    r = feasible_region(**kw)
    assert r.status == "ok" and r.converged
    assert r.n_lps == 2 * ref.n_lps
    assert_same_polygon(r.vertices, ref.vertices, atol=1e-6)


def test_halfspaces_of_degenerate_polygons() -> None:
    assert halfspaces_from_polygon(np.zeros((0, 2))).shape == (0, 3)
    hs = halfspaces_from_polygon([[1.0, 2.0]])
    assert stability_margin(hs, [1.0, 2.0]) == 0.0
    assert stability_margin(hs, [1.5, 2.0]) == pytest.approx(-0.5)
    hs = halfspaces_from_polygon([[0.0, 0.0], [1.0, 0.0]])
    assert stability_margin(hs, [0.5, 0.0]) == pytest.approx(0.0)
    assert stability_margin(hs, [0.5, 0.2]) == pytest.approx(-0.2)
    assert stability_margin(hs, [1.3, 0.0]) == pytest.approx(-0.3)


# ----------------------------------------------------------------------------------------------
# The conic program's assembly
# ----------------------------------------------------------------------------------------------


def reference_problem(args: tuple[Any, ...]) -> tuple[Any, np.ndarray, list[str]]:
    """``(A, b, cones)`` of region_program.build_program assembled the plain way: dense row blocks stacked in the
    documented order, rows with an infinite torque bound dropped, scipy's dense-to-CSC conversion."""
    feet, normals, mu, jac, lo, hi, bias, force, moment, n_faces, w_max, extent = args
    n = jac.shape[0]
    n_var = 4 + 3 * n

    def block_diag(blocks: np.ndarray) -> np.ndarray:
        out = np.zeros((blocks.shape[0] * blocks.shape[1], n_var))
        for i, blk in enumerate(blocks):
            out[i * blk.shape[0] : (i + 1) * blk.shape[0], 4 + 3 * i : 7 + 3 * i] = blk
        return out

    eq = np.zeros((6, n_var))
    eq[0:3, 4:] = np.tile(np.eye(3), n)
    eq[3, 1], eq[4, 0], eq[5, 0], eq[5, 1] = -force[2], force[2], -force[1], force[0]
    eq[3, 2] = eq[4, 3] = 1.0
    for i, (px, py, pz) in enumerate(feet):
        eq[3:6, 4 + 3 * i : 7 + 3 * i] = [[0.0, -pz, py], [pz, 0.0, -px], [-py, px, 0.0]]
    box = np.zeros((8, n_var))
    box[0:4, 0:2] = box[4:8, 2:4] = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]
    jt = np.transpose(jac, (0, 2, 1))
    tau = block_diag(np.concatenate([jt, -jt], axis=1))
    tau_b = np.concatenate([bias - lo, hi - bias], axis=1).ravel()
    finite = np.isfinite(tau_b)
    t1, t2 = tangent_bases(normals)
    if n_faces:
        th = 2.0 * np.pi * np.arange(n_faces) / n_faces
        d = np.cos(th)[None, :, None] * t1[:, None, :] + np.sin(th)[None, :, None] * t2[:, None, :]
        faces = d - mu * math.cos(math.pi / n_faces) * normals[:, None, :]
        fric = block_diag(np.concatenate([faces, -normals[:, None, :]], axis=1))
        cones = ["ZeroConeT(6)", f"NonnegativeConeT({8 + finite.sum() + fric.shape[0]})"]
    else:
        fric = block_diag(-np.stack([mu * normals, t1, t2], axis=1))
        cones = ["ZeroConeT(6)", f"NonnegativeConeT({8 + finite.sum()})"] + ["SecondOrderConeT(3)"] * n
    a = np.vstack([eq, box, tau[finite], fric])
    box_b = np.concatenate([np.full(4, extent), np.full(4, n * w_max)])
    b = np.concatenate([force, moment, box_b, tau_b[finite], np.zeros(fric.shape[0])])
    return sp.csc_matrix(a), b, cones


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("stance", [(True, True, True, True), (True, False, True, True), (True, False, False, True)])
@pytest.mark.parametrize("friction", ["cone", ("pyramid", 6)])
@pytest.mark.parametrize("infinite_bounds", [False, True])
def test_problem_assembly_matches_the_plain_reference(
    seed: int, stance: tuple[bool, ...], friction: Any, infinite_bounds: bool
) -> None:
    """The in-place Fortran-ordered assembly hands Clarabel exactly the reference CSC data (same entries,
    same order, no explicit zeros), right-hand side and cones: the solver sees the same problem."""
    kw = C.random_quadruped_case(np.random.default_rng(seed), stance)
    if infinite_bounds:  # rows with an infinite bound are dropped
        lo, hi = -kw["torque_limits"], kw["torque_limits"].copy()
        lo[0, 1], hi[3, 2] = -np.inf, np.inf
        kw["torque_limits"] = (lo, hi)
    feet, nrm, jac, lo, hi, bias, _ = validate_contact_arrays(
        kw["feet"], kw["normals"], kw["stance"], kw["jacobians"], kw["torque_limits"], None
    )
    wrench = gravito_inertial_wrench(
        kw["mass"], kw["com_acc"], kw["ang_momentum_rate"], kw["ext_force"], kw["ext_torque"], G
    )
    args = (feet, nrm, kw["mu"], jac, lo, hi, bias, wrench[:3], wrench[3:], parse_friction(friction), WM, 10.0)
    prob = region_program.build_program(*args)
    a_ref, b_ref, cones_ref = reference_problem(args)
    assert prob.A.shape == a_ref.shape and prob.n_var == a_ref.shape[1]
    np.testing.assert_array_equal(prob.A.indptr, a_ref.indptr)
    np.testing.assert_array_equal(prob.A.indices, a_ref.indices)
    np.testing.assert_array_equal(prob.A.data, a_ref.data)
    np.testing.assert_array_equal(prob.b, b_ref)
    assert [repr(c) for c in prob.cones] == cones_ref


def test_dense_to_csc_matches_scipy() -> None:
    rng = np.random.default_rng(0)
    for shape in [(1, 1), (5, 3), (50, 16), (7, 1)]:
        a = np.where(rng.random(shape) < 0.3, rng.normal(size=shape), 0.0)
        a[:, 0] = 0.0  # an empty column
        for dense in (a, np.asfortranarray(a)):
            got, ref = region_program._dense_to_csc(dense), sp.csc_matrix(dense)
            np.testing.assert_array_equal(got.indptr, ref.indptr)
            np.testing.assert_array_equal(got.indices, ref.indices)
            np.testing.assert_array_equal(got.data, ref.data)


# ----------------------------------------------------------------------------------------------
# Input validation
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("override", "name"),
    [
        (dict(feet=np.zeros((4, 2))), "feet"),
        (dict(normals=np.zeros((3, 3))), "normals"),
        (dict(normals=np.zeros((4, 3))), "normals"),
        (dict(stance=np.ones(3, dtype=bool)), "stance"),
        (dict(stance=np.array([0, 1, 2, 1])), "stance"),
        (dict(mu=0.0), "mu"),
        (dict(mu=-1.0), "mu"),
        (dict(mu=math.nan), "mu"),
        (dict(mass=0.0), "mass"),
        (dict(mass=math.inf), "mass"),
        (dict(jacobians=np.zeros((4, 2, 3))), "jacobians"),
        (dict(torque_limits=np.ones((4, 2))), "torque_limits"),
        (dict(torque_limits=-np.ones((4, 3))), "torque_limits"),
        (dict(torque_limits=(np.ones((4, 3)), -np.ones((4, 3)))), "lower > upper"),
        (dict(torque_limits=np.full((4, 3), math.nan)), "torque_limits"),
        (dict(leg_bias=np.zeros((4, 2))), "leg_bias"),
        (dict(com_acc=(0.0, 0.0)), "com_acc"),
        (dict(com_acc=(0.0, 0.0, math.nan)), "com_acc"),
        (dict(ext_force=(0.0, math.inf, 0.0)), "ext_force"),
        (dict(ext_torque=np.zeros(4)), "ext_torque"),
        (dict(ang_momentum_rate="abc"), "ang_momentum_rate"),
        (dict(friction="pyramid"), "friction"),
        (dict(friction=("pyramid", 2)), "friction"),
        (dict(friction=("pyramid", 4.0)), "friction"),
        (dict(tol=0.0), "tol"),
        (dict(max_lps=3), "max_lps"),
        (dict(contact_torque_limit=-1.0), "contact_torque_limit"),
        (dict(gravity=0.0), "gravity"),
        (dict(feet=np.where(np.eye(4, 3) > 0, np.nan, C.rect_feet())), "feet"),
    ],
)
def test_bad_inputs_raise_value_error_naming_the_argument(override: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        feasible_region(**rect_kwargs(**override))


def test_a_failed_refining_direction_is_retried_along_the_cap_bisector() -> None:
    """A rotated ellipse whose support oracle fails for one refining direction: that cap is still refined.

    (Without symmetry about the cap, the edge's outward normal differs from the cap's bisector.)
    """
    c, s = math.cos(0.3), math.sin(0.3)
    rot = np.array([[c, -s], [s, c]])
    shape = rot @ np.diag([4.0, 0.25]) @ rot.T  # ellipse {x: x^T shape^-1 x <= 1}
    calls: list[float] = []

    def support(ax: float, ay: float) -> tuple[int, float, float]:
        calls.append(math.atan2(ay, ax))
        if len(calls) == 5:  # the first refining direction fails
            return fr.SUPPORT_FAILED, math.nan, math.nan
        d = np.array([ax, ay])
        x = shape @ d / math.sqrt(d @ shape @ d)
        return fr.SUPPORT_OK, float(x[0]), float(x[1])

    proj = iterative_projection(support, tol=1e-2, max_evals=200)
    assert proj.status == "ok"  # nothing was given up
    assert calls[5] != calls[4]  # the retry used another direction of the same cap
    assert proj.gap <= 1e-2
    inverse = np.linalg.inv(shape)
    np.testing.assert_allclose(np.einsum("ni,ij,nj->n", proj.points, inverse, proj.points), 1.0)
