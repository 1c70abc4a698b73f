"""Joint trajectory commands: validation and the reference they define (no pybullet, no ROS)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from horizon_mpc.sim.trajectory import JointTrajectoryCommand, ReferenceGenerator

JOINTS = ["a", "b", "c"]


def command(times=(0.0, 0.5, 1.0), t0=0.0, names=JOINTS, velocities=True, efforts=True):
    k, nj = len(times), len(names)
    pos = np.arange(k * nj, dtype=float).reshape(k, nj)
    return JointTrajectoryCommand(
        list(names), t0, np.array(times, dtype=float), pos,
        np.ones((k, nj)) if velocities else None,
        np.full((k, nj), 2.0) if efforts else None,
    )


# ---------------------------------------------------------------- validation, one rule per test
def test_valid_command_passes_and_is_normalised():
    out = command().validate(JOINTS, now=0.2)
    assert out.positions.dtype == float and out.positions.shape == (3, 3)


def test_unknown_joint_name_is_named():
    with pytest.raises(ValueError, match="unknown joint names \\['x'\\]"):
        command(names=["a", "b", "x"]).validate(JOINTS)


def test_missing_joint_name_is_named():
    cmd = command(names=["a", "b"])
    with pytest.raises(ValueError, match="missing joint names \\['c'\\]"):
        cmd.validate(JOINTS)


def test_duplicate_joint_names_rejected():
    with pytest.raises(ValueError, match="duplicate"):
        command(names=["a", "a", "b"]).validate()



def test_joint_names_given_as_one_string_are_named_as_such():
    """'LF_HAA' was split into its letters: 'duplicate joint names: ['A']'."""
    cmd = JointTrajectoryCommand("abc", 0.0, [0.0], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="a list of names, got the string 'abc'"):
        cmd.validate()

def test_mismatched_lengths_rejected():
    cmd = command()
    cmd.positions = cmd.positions[:, :2]
    with pytest.raises(ValueError, match="positions has shape"):
        cmd.validate(JOINTS)


def test_nan_and_inf_rejected():
    for field in ("positions", "velocities", "efforts"):
        cmd = command()
        getattr(cmd, field)[1, 2] = math.nan if field != "efforts" else math.inf
        with pytest.raises(ValueError, match=f"{field} contains NaN/Inf"):
            cmd.validate(JOINTS)


def test_non_increasing_times_rejected():
    with pytest.raises(ValueError, match="not strictly increasing"):
        command(times=(0.0, 0.5, 0.5)).validate(JOINTS)


def test_points_too_close_for_their_motion_are_rejected():
    """Two points 1 ns and 0.3 rad apart (3e8 rad/s): accepted, the robot launched."""
    positions = np.zeros((2, len(JOINTS)))
    positions[1, 1] = 0.3
    cmd = JointTrajectoryCommand(JOINTS, 0.0, [0.0, 1e-9], positions)
    with pytest.raises(ValueError, match=f"ask joint '{JOINTS[1]}' to move 0.3 in 1e-09 s"):
        cmd.validate(JOINTS)
    JointTrajectoryCommand(JOINTS, 0.0, [0.0, 0.02], positions).validate(JOINTS)  # 15 rad/s


def test_negative_first_time_rejected():
    with pytest.raises(ValueError, match="negative"):
        command(times=(-0.1, 0.5, 1.0)).validate(JOINTS)


def test_stamp_far_in_the_past_or_future_rejected():
    with pytest.raises(ValueError, match="old"):
        command(t0=1.0).validate(JOINTS, now=5.0, max_stamp_offset=1.0)
    with pytest.raises(ValueError, match="in the future"):
        command(t0=9.0).validate(JOINTS, now=5.0, max_stamp_offset=1.0)
    command(t0=4.5).validate(JOINTS, now=5.0, max_stamp_offset=1.0)


def test_reordered_permutes_columns_by_name():
    cmd = command().reordered(["c", "a", "b"])
    np.testing.assert_array_equal(cmd.positions[0], [2.0, 0.0, 1.0])


_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-5, 5),
    st.none(),
    st.text(max_size=2),
)


@given(
    names=st.lists(st.sampled_from(["a", "b", "c", "x", ""]), max_size=4),
    times=st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
    rows=st.lists(st.lists(_values, max_size=4), max_size=4),
    t0=st.one_of(st.floats(), st.none(), st.text(max_size=2)),
    with_v=st.booleans(),
)
def test_validate_fuzz_raises_only_value_error(names, times, rows, t0, with_v):
    """Whatever the contents, validate() either returns a well-formed command or a ValueError."""
    cmd = JointTrajectoryCommand(names, t0, times, rows, rows if with_v else None, None)
    try:
        out = cmd.validate(JOINTS, now=0.0)
    except ValueError:
        return
    k = len(out.times)
    assert out.positions.shape == (k, 3) and np.all(np.isfinite(out.positions))
    assert np.all(np.diff(out.times) > 0)


# ---------------------------------------------------------------- reference generation
def test_hold_before_any_command():
    ref = ReferenceGenerator(3)
    ref.hold(np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.2, 0.3]))
    q, v, tau = ref.reference(10.0)
    np.testing.assert_array_equal(q, [1, 2, 3])
    np.testing.assert_array_equal(v, 0.0)
    np.testing.assert_array_equal(tau, [0.1, 0.2, 0.3])


def test_hermite_passes_through_points_with_their_velocities():
    ref = ReferenceGenerator(3, timeout=10.0)
    cmd = command()
    ref.set_command(cmd.validate(JOINTS), now=0.0)
    for k, t in enumerate(cmd.times[:-1]):
        q, v, _ = ref.reference(t)
        np.testing.assert_allclose(q, cmd.positions[k], atol=1e-12)
        np.testing.assert_allclose(v, cmd.velocities[k], atol=1e-12)


def test_hermite_velocity_is_the_derivative_of_position():
    ref = ReferenceGenerator(3, timeout=10.0)
    ref.set_command(command().validate(JOINTS), now=0.0)
    t, h = 0.37, 1e-6
    dq = (ref.reference(t + h)[0] - ref.reference(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(ref.reference(t)[1], dq, rtol=1e-6)


def test_linear_interpolation_without_velocities():
    ref = ReferenceGenerator(3, timeout=10.0)
    ref.set_command(command(velocities=False).validate(JOINTS), now=0.0)
    q, v, tau = ref.reference(0.25)  # halfway between rows 0 and 1 (step 3 per row)
    np.testing.assert_allclose(q, [1.5, 2.5, 3.5])
    np.testing.assert_allclose(v, 6.0)  # 3 rad over 0.5 s
    np.testing.assert_allclose(tau, 2.0)


def test_hold_last_point_with_zero_velocity_after_the_end():
    ref = ReferenceGenerator(3, timeout=10.0)
    cmd = command()
    ref.set_command(cmd.validate(JOINTS), now=0.0)
    q, v, tau = ref.reference(1.5)
    np.testing.assert_array_equal(q, cmd.positions[-1])
    np.testing.assert_array_equal(v, 0.0)
    np.testing.assert_array_equal(tau, cmd.efforts[-1])
    assert ref.holding


def test_stale_command_freezes_where_the_reference_was():
    ref = ReferenceGenerator(3, timeout=0.25)
    ref.set_command(command(velocities=False).validate(JOINTS), now=0.0)
    q, v, _ = ref.reference(0.6)
    np.testing.assert_allclose(q, [1.5, 2.5, 3.5])  # the reference at 0.25 s
    np.testing.assert_array_equal(v, 0.0)
    assert ref.holding


def test_a_command_cut_short_as_stale_is_counted_and_a_short_one_is_not():
    """A 1 s trajectory with a 0.25 s timeout stopped at a quarter without a word (an
    auditor's 'this posture in 2 s', sent once)."""
    ref = ReferenceGenerator(3, timeout=0.25)
    ref.set_command(command(times=(0.0, 0.1, 0.2)).validate(JOINTS), now=0.0)
    ref.reference(0.5)  # ran out: held its last point, nothing cut
    assert ref.holding and ref.stale_cuts == 0 and ref.last_cut is None
    ref.set_command(command(t0=1.0).validate(JOINTS), now=1.0)
    ref.reference(1.3)
    assert ref.holding and ref.stale_cuts == 1
    assert ref.last_cut == pytest.approx((0.25, 1.0))


def test_a_first_point_further_ahead_than_the_timeout_is_refused():
    """Accepted (max_stamp_offset 1 s), a point 0.8 s ahead with a 0.5 s timeout was frozen
    on the way, never reached."""
    ref = ReferenceGenerator(3, timeout=0.5)
    ref.hold(np.zeros(3), np.zeros(3))
    ahead = JointTrajectoryCommand(JOINTS, 0.8, [0.0], np.array([[0.0, 0.2, 0.0]]))
    with pytest.raises(ValueError, match=r"0.800 s ahead, beyond trajectory_timeout \(0.5 s\)"):
        ref.set_command(ahead.validate(JOINTS), now=0.0)
    assert ref.holding
    ref.set_command(ahead.validate(JOINTS), now=0.4)  # 0.4 s ahead: reached
    np.testing.assert_allclose(ref.reference(0.8)[0], [0.0, 0.2, 0.0])


def test_future_first_point_starts_from_the_current_reference():
    ref = ReferenceGenerator(3, timeout=10.0)
    ref.hold(np.zeros(3), np.zeros(3))
    ref.set_command(command(times=(1.0, 2.0), velocities=False).validate(JOINTS), now=0.0)
    np.testing.assert_allclose(ref.reference(0.0)[0], 0.0)
    np.testing.assert_allclose(ref.reference(0.5)[0], [0.0, 0.5, 1.0])  # halfway to row 0



def test_a_future_first_point_out_of_reach_from_the_reference_is_refused():
    """validate() checks the points' own segments; the one from the current reference to
    a future first point was not checked: one point 1.5 ms ahead and 0.8 rad away drove
    solo12's joints at 100 rad/s (20x the torque of the same step sent as 'now')."""
    ref = ReferenceGenerator(3, timeout=10.0)
    ref.hold(np.zeros(3), np.zeros(3))
    far = JointTrajectoryCommand(JOINTS, 0.0, [0.0015], np.array([[0.0, 0.8, 0.0]]))
    with pytest.raises(ValueError, match=r"0.0015 s ahead, asks joint 1 to move 0.8 .*533"):
        ref.set_command(far.validate(JOINTS), now=0.0)
    assert ref.holding  # nothing changed
    near = JointTrajectoryCommand(JOINTS, 0.0, [0.02], np.array([[0.0, 0.8, 0.0]]))
    ref.set_command(near.validate(JOINTS), now=0.0)  # 40 rad/s: a step, not a launch
    assert not ref.holding

@pytest.mark.parametrize("field, value", [("positions", 1e308), ("velocities", -1e300),
                                          ("efforts", 1e12)])
def test_finite_but_absurd_values_are_refused(field, value):
    # 1e308 positions overflowed in the interpolation: the simulated state went NaN for good
    cmd = command()
    getattr(cmd, field)[1, 2] = value
    with pytest.raises(ValueError, match=rf"{field} beyond the plausible .*\(1, 2\)"):
        cmd.validate(JOINTS)
