"""What the simulator and identifier entry points share: start-up errors as one line, and the
Jazzy demo_nodes_py spin/shutdown shape (shared/ros_stack.md section 2)."""
import sys

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import (InvalidParameterTypeException, ParameterException,
                              ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException

from auv_ident.core.errors import AuvIdentError

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

RCLError = _rclpy.RCLError


def type_hint(err):
    """An extra hint for the commonest parameter mistake (an int given for a double)."""
    if isinstance(err, InvalidParameterTypeException) and "'DOUBLE'" in str(err):
        return ' (write floats with a decimal point, e.g. 5.0)'
    return ''


def run_node(prog, args, make_node, spin, on_exit=None):
    """rclpy.init, build the node (a bad parameter: one line, exit 2), spin until done or
    SIGINT/SIGTERM, then on_exit(node), destroy and shut down. Returns the exit status."""
    try:
        rclpy.init(args=args)
    except RCLError as err:     # unparsable --ros-args (rcl has logged the details)
        print(f'{prog}: error: {err}', file=sys.stderr)
        return 2
    try:
        node = make_node()
    except (AuvIdentError, ParameterException) as err:
        print(f'{prog}: error: {err}' + type_hint(err), file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    try:
        spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if rclpy.ok():      # a real error, not a signal that invalidated the context
            raise
    finally:
        if on_exit is not None:
            on_exit(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def declare_described(node, parameters, **descriptor):
    """Declare (name, default, description) parameters, each with a ParameterDescriptor
    carrying its description and the given fields (read_only=..., dynamic_typing=...)."""
    for name, default, text in parameters:
        node.declare_parameter(name, default, ParameterDescriptor(description=text,
                                                                  **descriptor))


def declare_read_only(node, parameters):
    """Declare parameters read-only: they are read once at start-up, so `ros2 param set` is
    refused rather than silently ignored."""
    declare_described(node, parameters, read_only=True)


def parameter_values(node, parameters):
    """{name: value} of the declared (name, default, description) parameters."""
    return {name: node.get_parameter(name).value for name, _, _ in parameters}


def param_or_none(node, name):
    """A parameter's value, or None if it is not set (ROS maps '[]' to not set)."""
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None
