"""``ros2 launch horizon_mpc sim_mpc.launch.py [robot:=go2]``

``sim_node`` and ``mpc_node`` as two processes on the simulated clock: the robot stands,
and walks as soon as something publishes ``cmd_vel`` (e.g. teleop_twist_keyboard).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    """The simulator (the clock source) and the MPC on its clock, both with ``robot``."""
    robot = LaunchConfiguration("robot")
    return LaunchDescription([
        DeclareLaunchArgument("robot", default_value="go2",
                              description="robot config name (config/<robot>.yaml)"),
        Node(package="horizon_mpc", executable="sim_node", name="sim_node",
             parameters=[{"robot": robot}], output="screen"),
        Node(package="horizon_mpc", executable="mpc_node", name="mpc_node",
             parameters=[{"robot": robot, "use_sim_time": True}], output="screen"),
    ])
