"""RobotModel's construction, information attributes, caching and error messages."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pinocchio as pin
import pytest
from model_reference import ROBOTS, centauro_wheels_urdf, model

from horizon_mpc.model import RobotModel, UnknownNameError
from horizon_mpc.robots import example_robot_files

GO2_JOINTS = [
    f"{leg}_{part}_joint" for leg in ("FL", "FR", "RL", "RR") for part in ("hip", "thigh", "calf")
]


def test_go2_sizes_mass_and_joint_order():
    m = model("go2")
    assert (m.nq, m.nv) == (19, 18)
    assert m.floating_base
    assert m.joint_names == GO2_JOINTS
    assert m.mass == pytest.approx(pin.computeTotalMass(m.pin_model))
    assert m.joint_idx_q["FL_hip_joint"] == 7 and m.joint_idx_v["FL_hip_joint"] == 6


def test_from_urdf_path_and_string_give_the_same_model():
    path = example_robot_files("solo12").urdf
    from_path = RobotModel.from_urdf(path)
    from_text = RobotModel.from_urdf(path.read_text())
    assert from_path.joint_names == from_text.joint_names
    assert from_path.frame_names == from_text.frame_names
    q = from_path.neutral()
    assert np.array_equal(from_path.com()(q).full(), from_text.com()(q).full())


def test_arms_are_fixed_base_by_default():
    for name, n_joints in (("ur5", 6), ("panda", 9)):
        m = model(name)
        assert not m.floating_base
        assert m.nq == m.nv == n_joints



_WORLD_ARM = """<robot name="arm"><link name="world"/>
<joint name="fix" type="fixed"><parent link="world"/><child link="base"/></joint>
<link name="base"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
<limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
<link name="l1"><inertial><mass value="1"/><origin xyz="0 0 0.5"/>
<inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link></robot>"""


def test_a_free_flyer_above_a_world_root_link_is_warned_about(caplog):
    """from_urdf's default is a floating base: an arm fixed to 'world' silently got one."""
    with caplog.at_level("WARNING", logger="horizon_mpc.model.loading"):
        floating = RobotModel.from_urdf(_WORLD_ARM)
    assert (floating.nq, floating.nv) == (8, 7)
    assert "root link is 'world'" in caplog.text and "floating_base=False" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="horizon_mpc.model.loading"):
        fixed = RobotModel.from_urdf(_WORLD_ARM, floating_base=False)
        RobotModel.from_example("go2")
    assert (fixed.nq, fixed.nv) == (1, 1) and not caplog.text

def test_limits_come_from_the_urdf_and_base_is_unbounded():
    m = model("go2")
    pm = m.pin_model
    assert np.all(np.isinf(m.q_lower[:7])) and np.all(np.isinf(m.q_upper[:7]))
    assert np.array_equal(m.q_lower[7:], pm.lowerPositionLimit[7:])
    assert np.array_equal(m.joint_position_upper, pm.upperPositionLimit[7:])
    assert np.array_equal(m.joint_velocity_limit, pm.velocityLimit[6:])
    assert np.array_equal(m.joint_effort_limit, pm.effortLimit[6:])
    assert np.all(np.isinf(m.v_limit[:6])) and np.all(np.isinf(m.effort_limit[:6]))
    assert m.joint_position_lower.shape == (12,)


def _go2_urdf_with(attribute: str, value: str, count: int = 0, text: str | None = None) -> str:
    """go2's URDF (or ``text``) with the first ``count`` (0: every) ``attribute`` set."""
    import re

    text = example_robot_files("go2").urdf.read_text() if text is None else text
    return re.sub(rf'{attribute}="[^"]*"', f'{attribute}="{value}"', text, count=count)


def test_limits_written_as_zero_are_no_limit_and_said(caplog):
    """URDF exporters write effort="0" velocity="0" lower="0" upper="0" for unknown
    limits (an auditor's go2 copies): the walking problem took them as bounds of zero, and
    the robot fell at 0.36 s (effort), fell at 3 s (velocity) or stood still without a word
    (a [0, 0] range)."""
    with caplog.at_level("WARNING", logger="horizon_mpc.model.robot_model"):
        effort = RobotModel.from_urdf(_go2_urdf_with("effort", "0"))
    assert np.all(np.isinf(effort.joint_effort_limit))
    assert effort.unset_limits["effort"] == GO2_JOINTS
    assert "taken as no limit: effort (FL_hip_joint, " in caplog.text
    assert "... 4 more" in caplog.text
    velocity = RobotModel.from_urdf(_go2_urdf_with("velocity", "0", count=1))
    assert velocity.unset_limits == {"position": [], "velocity": ["FL_hip_joint"],
                                     "effort": []}
    assert np.isinf(velocity.joint_velocity_limit[0])
    assert np.all(np.isfinite(velocity.joint_velocity_limit[1:]))
    caplog.clear()
    with caplog.at_level("WARNING", logger="horizon_mpc.model.robot_model"):
        ranges = RobotModel.from_urdf(_go2_urdf_with("upper", "0",
                                                     text=_go2_urdf_with("lower", "0")))
    assert not caplog.text  # [0, 0]: the URDF's default range, said at INFO (CENTAURO)
    assert ranges.unset_limits["position"] == GO2_JOINTS
    assert np.all(np.isinf(ranges.q_lower)) and np.all(np.isinf(ranges.q_upper))
    caplog.clear()
    with caplog.at_level("WARNING", logger="horizon_mpc.model.robot_model"):
        go2 = RobotModel.from_example("go2")
    assert go2.unset_limits == {"position": [], "velocity": [], "effort": []}
    assert not caplog.text


def test_a_urdf_floating_joint_under_the_free_flyer_is_said_and_refused_for_a_robot(
        tmp_path, caplog):
    """An auditor's go2 URDF with world -> base as a 'floating' joint: warned about as a
    robot fixed to the world (advice: floating_base=False), then refused as having
    continuous joints [] or a base_link that is not the root. The model (two free-flyers)
    is valid and says what it is; a robot config's model refuses it by name."""
    text = example_robot_files("go2").urdf.read_text()
    at = text.index("<link")
    text = (text[:at] + '<link name="world"/><joint name="floating_base" type="floating">'
            '<parent link="world"/><child link="base"/></joint>' + text[at:])
    with caplog.at_level("WARNING", logger="horizon_mpc.model.loading"):
        assert RobotModel.from_urdf(text).nq == 26
    assert "['floating_base'] are 'floating' joints below the free-flyer" in caplog.text
    assert "fixed to the world" not in caplog.text
    assert RobotModel.from_urdf(text, floating_base=False).nq == 19
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.posture import standing_configuration

    path = tmp_path / "go2_floating.urdf"
    path.write_text(text)
    (tmp_path / "mine.yaml").write_text(f"robot: go2\nurdf_path: {path}\n"
                                        "feet: [FL_foot, FR_foot, RL_foot, RR_foot]\n")
    with pytest.raises(ValueError, match=r"\['floating_base'\] are 'floating' joints.*remove "
                                         "the floating joint"):
        standing_configuration(load_robot_config(str(tmp_path / "mine.yaml")))


def test_continuous_joints_take_cos_sin_and_are_unbounded():
    m = model("centauro_wheels")
    assert m.nq == m.nv + 1 + 4  # quaternion + four wheels
    iq = m.joint_idx_q["j_wheel_1"]
    assert np.array_equal(m.neutral()[iq : iq + 2], [1.0, 0.0])
    k = m.joint_names.index("j_wheel_1")
    assert np.isinf(m.joint_position_lower[k]) and np.isinf(m.joint_position_upper[k])


def test_reference_configuration_reads_the_srdf_posture():
    m = model("go2")
    q = m.reference_configuration("standing")
    assert np.array_equal(q[:7], [0, 0, 0, 0, 0, 0, 1])
    assert q[m.joint_idx_q["FL_thigh_joint"]] == 0.785
    assert "standing" in m.reference_configuration_names()


def test_reference_configuration_can_keep_the_srdf_base_placement():
    q = model("go2").reference_configuration("standing", with_base=True)
    assert np.array_equal(q[:7], [0, 0, 0.335, 0, 0, 0, 1])


def test_reference_configuration_of_continuous_joints_is_cos_sin(tmp_path):
    srdf = tmp_path / "wheels.srdf"
    srdf.write_text(
        '<robot name="c"><group_state name="turned" group="g">'
        '<joint name="j_wheel_1" value="0.5"/></group_state></robot>'
    )
    m = RobotModel.from_urdf(centauro_wheels_urdf(), srdf=srdf)
    q = m.reference_configuration("turned")
    iq = m.joint_idx_q["j_wheel_1"]
    assert np.allclose(q[iq : iq + 2], [np.cos(0.5), np.sin(0.5)])


def test_functions_are_cached_per_kind_frame_and_ref():
    m = model("go2")
    assert m.fk("FL_foot") is m.fk("FL_foot")
    assert m.jacobian("FL_foot", "WORLD") is m.jacobian("FL_foot", "WORLD")
    assert m.jacobian("FL_foot", "WORLD") is not m.jacobian("FL_foot", "LOCAL")
    assert m.inverse_dynamics(["FL_foot"]) is m.inverse_dynamics(["FL_foot"])


def test_functions_have_named_inputs_and_outputs():
    m = model("go2")
    fn = m.inverse_dynamics(["FL_foot", "FR_foot"])
    assert fn.name_in() == ["q", "v", "a", "f"] and fn.name_out() == ["tau"]
    assert fn.size_in(3) == (6, 1)
    assert m.frame_velocity("FL_foot").name_out() == ["lin", "ang"]
    assert m.forward_dynamics().name_in() == ["q", "v", "tau", "f"]


@pytest.mark.parametrize("sym", [cs.SX, cs.MX])
def test_functions_accept_symbols(sym):
    m = model("go2")
    q, v = sym.sym("q", m.nq), sym.sym("v", m.nv)
    lin, _ = m.frame_velocity("FL_foot")(q, v)
    assert isinstance(lin, sym) and lin.shape == (3, 1)


def test_pinocchio_reference_frame_enums_are_accepted():
    m = model("go2")
    assert m.jacobian("FL_foot", pin.ReferenceFrame.LOCAL) is m.jacobian("FL_foot", "LOCAL")


def test_unknown_frame_names_the_frame_and_lists_valid_ones():
    m = model("go2")
    with pytest.raises(UnknownNameError, match=r"unknown frame 'FL_fot'.*FL_foot"):
        m.fk("FL_fot")
    with pytest.raises(KeyError, match="RR_fot"):
        m.inverse_dynamics(["FL_foot", "RR_fot"])


def test_unknown_reference_frame_is_rejected():
    with pytest.raises(ValueError, match=r"unknown reference frame 'GLOBAL'.*LOCAL_WORLD_ALIGNED"):
        model("go2").jacobian("FL_foot", "GLOBAL")


def test_unknown_robot_lists_the_known_ones():
    with pytest.raises(KeyError, match=r"unknown robot 'go3'.*go2"):
        RobotModel.from_example("go3")


def test_missing_urdf_file_is_reported(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.urdf"):
        RobotModel.from_urdf(tmp_path / "nope.urdf")


def test_the_urdf_parsers_reason_is_in_the_error():
    """urdfdom prints why a URDF is invalid on stderr and raises 'does not contain a valid
    URDF model' only: the reason is in the ValueError now."""
    urdf = ('<robot name="r"><link name="a"/><link name="b"/><joint name="j1" '
            'type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>'
            '</robot>')
    with pytest.raises(ValueError, match=r"Joint \[j1\] is of type REVOLUTE but it does not "
                       "specify limits"):
        RobotModel.from_urdf(urdf)


def test_malformed_urdf_is_reported():
    with pytest.raises(ValueError, match="malformed URDF"):
        RobotModel.from_urdf('<robot name="x"><link name="a"></robot>')


def _one_joint_urdf(inertial: str = "", limit: str = 'effort="10" velocity="5"',
                    child: str = "arm", joint: str = "j") -> str:
    return (f'<robot name="r"><link name="base"/><link name="{child}">{inertial}</link>'
            f'<joint name="{joint}" type="revolute"><parent link="base"/>'
            f'<child link="{child}"/><axis xyz="0 1 0"/>'
            f'<limit lower="-1" upper="1" {limit}/></joint></robot>')


@pytest.mark.parametrize("inertial", [
    '<inertial><mass value="2kg"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" '
    'iyz="0"/></inertial>',
    '<inertial><mass value="2"/><inertia ixx="0.1kg*m^2" iyy="1" izz="1" ixy="0" ixz="0" '
    'iyz="0"/></inertial>',
], ids=["mass_with_unit", "inertia_with_unit"])
def test_an_inertial_the_parser_cannot_read_is_refused(inertial):
    """urdfdom dropped it with a line on stderr and the link became massless (or lost its
    rotational inertia): a model of 0 kg, no gravity torque, no error (a QA finding)."""
    with pytest.raises(ValueError, match="malformed URDF string: .*Could not parse inertial"):
        RobotModel.from_urdf(_one_joint_urdf(inertial), floating_base=False)


def test_a_negative_mass_is_refused_by_link():
    inertial = ('<inertial><mass value="-1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" '
                'ixz="0" iyz="0"/></inertial>')
    # also where the text is looser XML than ElementTree reads (Pinocchio's parser takes a
    # blank line before the declaration and text after the robot; the check was skipped)
    for text in (_one_joint_urdf(inertial),
                 '\n<?xml version="1.0"?>\n' + _one_joint_urdf(inertial),
                 _one_joint_urdf(inertial) + "<robot/>"):
        with pytest.raises(ValueError, match=r"link\(s\) of negative mass: arm \(-1 kg\)"):
            RobotModel.from_urdf(text, floating_base=False)


def test_an_unreadable_visual_or_collision_is_no_concern_of_the_model():
    """The dynamics never read them: only an unreadable <inertial> is refused (a review
    found pybullet_data's racecar refused for its 4-component mesh scale)."""
    inertial = ('<inertial><mass value="2"/><inertia ixx="1" iyy="1" izz="1" ixy="0" '
                'ixz="0" iyz="0"/></inertial><collision><geometry><capsule radius="0.1" '
                'length="0.3"/></geometry></collision>')
    assert RobotModel.from_urdf(_one_joint_urdf(inertial), floating_base=False).mass == 2.0


def test_negative_effort_or_velocity_limits_are_named_by_joint():
    """Pinocchio refused them as 'min_effort are greater than max_effort', naming no joint."""
    with pytest.raises(ValueError, match=r"negative limits: j\.effort = -3"):
        RobotModel.from_urdf(_one_joint_urdf(limit='effort="-3" velocity="5"'),
                             floating_base=False)
    with pytest.raises(ValueError, match=r"negative limits: j\.velocity = -5"):
        RobotModel.from_urdf(_one_joint_urdf(limit='effort="3" velocity="-5"'),
                             floating_base=False)


def test_names_pinocchio_gives_its_own_frames_are_refused():
    """A link 'universe' was shadowed by the world frame (fk gave the origin), a joint
    'root_joint' by the free-flyer (fk gave the base)."""
    with pytest.raises(ValueError, match="link 'universe'.*rename it"):
        RobotModel.from_urdf(_one_joint_urdf(child="universe"), floating_base=False)
    with pytest.raises(ValueError, match="joint 'root_joint'.*rename it"):
        RobotModel.from_urdf(_one_joint_urdf(joint="root_joint"), floating_base=True)
    # without a free-flyer the name is the URDF's own
    m = RobotModel.from_urdf(_one_joint_urdf(joint="root_joint"), floating_base=False)
    assert m.joint_names == ["root_joint"]


@pytest.mark.parametrize("frame", ["脚", "-", "_"])
def test_a_frame_named_without_ascii_letters_gets_every_function(frame):
    """'f_' + '_LOCAL_WORLD_ALIGNED' made a name with '__', which CasADi refused: the
    Jacobian and frame velocity of such a frame raised."""
    m = RobotModel.from_urdf(_one_joint_urdf(
        '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" '
        'iyz="0"/></inertial>', child=frame), floating_base=False)
    q, v = np.array([0.3]), np.array([0.5])
    data = m.pin_model.createData()
    pin.forwardKinematics(m.pin_model, data, q, v)
    pin.updateFramePlacements(m.pin_model, data)
    fid = m.pin_model.getFrameId(frame)
    J = pin.computeFrameJacobian(m.pin_model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(np.asarray(m.jacobian(frame)(q)), np.reshape(J, (6, 1)),
                               atol=1e-12)
    assert np.asarray(m.frame_velocity(frame)(q, v)).size == 6
    assert np.asarray(m.frame_acceleration(frame)(q, v, np.zeros(1))).size == 6


def test_unknown_reference_configuration_lists_the_available_ones():
    with pytest.raises(UnknownNameError, match=r"'sitting'.*standing"):
        model("go2").reference_configuration("sitting")


def test_unsupported_joint_type_is_rejected():
    urdf = (
        '<robot name="r"><link name="a"><inertial><mass value="1"/>'
        '<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
        '<link name="b"><inertial><mass value="1"/>'
        '<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
        '<joint name="j" type="planar"><parent link="a"/><child link="b"/></joint></robot>'
    )
    with pytest.raises(NotImplementedError, match="joint 'j': joint type JointModelPlanar "
                       "is not supported"):  # the joint named (session 32)
        RobotModel.from_urdf(urdf, floating_base=False)


def test_a_one_axis_joint_of_another_type_is_refused():
    """A composite joint of one degree of freedom has a motion axis like a revolute one:
    its inner placement was dropped and its kinematics wrong, silently (a QA finding)."""
    model = pin.Model()
    joint = pin.JointModelComposite(pin.JointModelRX(),
                                    pin.SE3(pin.utils.rotate("y", 0.7), np.ones(3)))
    j = model.addJoint(0, joint, pin.SE3.Identity(), "comp")
    model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    with pytest.raises(NotImplementedError, match="JointModelComposite is not supported"):
        RobotModel(model)


def test_mimic_joints_are_named_in_a_warning(caplog):
    """Pinocchio's URDF parser makes a mimic joint an independent one: said, not silent."""
    link = ('<link name="{}"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" '
            'ixy="0" ixz="0" iyz="0"/></inertial></link>')
    joint = ('<joint name="{}" type="revolute"><parent link="{}"/><child link="{}"/>'
             '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>{}'
             '</joint>')
    urdf = ('<robot name="r">' + "".join(link.format(x) for x in "abc")
            + joint.format("j1", "a", "b", "")
            + joint.format("j2", "b", "c", '<mimic joint="j1" multiplier="2"/>') + "</robot>")
    with caplog.at_level("WARNING", logger="horizon_mpc.model.loading"):
        m = RobotModel.from_urdf(urdf, floating_base=False)
    assert m.joint_names == ["j1", "j2"]
    assert "mimic joints become independent joints of the model (j2 mimics j1)" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="horizon_mpc.model.loading"):
        RobotModel.from_urdf(urdf.replace('<mimic joint="j1" multiplier="2"/>', ""),
                             floating_base=False)
    assert "mimic" not in caplog.text
    # a fixed joint's mimic (talos' gripper has six) moves nothing: not named (it was)
    caplog.clear()
    with caplog.at_level("WARNING", logger="horizon_mpc.model.loading"):
        m = RobotModel.from_urdf(urdf.replace('name="j2" type="revolute"',
                                              'name="j2" type="fixed"'), floating_base=False)
    assert m.joint_names == ["j1"] and "mimic" not in caplog.text


@pytest.mark.parametrize("name", ROBOTS)
def test_every_frame_gets_a_validly_named_function(name):
    # Function names are C symbols: frame names with dots, dashes or "__" must still work.
    m = model(name)
    for frame in m.frame_names:
        assert m.fk(frame).name().startswith("fk_")


def test_a_pinocchio_model_with_armature_is_refused_by_name():
    """Pinocchio's crba/rnea/aba add the armature (rotor inertia), the symbolic dynamics
    did not: M off by the armature, forward dynamics by 119 rad/s^2 on a panda, silently
    (a QA finding). Refused, naming the joints."""
    model = pin.buildSampleModelManipulator()
    model.armature[2] = 0.1
    with pytest.raises(ValueError, match=r"armature is not zero \(joints \['shoulder3_joint'\]\)"):
        RobotModel(model)
    model.armature[:] = 0.0
    assert RobotModel(model).nv == model.nv


def test_an_empty_urdf_string_is_named_as_such():
    """It was looked up as the path '.': 'URDF file not found: .'."""
    for empty in ("", "  \n"):
        with pytest.raises(ValueError, match="no URDF: an empty string"):
            RobotModel.from_urdf(empty)


def test_a_robot_name_given_to_the_constructor_points_to_from_example():
    """RobotModel('go2') was "'str' object has no attribute 'armature'"."""
    with pytest.raises(TypeError, match=r"use RobotModel.from_example\(name\)"):
        RobotModel("go2")
