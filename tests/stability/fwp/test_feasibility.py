"""Tests of margin_rl.stability.fwp.feasibility: eq. (3)/(10)/(11) against closed forms and scipy, the Minkowski
pruning against qhull and brute-force LPs, eq. (24) against its geometry, the physics (static robot,
violated limits) and consistency with the feasible region."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from margin_rl import load_robot
from margin_rl.stability.analytic.contact_problem import contact_problem
from margin_rl.stability.analytic.margin import AnalyticSettings, analytic_margin
from margin_rl.stability.analytic.sampling import nominal_feet, standing_state
from margin_rl.stability.fwp.factor import (
    feasibility_factor,
    fwp_halfspaces,
    halfspace_margin,
    minkowski_feasibility_factor,
    wrench_violations,
)
from margin_rl.stability.fwp.feasibility import fwp_feasibility
from margin_rl.stability.fwp.polytope import (
    FeasibleWrenchPolytope,
    bounded_friction_cone,
    contact_wrench_vertices,
    feasible_wrench_polytope,
    force_polytope,
    friction_cone_edges,
)
from margin_rl.stability.geometry.contact import gravito_inertial_wrench
from margin_rl.stability.geometry.region import feasible_region

THREE = np.array([True, True, True, False])  # LF, RF, LH: RH lifted
# The feasible region with the FWP's friction model: the same inscribed 4-face pyramid, no contact torques.
PYRAMID = AnalyticSettings(friction=("pyramid", 4), contact_torque_limit=0.0)


@pytest.fixture(scope="module")
def robot():
    return load_robot("anymal_c")


@pytest.fixture(scope="module")
def problem(robot):
    return contact_problem(robot, standing_state(robot)[None])[0]


def polytope(problem, stance=THREE, **over) -> FeasibleWrenchPolytope:
    kwargs = dict(
        points=problem.contact_points,
        normals=problem.normals,
        stance=stance,
        mu=problem.mu,
        jacobians=problem.jacobians,
        torque_limits=problem.torque_limits,
        leg_bias=problem.leg_bias,
    )
    kwargs.update(over)
    return feasible_wrench_polytope(**kwargs)


@pytest.fixture(scope="module")
def fwp3(problem):
    return polytope(problem)


def homogenise(w: np.ndarray, ell: float) -> np.ndarray:
    return w * np.concatenate([np.ones(3), np.full(3, 1.0 / ell)])


# ------------------------------------------------------------------------------ per contact


def test_force_polytope_is_eq3_with_bias() -> None:
    rng = np.random.default_rng(3)
    J = rng.normal(size=(3, 3)) + 2.0 * np.eye(3)
    lo, hi, bias = np.array([-30.0, -50.0, -20.0]), np.array([40.0, 50.0, 25.0]), np.array([3.0, -4.0, 1.5])
    got = force_polytope(J, lo, hi, bias)
    # Eq. (3): f = J^-T (delta - tau_lim) over the 2^3 corners of the torque box.
    corners = np.array(list(itertools.product(*zip(lo, hi, strict=True))))
    expected = np.linalg.solve(J.T, (bias - corners).T).T
    assert got.shape == (8, 3)
    dist = np.linalg.norm(got[:, None, :] - expected[None, :, :], axis=2)
    assert np.all(dist.min(axis=1) < 1e-9) and np.all(dist.min(axis=0) < 1e-9)


def test_bounded_friction_cone_is_the_intersection(problem) -> None:
    n, J, lim, bias, mu = problem.normals[0], problem.jacobians[0], problem.torque_limits[0], problem.leg_bias[0], 0.6
    b = bounded_friction_cone(n, mu, J, -lim, lim, bias, n_faces=5)
    # Every vertex respects both limits; the unloaded leg is within its limits, so 0 is a vertex.
    tau = bias - b @ J
    assert np.all(np.abs(tau) <= lim + 1e-9)
    edges = friction_cone_edges(n, mu, 5)
    assert np.all(b @ n >= -1e-9)
    assert np.min(np.linalg.norm(b, axis=1)) < 1e-9
    # Same set as scipy's half-space intersection of pyramid and torque box (independent check).
    faces = np.cross(edges, np.roll(edges, -1, axis=0))  # inward normals of the pyramid (CCW edges)
    faces *= np.sign(faces @ n)[:, None]
    halfspaces = np.vstack(
        [
            np.column_stack([-faces, np.zeros(5)]),  # faces . f >= 0
            np.column_stack([J.T, -(bias + lim)]),  # J^T f <= delta + lim
            np.column_stack([-J.T, bias - lim]),  # -J^T f <= lim - delta
        ]
    )
    ref = HalfspaceIntersection(halfspaces, 20.0 * n).intersections
    assert ConvexHull(b).volume == pytest.approx(ConvexHull(ref).volume, rel=1e-9)
    assert len(ConvexHull(b).vertices) == len(b)  # no interior or duplicate points


def test_bounded_friction_cone_is_empty_when_no_force_is_admissible() -> None:
    # The leg's own weight needs -100 N m on a joint limited to 10 N m; only pulling forces could help.
    b = bounded_friction_cone([0, 0, 1], 0.8, np.eye(3), -np.full(3, 10.0), np.full(3, 10.0), [0.0, 0.0, -100.0])
    assert b.shape == (0, 3)


def test_contact_wrench_vertices_add_moments_about_the_com() -> None:
    w = contact_wrench_vertices([0.5, 0.0, -0.5], [[0.0, 0.0, 100.0], [10.0, 0.0, 0.0]])
    np.testing.assert_allclose(w, [[0, 0, 100, 0, -50, 0], [10, 0, 0, 0, -5, 0]], atol=1e-12)


def test_gravito_inertial_wrench_signs() -> None:
    m, g = 2.0, 10.0
    np.testing.assert_allclose(gravito_inertial_wrench(m, gravity=g), [0, 0, 20, 0, 0, 0])
    # F = m (c_dd - g_vec) - f_ext; moment = L_dot - tau_ext + c x F (module docstring).
    w = gravito_inertial_wrench(m, [1.0, 0, 0], [0, 0, 0.3], [0, 4.0, 0], [0.1, 0, 0], g, com=[0.0, 1.0, 0.0])
    force = np.array([2.0, -4.0, 20.0])
    np.testing.assert_allclose(w[:3], force)
    np.testing.assert_allclose(w[3:], np.array([-0.1, 0.0, 0.3]) + np.cross([0.0, 1.0, 0.0], force))


# ------------------------------------------------------------------------------ Minkowski sum (eq. 13)


def test_pruning_agrees_with_qhull_for_three_contacts(fwp3) -> None:
    """qhull on the pruned vertices keeps all of them, and every unpruned sum lies in their hull."""
    ell = fwp3.length_scale
    assert fwp3.dim == 6 and fwp3.n_vertices > 100
    pts = homogenise(fwp3.vertices, ell)
    hull = ConvexHull(pts - pts.mean(axis=0), qhull_options="Qx Q12")
    assert len(hull.vertices) == fwp3.n_vertices
    sums = np.zeros((1, 6))
    for p, f in zip(fwp3.points, fwp3.force_vertices, strict=True):
        w = contact_wrench_vertices(p, f)
        sums = (sums[:, None, :] + w[None, :, :]).reshape(-1, 6)
    assert sums.shape == (fwp3.n_unpruned, 6)
    centred = homogenise(sums, ell) - pts.mean(axis=0)
    a, b = hull.equations[:, :6], hull.equations[:, 6]
    worst = max(float(np.max(chunk @ a.T + b)) for chunk in centred.reshape(11, -1, 6))
    assert worst < 1e-6 * np.abs(pts).max()
    # The vertex tuples index the summands' vertices.
    rebuilt = sum(
        contact_wrench_vertices(p, f)[fwp3.vertex_tuples[:, i]]
        for i, (p, f) in enumerate(zip(fwp3.points, fwp3.force_vertices, strict=True))
    )
    np.testing.assert_allclose(rebuilt, fwp3.vertices, atol=1e-9)


def test_vertex_set_does_not_depend_on_the_contact_order(problem, fwp3) -> None:
    order = np.array([2, 0, 1, 3])  # LH, LF, RF, RH (lifted)
    permuted = polytope(
        problem,
        stance=THREE[order],
        points=problem.contact_points[order],
        normals=problem.normals[order],
        jacobians=problem.jacobians[order],
        torque_limits=problem.torque_limits[order],
        leg_bias=problem.leg_bias[order],
    )
    assert permuted.n_vertices == fwp3.n_vertices
    dist = np.linalg.norm(permuted.vertices[:, None, :] - fwp3.vertices[None, :, :], axis=2)
    assert np.all(dist.min(axis=0) < 1e-6) and np.all(dist.min(axis=1) < 1e-6)
    np.testing.assert_allclose(permuted.center, fwp3.center, atol=1e-9)


def normal_cone_depth(fwp: FeasibleWrenchPolytope, tup: np.ndarray) -> float:
    """max t s.t. g^T c + t <= 0, |c| <= 1, over the directions to *all* other summand vertices (HiGHS)."""
    rows = []
    for i, (p, f) in enumerate(zip(fwp.points, fwp.force_vertices, strict=True)):
        w = homogenise(contact_wrench_vertices(p, f), fwp.length_scale)
        d = np.delete(w, tup[i], axis=0) - w[tup[i]]
        rows.append(d / np.linalg.norm(d, axis=1, keepdims=True))
    g = np.vstack(rows)
    res = linprog(
        np.r_[np.zeros(6), -1.0],
        A_ub=np.column_stack([g, np.ones(len(g))]),
        b_ub=np.zeros(len(g)),
        bounds=[(-1, 1)] * 6 + [(None, 1)],
        method="highs",
    )
    assert res.status == 0
    return -res.fun


def test_pruning_agrees_with_brute_force_lps_for_four_non_coplanar_contacts(problem) -> None:
    points = problem.contact_points + np.array([[0, 0, 0.10], [0, 0, 0.03], [0, 0, 0.0], [0, 0, -0.06]])
    normals = np.array([[0.2, 0, 1], [0, 0, 1], [0, -0.15, 1], [0.1, 0.1, 1]])
    fwp = polytope(problem, stance=np.ones(4, bool), points=points, normals=normals)
    assert fwp.dim == 6 and fwp.n_vertices > 1000
    rng = np.random.default_rng(0)
    pruned = {tuple(t) for t in fwp.vertex_tuples}
    sample = [fwp.vertex_tuples[i] for i in rng.choice(fwp.n_vertices, 40, replace=False)]
    sample += [np.array([rng.integers(m) for m in fwp.contact_vertex_counts]) for _ in range(80)]
    n_non_vertices = 0
    for tup in sample:
        depth = normal_cone_depth(fwp, tup)
        assert (depth > 1e-7) == (tuple(tup) in pruned), (tup, depth)
        n_non_vertices += depth <= 1e-7
    assert n_non_vertices > 10  # the sample did exercise rejections


# ------------------------------------------------------------------------------ feasibility factor (eq. 24)


def test_factor_of_a_cube_is_one_minus_its_gauge() -> None:
    cube = np.array(list(itertools.product([-1.0, 1.0], repeat=6)))
    for w, s in (([0, 0, 0, 0, 0, 0], 1.0), ([0.5, 0, 0, 0, 0, 0], 0.5), ([0, 0, 0, 1, 0, -0.3], 0.0)):
        r = feasibility_factor(cube, w)
        assert r.status == "ok" and r.s == pytest.approx(s, abs=1e-7)
        assert (r.n_variables, r.n_constraints) == (65, 7)  # Table I: n_v + 1 variables, 7 rows
    assert feasibility_factor(cube, [0, 0, 3.0, 0, 0, 0]).s == pytest.approx(-2.0, abs=1e-7)
    assert feasibility_factor(cube + 5.0, [5, 5, 5, 5, 5, 5.5]).s == pytest.approx(0.5, abs=1e-7)
    # A centre outside the polytope: wrenches beyond the cone of the centred vertices cannot be reached.
    for dual in (True, False):
        r = feasibility_factor(cube, [3.0, 0, 0, 0, 0, 0], center=[2.0, 0, 0, 0, 0, 0], dual=dual)
        assert r.status == "ok" and r.s == -math.inf


def test_factor_is_linear_along_rays_from_the_centre(fwp3) -> None:
    rng = np.random.default_rng(1)
    c = fwp3.center
    assert minkowski_feasibility_factor(fwp3, c).s == pytest.approx(1.0, abs=1e-7)
    for v in fwp3.vertices[rng.choice(fwp3.n_vertices, 3, replace=False)]:
        for alpha in (0.3, 1.0, 1.7):  # inside, on the boundary (a vertex), outside
            s = minkowski_feasibility_factor(fwp3, c + alpha * (v - c)).s
            assert s == pytest.approx(1.0 - alpha, abs=1e-6)


def test_vertex_lp_and_summand_lp_give_the_same_factor(fwp3, problem) -> None:
    rng = np.random.default_rng(2)
    wrenches = [gravito_inertial_wrench(problem.mass), fwp3.center + 300.0 * rng.normal(size=6)]
    wrenches += [gravito_inertial_wrench(problem.mass, ext_force=[0, 150.0, 0])]
    for w in wrenches:
        a = feasibility_factor(fwp3.vertices, w, center=fwp3.center, length_scale=fwp3.length_scale)
        primal = feasibility_factor(fwp3.vertices, w, center=fwp3.center, length_scale=fwp3.length_scale, dual=False)
        b = minkowski_feasibility_factor(fwp3, w)
        assert a.status == primal.status == b.status == "ok"
        assert a.s == pytest.approx(b.s, abs=1e-6) and primal.s == pytest.approx(b.s, abs=1e-6)
        assert a.s <= 1.0
    # The paper's centring (centroid of the pruned vertices) moves s but not its sign.
    w = gravito_inertial_wrench(problem.mass)
    paper = feasibility_factor(fwp3.vertices, w)
    assert np.sign(paper.s) == np.sign(minkowski_feasibility_factor(fwp3, w).s)


def test_two_contacts_span_five_dimensions(problem) -> None:
    diagonal = np.array([True, False, False, True])  # LF, RH
    fwp = polytope(problem, stance=diagonal)
    assert fwp.dim == 5
    p1, p2 = fwp.points
    on_line = np.r_[0.5 * (p1 + p2)[:2], 0.0]  # vertical gravity line through the contact line
    s_on = minkowski_feasibility_factor(fwp, gravito_inertial_wrench(problem.mass, com=on_line)).s
    assert 0.0 < s_on < 1.0
    off = minkowski_feasibility_factor(fwp, gravito_inertial_wrench(problem.mass, com=on_line + np.array([0, 0.05, 0])))
    assert off.s == -math.inf and "span" in off.message


# ------------------------------------------------------------------------------ H-description (eq. 17-20)


def test_halfspace_margin_weights_moments_by_the_length_scale() -> None:
    eye = np.eye(6)
    box = np.column_stack([np.vstack([eye, -eye]), -np.ones(12)])  # |w_j| <= 1
    assert halfspace_margin(box, np.zeros(6), length_scale=1.0) == pytest.approx(1.0)
    # A 1 N m moment margin at a 2 m lever arm is worth 0.5 N of force.
    assert halfspace_margin(box, np.zeros(6), length_scale=2.0) == pytest.approx(0.5)
    assert halfspace_margin(box, [0.25, 0, 0, 0, 0, 0], length_scale=0.5) == pytest.approx(0.75)
    assert halfspace_margin(box, [0, 0, 0, 0, 1.5, 0], length_scale=1.0) == pytest.approx(-0.5)


def test_halfspace_margin_and_factor_agree_in_sign(fwp3, problem) -> None:
    ell = problem.com_height
    h = fwp_halfspaces(fwp3.vertices, ell)
    assert np.max(fwp3.vertices @ h[:, :6].T + h[:, 6]) < 1e-6 * np.abs(fwp3.vertices).max()
    c = fwp3.center
    rng = np.random.default_rng(4)
    for v in fwp3.vertices[rng.choice(fwp3.n_vertices, 3, replace=False)]:
        margins = [halfspace_margin(h, c + a * (v - c), ell) for a in (0.5, 1.0, 1.5)]
        assert margins[0] > 0.0 and abs(margins[1]) < 1e-6 * np.abs(v).max() and margins[2] < 0.0
    w = gravito_inertial_wrench(problem.mass)
    assert np.sign(halfspace_margin(h, w, ell)) == np.sign(minkowski_feasibility_factor(fwp3, w).s)


# ------------------------------------------------------------------------------ physics


def test_static_robot_factor_falls_through_zero_where_the_region_ends(robot) -> None:
    """Three feet (RH lifted); the CoM starts over the support triangle and moves towards RH."""
    feet, u = nominal_feet(robot), np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    ts = np.linspace(0.14, -0.10, 9)  # CoM displacement along u [m]: feet relative to the CoM move by -t u
    s, margin = [], []
    for t in ts:
        lam = standing_state(robot, feet=feet - t * u, contacts=THREE.astype(float))
        r = fwp_feasibility(robot, lam)
        assert r.status == "ok"
        s.append(r.s)
        margin.append(analytic_margin(robot, lam, PYRAMID).margin)
        assert r.violated == (() if r.s >= 0 else ("contact",))  # it tips: outside the CWC
    s, margin = np.array(s), np.array(margin)
    assert s[0] > 0.2 and s[-1] < -0.1
    assert np.all(np.diff(s) < 0)

    def zero_crossing(y: np.ndarray) -> float:
        k = int(np.flatnonzero(np.diff(np.sign(y)) != 0)[0])
        return float(ts[k] + (ts[k + 1] - ts[k]) * y[k] / (y[k] - y[k + 1]))

    assert zero_crossing(s) == pytest.approx(zero_crossing(margin), abs=5e-3)


@pytest.mark.parametrize("name", ["anymal_b", "anymal_c"])
def test_com_inside_feasible_region_iff_factor_non_negative(name) -> None:
    """Static states: the analytic margin (CoM = ICP) is the signed distance of the CoM to the region."""
    robot = load_robot(name)
    feet = nominal_feet(robot)
    signs = []
    for contacts in (np.ones(4), THREE.astype(float)):
        for angle, dist in itertools.product((0.3, 1.9, 3.4, 5.0), (0.0, 0.05, 0.1)):
            d = dist * np.array([math.cos(angle), math.sin(angle), 0.0])
            lam = standing_state(robot, feet=feet - d, contacts=contacts)
            m = analytic_margin(robot, lam, PYRAMID)
            r = fwp_feasibility(robot, lam)
            assert r.status == m.status == "ok"
            if abs(m.margin) > 2e-3:
                assert (m.margin > 0) == (r.s > 0), (contacts, angle, dist, m.margin, r.s)
                signs.append(m.margin > 0)
    assert sum(signs) >= 5 and len(signs) - sum(signs) >= 3  # both sides were visited


def test_com_inside_torque_limited_region_iff_factor_non_negative(problem) -> None:
    """Weak joints (25 N m) shrink the region well inside the support polygon; CoM moved with `com`."""
    limits = np.full((4, 3), 25.0)
    labels = set()
    for stance in (np.ones(4, bool), THREE):
        region = feasible_region(
            problem.contact_points,
            problem.normals,
            stance,
            problem.mu,
            problem.mass,
            problem.jacobians,
            limits,
            problem.leg_bias,
            friction=("pyramid", 4),
            contact_torque_limit=0.0,
            tol=1e-7,
            max_lps=200,
        )
        assert region.status == "ok" and region.converged
        fwp = polytope(problem, stance=stance, torque_limits=limits, prune=False)
        for x, y in itertools.product(np.linspace(-0.45, 0.45, 7), np.linspace(-0.35, 0.35, 7)):
            dist = float(np.min(region.halfspaces[:, :2] @ [x, y] - region.halfspaces[:, 2]))
            w = gravito_inertial_wrench(problem.mass, com=[x, y, 0.0])
            s = minkowski_feasibility_factor(fwp, w).s
            if abs(dist) > 2e-3:
                assert (dist > 0) == (s > 0), (stance, x, y, dist, s)
            if s < 0:
                labels.add(wrench_violations(fwp, w))
    assert ("actuation",) in labels  # the torque limits did bind somewhere


def test_violations_name_the_limit(robot) -> None:
    mg = robot.total_mass * robot.gravity
    pushed = fwp_feasibility(robot, standing_state(robot, ext_force=np.array([0.0, 0.7 * mg, 0.0])))
    assert pushed.s < 0 and pushed.violated == ("contact",)  # sideways: the feet would slip
    loaded = fwp_feasibility(robot, standing_state(robot, ext_force=np.array([0.0, 0.0, -4000.0])))
    assert loaded.s < 0 and loaded.violated == ("actuation",)  # pressed down: the knees give in
    calm = fwp_feasibility(robot, standing_state(robot))
    assert calm.s > 0 and calm.violated == ()


def test_coupled_violation_inside_cwc_and_awp() -> None:
    """Two legs on one point: leg 0 strong sideways but weak vertically, leg 1 the reverse. 50 N sideways
    under 100 N is inside the friction cone (CWC) and splits between the legs' boxes (AWP), but no leg can
    push sideways without the normal force to hold it by friction."""
    fwp = feasible_wrench_polytope(
        points=np.tile([0.0, 0.0, -0.5], (2, 1)),
        normals=np.tile([0.0, 0.0, 1.0], (2, 1)),
        stance=[True, True],
        mu=1.0,
        jacobians=np.tile(np.eye(3), (2, 1, 1)),  # tau = -f: the torque box is a force box
        torque_limits=np.array([[100.0, 100.0, 1.0], [1.0, 1.0, 100.0]]),
    )
    w = contact_wrench_vertices([0.0, 0.0, -0.5], [[50.0, 0.0, 100.0]])[0]
    assert minkowski_feasibility_factor(fwp, w).s < -0.5
    assert wrench_violations(fwp, w) == ("coupled",)


# ------------------------------------------------------------------------------ robot layer


def test_pruned_pipeline_gives_the_same_factor(robot) -> None:
    lam = standing_state(robot)
    fast, paper = fwp_feasibility(robot, lam), fwp_feasibility(robot, lam, prune=True)
    assert fast.n_vertices is None and paper.n_vertices is not None and paper.n_vertices > 1000
    assert paper.s == pytest.approx(fast.s, abs=1e-6)
    assert paper.contact_vertex_counts == fast.contact_vertex_counts == (11, 11, 11, 11)
    np.testing.assert_allclose(fast.wrench, [0, 0, robot.total_mass * robot.gravity, 0, 0, 0], atol=1e-9)
    assert set(fast.timings) >= {"kinematics", "fwp", "lp", "total"}
    assert not fast.fwp.vertices.flags.writeable


def test_same_statuses_as_the_analytic_margin(robot) -> None:
    cases = {
        "no_contact": standing_state(robot, contacts=np.zeros(4)),
        "unreachable": standing_state(robot, feet=nominal_feet(robot) + np.array([1.0, 0.0, 0.0])),
    }
    for status, lam in cases.items():
        r = fwp_feasibility(robot, lam)
        assert r.status == analytic_margin(robot, lam).status == status
        assert math.isnan(r.s) and r.fwp is None


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: bounded_friction_cone([0, 0, 1], 0.0, np.eye(3), -np.ones(3), np.ones(3)), "mu"),
        (lambda: bounded_friction_cone([0, 0, 1], 0.5, np.eye(3), -np.ones(3), np.ones(3), n_faces=2), "n_faces"),
        (lambda: bounded_friction_cone([0, 0, 0], 0.5, np.eye(3), -np.ones(3), np.ones(3)), "normal"),
        (lambda: force_polytope(np.diag([1.0, 1.0, 0.0]), -np.ones(3), np.ones(3)), "jacobian"),
        (lambda: force_polytope(np.eye(3), np.ones(3), -np.ones(3)), "torque_lo"),
        (lambda: force_polytope(np.eye(3), -np.ones(3), [1.0, np.nan, 1.0]), "torque_hi"),
        (lambda: contact_wrench_vertices([0, 0], [[1.0, 0, 0]]), "point"),
        (lambda: gravito_inertial_wrench(-1.0), "mass"),
        (lambda: gravito_inertial_wrench(1.0, com_acc=[0, 0, np.inf]), "com_acc"),
        (lambda: feasibility_factor(np.zeros((3, 5)), np.zeros(6)), "vertices"),
        (lambda: feasibility_factor(np.eye(6), [0, 0, 0, 0, 0, np.nan]), "wrench"),
        (lambda: halfspace_margin(np.ones((2, 7)), np.zeros(6), 0.0), "length_scale"),
    ],
)
def test_bad_inputs_raise_naming_the_argument(call, name) -> None:
    with pytest.raises(ValueError, match=name):
        call()


def test_bad_polytope_inputs_raise_naming_the_argument(problem) -> None:
    with pytest.raises(ValueError, match="torque_limits"):
        polytope(problem, torque_limits=np.full((4, 3), np.inf))
    with pytest.raises(ValueError, match="points"):
        polytope(problem, points=np.zeros((4, 2)))
    with pytest.raises(ValueError, match="stance"):
        polytope(problem, stance=[1, 0, 2, 1])
    with pytest.raises(ValueError, match=r"jacobians\[1\]"):
        polytope(problem, jacobians=np.concatenate([problem.jacobians[:1], np.zeros((3, 3, 3))]))


def test_torque_limits_override_the_robots_own():
    """The robot's own limits passed explicitly give the same s; drives of 1 N m cannot hold the robot up
    (s < 0, the actuation limits violated) where its own drives can; malformed limits are refused by name."""
    robot = load_robot("anymal_c")
    lam = standing_state(robot)
    own = fwp_feasibility(robot, lam)
    same = fwp_feasibility(robot, lam, torque_limits=np.asarray(robot.torque_limits).reshape(4, 3))
    assert own.s > 0 and same.s == pytest.approx(own.s, abs=1e-9)
    weak = fwp_feasibility(robot, lam, torque_limits=np.ones((4, 3)))
    assert weak.s < 0 and "actuation" in weak.violated
    with pytest.raises(ValueError, match=r"torque_limits must be positive finite numbers of shape \(4, 3\)"):
        fwp_feasibility(robot, lam, torque_limits=np.ones(12))
