"""Launch prsm_health_node in a ROS 2 Jazzy install.

    ros2 launch prsm_health prsm_health.launch.py hardware_id:=left input_topic:=/left/motor_state

Every node parameter is an argument of the same name with the node's default (docs/ros.md).
Four of them default to an empty string, which the node reads as: params_file the bundled
config/default.yaml, preset the params file's, input_topic motor_state or joint_states by
input_type, state_file ~/.local/state/prsm_health/<hardware_id>.json; for the others an empty
string is refused at configure. The node configures and activates itself (autostart); set
autostart:=false to drive it through the lifecycle instead.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

#: (parameter, default, type) of the arguments; the types keep 1 from becoming an integer.
ARGUMENTS = (
    ("autostart", "true", bool),
    ("params_file", "", str),
    ("preset", "", str),
    ("hardware_id", "prsm_actuator", str),
    ("input_type", "motor_state", str),
    ("input_topic", "", str),
    ("joint_name", "prsm_motor", str),
    ("effort_is", "current", str),
    ("input_qos", "sensor_data", str),
    ("input_queue_depth", "1000", int),
    ("batch_period_s", "0.005", float),
    ("health_rate_hz", "0.0", float),
    ("diagnostics_rate_hz", "1.0", float),
    ("state_file", "", str),
    ("save_period_s", "10.0", float),
    ("use_sim_time", "false", bool),
)


def generate_launch_description() -> LaunchDescription:
    """The node with one launch argument per parameter of ARGUMENTS."""
    declared = [
        DeclareLaunchArgument(name, default_value=default) for name, default, _ in ARGUMENTS
    ]
    parameters = {
        name: ParameterValue(LaunchConfiguration(name), value_type=kind)
        for name, _, kind in ARGUMENTS
    }
    node = Node(
        package="prsm_health",
        executable="prsm-health-node",
        name="prsm_health",
        output="screen",
        emulate_tty=True,
        parameters=[parameters],
    )
    return LaunchDescription([*declared, node])
