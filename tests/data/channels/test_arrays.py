"""Arrays as Sionna defines them, evaluated along paths without a scene (the pattern functions need Sionna)."""

import numpy as np
import pytest

from dtradar_data.channels import Array
from dtradar_data.channels.arrays import look_at_orientation, rotation_matrix
from dtradar_data.core.errors import InvalidSettingError


def test_an_array_that_sionna_would_not_build_is_refused_naming_every_problem():
    with pytest.raises(InvalidSettingError) as caught:
        Array(0, 2, "horn", "X")
    message = str(caught.value)
    assert "num_rows 0" in message and "pattern 'horn'" in message and "polarization 'X'" in message


def test_ports_count_elements_times_polarisations():
    assert Array(8, 2, "tr38901", "VH").num_ports == 32 and Array(4, 4, "dipole", "V").num_ports == 16


def test_the_rotation_is_sionnas_yaw_pitch_roll_and_look_at_points_the_local_x_axis_at_the_target():
    r = rotation_matrix((np.pi / 2, 0.0, 0.0))
    np.testing.assert_allclose(r @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    yaw, pitch, roll = look_at_orientation((0, 0, 3), (1, 1, 0))
    d = np.array([1, 1, -3]) / np.sqrt(11)
    np.testing.assert_allclose(rotation_matrix((yaw, pitch, roll)) @ [1, 0, 0], d, atol=1e-12)


@pytest.mark.sionna
def test_element_positions_are_sionnas_rotated_planar_array():
    import mitsuba as mi

    arr = Array(2, 3, "iso", "V", vertical_spacing=0.7, horizontal_spacing=0.4)
    ours = arr.element_positions(0.125, (0.3, -0.2, 0.1))
    theirs = arr.sionna().rotate(0.125, mi.Point3f(0.3, -0.2, 0.1))
    np.testing.assert_allclose(
        ours, np.stack([np.asarray(theirs.x), np.asarray(theirs.y), np.asarray(theirs.z)], 1), atol=1e-6
    )


@pytest.mark.sionna
def test_an_unturned_isotropic_dual_polarised_element_radiates_theta_hat_then_phi_hat():
    theta, phi = np.array([0.3, 1.2, 2.9]), np.array([-2.0, 0.1, 1.5])
    field = Array(1, 1, "iso", "VH").field(theta, phi)
    np.testing.assert_allclose(field[0], [[1, 0]] * 3, atol=1e-6)
    np.testing.assert_allclose(field[1], [[0, 1]] * 3, atol=1e-6)
    turned = Array(1, 1, "iso", "V").field(theta, phi, (0.4, 0.2, -0.3))
    np.testing.assert_allclose(np.abs(turned[0]) ** 2 @ [1, 1], 1.0, rtol=1e-6)  # a rotation keeps unit gain
