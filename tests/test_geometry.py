import numpy as np
import pytest

from mgelens.geometry import (
    axis_ratio_and_angle_from,
    ell_comps_from,
    from_profile_frame,
    to_profile_frame,
)


@pytest.mark.parametrize("q", [0.2, 0.55, 0.999, 1.0])
@pytest.mark.parametrize("angle", [0.0, 17.0, 90.0, 135.5, 179.0])
def test_ell_comps_round_trip(q, angle):
    e1, e2 = ell_comps_from(q, angle)
    assert np.hypot(e1, e2) == pytest.approx((1 - q) / (1 + q))
    q_back, angle_back = axis_ratio_and_angle_from((e1, e2))
    assert q_back == pytest.approx(q, abs=1e-12)
    if q < 1.0:
        assert angle_back == pytest.approx(angle, abs=1e-9)


def test_ell_comps_order_is_lenstronomy():
    e1, e2 = ell_comps_from(0.5, 22.5)  # 2φ = 45°: e1 = e2 = f/√2
    assert e1 == pytest.approx(e2)
    assert ell_comps_from(0.5, 45.0)[0] == pytest.approx(0.0, abs=1e-15)
    assert ell_comps_from(0.5, 45.0)[1] == pytest.approx(1 / 3)


def test_negative_angles_wrap_to_0_180_and_f_is_capped():
    assert axis_ratio_and_angle_from(ell_comps_from(0.5, -30.0))[1] == pytest.approx(150.0)
    q, _ = axis_ratio_and_angle_from((2.0, 0.0))
    assert q == pytest.approx((1 - 0.999) / (1 + 0.999))
    with pytest.raises(ValueError, match="axis_ratio"):
        ell_comps_from(0.0, 10.0)


def test_profile_frame_puts_the_major_axis_along_x_prime():
    xp, yp = to_profile_frame(
        1.0 + np.cos(np.deg2rad(30)), 2.0 + np.sin(np.deg2rad(30)), (1, 2), 30
    )
    assert xp == pytest.approx(1.0)
    assert yp == pytest.approx(0.0, abs=1e-15)
    vx, vy = from_profile_frame(np.array(1.0), np.array(0.0), 30.0)
    assert (vx, vy) == pytest.approx((np.cos(np.deg2rad(30)), np.sin(np.deg2rad(30))))
