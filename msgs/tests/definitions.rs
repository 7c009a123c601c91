//! The `.msg` files, the ROS 2 interface package and the generated definitions agree.

use equiarm_msgs::msg::{GripperCommand, Observation, Transition};
use equiarm_msgs::sensor_msgs::{CameraInfo, Image};
use equiarm_msgs::{ALL_TYPES, RosMessage, TypeInfo};
use std::path::Path;

fn dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn cmake_lists_every_msg_file_and_nothing_else() {
    let cmake = std::fs::read_to_string(dir().join("CMakeLists.txt")).unwrap();
    let mut listed: Vec<String> =
        cmake.split('"').filter(|s| s.starts_with("msg/") && s.ends_with(".msg")).map(str::to_string).collect();
    listed.sort();
    let mut files: Vec<String> = std::fs::read_dir(dir().join("msg"))
        .unwrap()
        .map(|e| format!("msg/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    files.sort();
    assert_eq!(listed, files);
    let pkg = std::fs::read_to_string(dir().join("package.xml")).unwrap();
    assert!(pkg.contains("<name>equiarm_msgs</name>"));
    assert!(pkg.contains("<member_of_group>rosidl_interface_packages</member_of_group>"));
}

#[test]
fn definitions_follow_rosbag2s_concatenated_format() {
    // own text first, verbatim
    assert!(Observation::DEFINITION.starts_with(Observation::MSG_TEXT));
    // then dependencies depth first, in sorted order, each once
    let order: Vec<&str> = Observation::DEFINITION.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
    assert_eq!(order, ["equiarm_msgs/GripperCommand", "std_msgs/Header", "builtin_interfaces/Time"]);
    let sep = format!("\n\n{}\nMSG: std_msgs/Header\n", "=".repeat(80));
    assert!(Image::DEFINITION.contains(&sep), "separator: blank line, 80 '=', MSG line");
    let order: Vec<&str> = CameraInfo::DEFINITION.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
    assert_eq!(order, ["sensor_msgs/RegionOfInterest", "std_msgs/Header", "builtin_interfaces/Time"]);
    assert_eq!(Transition::DEFINITION.matches("MSG: std_msgs/Header").count(), 1);
}

#[test]
fn names_and_constants_come_from_the_msg_files() {
    assert_eq!(GripperCommand::TYPE_NAME, "equiarm_msgs/msg/GripperCommand");
    assert_eq!(GripperCommand::DDS_TYPE_NAME, "equiarm_msgs::msg::dds_::GripperCommand_");
    assert_eq!(
        (GripperCommand::SOURCE_POLICY, GripperCommand::SOURCE_EXPERT, GripperCommand::SOURCE_RANDOM),
        (0, 1, 2)
    );
    assert_eq!(GripperCommand::SOURCE_TELEOP, 3);
    for t in ALL_TYPES {
        assert_eq!(TypeInfo::find(t.type_name), Some(t));
    }
    assert_eq!(TypeInfo::find("sensor_msgs/Image").unwrap().type_name, "sensor_msgs/msg/Image");
    assert!(TypeInfo::find("sensor_msgs/msg/Imag").is_none());
    assert_eq!(ALL_TYPES.len(), 17);
}
