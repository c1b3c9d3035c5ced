"""Start the stylizer with its params YAML, and optionally the VMC bridge and a synthetic or learned
performer.

    ros2 launch motion_style_ros stylizer.launch.py target_style:=elderly alpha:=0.8
    ros2 launch motion_style_ros stylizer.launch.py use_synthetic:=true markers:=true  # try-out
    ros2 launch motion_style_ros stylizer.launch.py use_learned:=true learned_style:=elderly  # SAAE samples
    ros2 launch motion_style_ros stylizer.launch.py use_vmc:=true   # VMC in: config/vmc_bridge.yaml
    ros2 launch motion_style_ros stylizer.launch.py use_synthetic:=true use_rsp:=true  # RViz RobotModel
    ros2 launch motion_style_ros stylizer.launch.py managed:=true  # lifecycle node, brought to active

Parameters come from ``params_file`` (default: the installed ``config/stylizer.yaml``); a
stylizer argument given on the command line overrides its parameter, one left empty keeps the
file's value. Every node starts in ``namespace``, so the topics are ``<namespace>/joint_states``
in and ``<namespace>/stylized/...`` out, and the VMC bridge and the synthetic or learned performer
(start one of them: they publish on the same topic) feed the stylizer and the bridge streams its
output back out without remapping. With ``use_rsp``, robot_state_publisher turns
``stylized/joint_states`` into TF with ``robot_description_file`` (default: the installed canonical
skeleton's URDF, whose joints are the layout's names).
"""

from pathlib import Path


import yaml
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.conditions import IfCondition
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare
from lifecycle_msgs.msg import Transition

from motion_style_ros.runtime.stylizer_settings import PARAMETERS

PACKAGE = 'motion_style_ros'

# Launch argument -> the stylizer parameter it overrides; the descriptions and how an argument's
# text is read come from the parameter table, so that they follow it.
STYLIZER_ARGUMENTS = {
    'backend': 'backend', 'model': 'model', 'target_style': 'target_style', 'alpha': 'alpha',
    'part_alpha': 'part_alpha', 'latent_seed': 'latent_seed', 'seed_spread': 'seed_spread',
    'reference': 'reference', 'performers': 'performers', 'markers': 'publish_markers',
    'qos_reliability': 'qos_reliability', 'pipelined': 'pipelined',
}
_TABLE = {p.name: p for p in PARAMETERS}
_DESCRIPTIONS = {
    **{name: p.description for name, p in _TABLE.items()},
    'target_style': "style to restyle into, one of the model card's styles; the card's neutral style by default",
    'qos_reliability': 'QoS reliability of the streams: best_effort or reliable',
}


def _reader(parameter):
    """How a launch argument's text becomes the parameter's value: by the type of its default."""
    default = _TABLE[parameter].default if parameter in _TABLE else ''
    if isinstance(default, (bool, list)):
        return yaml.safe_load
    return type(default)


def _stylizer(context, *args, **kwargs):
    """The stylizer node, with an override for every stylizer argument that was given."""
    overrides = {}
    for argument, parameter in STYLIZER_ARGUMENTS.items():
        text = LaunchConfiguration(argument).perform(context)
        if text:
            try:
                overrides[parameter] = _reader(parameter)(text)
            except (ValueError, yaml.YAMLError):
                raise RuntimeError(f'launch argument {argument}:={text!r} is not a valid '
                                   f'{parameter} ({_DESCRIPTIONS[parameter]})') from None
    common = dict(namespace=LaunchConfiguration('namespace'), output='screen', emulate_tty=True,
                  parameters=[LaunchConfiguration('params_file'), overrides])
    workers = LaunchConfiguration('workers').perform(context)
    if not workers.isdigit() or int(workers) < 1:
        raise RuntimeError(f'launch argument workers:={workers!r} is not a number of processes >= 1')
    if int(workers) > 1:
        return _workers(context, int(workers), overrides)
    if LaunchConfiguration('managed').perform(context) != 'true':
        return [Node(package=PACKAGE, executable='stylizer', name='stylizer', **common)]
    # The managed node, brought to active: configure now, activate once it is inactive.
    node = LifecycleNode(package=PACKAGE, executable='stylizer_managed', name='stylizer', **common)

    def change(transition):
        return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node),
                                           transition_id=transition))

    # Once: a user's later `ros2 lifecycle set ... deactivate` must leave it inactive.
    activate = RegisterEventHandler(OnStateTransition(
        target_lifecycle_node=node, goal_state='inactive',
        entities=[change(Transition.TRANSITION_ACTIVATE)], handle_once=True))
    return [node, activate, change(Transition.TRANSITION_CONFIGURE)]


def _workers(context, count, overrides):
    """``count`` stylizer processes, ``stylizer_0`` ... (ROS 2 runs one Python thread per process:
    more processes use more cores), each with the params file's values and the overrides, and
    every ``count``-th performer of ``performers`` from the k-th."""
    if LaunchConfiguration('managed').perform(context) == 'true':
        raise RuntimeError('launch arguments workers and managed:=true do not combine')
    path = Path(LaunchConfiguration('params_file').perform(context))
    data = yaml.safe_load(path.read_text(encoding='utf-8')) or {}
    # The params file's keys name the node "stylizer"; the workers have names of their own.
    keys = [k for k in ('/**/stylizer', 'stylizer', '/stylizer', '/**') if k in data]
    values = {**(data[keys[0]].get('ros__parameters', {}) if keys else {}), **overrides}
    performers = list(values.get('performers', ['']))
    if count > len(performers):
        raise RuntimeError(f'launch argument workers:={count} is more than the {len(performers)} '
                           f'performers {performers}: give at least one performer per worker')
    return [Node(package=PACKAGE, executable='stylizer', name=f'stylizer_{k}',
                 namespace=LaunchConfiguration('namespace'), output='screen', emulate_tty=True,
                 parameters=[{**values, 'performers': performers[k::count]}])
            for k in range(count)]


def _robot_state_publisher(context, *args, **kwargs):
    """robot_state_publisher on the stylized stream, with the description file's text."""
    path = Path(LaunchConfiguration('robot_description_file').perform(context))
    try:
        description = path.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise RuntimeError(f'launch argument robot_description_file: cannot read {path} ({exc})') from None
    return [Node(
        package='robot_state_publisher', executable='robot_state_publisher',
        namespace=LaunchConfiguration('namespace'), output='screen',
        parameters=[{'robot_description': description}],
        remappings=[('joint_states', 'stylized/joint_states')],
    )]


def generate_launch_description():
    share = FindPackageShare(PACKAGE)
    arguments = [
        DeclareLaunchArgument(
            'params_file', default_value=PathJoinSubstitution([share, 'config', 'stylizer.yaml']),
            description='stylizer parameters (node_name: ros__parameters: ...)'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of every node started here'),
        *(DeclareLaunchArgument(name, default_value='',
                                description=f'{_DESCRIPTIONS[parameter]}; empty: from params_file')
          for name, parameter in STYLIZER_ARGUMENTS.items()),
        DeclareLaunchArgument('workers', default_value='1',
                              description='stylizer processes to share the performers out over '
                                          '(round robin): stylizer_0, stylizer_1, ... when above 1'),
        DeclareLaunchArgument('managed', default_value='false', choices=['true', 'false'],
                              description='run the stylizer as a managed (lifecycle) node, '
                                          'brought to active'),
        DeclareLaunchArgument('use_vmc', default_value='false', choices=['true', 'false'],
                              description='also start vmc_bridge (VMC/OSC in and out)'),
        DeclareLaunchArgument(
            'vmc_params_file', default_value=PathJoinSubstitution([share, 'config', 'vmc_bridge.yaml']),
            description='vmc_bridge parameters (OSC ports, avatar host)'),
        DeclareLaunchArgument('use_synthetic', default_value='false', choices=['true', 'false'],
                              description='also start synthetic_performer (a try-out without mocap)'),
        DeclareLaunchArgument('use_learned', default_value='false', choices=['true', 'false'],
                              description='also start learned_performer (new motion sampled from the '
                                          'SAAE model, no mocap)'),
        DeclareLaunchArgument('use_rsp', default_value='false', choices=['true', 'false'],
                              description='also start robot_state_publisher on stylized/joint_states '
                                          '(TF for RViz\'s RobotModel display)'),
        DeclareLaunchArgument(
            'robot_description_file',
            default_value=PathJoinSubstitution([share, 'urdf', 'canonical_skeleton.urdf']),
            description='URDF for robot_state_publisher (default: the canonical skeleton)'),
        DeclareLaunchArgument('synthetic_motion', default_value='walk',
                              choices=['walk', 'run', 'wave'],
                              description='what the synthetic performer performs'),
        DeclareLaunchArgument('learned_style', default_value='',
                              description='style the learned performer performs, one of its model '
                                          'card\'s styles; empty: the model\'s neutral style'),
    ]
    vmc_bridge = Node(
        package=PACKAGE, executable='vmc_bridge', name='vmc_bridge',
        namespace=LaunchConfiguration('namespace'), output='screen', emulate_tty=True,
        parameters=[LaunchConfiguration('vmc_params_file')],
        condition=IfCondition(LaunchConfiguration('use_vmc')),
    )
    performer = Node(
        package=PACKAGE, executable='synthetic_performer', name='synthetic_performer',
        namespace=LaunchConfiguration('namespace'), output='screen', emulate_tty=True,
        parameters=[{'motion': LaunchConfiguration('synthetic_motion')}],
        condition=IfCondition(LaunchConfiguration('use_synthetic')),
    )
    learned = Node(
        package=PACKAGE, executable='learned_performer', name='learned_performer',
        namespace=LaunchConfiguration('namespace'), output='screen', emulate_tty=True,
        # a string even when empty (launch_ros reads a bare substitution as YAML, '' as null)
        parameters=[{'style': ParameterValue(LaunchConfiguration('learned_style'), value_type=str)}],
        condition=IfCondition(LaunchConfiguration('use_learned')),
    )
    rsp = OpaqueFunction(function=_robot_state_publisher, condition=IfCondition(LaunchConfiguration('use_rsp')))
    return LaunchDescription([*arguments, OpaqueFunction(function=_stylizer), vmc_bridge, performer, learned,
                              rsp])
