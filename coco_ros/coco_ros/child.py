"""A child process of the ROS launcher: ``python -m coco_ros.child FD PARENT_PID``.

The same child as ``coco_core.processes.child`` (it builds and runs its ``<process>``'s part of the
application), with an rclpy node of its own, named after the launcher's node and the process
(``<launcher node>_<process>``), whose executor hosts the process's activities as the launcher's
executor hosts its own, by the launch's one deployment plan (``--executor-threads`` included):
ROSInterface, TFBridge and BagReplay work in a child as in the launcher.
"""

from __future__ import annotations

import sys

from coco_core import Application, CocoError
from coco_core.processes.child import ChildProcess, main
from coco_core.processes.messages import Config
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from .deployment import RosChildConfig
from .hosting import ExecutorHost

from .component_parameters import ComponentParameters
from .launcher import host_in_node, node_name, run_hosted
from .mirror import PortMirrors
from .parameters import ArgParameters
from .rosout import RosoutLogging


def without_node_renames(ros_args: list[str]) -> list[str]:
    """``ros_args`` less its node renames (``-r __node:=NAME``, ``--remap __name:=NAME``): the
    child's node is named after the launcher's final name already, and a rename would give every
    process's node the launcher's name (two nodes of one name: their parameters and /rosout lines
    could not be told apart)."""
    kept: list[str] = []
    words = iter(ros_args)
    for word in words:
        if word in ("-r", "--remap"):
            rule = next(words, "")
            if rule.split(":=", 1)[0].rsplit(":", 1)[-1] in ("__node", "__name"):
                continue
            kept += [word, rule]
        else:
            kept.append(word)
    return kept


class RosChildProcess(ChildProcess):
    """A child that hosts its part of the application in an rclpy node."""

    node: Node | None = None
    host: ExecutorHost | None = None
    """The node's host, once the application stopped cleanly (closed by :meth:`release`)."""

    def run_app(self, app: Application, config: Config) -> bool:
        import rclpy

        given = config.host
        if not isinstance(given, RosChildConfig):
            raise CocoError(f"process {app.process}: the launcher sent {type(given).__name__}, not the ROS launcher's "
                            "RosChildConfig (a coco_ros child of another launcher)")
        rclpy.init(args=["launcher", *without_node_renames(list(given.ros_args))],
                   signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = self.node = Node(f"{given.node}_{node_name(app.process)}",
                                    automatically_declare_parameters_from_overrides=True)
            # The launcher resolved the args (its -p values included) and reported the -p values no arg
            # takes: a child's node shows the args and refuses changes as the launcher's does.
            ArgParameters(node, config.deployment.spec).declare({})
            ComponentParameters(node, app).declare()
            host, executor = host_in_node(node, app, config.deployment)
            with (RosoutLogging(node),  # this process's log lines on /rosout, under its node's name
                  PortMirrors(node, app, config.deployment.spec, list(given.expose))):
                clean = run_hosted(app, host, executor)
            self.host = host if clean else None  # else a hung callback may still use it: left to the exit
            return clean
        except BaseException:
            self.release()
            raise

    def release(self) -> None:
        """The node and rclpy, after the launcher heard that this process stopped: destroying a node
        and shutting rclpy down took over a second on a loaded machine, and a launcher that waited
        for it before it learnt that the activities had stopped called them hung."""
        import rclpy

        if self.host is not None:
            self.host.close()
        if self.node is not None:
            self.node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main(kind=RosChildProcess))
