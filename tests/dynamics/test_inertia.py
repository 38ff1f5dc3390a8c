"""Inertia tensors against their defining integrals and the parallel-axis theorem."""

import numpy as np
import pytest
from scipy.integrate import quad

from gyroemu.dynamics import inertia
from gyroemu.dynamics.inertia import InertiaError
from gyroemu.dynamics.rotation import quat_from_rotvec, quat_rotate

EPS = np.finfo(float).eps


def test_point_masses_at_cube_corners():
    # Eight masses m at (±a, ±a, ±a): Ixx = Σ m (y² + z²) = 16 m a², no products of inertia.
    a, m = 0.3, 2.0
    corners = np.array(np.meshgrid([-a, a], [-a, a], [-a, a])).reshape(3, -1).T
    np.testing.assert_allclose(inertia.point_masses(np.full(8, m), corners), 16 * m * a**2 * np.eye(3), rtol=1e-15)


def test_box_equals_its_midpoint_point_cloud_exactly():
    # A box as n³ equal point masses at cell centres: the midpoint sum of x² over n cells of an edge L is
    # L³/12 − L h²/12 per unit density (h = L/n), so the cloud's tensor is the box's minus m h_i²/12 terms.
    m, (lx, ly, lz), n = 3.0, (0.4, 0.2, 0.1), 20
    axes = [(np.arange(n) + 0.5) / n * length - length / 2 for length in (lx, ly, lz)]
    pts = np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T
    cloud = inertia.point_masses(np.full(n**3, m / n**3), pts)
    h2 = (np.array([lx, ly, lz]) / n) ** 2
    correction = m / 12 * np.diag([h2[1] + h2[2], h2[0] + h2[2], h2[0] + h2[1]])
    np.testing.assert_allclose(cloud + correction, inertia.box(m, lx, ly, lz), rtol=1e-12, atol=1e-15)


def test_cone_matches_integration_over_discs():
    # Solid cone, base radius R at z = 0, apex at z = h; radius r(z) = R (1 − z/h); centre of mass at h/4.
    m, radius, h = 1.5, 0.2, 0.5
    rho = m / (np.pi * radius**2 * h / 3)
    r = lambda z: radius * (1 - z / h)  # noqa: E731
    izz = quad(lambda z: rho * np.pi * r(z) ** 4 / 2, 0, h)[0]
    ixx = quad(lambda z: rho * np.pi * r(z) ** 2 * (r(z) ** 2 / 4 + (z - h / 4) ** 2), 0, h)[0]
    np.testing.assert_allclose(inertia.cone(m, radius, h), np.diag([ixx, ixx, izz]), rtol=1e-12)


def test_hollow_cylinder_is_difference_of_solids():
    # A tube is the outer solid minus the inner solid, with masses in proportion to their volumes.
    rho, r_out, r_in, h = 7800.0, 0.1, 0.06, 0.3
    m_out, m_in = rho * np.pi * r_out**2 * h, rho * np.pi * r_in**2 * h
    tube = inertia.cylinder(m_out - m_in, r_out, h, inner_radius=r_in)
    np.testing.assert_allclose(tube, inertia.cylinder(m_out, r_out, h) - inertia.cylinder(m_in, r_in, h), rtol=1e-12)
    np.testing.assert_allclose(inertia.sphere(2.0, 0.5, hollow=True), 2 / 3 * 2.0 * 0.25 * np.eye(3))


def test_composite_of_two_half_boxes_is_the_box():
    m, lx, ly, lz = 2.0, 0.6, 0.2, 0.1
    halves = [(m / 2, inertia.box(m / 2, lx / 2, ly, lz), (s * lx / 4, 0, 0)) for s in (-1, 1)]
    total, cm, tensor = inertia.composite(halves)
    assert total == m
    np.testing.assert_allclose(cm, 0, atol=EPS)
    np.testing.assert_allclose(tensor, inertia.box(m, lx, ly, lz), rtol=1e-14)


def test_composite_with_rotated_part_and_parallel_axis():
    rod = inertia.cylinder(1.0, 0.01, 1.0)  # along its own z
    q = quat_from_rotvec([0, np.pi / 2, 0])  # rotated to lie along x
    total, cm, tensor = inertia.composite([(1.0, rod, (0, 0, 0), q), (1.0, inertia.sphere(1.0, 0.1), (0, 0, 1.0))])
    np.testing.assert_allclose(cm, [0, 0, 0.5])
    expected = inertia.world_tensor(q, rod) + inertia.sphere(1.0, 0.1) + 2 * 0.25 * np.diag([1, 1, 0])
    np.testing.assert_allclose(tensor, expected, atol=1e-15)


def test_principal_axes_recover_a_rotated_tensor():
    moments = np.array([1.0, 2.0, 2.5])
    q = quat_from_rotvec([0.3, -1.1, 0.7])
    tensor = inertia.world_tensor(q, np.diag(moments))
    found, axes = inertia.principal_axes(tensor)
    np.testing.assert_allclose(found, moments, rtol=1e-14)
    assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(axes @ np.diag(found) @ axes.T, tensor, atol=1e-14)
    # Each principal axis is the rotated body axis (up to sign).
    for k in range(3):
        assert abs(axes[:, k] @ quat_rotate(q, np.eye(3)[k])) == pytest.approx(1.0, abs=1e-12)


def test_world_tensor_maps_body_momentum():
    q = quat_from_rotvec([0.5, 0.2, -0.4])
    i_body, w_body = np.diag([1.0, 2.0, 3.0]), np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(
        inertia.world_tensor(q, i_body) @ quat_rotate(q, w_body), quat_rotate(q, i_body @ w_body)
    )


@pytest.mark.parametrize(
    "bad, why",
    [
        ([[1, 0.1, 0], [0, 1, 0], [0, 0, 1]], "not symmetric"),
        ([1.0, -1.0, 1.0], "not positive definite"),
        ([1.0, 1.0, 2.5], "triangle inequality"),
        ([1.0, 1.0], "3 principal moments"),
    ],
)
def test_non_physical_tensors_are_refused_with_the_reason(bad, why):
    with pytest.raises(InertiaError, match=why):
        inertia.inertia_tensor(bad)


def test_flat_lamina_is_the_equality_case_and_accepted():
    np.testing.assert_allclose(inertia.inertia_tensor(inertia.disc(1.0, 0.2)), inertia.disc(1.0, 0.2))
