"""``ros2 launch horizon_mpc sim_mpc.launch.py [robot:=go2] [config:=...] [urdf_path:=...]``

``sim_node`` and ``mpc_node`` as two processes on the simulated clock: the robot stands,
and walks as soon as something publishes ``cmd_vel`` (e.g. teleop_twist_keyboard). Both
nodes get the same robot: a config name, or a config YAML file, and optionally a URDF file
that replaces the config's model (the config still gives feet, posture, gains, weights).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

# launch argument -> (default, description); each is the parameter of that name of both nodes
ARGUMENTS = {
    "robot": ("go2", "robot config name (config/<robot>.yaml)"),
    "config": ("", "path of a robot config YAML (overrides 'robot')"),
    "urdf_path": ("", "URDF file of the robot (overrides the config's URDF)"),
}


def generate_launch_description() -> LaunchDescription:
    """The simulator (the clock source) and the MPC on its clock, with the same robot."""
    args = [DeclareLaunchArgument(name, default_value=default, description=text)
            for name, (default, text) in ARGUMENTS.items()]
    robot = {name: LaunchConfiguration(name) for name in ARGUMENTS}
    return LaunchDescription([
        *args,
        Node(package="horizon_mpc", executable="sim_node", name="sim",
             parameters=[robot], output="screen"),
        Node(package="horizon_mpc", executable="mpc_node", name="mpc",
             parameters=[{**robot, "use_sim_time": True}], output="screen"),
    ])
