"""Consistency of the Python side with the .msg files: the hand-written Cyclone DDS IDL types in
equiarm_idl.py declare the fields of msgs/msg/*.msg (and of the upstream standard types) in the same
order with the same types, and msgs/ros_std/ declares the upstream Jazzy field lists."""

import pathlib

import pytest
from cyclonedds.idl.types import array, sequence
from rosbags.typesys import get_types_from_msg

import equiarm_idl as idl
import golden

ROOT = pathlib.Path(__file__).resolve().parents[2]
IDL_BASE = {"int32": "int32", "uint32": "uint32", "uint64": "uint64", "uint8": "uint8", "float32": "float32",
            "float64": "float64", "str": "string", "bool": "bool"}


def idl_fields(cls):
    """[(name, kind, detail)] of an IDL dataclass, in declaration order."""
    out = []
    for name, ann in cls.__annotations__.items():
        text = getattr(ann, "__name__", None) or repr(ann)
        if isinstance(ann, type) and hasattr(ann, "__idl_typename__"):
            out.append((name, "NAME", idl.ros_name(ann)))
        elif hasattr(ann, "__metadata__"):
            meta = ann.__metadata__[0]
            if isinstance(meta, (sequence, array)):
                sub = meta.subtype
                sub_name = idl.ros_name(sub) if hasattr(sub, "__idl_typename__") else IDL_BASE[sub.__metadata__[0]]
                kind = "ARRAY" if isinstance(meta, array) else "SEQUENCE"
                out.append((name, kind, (sub_name, meta.length if kind == "ARRAY" else 0)))
            else:
                out.append((name, "BASE", IDL_BASE[meta]))
        else:
            out.append((name, "BASE", IDL_BASE[text]))
    return out


def msg_fields(ts, name):
    out = []
    for fname, (kind, detail) in ts.fielddefs[name][1]:
        if kind.name == "NAME":
            out.append((fname, "NAME", detail))
        elif kind.name in ("ARRAY", "SEQUENCE"):
            (ekind, edetail), n = detail
            sub = edetail if ekind.name == "NAME" else edetail[0]
            out.append((fname, kind.name, (sub, n)))
        else:
            out.append((fname, "BASE", detail[0]))
    return out


@pytest.fixture(scope="module")
def ts():
    return golden.typestore()


@pytest.mark.parametrize("cls", idl.ALL, ids=lambda c: c.__name__)
def test_idl_types_match_the_msg_definitions(ts, cls):
    assert idl_fields(cls) == msg_fields(ts, idl.ros_name(cls))


def test_ros_std_msgs_declare_the_upstream_fields(ts):
    golden.check_std_msgs_match_upstream(ts)


def test_every_own_msg_file_has_an_idl_type():
    own = {f"equiarm_msgs/msg/{p.stem}" for p in (ROOT / "msgs" / "msg").glob("*.msg")}
    assert own == {idl.ros_name(c) for c in idl.ALL if idl.ros_name(c).startswith("equiarm_msgs/")}


def test_a_misdeclared_field_is_caught(ts):
    text = (ROOT / "msgs" / "msg" / "GripperCommand.msg").read_text().replace("float32 dx", "float64 dx")
    bad = get_types_from_msg(text, "equiarm_msgs/msg/GripperCommand")
    ts2 = golden.typestore()
    ts2.fielddefs.update(bad)
    assert idl_fields(idl.GripperCommand) != msg_fields(ts2, "equiarm_msgs/msg/GripperCommand")
