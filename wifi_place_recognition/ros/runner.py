"""The one place for a node's life cycle: start, spin, Jazzy-style shutdown."""

import rclpy
from rclpy.executors import ExternalShutdownException


def run(make_node, args=None, startup_errors=(ValueError,)):
    """
    Spin ``make_node()`` until SIGINT/SIGTERM; return the exit code.

    A ``startup_errors`` exception while constructing the node (a bad model
    file, a bad parameter) is logged as one line and gives exit code 1.
    """
    rclpy.init(args=args)
    try:
        node = make_node()
    except startup_errors as exc:
        rclpy.logging.get_logger(getattr(make_node, '__name__', 'node')) \
            .error(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return 1
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
