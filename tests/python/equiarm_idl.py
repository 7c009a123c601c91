"""equiarm's messages as Cyclone DDS Python IDL types, named and laid out as ROS 2 (rmw_cyclonedds)
puts them on the wire: topics `rt/<name>`, types `<pkg>::msg::dds_::<Type>_`, XCDR1.

Written by hand from the ROS 2 definitions (not generated from our .msg files), so the tests that use
it check our Rust encoder against an independent implementation. Users without a ROS installation can
use it to talk to the equiarm nodes from Python with nothing but `pip install cyclonedds`.

`uint8[]` members use Cyclone's bytes machine (same wire format as `sequence[uint8]`, but decoded to
`bytes` instead of a list of ints: ~20x faster for images).
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl._machinery import BytesMachine
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32, uint64


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time = field(default_factory=Time)


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: sequence[uint8] = field(default_factory=bytes)


@dataclass
class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
    x_offset: uint32 = 0
    y_offset: uint32 = 0
    height: uint32 = 0
    width: uint32 = 0
    do_rectify: bool = False


@dataclass
class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    distortion_model: str = ""
    d: sequence[float64] = field(default_factory=list)
    k: array[float64, 9] = field(default_factory=lambda: [0.0] * 9)
    r: array[float64, 9] = field(default_factory=lambda: [0.0] * 9)
    p: array[float64, 12] = field(default_factory=lambda: [0.0] * 12)
    binning_x: uint32 = 0
    binning_y: uint32 = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped] = field(default_factory=list)


@dataclass
class GripperCommand(IdlStruct, typename="equiarm_msgs::msg::dds_::GripperCommand_"):
    header: Header = field(default_factory=Header)
    obs_seq: uint64 = 0
    open_ratio: float32 = 0.0
    dx: float32 = 0.0
    dy: float32 = 0.0
    dz: float32 = 0.0
    dtheta: float32 = 0.0
    source: uint8 = 0


SOURCE_POLICY, SOURCE_EXPERT, SOURCE_RANDOM, SOURCE_TELEOP = 0, 1, 2, 3


@dataclass
class Observation(IdlStruct, typename="equiarm_msgs::msg::dds_::Observation_"):
    header: Header = field(default_factory=Header)
    seq: uint64 = 0
    env: str = ""
    episode: uint32 = 0
    step: uint32 = 0
    height: uint32 = 0
    width: uint32 = 0
    color: sequence[uint8] = field(default_factory=bytes)
    depth: sequence[uint8] = field(default_factory=bytes)
    holding: bool = False
    expert_action: GripperCommand = field(default_factory=GripperCommand)
    terminal: bool = False


@dataclass
class Transition(IdlStruct, typename="equiarm_msgs::msg::dds_::Transition_"):
    """One step; its two observations are the Observations of the same `env` whose `seq` are
    `obs_seq` and `next_obs_seq` (join on (env, seq); see launch_scripts/bag_transitions.py)."""
    header: Header = field(default_factory=Header)
    env: str = ""
    episode: uint32 = 0
    step: uint32 = 0
    obs_seq: uint64 = 0
    next_obs_seq: uint64 = 0
    action: GripperCommand = field(default_factory=GripperCommand)
    reward: float32 = 0.0
    done: bool = False
    timeout: bool = False
    expert: bool = False


@dataclass
class EpisodeResult(IdlStruct, typename="equiarm_msgs::msg::dds_::EpisodeResult_"):
    header: Header = field(default_factory=Header)
    env: str = ""
    task: str = ""
    seed: uint64 = 0
    episode: uint32 = 0
    steps: uint32 = 0
    success: bool = False
    ret: float32 = 0.0
    discounted_return: float32 = 0.0
    expert: bool = False
    eval: bool = False


@dataclass
class PolicyWeights(IdlStruct, typename="equiarm_msgs::msg::dds_::PolicyWeights_"):
    header: Header = field(default_factory=Header)
    run_id: str = ""
    version: uint64 = 0
    updates: uint64 = 0
    model: str = ""
    format: str = ""
    data: sequence[uint8] = field(default_factory=bytes)


@dataclass
class TrainerStatus(IdlStruct, typename="equiarm_msgs::msg::dds_::TrainerStatus_"):
    header: Header = field(default_factory=Header)
    updates: uint64 = 0
    transitions: uint64 = 0
    buffer_size: uint64 = 0
    expert_transitions: uint64 = 0
    critic_loss: float32 = 0.0
    actor_loss: float32 = 0.0
    alpha: float32 = 0.0
    updates_per_s: float32 = 0.0
    transitions_per_s: float32 = 0.0
    last_eval_return: float32 = 0.0
    last_eval_success_rate: float32 = 0.0
    last_eval_episodes: uint32 = 0


ALL = [Time, Clock, Header, Image, RegionOfInterest, CameraInfo, GripperCommand, Observation, Transition,
       EpisodeResult, PolicyWeights, TrainerStatus]

for _cls, _member in ((Image, "data"), (Observation, "color"), (Observation, "depth"), (PolicyWeights, "data")):
    _cls.__idl__.populate()
    for _m in (_cls.__idl__.v1_machine, _cls.__idl__.v2_machine):
        _m.members_machines[_member] = BytesMachine()


def ros_name(cls) -> str:
    """`pkg/msg/Type` for an IDL class (`pkg::msg::dds_::Type_`)."""
    pkg, _, _, name = cls.__idl_typename__.split("::")
    return f"{pkg}/msg/{name[:-1]}"


def by_ros_name(name: str):
    for cls in ALL:
        if ros_name(cls) == name:
            return cls
    raise KeyError(name)
