"""config/foxglove/actuator.json: a Foxglove layout for the node's topics. Every panel the layout places is
configured, and every plotted path names a topic the node publishes with the element the title promises."""

from __future__ import annotations

import json
import re
from pathlib import Path

LAYOUT = Path(__file__).resolve().parents[1] / "config" / "foxglove" / "actuator.json"
NODE_TOPICS = {"/joint_states", "/bldc_actuator/q_axis_state", "/bldc_actuator/phase_currents",
               "/bldc_actuator/winding_temperature", "/bldc_actuator/housing_temperature",
               "/bldc_actuator/torque_command", "/bldc_actuator/commands", "/diagnostics"}


def _leaves(node):
    if isinstance(node, str):
        yield node
    else:
        yield from _leaves(node["first"])
        yield from _leaves(node["second"])


def test_layout_panels_and_paths_match_the_node():
    from bldc_actuator.node import Q_AXIS_FIELDS

    doc = json.loads(LAYOUT.read_text())
    panels = list(_leaves(doc["layout"]))
    assert sorted(panels) == sorted(doc["configById"])
    q_paths = []
    for pid, cfg in doc["configById"].items():
        for p in cfg.get("paths", []):
            topic = p["value"].split(".")[0]
            assert topic in NODE_TOPICS, (pid, p["value"])
            m = re.match(r"/bldc_actuator/q_axis_state\.data\[(\d+)\]", p["value"])
            if m:
                q_paths.append((cfg["title"], int(m.group(1))))
    # the titles name the q_axis_state elements by index: they must be the node's layout
    named = {"i_q": 0, "i_d": 1, "i_q_ref": 2, "v_limit_q": 5, "v_magnitude_q": 7}
    for name, index in named.items():
        assert Q_AXIS_FIELDS[index] == name
    assert {i for _, i in q_paths} == set(named.values())
