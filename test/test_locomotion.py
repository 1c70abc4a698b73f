"""Gaits, the stop/start scheduler and the walking problem's consistency."""

import math

import numpy as np
import pytest

from horizon_mpc.locomotion import make_gait
from horizon_mpc.locomotion.gaits import swing_height_profile
from horizon_mpc.locomotion.pose_reference import base_yaw, wrap_angle
from horizon_mpc.mpc.schedule import GaitScheduler


def test_trot_moves_diagonal_pairs_together_half_a_period_apart():
    g = make_gait("trot", step_duration=0.3)
    s = g.schedule(0.0, 60, 0.01)
    fl, fr, hl, hr = s.stance
    np.testing.assert_array_equal(fl, hr)
    np.testing.assert_array_equal(fr, hl)
    assert not np.any(fl & fr & ~(np.isclose(s.swing_progress[0], 0)))  # never both front up
    assert g.period == pytest.approx(0.6)
    assert np.mean(fl) == pytest.approx(0.5, abs=0.05)


def test_walk_lifts_one_foot_at_a_time():
    s = make_gait("walk", step_duration=0.25).schedule(0.0, 200, 0.005)
    assert np.max((~s.stance).sum(axis=0)) == 1
    assert np.all(s.count_swings() >= 1)


def test_swing_profile_reaches_the_step_height_with_zero_end_velocity():
    s = np.linspace(0, 1, 101)
    z = swing_height_profile(s, 0.08)
    assert z.max() == pytest.approx(0.08)
    assert z[0] == 0 and z[-1] == 0
    assert abs(z[1] - z[0]) < 2e-4 and abs(z[-1] - z[-2]) < 2e-4  # O(h^2): zero slope


def test_unknown_gait_names_the_valid_ones():
    with pytest.raises(ValueError, match="trot"):
        make_gait("gallop")


def test_scheduler_stands_until_commanded_and_finishes_swings_after_stop():
    sch = GaitScheduler(make_gait("trot", step_duration=0.3))
    assert sch.schedule(0.0, 20, 0.02).stance.all()
    sch.command(0.5, moving=True)
    moving = sch.schedule(0.5, 40, 0.02)
    assert not moving.stance.all()
    sch.command(1.0, moving=False)  # stop while two feet swing
    s = sch.schedule(1.0, 40, 0.02)
    # feet that were swinging at the stop finish their swing, then everything stays down
    t = 1.0 + 0.02 * np.arange(41)
    assert s.stance[:, t > 1.0 + 0.3 + 1e-9].all()
    sch.command(1.0 + 0.31, moving=False)
    assert not sch.walking


@pytest.mark.slow
def test_walking_problem_converges_to_a_dynamically_consistent_trot():
    """A full trot horizon solved by the ILQR: feasible, base wrench zero, feet fixed in stance."""
    import pinocchio as pin

    from horizon_mpc.mpc import WalkingMpc
    from horizon_mpc.posture import standing_configuration

    mpc = WalkingMpc("go2")
    _, q0 = standing_configuration(mpc.cfg)
    mpc.start(q0, np.zeros(mpc.model.nv), 0.0)
    mpc.scheduler.command(0.0, True)
    mpc.cmd[:] = [0.3, 0.0, 0.0]
    mpc._set_references(0.0)
    mpc.solver.set_option("rti", False)
    mpc.solver.set_option("max_iter", 60)
    assert mpc.solver.solve(), mpc.solver.stats.status
    assert mpc.solver.stats.constraint_violation < 1e-5
    plan = mpc._plan(0.0)
    # the plan's own inverse dynamics: base wrench ~ 0 (under-actuation honoured)
    assert np.max(np.abs(plan.tau[:6])) < 1e-4
    # Pinocchio's numeric dynamics reproduce the plan: rnea with the plan's forces
    pm = mpc.model.pin_model
    data = pm.createData()
    for k in range(0, plan.a.shape[1], 7):
        fext = pin.StdVec_Force()
        for _ in range(pm.njoints):
            fext.append(pin.Force.Zero())
        pin.framesForwardKinematics(pm, data, plan.q[:, k])
        for i, foot in enumerate(mpc.wp.feet):
            fid = pm.getFrameId(foot)
            jid = pm.frames[fid].parentJoint
            f_world = plan.f[3 * i:3 * i + 3, k]
            oMf = data.oMf[fid]
            oMj = data.oMi[jid]
            # point force at the foot, in the joint frame
            f_local = oMj.rotation.T @ f_world
            p_local = oMj.rotation.T @ (oMf.translation - oMj.translation)
            fext[jid] += pin.Force(f_local, np.cross(p_local, f_local))
        tau = pin.rnea(pm, data, plan.q[:, k], plan.v[:, k], plan.a[:, k], fext)
        np.testing.assert_allclose(tau, plan.tau[:, k], atol=1e-6)
    # swing feet carry no force; stance feet stay inside the friction cone
    mu = mpc.cfg.friction
    for i in range(len(mpc.wp.feet)):
        f = plan.f[3 * i:3 * i + 3]
        swing = ~plan.stance[i, :-1]
        assert np.max(np.abs(f[:, swing]), initial=0) < 1e-5
        st = plan.stance[i, :-1]
        assert np.all(f[2, st] >= -1e-5)
        assert np.all(np.abs(f[0, st]) <= mu * f[2, st] + 1e-5)
    # stance feet roll without slipping: the contact point p_foot - r e_z is at rest
    r = mpc.cfg.foot_radius
    assert r > 0.0  # go2's config declares its sphere feet
    for k in range(1, plan.a.shape[1]):
        pin.forwardKinematics(pm, data, plan.q[:, k], plan.v[:, k])
        pin.updateFramePlacements(pm, data)
        for i, foot in enumerate(mpc.wp.feet):
            if plan.stance[i, k]:
                vel = pin.getFrameVelocity(pm, data, pm.getFrameId(foot),
                                           pin.LOCAL_WORLD_ALIGNED)
                contact = vel.linear + np.cross(vel.angular, [0.0, 0.0, -r])
                assert np.linalg.norm(contact) < 1e-5, (k, foot, contact)
    # the plan moves forward
    assert plan.q[0, -1] > 0.05


def test_foot_radius_must_be_a_non_negative_number(tmp_path):
    from horizon_mpc.config import load_robot_config

    path = tmp_path / "bot.yaml"
    path.write_text("robot: go2\nfeet: [FL_foot]\nfoot_radius: -0.01\n")
    with pytest.raises(ValueError, match="foot_radius"):
        load_robot_config(path)
    path.write_text("robot: go2\nfeet: [FL_foot]\n")
    assert load_robot_config(path).foot_radius == 0.0


# ---------------------------------------------------------------------- the MPC's tick path
@pytest.fixture(scope="module")
def walking_mpc():
    from horizon_mpc.mpc import WalkingMpc

    return WalkingMpc("go2")


def _perfect_model_ticks(mpc, commands):
    """Tick ``mpc`` from standing with the state of its own plan's node 1 (a perfect model);
    yields each plan after its tick."""
    from horizon_mpc.posture import standing_configuration

    _, q0 = standing_configuration(mpc.cfg)
    mpc.t_last = None
    plan = mpc.start(q0, np.zeros(mpc.model.nv), 0.0)
    dt = mpc.settings.dt
    for k, cmd in enumerate(commands, start=1):
        plan = mpc.update(k * dt, plan.q[:, 1], plan.v[:, 1], np.asarray(cmd, float))
        yield plan



def test_a_gait_change_while_walking_ramps_the_command_down_and_drops_the_pose_lag(
        walking_mpc):
    """walk -> trot: the walk tracks ~75 % of its command, its pose lag grew to pose_leash,
    the change stopped the walk with the ramped command still at 0.2 m/s, and the trot's
    limits released command and lag at once: go2 lunged to 0.8 m/s for 0.3 (lockstep)
    and fell in real time."""
    mpc = walking_mpc
    ticks = _perfect_model_ticks(mpc, [(0, 0, 0)] * 3 + [(0.3, 0, 0)] * 400)
    for _ in range(30):
        next(ticks)
    assert mpc.scheduler.walking and mpc.cmd[0] == pytest.approx(0.3)
    mpc.pose_ref[0] += 0.3  # a lag as a walk leaves it
    lagging = mpc.pose_ref.copy()
    try:
        mpc.set_gait("trot")  # the gait it walks (a ros2 param set of the same value)
        np.testing.assert_array_equal(mpc.pose_ref, lagging)
        mpc.set_gait("walk")
        assert mpc.pose_ref[:2] == pytest.approx(mpc._pose_expected[:2])
        cmds = []
        while mpc.scheduler.pending is not None:
            next(ticks)
            cmds.append(mpc.cmd[0])
        # down at the acceleration limit (1 m/s^2: 0.02 m/s per 20 ms tick) while the
        # swings end, then up again with the new gait
        assert cmds == pytest.approx([max(0.3 - 0.02 * k, 0.0)
                                      for k in range(1, len(cmds) + 1)])
        next(ticks)
        assert mpc.scheduler.gait.name == "walk" and mpc.cmd[0] > cmds[-1]
    finally:  # the module's MPC: standing, trot, for the tests after this one
        mpc.scheduler.reset(0.0)
        mpc.set_gait("trot", duty_factor=None)

def _contact_masks(contacts):
    return {f"{kind}/{foot}": term.active
            for kind in ("velocity", "friction", "zero_force", "clearance")
            for foot, term in getattr(contacts, kind).items()}


def test_the_ticks_contact_terms_are_what_set_schedule_makes_of_the_plan_stance(walking_mpc):
    """The tick skips unchanged node sets: on every tick (standing, starting, trotting,
    stopping) the problem's contact terms and swing heights must be exactly what a full
    ``set_schedule`` of that tick's stance gives."""
    mpc = walking_mpc
    wp = mpc.wp
    commands = [(0, 0, 0)] * 5 + [(0.3, 0, 0)] * 25 + [(0, 0, 0)] * 25
    swinging = []
    for plan in _perfect_model_ticks(mpc, commands):
        swinging.append(not plan.stance.all())
        masks, swing_z = _contact_masks(wp.contacts), wp.contacts.swing_z.values
        wp.contacts.set_schedule(plan.stance, swing_z)  # the unconditional path
        again = _contact_masks(wp.contacts)
        for name, mask in masks.items():
            np.testing.assert_array_equal(mask, again[name], err_msg=name)
        # and the stance column k is what the term masks say (k < N for the stage terms)
        foot = wp.feet[0]
        np.testing.assert_array_equal(masks[f"velocity/{foot}"], plan.stance[0])
        np.testing.assert_array_equal(masks[f"zero_force/{foot}"][:-1], ~plan.stance[0, :-1])
    # the sample covers standing (memo hits), trotting (new stance every tick), stopping
    assert not any(swinging[:5]) and all(swinging[10:30]) and not swinging[-1]


def test_the_plans_tau_head_is_the_full_horizon_inverse_dynamics_bit_for_bit(walking_mpc):
    plan = next(_perfect_model_ticks(walking_mpc, [(0.3, 0.0, 0.0)]))
    head = plan.tau_head(6)
    assert head.shape == (walking_mpc.model.nv, 6)
    full = walking_mpc.inverse_dynamics(plan.q[:, :-1], plan.v[:, :-1], plan.a, plan.f)
    np.testing.assert_array_equal(head, full[:, :6])  # same compiled code per node
    np.testing.assert_array_equal(plan.tau, full)


def test_the_plans_stats_are_the_solver_stats_without_the_history(walking_mpc):
    plan = next(_perfect_model_ticks(walking_mpc, [(0.0, 0.0, 0.0)]))
    expected = walking_mpc.solver.stats.as_dict()
    expected.pop("history")
    assert plan.stats == expected


def test_prepared_ticks_are_feedback_steps_that_trot_a_perfect_model(walking_mpc):
    """prepare() after each tick, then the tick at the prepared time: every tick is the
    feedback step alone, the plans stay consistent and the base moves with the command."""
    import pinocchio as pin

    from horizon_mpc.posture import standing_configuration

    mpc = walking_mpc
    _, q0 = standing_configuration(mpc.cfg)
    mpc.t_last = None
    plan = mpc.start(q0, np.zeros(mpc.model.nv), 0.0)
    dt, cmd = mpc.settings.dt, np.array([0.3, 0.0, 0.0])
    misses, violations, head = mpc.prepare_misses, [], []
    sv = mpc.solver
    for k in range(1, 41):
        assert mpc.prepare(k * dt, cmd)
        plan = mpc.update(k * dt, plan.q[:, 1], plan.v[:, 1], cmd)
        assert sv.stats.status == "feedback" and plan.t0 == k * dt
        assert plan.stats["iterations"] == mpc.iterations
        violations.append(plan.stats["constraint_violation"])
        # defects and projected equalities on the first nodes (those a tick applies)
        ev = sv._evaluate(sv.X, sv.U)
        eq = np.where(sv._eq_rows, ev["c"][:, :sv.model.nc_con] - sv._layout.b, 0.0)
        head.append(max(np.abs(eq[:5]).max(), np.abs(ev["gap"][:5]).max()))
    assert mpc.prepare_misses == misses
    # the start of the gait (new swing constraints; its first lift-offs enter the horizon's
    # last nodes up to tick ~12 with 24 nodes) is not feasible at once; after it the ticks
    # stay within what whole ticks reach (<= 0.86 at lift-offs with one iteration per tick,
    # at the horizon's last nodes, new to the problem at each tick); the nodes a tick
    # applies are consistent
    assert max(violations[15:]) < 1.0 and np.median(violations) < 0.2
    # (median head residual: 1.5e-3 with 24 nodes, 4e-4 with 30, 8e-5 with 40: a longer
    # horizon keeps its first nodes closer to feasible between ticks)
    assert np.median(head) < 3e-3 and max(head[10:]) < 0.1
    assert plan.q[0, 0] - q0[0] > 0.15  # 0.8 s, with the 1 m/s^2 ramp to 0.3 m/s
    # with max_extrapolation (0 by default: a whole tick), a state stamped 3 ms before the
    # prepared time is predicted to it with the last plan's first acceleration (the one
    # planned for the 3 ms before the prepared time)
    mpc.settings.max_extrapolation = 0.005
    t_next = 41 * dt
    acc = plan.a[:, 0].copy()
    assert mpc.prepare(t_next, cmd)
    q, v = plan.q[:, 1].copy(), plan.v[:, 1].copy()
    plan = mpc.update(t_next - 0.003, q, v, cmd)
    assert plan.t0 == t_next
    # the predicted state is the iteration's fixed node 0 whatever its step length
    x0 = mpc.solver.x_init
    nq = mpc.model.nq
    np.testing.assert_allclose(
        x0[:nq], pin.integrate(mpc.model.pin_model, q, 0.003 * (v + 0.0015 * acc)),
        atol=1e-9)
    np.testing.assert_allclose(x0[nq:], v + 0.003 * acc, atol=1e-9)
    # 10 ms away (beyond max_extrapolation): a whole tick from the state's own time
    assert mpc.prepare(t_next + dt, cmd)
    plan = mpc.update(t_next + dt + 0.010, plan.q[:, 1], plan.v[:, 1], cmd)
    assert plan.t0 == t_next + dt + 0.010 and mpc.prepare_misses == misses + 1
    assert mpc.solver.stats.status == "rti"
    mpc.settings.max_extrapolation = 0.0  # the fixture is shared


def test_a_state_at_the_prepared_time_up_to_round_off_gets_the_feedback_step(walking_mpc):
    """prepare(t + dt) in floating point is 1e-17 s off a state stamped (k + 1) dt: the
    same tick time (SAME_TIME), the plan at the prepared time; a state 1.5 ms off (a robot's
    driver stamps when it measures) gets the prepared step as measured, the plan at its own
    time (feedback_tolerance); 3 ms off, a whole tick (max_extrapolation 0)."""
    from horizon_mpc.mpc.controller import SAME_TIME
    from horizon_mpc.posture import standing_configuration

    mpc = walking_mpc
    assert mpc.settings.max_extrapolation == 0.0
    _, q0 = standing_configuration(mpc.cfg)
    mpc.t_last = None
    plan = mpc.start(q0, np.zeros(mpc.model.nv), 0.1)
    misses = mpc.prepare_misses
    t_next = 0.1 + mpc.settings.dt  # 0.12000000000000001
    assert t_next != 0.12 and abs(t_next - 0.12) < SAME_TIME
    assert mpc.prepare(t_next, None)
    plan = mpc.update(0.12, plan.q[:, 1], plan.v[:, 1], None)
    assert mpc.solver.stats.status == "feedback" and mpc.prepare_misses == misses
    assert plan.t0 == 0.12  # the state's own stamp
    assert mpc.settings.feedback_tolerance == 0.002
    assert mpc.prepare(0.14, None)
    q, v = plan.q[:, 1].copy(), plan.v[:, 1].copy()
    plan = mpc.update(0.1415, q, v, None)
    assert mpc.solver.stats.status == "feedback" and mpc.prepare_misses == misses
    assert plan.t0 == 0.1415
    np.testing.assert_array_equal(mpc.solver.x_init, np.concatenate((q, v)))  # as measured
    assert mpc.prepare(0.16, None)
    plan = mpc.update(0.163, plan.q[:, 1], plan.v[:, 1], None)
    assert mpc.solver.stats.status == "rti" and mpc.prepare_misses == misses + 1
    assert plan.t0 == 0.163


def test_the_dynamics_pattern_covers_every_nonzero_of_the_walking_jacobians(walking_mpc):
    """The compiled backward pass reads A and B only on the stage model's structural pattern:
    every entry the quadratisation produces outside it must be exactly zero (go2: 5 %)."""
    from horizon_mpc.solvers.ilqr import riccati_c

    solver = walking_mpc.solver
    next(_perfect_model_ticks(walking_mpc, [(0.3, 0.0, 0.0)]))
    pattern = solver.model.ab_pattern
    assert pattern.mean() < 0.1
    solver._gather()
    q = solver._quadratise(solver.X, solver.U, solver._evaluate(solver.X, solver.U))
    outside = np.concatenate([q["A"], q["B"]], axis=2)[:, ~pattern]
    assert outside.size and not outside.any()
    if riccati_c.available():
        assert solver._backward.keywords["pattern"].mask.sum() == pattern.sum()


def test_the_pose_reference_stays_within_the_leash_of_the_measured_pose(walking_mpc):
    """The integral action's reference runs ahead of a robot that lags, at most
    settings.pose_leash (m) and yaw_leash (rad) away (no wind-up)."""
    mpc = walking_mpc
    saved = (mpc.pose_ref.copy(), mpc.cmd.copy(), mpc.settings.pose_leash)
    try:
        q = mpc.wp.q_nominal.copy()
        mpc.pose_ref = np.zeros(3)
        mpc.cmd[:] = [-0.3, 0.0, 0.5]
        for _ in range(200):  # 4 s of commanded motion, the robot not moving at all
            mpc._advance_pose_ref(q, 0.02)
        assert np.hypot(*(mpc.pose_ref[:2] - q[:2])) == pytest.approx(mpc.settings.pose_leash)
        assert abs(mpc.pose_ref[2]) == pytest.approx(mpc.settings.yaw_leash)
        mpc.settings.pose_leash = 0.1
        mpc._advance_pose_ref(q, 0.02)
        assert np.hypot(*(mpc.pose_ref[:2] - q[:2])) == pytest.approx(0.1)
    finally:
        mpc.pose_ref, mpc.cmd[:], mpc.settings.pose_leash = saved[0], saved[1], saved[2]


@pytest.mark.parametrize("jump", ["pose", "small pose", "yaw", "time"])
def test_a_state_discontinuous_with_the_plan_restarts_the_controller(walking_mpc, jump):
    """A simulator/estimator reset or an odometry glitch: the pose reference and the plan
    stayed anchored to the old pose, and the robot walked back towards it (0.42 m/s for a
    0.3 command after a simulator reset). Also a reset 0.13-0.27 m from the start pose
    (below the 0.3 m pose_jump of sessions 13-25): the robot walked that distance again,
    0.41 m/s for 0.3 (a QA finding)."""
    mpc = walking_mpc
    *_, plan = _perfect_model_ticks(mpc, [(0.3, 0.0, 0.0)] * 30)
    restarts = mpc.restarts
    q, v = plan.q[:, 1].copy(), plan.v[:, 1].copy()
    t = mpc.t_last + mpc.settings.dt
    if jump == "pose":
        q[0] += 1.0  # odometry 1 m ahead of where the plan put the robot
    elif jump == "small pose":
        q[0] -= 0.15  # a simulator reset 0.15 m back
    elif jump == "yaw":  # 0.2 rad about z
        c, s = np.cos(0.1), np.sin(0.1)
        q[3:7] = [c * q[3] - s * q[4], s * q[3] + c * q[4], c * q[5] + s * q[6],
                  c * q[6] - s * q[5]]
    else:
        t = 0.02  # time back to the start, as after a simulator reset
    after = mpc.update(t, q, v, np.array([0.3, 0.0, 0.0]))
    assert mpc.restarts == restarts + 1
    assert after.q[0, 0] == pytest.approx(q[0])
    np.testing.assert_allclose(mpc.pose_ref[:2], q[:2])  # re-anchored at the measured pose
    # ordinary motion does not restart
    plan = mpc.update(t + mpc.settings.dt, after.q[:, 1], after.v[:, 1], np.zeros(3))
    assert mpc.restarts == restarts + 1


def test_a_command_is_limited_per_axis_then_to_the_combined_norm():
    from horizon_mpc.locomotion.command import limit_command

    lims = [0.6, 0.5, 0.8]
    assert limit_command([0.3, -0.2, 0.1], lims) == (0.3, -0.2, 0.1)  # within: unchanged
    assert limit_command([0.6, -0.5, 0.0], lims) == (0.6, -0.5, 0.0)  # two at their limits
    assert limit_command([2.0, 0.0, -0.1], lims) == (0.6, 0.0, -0.1)  # clamped per axis
    out = np.array(limit_command([0.6, -0.5, -0.8], lims))  # all three: scaled to sqrt(2)
    np.testing.assert_allclose(out, np.array([0.6, -0.5, -0.8]) * math.sqrt(2 / 3))
    out = np.array(limit_command([9.0, 9.0, -9.0], lims, max_norm=1.0))  # per axis, then norm
    np.testing.assert_allclose(np.linalg.norm(out / lims), 1.0)
    np.testing.assert_allclose(out / np.array(lims), np.array([1, 1, -1]) / math.sqrt(3))
    assert limit_command([0.6, -0.5, -0.8], lims, max_norm=2.0) == (0.6, -0.5, -0.8)
    assert limit_command([0.4, 0.2, 0.3], [0.0, 0.5, 0.8]) == (0.0, 0.2, 0.3)  # a zero limit


def test_a_new_step_duration_while_trotting_keeps_the_cycles_phase():
    """Swapping the gait under a running phase put feet 5 cm up into stance and lifted the
    standing pair (go2 fell 0.2 s after step_duration 0.3 -> 0.5)."""
    sch = GaitScheduler(make_gait("trot", step_duration=0.3))
    sch.command(0.0, moving=True)
    before = sch.schedule(1.13, 0, 0.02)
    sch.set_gait(make_gait("trot", step_duration=0.5), 1.13)
    after = sch.schedule(1.13, 0, 0.02)
    np.testing.assert_array_equal(after.stance, before.stance)
    np.testing.assert_allclose(after.swing_progress, before.swing_progress, atol=1e-12)
    assert sch.gait.step_duration == 0.5 and sch.pending is None


def test_stepping_in_place_asked_during_a_stop_starts_once_the_stop_ends():
    """stand_when_idle off while a stop's swings were ending: the stop was never cleared,
    every later swing stayed stance for good while 'walking' (go2 pushed along on planted
    feet at 0.3 m/s, then fell)."""
    sch = GaitScheduler(make_gait("trot", step_duration=0.3, step_height=0.07))
    t = 0.0
    for _ in range(100):
        sch.command(t, True)
        t += 0.02
    sch.command(t, False)  # the stop: the swings in progress end
    t += 0.1
    sch.stand_when_idle = False
    sch.command(t, False)
    assert sch.t_stop is not None  # still ending them
    for _ in range(50):
        sch.command(t, False)
        t += 0.02
    assert sch.t_stop is None and sch.walking
    assert not sch.schedule(t, 24, 0.02).stance.all()  # stepping in place
    for _ in range(50):
        sch.command(t, True)
        t += 0.02
    assert not sch.schedule(t, 24, 0.02).stance.all() and sch.t_stop is None


def test_another_gait_while_walking_starts_once_the_swings_in_progress_end():
    sch = GaitScheduler(make_gait("trot", step_duration=0.3))
    sch.command(0.0, moving=True)
    t = 1.13
    swinging = ~sch.schedule(t, 0, 0.02).stance[:, 0]
    assert swinging.any()
    sch.set_gait(make_gait("walk", step_duration=0.3), t)  # duty 0.75: the walk's own
    assert sch.gait.name == "trot" and sch.pending.duty_factor == 0.75
    s = sch.schedule(t, 30, 0.02)
    np.testing.assert_array_equal(~s.stance[:, 0], swinging)  # nothing jumps
    assert s.stance[:, 0.02 * np.arange(31) > 0.3 + 1e-9].all()  # then the feet stay down
    sch.command(t + 0.1, moving=True)
    assert sch.gait.name == "trot"  # still ending its swings
    sch.command(t + 0.31, moving=True)
    assert sch.gait.name == "walk" and sch.pending is None and sch.t_start == t + 0.31


def test_the_stand_gait_keeps_the_feet_down_and_leaves_no_walk_behind():
    """stand -> trot with a zero command lifted two feet at once (the stand gait had
    started a 'walk' in the scheduler)."""
    sch = GaitScheduler(make_gait("stand"))
    sch.command(0.5, moving=True)
    assert sch.schedule(0.5, 10, 0.02).stance.all() and not sch.walking
    sch.set_gait(make_gait("trot"), 0.6)
    sch.command(0.6, moving=False)
    assert sch.schedule(0.6, 10, 0.02).stance.all()


def test_gait_values_out_of_range_are_refused():
    for kwargs, match in (({"step_duration": float("nan")}, "step_duration"),
                          ({"step_height": -0.05}, "step_height"),
                          ({"step_height": float("inf")}, "step_height"),
                          ({"duty_factor": 1.5}, "duty factor")):
        with pytest.raises(ValueError, match=match):
            make_gait("trot", **kwargs)
    assert make_gait("walk").duty_factor == 0.75  # the gait's own by default


def test_set_gait_checks_before_it_changes_anything(walking_mpc):
    """A refused duty factor 1.5 stayed in the settings and made every later set_gait
    fail; step_duration 0 was ignored (falsy)."""
    g = walking_mpc.settings.gait
    before = (g.name, g.step_duration, g.duty_factor, g.step_height)
    for kwargs in ({"duty_factor": 1.5}, {"step_duration": 0.0}, {"step_height": -0.05}):
        with pytest.raises(ValueError):
            walking_mpc.set_gait("trot", **kwargs)
        assert (g.name, g.step_duration, g.duty_factor, g.step_height) == before
    with pytest.raises(ValueError, match="unknown gait"):
        walking_mpc.set_gait("foo")
    assert walking_mpc.scheduler.gait.name == g.name == before[0]
    walking_mpc.set_gait("walk")
    assert walking_mpc.scheduler.gait.duty_factor == 0.75 and g.duty_factor is None
    walking_mpc.set_gait(*before[:2], step_height=before[3], duty_factor=before[2])


def test_a_bad_state_is_refused_before_the_controller_changes(walking_mpc):
    """One state with an infinite joint (or a command of the wrong length) raised from deep
    inside after the pose reference had moved: it stayed NaN and the go2 never walked
    again; now it is refused first, and the next good state is planned from normally."""
    from horizon_mpc.posture import standing_configuration

    _, q = standing_configuration(walking_mpc.cfg)
    v = np.zeros(walking_mpc.model.nv)
    walking_mpc.start(q, v, 0.0)
    pose = walking_mpc.pose_ref.copy()
    bad_q = q.copy()
    bad_q[8] = np.inf
    for args, match in (((0.02, bad_q, v), r"not finite at q\[8\]"),
                        ((float("nan"), q, v), "time must be a finite number"),
                        ((0.02, q[:-1], v), "shapes"),
                        ((0.02, q, v, [0.1, 0.0]), "3 numbers"),
                        ((0.02, np.r_[q[:3], np.nan, 0.0, 0.0, 1.0, q[7:]], v),
                         r"not finite at q\[3\]")):  # was taken as the identity
        with pytest.raises(ValueError, match=match):
            walking_mpc.update(*args)
        np.testing.assert_array_equal(walking_mpc.pose_ref, pose)
    plan = walking_mpc.update(0.02, q, v, np.array([0.2, 0.0, 0.0]))
    assert np.isfinite(plan.q).all() and walking_mpc.failures == 0
    np.testing.assert_allclose(walking_mpc.pose_ref[:2], pose[:2], atol=0.01)


def test_the_stand_gait_does_not_walk_a_command(walking_mpc):
    """With gait stand the base moved 13 cm and yawed 34 deg on planted feet."""
    from horizon_mpc.posture import standing_configuration

    _, q = standing_configuration(walking_mpc.cfg)
    walking_mpc.start(q, np.zeros(walking_mpc.model.nv), 0.0)
    walking_mpc.set_gait("stand")
    try:
        for k in range(1, 6):
            walking_mpc.update(0.02 * k, q, np.zeros(walking_mpc.model.nv), [0.3, 0.0, 0.5])
        assert np.all(walking_mpc.cmd == 0.0)
    finally:
        walking_mpc.set_gait("trot", duty_factor=None)


@pytest.mark.parametrize("change", ["stand", "shorter_steps_while_stopping"])
def test_no_gait_change_puts_a_swinging_foot_down(change):
    """stand while trotting, or a new step duration while a stop finishes the swings,
    put feet 4-6 cm up into stance."""
    sch = GaitScheduler(make_gait("trot", step_duration=0.3))
    sch.command(0.0, moving=True)
    t = 0.8
    if change == "stand":
        new = make_gait("stand")
    else:
        sch.command(0.75, moving=False)  # stopping
        new = make_gait("trot", step_duration=0.15)
    before = sch.schedule(t, 0, 0.02)
    sch.set_gait(new, t)
    after = sch.schedule(t, 0, 0.02)
    np.testing.assert_array_equal(after.stance, before.stance)
    np.testing.assert_allclose(after.swing_progress, before.swing_progress)
    sch.command(t + 0.31, moving=True)
    assert sch.gait is new and sch.pending is None


def test_slower_gait_cycles_get_a_share_of_the_velocity_limits():
    """The limits of a robot config are its gait's (trot): the walk (a cycle twice as long at
    one step duration, a foot down 0.75 of it: three times the trot's stance) fell at them
    (anymal_c at 0.4-0.5 m/s forward, a1 at 0.4 m/s sideways) and gets a third of them."""
    from horizon_mpc.locomotion import speed_scale

    trot = make_gait("trot", 0.3)
    assert speed_scale(make_gait("walk", 0.3), trot) == pytest.approx(1 / 3)
    assert speed_scale(make_gait("walk", 0.3, duty_factor=0.5), trot) == 1.0  # the trot's stance
    assert speed_scale(make_gait("walk", 0.3, duty_factor=0.6), trot) == pytest.approx(2 / 3)
    assert speed_scale(make_gait("trot", 0.4), trot) == pytest.approx(0.75)
    assert speed_scale(make_gait("trot", 0.2), trot) == 1.0  # never above the config's
    assert speed_scale(make_gait("pace", 0.3), trot) == 1.0
    assert speed_scale(make_gait("stand"), trot) == 1.0
    assert speed_scale(make_gait("walk", 0.3), make_gait("walk", 0.3)) == 1.0


def test_the_controller_and_the_closed_loop_limit_commands_by_the_gait_walked():
    from horizon_mpc.closed_loop import command_limits
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.mpc import WalkingMpc

    mpc = WalkingMpc("solo12")
    lim = list(mpc.settings.max_velocity)
    assert mpc.velocity_limits == pytest.approx(lim)
    assert mpc.scheduler.gait.duty_factor == 0.5
    mpc.set_gait("walk")  # standing: taken at once
    assert mpc.scheduler.gait.duty_factor == 0.75  # solo12's config no longer forces 0.5
    assert mpc.velocity_limits == pytest.approx([x / 3 for x in lim])
    mpc._ramp_command(np.array([10.0, 0.0, -10.0]), 100.0)  # long enough to reach it
    assert mpc.cmd.tolist() == pytest.approx([lim[0] / 3, 0.0, -lim[2] / 3])
    # walking, a change to the trot waits for the walk's swings: the walk's limits hold
    mpc.scheduler.command(0.0, True)
    mpc.set_gait("trot")
    assert mpc.scheduler.pending is not None
    assert mpc.velocity_limits == pytest.approx([x / 3 for x in lim])
    mpc.scheduler.command(1.0, True)  # the swings ended: the trot now
    assert mpc.scheduler.pending is None and mpc.velocity_limits == pytest.approx(lim)
    cfg = load_robot_config("solo12")
    assert command_limits(cfg)[0] == pytest.approx(lim)
    assert command_limits(cfg, {"gait": "walk"})[0] == pytest.approx([x / 3 for x in lim])
    assert command_limits(cfg, {"gait": "walk", "duty_factor": 0.5})[0] == pytest.approx(lim)
    assert command_limits(cfg, {"gait": "walk", "duty_factor": 0.0})[0] == pytest.approx(
        [x / 3 for x in lim])  # 0: the gait's own


def test_the_velocity_reference_closes_the_pose_error_over_the_horizon_while_walking(
        walking_mpc):
    """Walking, the base velocity reference is the command plus the pose error over the
    horizon (base frame), so the velocity cost no longer holds the plan at the bare command
    against the pose cost (go2 walked 0.036 m/s for 0.02 and 0.012-0.024 m/s forward for a
    lateral command, 0.06-0.10 m ahead of its pose reference); standing, the command."""
    mpc = walking_mpc
    ticks = _perfect_model_ticks(mpc, [(0.0, 0.0, 0.0)] + [(0.1, 0.05, 0.0)] * 10)
    next(ticks)
    np.testing.assert_array_equal(mpc.wp.v_ref.values, 0.0)  # standing, zero command
    plan = list(ticks)[-1]
    assert mpc.scheduler.walking
    q = plan.q[:, 1].copy()
    q[0] -= 0.05  # 5 cm behind the plan (and its pose reference)
    mpc.update(mpc.t_last + mpc.settings.dt, q, plan.v[:, 1], np.array([0.1, 0.05, 0.0]))
    horizon = mpc.wp.n_nodes * mpc.settings.dt
    ex, ey = mpc.pose_ref[0] - q[0], mpc.pose_ref[1] - q[1]
    yaw = base_yaw(q)
    c, s = math.cos(yaw), math.sin(yaw)
    expected = [mpc.cmd[0] + (c * ex + s * ey) / horizon, mpc.cmd[1] + (c * ey - s * ex) / horizon,
                0.0, 0.0, 0.0, mpc.cmd[2] + wrap_angle(mpc.pose_ref[2] - yaw) / horizon]
    v_ref = mpc.wp.v_ref.values
    np.testing.assert_allclose(v_ref, np.repeat(np.array(expected)[:, None], v_ref.shape[1], 1),
                               atol=1e-12)
    assert v_ref[0, 0] > mpc.cmd[0] + 0.04 / horizon  # it asks to catch up
    # within the command limits whatever the error
    mpc.pose_ref[0] += 10.0
    mpc._set_references(mpc.t_last)
    assert mpc.wp.v_ref.values[0, 0] <= mpc.velocity_limits[0] + 1e-12


def _stance_widths(mpc, q: np.ndarray) -> np.ndarray:
    """Lateral distance (base frame) between the left and right feet of the front and the
    hind pair (go2 order FL FR RL RR)."""
    import pinocchio as pin

    m = mpc.model.pin_model
    d = m.createData()
    pin.framesForwardKinematics(m, d, q)
    rot = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
    y = [float(rot[:, 1] @ (d.oMf[m.getFrameId(f)].translation - q[:3])) for f in mpc.wp.feet]
    return np.array([y[0] - y[1], y[2] - y[3]])


@pytest.mark.parametrize("foot_lateral", [None, 0.0])
def test_the_walk_keeps_its_feet_apart_by_the_foot_lateral_cost(walking_mpc, foot_lateral):
    """The walk (three feet down, the CoM on an edge of their triangle) landed its swing feet
    under the body rather than sway it, until the hind legs crossed and the robot tipped
    over once stopped (go2, anymal_b, anymal_c in the closed loop). The foot_lateral cost
    keeps each pair apart; without it (weight 0) the plans still cross the hind feet."""
    import dataclasses

    from horizon_mpc.posture import standing_configuration

    mpc = walking_mpc
    weights = mpc.settings.weights
    if foot_lateral is not None:
        mpc.wp.set_weights(dataclasses.replace(weights, foot_lateral=foot_lateral))
    try:
        _, q0 = standing_configuration(mpc.cfg)
        nominal = _stance_widths(mpc, q0)
        ticks = _perfect_model_ticks(mpc, [(0.0, 0.0, 0.0)] + [(-0.1, 0.0, 0.0)] * 200)
        next(ticks)
        mpc.set_gait("walk")  # standing: at once
        widths = np.array([_stance_widths(mpc, plan.q[:, 0]) for plan in ticks])
        assert float(mpc.wp.q.initial_guess[0, 0]) < -0.2  # it walked back
        if foot_lateral is None:
            assert (widths.min(0) > 0.3 * nominal).all(), widths.min(0) / nominal
        else:
            assert widths[:, 1].min() < 0.0  # crossed
    finally:
        mpc.wp.set_weights(weights)
        mpc.set_gait("trot")


def test_a_completed_stop_anchors_the_pose_reference_where_the_robot_stands(walking_mpc):
    """Feet down for good, the pose reference is the measured pose: the lag a walk left in
    it (up to pose_leash) is no place planted feet can take the base to."""
    mpc = walking_mpc
    was_walking, anchored = False, None
    for plan in _perfect_model_ticks(mpc, [(0.3, 0.0, 0.3)] * 60 + [(0.0, 0.0, 0.0)] * 60):
        if was_walking and not mpc.scheduler.walking:
            anchored = (mpc.pose_ref.copy(), plan.q[:, 0].copy())
        was_walking = mpc.scheduler.walking
    assert anchored is not None, "the stop never completed"
    pose_ref, q = anchored
    np.testing.assert_allclose(pose_ref, [q[0], q[1], base_yaw(q)], atol=1e-9)


@pytest.mark.slow
def test_go2_switches_from_walk_to_trot_without_a_lunge():
    """Lockstep direct loop at 0.3 m/s: trot, walk for 2.5 s, trot again. Before the fix
    the peak forward speed (over 0.1 s) after walk -> trot was 0.72 m/s here (0.80 after
    3 s of walk; 0.65 with the pose lag dropped alone); now ~0.5, against ~0.37 when
    starting from standing."""
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.mpc import WalkingMpc
    from horizon_mpc.sim.simulator import Simulator
    from horizon_mpc.sim.trajectory import JointTrajectoryCommand

    cfg = load_robot_config("go2")
    sim, mpc = Simulator(cfg), WalkingMpc(cfg)
    dt = mpc.settings.dt
    h0 = float(sim.state().q[2])
    gaits, plan, after = {2.5: "walk", 5.0: "trot"}, None, []
    while (st := sim.state()).time < 6.5:
        t = st.time
        for when in [w for w in gaits if t >= w - 1e-9]:
            mpc.set_gait(gaits.pop(when))
        cmd = np.array([0.3 if t >= 1.0 else 0.0, 0.0, 0.0])
        plan = mpc.start(st.q, st.v, t) if plan is None else mpc.update(t, st.q, st.v, cmd)
        if t >= 5.0:
            after.append((t, st.q[0], st.q[2]))
        sim.set_trajectory(JointTrajectoryCommand(
            sim.joint_names, t, dt * np.arange(6), plan.q[7:, :6].T, plan.v[6:, :6].T,
            plan.tau_head(6)[6:].T))
        sim.step(round(dt / sim.dt))
    t, x, z = np.array(after).T
    speed = (x[5:] - x[:-5]) / (t[5:] - t[:-5])  # over 0.1 s
    assert speed.max() < 0.6 and z.min() > 0.85 * h0
    assert (x[-1] - x[0]) / (t[-1] - t[0]) == pytest.approx(0.3, abs=0.1)


def test_failed_ticks_are_logged_once_per_burst_and_at_most_every_two_seconds(monkeypatch,
                                                                               caplog):
    """Every other tick failing (hostile odometry) logged 'ILQR failed' 10 times in 2 s:
    bursts closer than FAILURE_LOG_PERIOD are counted into the next line."""
    import logging
    from types import SimpleNamespace

    from horizon_mpc.mpc import controller
    from horizon_mpc.mpc.controller import WalkingMpc

    clock = [100.0]
    monkeypatch.setattr(controller.time, "monotonic", lambda: clock[0])
    good = {"x": np.zeros((2, 3)), "u": np.zeros((1, 2))}
    bad = {"x": np.full((2, 3), np.nan), "u": np.zeros((1, 2))}
    mpc = SimpleNamespace(solver=SimpleNamespace(solution=good, stats=SimpleNamespace(
        constraint_violation=0.0, cost=1.0, status="rti")), divergence_threshold=1e3,
        failures=0, _failure_log=(-math.inf, 0))
    caplog.set_level(logging.WARNING, logger="horizon_mpc.mpc.controller")
    for k in range(20):  # 20 ticks 0.1 s apart, every other one failing: 10 bursts in 2 s
        mpc.solver.solution = bad if k % 2 == 0 else good
        assert WalkingMpc._healthy(mpc) == (k % 2 == 1)
        clock[0] += 0.1
    lines = [r.getMessage() for r in caplog.records if "ILQR failed" in r.getMessage()]
    assert lines == ["ILQR failed (rti): back to the standing warm start"]
    mpc.solver.solution = bad
    clock[0] = 102.5
    WalkingMpc._healthy(mpc)  # 2.5 s after the first line: said, with the bursts between
    lines = [r.getMessage() for r in caplog.records if "ILQR failed" in r.getMessage()]
    assert lines[-1] == ("ILQR failed (rti): back to the standing warm start (9 more bursts "
                         "of failures before it)")
    assert mpc.failures == 1


# --------------------------------------------------------------------------------------------
# session 28 audit of the library API


def test_prepare_for_a_time_before_the_last_tick_is_refused(walking_mpc):
    """It moved the controller's time back: the next update took the gap as elapsed, and
    solo12 ran 0.55 m/s for a 0.2 command."""
    plans = list(_perfect_model_ticks(walking_mpc, [(0.2, 0.0, 0.0)] * 5))
    t = walking_mpc.t_last
    with pytest.raises(ValueError, match="before the last tick's"):
        walking_mpc.prepare(t - 0.5, np.array([0.2, 0.0, 0.0]))
    assert walking_mpc.t_last == t and walking_mpc.prepared_for is None
    assert walking_mpc.prepare(t + walking_mpc.settings.dt, np.array([0.2, 0.0, 0.0]))
    assert plans[-1].t0 == pytest.approx(t)


def test_walking_settings_are_checked_by_key_when_they_are_read():
    """Weights, flags and choices were taken as given and failed at the build naming a cost
    (or nothing: 'could not convert string to float'), a quoted "false" was a true flag."""
    from horizon_mpc.locomotion import MpcSettings

    for data, match in (
            ({"weights": {"swing_height": -5.0}},
             r"'mpc.weights.swing_height' must be a number in \[0, 1e\+09\]"),
            ({"weights": {"force": "x"}}, "'mpc.weights.force' must be a number in"),
            ({"weights": {"posture": float("nan")}}, "'mpc.weights.posture'"),
            ({"weights": {"base_linear_velocity": [1, 2]}},
             r"'mpc.weights.base_linear_velocity' must be 3 numbers in \[0, 1e\+09\]"),
            ({"weights": {"base_linear_velocity": 5.0}}, "must be 3 numbers"),
            ({"stand_when_idle": "false"}, "'mpc.stand_when_idle' must be true or false"),
            ({"torque_limits": 0}, "'mpc.torque_limits' must be true or false"),
            ({"clearance": "bogus"}, r"'mpc.clearance' must be one of \['cost'"),
            ({"inequality": "bogus"}, r"'mpc.inequality' must be one of \['barrier'"),
            ({"gait": {"name": "gallop"}}, r"'mpc.gait.name' must be one of \['stand'"),
            ({"gait": {"name": 3}}, "'mpc.gait.name' must be one of")):
        with pytest.raises(ValueError, match=match):
            MpcSettings.from_dict(data)
    st = MpcSettings.from_dict({"weights": {"base_linear_velocity": [1, 2, 3.5]},
                                "clearance": "none", "inequality": "lagrangian"})
    assert st.weights.base_linear_velocity == [1, 2, 3.5]


def test_gaits_refuse_what_they_cannot_be_and_a_stand_its_duty_factor(walking_mpc):
    """n_feet 0 made a gait of no foot, a text step duration numpy's TypeError, and a
    stand's duty factor 5.0 was stored (the settings were then invalid)."""
    with pytest.raises(ValueError, match="at least one foot"):
        make_gait("trot", n_feet=0)
    with pytest.raises(ValueError, match="step_duration must be a number, got 'a'"):
        make_gait("trot", step_duration="a")
    with pytest.raises(ValueError, match="duty factor must be in"):
        make_gait("stand", duty_factor=5.0)
    assert make_gait("walk", n_feet=6).offsets == (0.0, 0.5, 0.75, 0.25, 0.0, 0.5)
    g = walking_mpc.settings.gait
    before = (g.name, g.duty_factor)
    with pytest.raises(ValueError, match="duty factor"):
        walking_mpc.set_gait("stand", duty_factor=5.0)
    assert (g.name, g.duty_factor) == before
    from horizon_mpc.mpc import WalkingMpc

    with pytest.raises(ValueError, match="whole number >= 1, got 1.7"):
        WalkingMpc("go2", iterations=1.7)


def test_successive_ticks_agree_on_the_contacts_of_the_nodes_they_share():
    """A node on a lift-off or touch-down came out on either side of it from one tick to
    the next by the rounding of its time: 64 of 949 ticks (trot, 0.3 s steps)."""
    for gait in (make_gait("trot", 0.3), make_gait("walk", 0.3), make_gait("trot", 0.35)):
        dt, n = 0.02, 24
        before = None
        flips = 0
        for k in range(400):
            t0 = k * dt
            stance = gait.schedule(t0, n, dt).stance
            if before is not None:
                flips += int(np.any(before[:, 1:] != stance[:, :-1]))
            before = stance
        assert flips == 0, (gait.name, gait.step_duration, flips)
    walk = make_gait("walk", 0.3)
    np.testing.assert_array_equal(walk.schedule(0.37, 24, 0.02).stance,
                                  walk.schedule(0.37 + walk.period, 24, 0.02).stance)


def test_add_contacts_checks_everything_before_it_builds_a_term():
    """A wrong foot name raised after the feet before it and swing_z were in the problem
    (variables cannot be removed: the next call said 'swing_z already exists'); a force
    of the wrong size failed in CasADi's slice assertion; a negative mu made a cone that
    allows no force (an auditor of the API)."""
    from horizon_mpc.locomotion.formulation import add_contacts, floating_base_double_integrator
    from horizon_mpc.model import RobotModel, UnknownNameError
    from horizon_mpc.problem import Problem

    m = RobotModel.from_example("solo12")
    prb = Problem(3)
    q = prb.create_state_variable("q", m.nq)
    v = prb.create_state_variable("v", m.nv)
    prb.create_input_variable("a", m.nv)
    f = prb.create_input_variable("f", 6)
    with pytest.raises(UnknownNameError, match="nope"):
        add_contacts(prb, m, ["FL_FOOT", "nope"], q, v, f, 0.6)
    for feet, mu, match in ((["FL_FOOT", "FR_FOOT", "HL_FOOT"], 0.6, "f has 6 rows; 3 feet"),
                            (["FL_FOOT", "FL_FOOT"], 0.6, "distinct frame names"),
                            (["FL_FOOT", "FR_FOOT"], -0.6, "mu must be a finite number > 0")):
        with pytest.raises(ValueError, match=match):
            add_contacts(prb, m, feet, q, v, f, mu)
    terms = add_contacts(prb, m, ["FL_FOOT", "FR_FOOT"], q, v, f, 0.6)  # nothing was left
    assert sorted(terms.velocity) == ["FL_FOOT", "FR_FOOT"]
    with pytest.raises(ValueError, match="a has 6 rows; the model needs 18"):
        floating_base_double_integrator(m, q, v, f)


def test_start_refuses_a_bad_max_iter_before_it_changes_anything(walking_mpc):
    """start(max_iter=0) failed in the solver after the controller had reset its warm start
    and left the ILQR out of its real-time mode; set_stand_when_idle('false') stored True."""
    from horizon_mpc.posture import standing_configuration

    _, q = standing_configuration(walking_mpc.cfg)
    walking_mpc.start(q, np.zeros(walking_mpc.model.nv), 0.0)
    rti, t_last = walking_mpc.solver.opts["rti"], walking_mpc.t_last
    with pytest.raises(ValueError, match="max_iter must be an integer >= 1, got 0"):
        walking_mpc.start(q, np.zeros(walking_mpc.model.nv), 5.0, max_iter=0)
    assert (walking_mpc.solver.opts["rti"], walking_mpc.t_last) == (rti, t_last) == (True, 0.0)
    with pytest.raises(TypeError, match="True or False"):
        walking_mpc.set_stand_when_idle("false")
    assert walking_mpc.scheduler.stand_when_idle is True


def test_plans_schedules_and_ticks_refuse_arguments_of_the_wrong_kind(walking_mpc):
    """An auditor of the API: tau_head(-1) was numpy's reshape error and tau_head(0)
    CasADi's 'degenerate map'; a gait schedule of 2.5 nodes gave 4 and a NaN dt every foot
    in swing; update('0', ...) was 'must be real number, not str'; Problem(True) was a
    1-interval problem."""
    from horizon_mpc.posture import standing_configuration
    from horizon_mpc.problem import Problem

    _, q = standing_configuration(walking_mpc.cfg)
    plan = walking_mpc.start(q, np.zeros(walking_mpc.model.nv), 0.0)
    assert plan.tau_head(1).shape == (walking_mpc.model.nv, 1)
    for n in (0, -1, 2.5):
        with pytest.raises(ValueError, match="n must be an integer >= 1"):
            plan.tau_head(n)
    gait = make_gait("trot")
    for args in ((0.0, 2.5, 0.02), (0.0, 4, float("nan")), (0.0, 4, 0.0), (math.inf, 4, 0.02)):
        with pytest.raises(ValueError, match="schedule: n_nodes must be an integer"):
            gait.schedule(*args)
    with pytest.raises(ValueError, match="time must be a finite number"):
        walking_mpc.update("0", q, np.zeros(walking_mpc.model.nv))
    for bad in (True, "0.04", math.nan):  # True was a tick at 1 s (a reviewer)
        with pytest.raises(ValueError, match=r"prepare\(\): the tick time must be a finite"):
            walking_mpc.prepare(bad)
    assert walking_mpc.t_last == 0.0
    assert walking_mpc.prepare(np.array(0.02)) and walking_mpc.t_last == 0.02  # 0-d: taken
    assert isinstance(walking_mpc.t_last, float)
    with pytest.raises(ValueError, match="n_nodes must be an int >= 1, got True"):
        Problem(True)


def test_the_command_ramps_along_a_line_with_combined_accelerations(walking_mpc):
    """Each axis ramped at its own limit: a reversal of vx, vy and wz together (go2, -0.25,
    -0.2, 0.4 to 0.4, 0.3, -0.4) was 1.4x the acceleration of any axis, and go2 sank 6 cm
    with a tracking RMSE of 0.15 for 2 s. Now the axes move together, their accelerations
    (shares of the limits) of norm 1: one axis alone still at its limit."""
    from horizon_mpc.locomotion.command import ramp_time

    mpc = walking_mpc
    amax = mpc.settings.max_acceleration  # 1, 1, 2
    assert ramp_time([0.65, 0.5, 0.8], amax) == pytest.approx(math.sqrt(0.65 ** 2 + 0.5 ** 2
                                                                        + 0.4 ** 2))
    assert ramp_time([0.3, 0.0, 0.0], amax) == pytest.approx(0.3)
    mpc.cmd[:] = [-0.25, -0.2, 0.4]
    steps = 0
    while not np.allclose(mpc.cmd, [0.4, 0.3, -0.4]):
        before = mpc.cmd.copy()
        mpc._ramp_command(np.array([0.4, 0.3, -0.4]), 0.02)
        step = (mpc.cmd - before) / np.array(amax) / 0.02
        assert np.linalg.norm(step) <= 1.0 + 1e-9  # the combined acceleration
        np.testing.assert_allclose(step / np.linalg.norm(step), [0.65, 0.5, -0.4]
                                   / np.linalg.norm([0.65, 0.5, -0.4]), atol=1e-9)  # a line
        steps += 1
    assert steps == math.ceil(ramp_time([0.65, 0.5, 0.8], amax) / 0.02)
    mpc.cmd[:] = 0.0
    mpc._ramp_command(np.array([0.3, 0.0, 0.0]), 0.02)
    assert mpc.cmd.tolist() == pytest.approx([0.02, 0.0, 0.0])  # one axis: at its limit
    mpc.cmd[:] = 0.0


def test_misspelt_gait_weight_and_frame_names_get_the_nearest_known_one():
    """Config keys had nearest-name hints; gait names, weight keys and frame names listed
    everything and left the reader to spot the typo (an extender's audit)."""
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.locomotion.gaits import make_gait
    from horizon_mpc.locomotion.settings import GaitSettings, MpcSettings
    from horizon_mpc.model import RobotModel
    from horizon_mpc.model.robot_model import UnknownNameError

    with pytest.raises(ValueError, match=r"unknown gait 'trott' \(did you mean 'trot'\?\)"):
        make_gait("trott")
    with pytest.raises(ValueError, match=r"got 'Walk' \(did you mean 'walk'\?\)"):
        GaitSettings(name="Walk")
    with pytest.raises(ValueError, match=r"\['base_yaww' \(did you mean 'base_yaw'\?\)\] in "
                                         r"'mpc.weights'"):
        MpcSettings.from_dict({"weights": {"base_yaww": 1.0}})
    with pytest.raises(ValueError, match=r"unknown gait 'gallop'; gaits are"):  # no near one
        make_gait("gallop")
    model = RobotModel.from_config(load_robot_config("go2"))
    with pytest.raises(UnknownNameError, match=r"unknown frame 'FL_fot' \(did you mean "
                                               r"'FL_foot'\?\)"):
        model.frame_id("FL_fot")


def test_feet_listed_out_of_the_gait_order_are_refused_naming_the_order_that_is():
    """The gaits' offsets are for front left, front right, hind left, hind right: go2's feet
    listed FL, RR, FR, RL made its trot a pace, and it fell, without a word (an extender's
    audit)."""
    import dataclasses

    from horizon_mpc.config import load_robot_config
    from horizon_mpc.locomotion import build_walking_problem
    from horizon_mpc.locomotion.gaits import feet_order_error
    from horizon_mpc.model import RobotModel

    square = [[0.2, 0.15], [0.2, -0.15], [-0.2, 0.15], [-0.2, -0.15]]
    assert feet_order_error(["a", "b", "c", "d"], square) is None
    text = feet_order_error(["a", "d", "b", "c"], [square[i] for i in (0, 3, 1, 2)])
    assert "not in the gait order front left, front right, hind left, hind right" in text
    assert text.endswith("list them as ['a', 'b', 'c', 'd']")
    # no side to tell (a foot on the centre line), or not four feet: not checked
    assert feet_order_error(list("abcd"), [[0.2, 0.0], *square[1:]]) is None
    assert feet_order_error(list("ab"), square[:2]) is None

    cfg = load_robot_config("go2")
    model = RobotModel.from_config(cfg)
    wrong = dataclasses.replace(cfg, feet=["FL_foot", "RR_foot", "FR_foot", "RL_foot"])
    with pytest.raises(ValueError, match=r"list them as \['FL_foot', 'FR_foot', 'RL_foot', "
                                         r"'RR_foot'\]"):
        build_walking_problem(model, wrong)


def test_every_weight_reaches_a_cost_of_the_walking_problem():
    """A Weights field that set_weights forgets is a config key and a live w_* parameter
    that do nothing (doc/locomotion.md, Extending it): each field, changed alone, changes
    the weight of some cost term."""
    import dataclasses

    from horizon_mpc.config import load_robot_config
    from horizon_mpc.locomotion import build_walking_problem
    from horizon_mpc.locomotion.settings import Weights
    from horizon_mpc.model import RobotModel

    cfg = load_robot_config("go2")
    wp = build_walking_problem(RobotModel.from_config(cfg), cfg)
    terms = {**wp.prb.costs, **{f"clearance {k}": t for k, t in wp.contacts.clearance.items()
                                if hasattr(t, "set_weight")}}

    def snapshot() -> dict:
        return {name: np.array(t.weight, copy=True) for name, t in terms.items()}

    base = Weights()
    wp.set_weights(base)
    before = snapshot()
    for f in dataclasses.fields(Weights):
        value = getattr(base, f.name)
        changed = ([2.0 * x + 1.0 for x in value] if isinstance(value, list)
                   else 2.0 * value + 1.0)
        wp.set_weights(dataclasses.replace(base, **{f.name: changed}))
        after = snapshot()
        assert any(not np.array_equal(before[n], after[n]) for n in terms), f.name
        wp.set_weights(base)
