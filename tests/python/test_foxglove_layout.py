"""The Foxglove layout (launch_scripts/foxglove/equiarm_layout.json) shows topics the suite publishes,
with message paths that exist in their types: every panel of the layout tree has a config and every
config a place in the tree; each topic is one a node publishes (its name is in the node's source, with
the type the panel needs), and each plotted field and filter is a field of that type's `.msg`."""

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LAYOUT = ROOT / "launch_scripts" / "foxglove" / "equiarm_layout.json"

# topic (namespace stripped) -> (message type's .msg file, the node source that publishes it)
PUBLISHED = {
    "camera/color/image_raw": ("msgs/ros_std/sensor_msgs/msg/Image.msg", "nodes/src/camera.rs"),
    "camera/depth/image_raw": ("msgs/ros_std/sensor_msgs/msg/Image.msg", "nodes/src/camera.rs"),
    "camera/camera_info": ("msgs/ros_std/sensor_msgs/msg/CameraInfo.msg", "nodes/src/camera.rs"),
    "/episodes": ("msgs/msg/EpisodeResult.msg", "nodes/src/sim.rs"),
    "/trainer/status": ("msgs/msg/TrainerStatus.msg", "nodes/src/trainer.rs"),
}
NAMESPACED = re.compile(r"^/(env\d+|eval)/(camera/.+)$")


def _fields(msg_file):
    """`name -> type` of a .msg file's fields (constants and comments skipped)."""
    out = {}
    for line in (ROOT / msg_file).read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or "=" in line:
            continue
        ty, name = line.split()[:2]
        out[name] = ty
    return out


def _leaves(node):
    if isinstance(node, str):
        return [node]
    return _leaves(node["first"]) + _leaves(node["second"])


def _topic_key(topic):
    m = NAMESPACED.match(topic)
    return m.group(2) if m else topic


def _check_topic(topic, where):
    key = _topic_key(topic)
    assert key in PUBLISHED, f"{where}: {topic} is not a topic the suite publishes"
    msg_file, source = PUBLISHED[key]
    assert f'"{key}"' in (ROOT / source).read_text(encoding="utf-8"), f"{where}: {source} no longer publishes {key}"
    return _fields(msg_file)


def _check_path(path, where):
    """A Foxglove message path `/topic{field==value}.field`: the topic, the filter field, the field."""
    m = re.match(r"^(/[\w/]+?)(\{(\w+)==(\w+)\})?\.(\w+)$", path)
    assert m, f"{where}: cannot read the message path {path!r}"
    topic, _, filt, value, field = m.groups()
    fields = _check_topic(topic, where)
    assert field in fields, f"{where}: {topic} has no field {field!r}"
    if filt:
        assert fields.get(filt) == "bool" and value in ("true", "false"), f"{where}: bad filter {filt}=={value}"


def _problems(layout):
    problems = []
    config = layout["configById"]
    leaves = _leaves(layout["layout"])
    if sorted(leaves) != sorted(config):
        problems.append(f"panels in the tree {sorted(leaves)} != configured panels {sorted(config)}")
    for pid, cfg in config.items():
        try:
            kind = pid.split("!", 1)[0]
            if kind == "Image":
                _check_topic(cfg["imageMode"]["imageTopic"], pid)
                _check_topic(cfg["imageMode"]["calibrationTopic"], pid)
            elif kind in ("RawMessages", "Table"):
                _check_topic(cfg["topicPath"], pid)
            elif kind == "Plot":
                assert cfg["paths"], f"{pid}: no paths"
                for p in cfg["paths"]:
                    _check_path(p["value"], pid)
            else:
                problems.append(f"{pid}: a panel kind this test does not know")
        except (AssertionError, KeyError) as e:
            problems.append(f"{pid}: {e!r}")
    return problems


def test_the_layout_shows_published_topics_and_real_fields():
    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    assert not _problems(layout)
    kinds = {pid.split("!", 1)[0] for pid in layout["configById"]}
    assert {"Image", "RawMessages", "Plot"} <= kinds, "camera images, trainer status and episode results"


def test_the_layout_check_sees_bad_panels():
    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    layout["configById"]["Plot!episodes"]["paths"][0]["value"] = "/episodes.no_such_field"
    layout["configById"]["RawMessages!trainerstatus"]["topicPath"] = "/trainer/state"
    layout["configById"]["Image!extra"] = {"imageMode": {"imageTopic": "/env0/camera/ir", "calibrationTopic": ""}}
    problems = "\n".join(_problems(layout))
    assert "no field 'no_such_field'" in problems
    assert "/trainer/state is not a topic" in problems
    assert "Image!extra" in problems and "panels in the tree" in problems
