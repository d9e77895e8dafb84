"""The parameter counts docs/ros_interface.md states are measured, not typed.

The sentence is generated from the code (`ros.parameters.counts_sentence`, from `declared_names`: what each
role declares with the package's parameter file) and the doc must contain it; over real Fast DDS, each node,
started as the launcher starts it, lists exactly those parameters through its parameter services (what
`ros2 param list` asks).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from rta_attitude import topics
from rta_attitude.ros.controller_node import ControllerNode
from rta_attitude.ros.filter_node import FilterNode
from rta_attitude.ros.parameters import COUNTED_ROLES, counts_sentence, declared_names
from rta_attitude.ros.plant_node import PlantNode
from rta_attitude.ros.recorder_node import RecorderNode
from rta_attitude.ros.scene_node import SceneNode
from rta_attitude.ros.spin import make_executor

DOC = Path(__file__).resolve().parents[1] / "docs" / "ros_interface.md"
NS = topics.DEFAULT_NAMESPACE
CLASSES = {topics.PLANT: PlantNode, topics.FILTER: FilterNode, topics.CONTROLLER: ControllerNode,
           topics.RECORDER: RecorderNode, topics.SCENE: SceneNode}


def test_the_doc_states_the_counts_the_code_declares() -> None:
    sentence = counts_sentence()
    assert sentence in " ".join(DOC.read_text().split()), f"docs/ros_interface.md must say: {sentence}"
    for role in COUNTED_ROLES:
        assert f"{len(declared_names(role))} {'parameters ' if role == COUNTED_ROLES[0] else ''}on " \
               f"`{topics.NODE_NAMES[role]}`" in sentence


@pytest.mark.dds
def test_each_running_node_lists_the_parameters_counted(tmp_path: Path) -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor("single", context=context)
    nodes: dict[str, Any] = {}
    listed: dict[str, list[str]] = {}
    try:
        for role, cls in CLASSES.items():
            extra = {"bag_path": str(tmp_path / "unused.mcap")} if role == topics.RECORDER else {}
            nodes[role] = cls(context=context, namespace=NS, parameter_overrides=[
                Parameter(k, value=v) for k, v in {"startup_timeout_s": 600.0, **extra}.items()])
            executor.add_node(nodes[role])
        probe = rclpy.create_node("param_list_probe", context=context)
        executor.add_node(probe)
        clients = {role: AsyncParameterClient(probe, f"{NS}/{topics.NODE_NAMES[role]}") for role in CLASSES}
        futures: dict[str, Any] = {}
        deadline = time.monotonic() + 120
        while len(listed) < len(CLASSES):
            assert time.monotonic() < deadline, f"listed {sorted(listed)}"
            executor.spin_once(timeout_sec=0.05)
            for role, client in clients.items():
                if role not in futures and client.services_are_ready():
                    futures[role] = client.list_parameters()  # as `ros2 param list`: every prefix, any depth
                elif role in futures and futures[role].done() and role not in listed:
                    listed[role] = sorted(futures[role].result().result.names)
    finally:
        executor.shutdown()
        for node in nodes.values():
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    for role in CLASSES:
        assert listed[role] == declared_names(role), role
