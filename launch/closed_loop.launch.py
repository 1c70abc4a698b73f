"""``ros2 launch horizon_mpc closed_loop.launch.py [robot:=go2] [mode:=realtime] ...``

The closed-loop demo for a full ROS 2 installation: the same as
``ros2 run horizon_mpc closed_loop`` (simulator node + MPC node + command profile, report
written to ``out``). For the two nodes as separate processes, driven by your own
``cmd_vel``, use ``sim_mpc.launch.py``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

ARGUMENTS = {
    "robot": ("go2", "robot config name (config/<robot>.yaml)"),
    "mode": ("realtime", "'realtime' (two processes, real time) or 'lockstep' "
             "(deterministic; the run of `make demo`)"),
    "profile": ("", "command profile YAML (empty: config/commands/default.yaml)"),
    "out": ("out/closed_loop", "output folder for summary.json, plots and the GIF"),
}


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments and run the ``closed_loop`` executable with them."""
    args = [DeclareLaunchArgument(name, default_value=default, description=text)
            for name, (default, text) in ARGUMENTS.items()]
    cli = ["--robot", LaunchConfiguration("robot"), "--mode", LaunchConfiguration("mode"),
           "--out", LaunchConfiguration("out"), "--profile", LaunchConfiguration("profile")]
    return LaunchDescription([
        *args,
        # no node name: the process runs several nodes of its own (sim, mpc, the player)
        Node(package="horizon_mpc", executable="closed_loop", arguments=cli, output="screen"),
    ])
