//! URDF assets: the gripper, cube, flat block, table, drawer cabinet and bowl of the paper's tasks,
//! and the 7-DoF arm that carries the gripper in view.
//!
//! Each file is read once, parsed with the urdf-rs that `rapier3d-urdf` re-exports, validated, and kept
//! as a [`urdf_rs::Robot`]; every reset builds fresh rapier bodies from it with
//! `rapier3d_urdf::UrdfRobot::from_robot`. The bundled copies of `urdf/*.urdf` are compiled in
//! ([`Assets::bundled`]); [`Assets::from_dir`] reads a directory instead.
//!
//! Limitations: only `box`, `cylinder`, `sphere` and `capsule` collision geometry is accepted (meshes
//! would be dropped silently by rapier3d-urdf without its mesh features, so they are rejected here).
//! Colours come from each link's first `<visual>` material (inline colour, or a robot-level material
//! by name); one colour per link. `<mimic>`, effort and velocity limits are ignored by the loader.

use std::collections::HashMap;
use std::path::Path;

use rapier3d_urdf::urdf_rs;

use crate::error::{Result, SimError};

/// The asset files the simulator knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AssetKind {
    /// `gripper.urdf`: the floating parallel-jaw gripper, a palm with two prismatic fingers.
    Gripper,
    /// `cube.urdf`: the 0.05 m, 0.1 kg red cube of pushing, picking and block in bowl.
    Cube,
    /// `flat_block.urdf`: the 0.08 × 0.08 × 0.05 m, 0.5 kg blue block of pulling (two per episode).
    FlatBlock,
    /// `table.urdf`: the 1.2 × 1.2 m ground slab with its top face at z = 0.
    Table,
    /// `drawer.urdf`: the cabinet with a drawer on a prismatic joint and a handle fixed to it.
    Drawer,
    /// `bowl.urdf`: the box-built bowl of block in bowl (rim about 0.155 m across, 0.063 m tall).
    Bowl,
    /// `arm.urdf`: the 7-DoF arm drawn carrying the gripper (seen, not simulated; [`crate::arm`]).
    Arm,
}

impl AssetKind {
    /// Every asset kind, each once.
    pub const ALL: [AssetKind; 7] = [
        AssetKind::Gripper,
        AssetKind::Cube,
        AssetKind::FlatBlock,
        AssetKind::Table,
        AssetKind::Drawer,
        AssetKind::Bowl,
        AssetKind::Arm,
    ];

    /// File name inside the `urdf/` directory.
    pub fn file_name(self) -> &'static str {
        match self {
            AssetKind::Gripper => "gripper.urdf",
            AssetKind::Cube => "cube.urdf",
            AssetKind::FlatBlock => "flat_block.urdf",
            AssetKind::Table => "table.urdf",
            AssetKind::Drawer => "drawer.urdf",
            AssetKind::Bowl => "bowl.urdf",
            AssetKind::Arm => "arm.urdf",
        }
    }

    pub(crate) fn bundled_text(self) -> &'static str {
        match self {
            AssetKind::Gripper => include_str!("../../../urdf/gripper.urdf"),
            AssetKind::Cube => include_str!("../../../urdf/cube.urdf"),
            AssetKind::FlatBlock => include_str!("../../../urdf/flat_block.urdf"),
            AssetKind::Table => include_str!("../../../urdf/table.urdf"),
            AssetKind::Drawer => include_str!("../../../urdf/drawer.urdf"),
            AssetKind::Bowl => include_str!("../../../urdf/bowl.urdf"),
            AssetKind::Arm => include_str!("../../../urdf/arm.urdf"),
        }
    }
}

/// One parsed and validated URDF.
#[derive(Clone, Debug)]
pub struct Asset {
    /// Where it came from (for error messages).
    pub file: String,
    /// The parsed URDF: links, joints and robot-level materials.
    pub robot: urdf_rs::Robot,
    /// Linear RGB colour in [0, 1] of each URDF link, indexed like `robot.links`.
    pub link_colors: Vec<[f32; 3]>,
}

impl Asset {
    /// Index of the URDF link named `name`, or an error naming the file and link.
    pub fn link_index(&self, name: &str) -> Result<usize> {
        self.robot.links.iter().position(|l| l.name == name).ok_or_else(|| SimError::UrdfInvalid {
            file: self.file.clone(),
            element: format!("link `{name}`"),
            message: "the simulator needs this link but the file has none by that name".into(),
        })
    }

    /// Index of the URDF joint named `name`, or an error naming the file and joint.
    pub fn joint_index(&self, name: &str) -> Result<usize> {
        self.robot.joints.iter().position(|j| j.name == name).ok_or_else(|| SimError::UrdfInvalid {
            file: self.file.clone(),
            element: format!("joint `{name}`"),
            message: "the simulator needs this joint but the file has none by that name".into(),
        })
    }
}

/// All assets, parsed once and shared (read-only) by every env.
#[derive(Clone, Debug)]
pub struct Assets {
    assets: HashMap<AssetKind, Asset>,
}

impl Assets {
    /// The copies of `urdf/*.urdf` compiled into the crate.
    pub fn bundled() -> Result<Self> {
        let mut assets = HashMap::new();
        for kind in AssetKind::ALL {
            let name = format!("urdf/{}", kind.file_name());
            assets.insert(kind, parse_urdf(&name, kind.bundled_text())?);
        }
        Self::check(assets)
    }

    /// Reads every asset from `dir` (a directory laid out like the repository's `urdf/`).
    pub fn from_dir(dir: &Path) -> Result<Self> {
        let mut assets = HashMap::new();
        for kind in AssetKind::ALL {
            assets.insert(kind, load_urdf(&dir.join(kind.file_name()))?);
        }
        Self::check(assets)
    }

    fn check(assets: HashMap<AssetKind, Asset>) -> Result<Self> {
        let a = Self { assets };
        let g = a.get(AssetKind::Gripper);
        g.link_index("palm")?;
        g.link_index("left_finger")?;
        g.link_index("right_finger")?;
        g.joint_index("left_finger_joint")?;
        g.joint_index("right_finger_joint")?;
        let d = a.get(AssetKind::Drawer);
        d.link_index("cabinet")?;
        d.link_index("drawer")?;
        d.link_index("handle")?;
        d.joint_index("drawer_joint")?;
        crate::arm::Chain::of(a.get(AssetKind::Arm))?;
        Ok(a)
    }

    /// The asset of `kind` (every kind is present).
    pub fn get(&self, kind: AssetKind) -> &Asset {
        // Construction inserts every kind, so this lookup cannot fail.
        &self.assets[&kind]
    }
}

/// Reads and parses one URDF file.
pub fn load_urdf(path: &Path) -> Result<Asset> {
    let text = std::fs::read_to_string(path).map_err(|cause| SimError::Read { file: path.to_path_buf(), cause })?;
    parse_urdf(&path.display().to_string(), &text)
}

/// Parses and validates URDF text; `file` is used in error messages.
pub fn parse_urdf(file: &str, text: &str) -> Result<Asset> {
    let robot = urdf_rs::read_from_string(text).map_err(|e| match locate_xml_error(text) {
        // The parser's message does not say where; name the element ourselves when we can.
        Some((element, message)) => {
            SimError::UrdfInvalid { file: file.to_string(), element, message: format!("{message} (parser: {e})") }
        }
        None => SimError::UrdfParse { file: file.to_string(), message: e.to_string() },
    })?;
    validate(file, &robot)?;
    let materials: HashMap<&str, [f32; 3]> =
        robot.materials.iter().filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), rgb(c.rgba.0)))).collect();
    let mut link_colors = Vec::with_capacity(robot.links.len());
    for link in &robot.links {
        let mut color = [0.6, 0.6, 0.6];
        if let Some(mat) = link.visual.iter().find_map(|v| v.material.as_ref()) {
            if let Some(c) = &mat.color {
                color = rgb(c.rgba.0);
            } else if let Some(c) = materials.get(mat.name.as_str()) {
                color = *c;
            } else {
                return Err(SimError::UrdfInvalid {
                    file: file.to_string(),
                    element: format!("link `{}` material `{}`", link.name, mat.name),
                    message: "material has no colour and no robot-level material of that name".into(),
                });
            }
        }
        link_colors.push(color);
    }
    Ok(Asset { file: file.to_string(), robot, link_colors })
}

const NUMERIC_ATTRIBUTES: [&str; 22] = [
    "value",
    "xyz",
    "rpy",
    "size",
    "radius",
    "length",
    "lower",
    "upper",
    "effort",
    "velocity",
    "ixx",
    "ixy",
    "ixz",
    "iyy",
    "iyz",
    "izz",
    "rgba",
    "scale",
    "multiplier",
    "offset",
    "damping",
    "friction",
];
const JOINT_TYPES: [&str; 7] = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "spherical"];

/// A light scan of URDF text for the errors urdf-rs reports without a location: a numeric attribute
/// that is not a number, or an unknown joint type. Returns ("line N: <owner> <tag attr=...>", message).
fn locate_xml_error(text: &str) -> Option<(String, String)> {
    let mut owner = String::from("robot");
    let mut pos = 0;
    while let Some(off) = text[pos..].find('<') {
        let start = pos + off;
        if text[start..].starts_with("<!--") {
            pos = start + text[start..].find("-->").map(|e| e + 3)?;
            continue;
        }
        let end = start + text[start..].find('>')?;
        pos = end + 1;
        let tag = text[start + 1..end].trim_end_matches('/').trim();
        if tag.starts_with(['/', '?', '!']) {
            continue;
        }
        let line = text[..start].matches('\n').count() + 1;
        let (name, rest) = tag.split_once(char::is_whitespace).unwrap_or((tag, ""));
        let attrs = parse_attributes(rest);
        let attr = |k: &str| attrs.iter().find(|(a, _)| *a == k).map(|(_, v)| *v);
        if (name == "link" || name == "joint")
            && let Some(n) = attr("name")
        {
            owner = format!("{name} `{n}`");
        }
        if name == "joint"
            && let Some(t) = attr("type")
            && !JOINT_TYPES.contains(&t)
        {
            return Some((
                format!("line {line}: {owner} <joint type=\"{t}\">"),
                format!("unknown joint type `{t}` (expected one of {})", JOINT_TYPES.join(", ")),
            ));
        }
        for (k, v) in &attrs {
            if !NUMERIC_ATTRIBUTES.contains(k) {
                continue;
            }
            if let Some(bad) = v.split_whitespace().find(|tok| tok.parse::<f64>().is_err()) {
                return Some((
                    format!("line {line}: {owner} <{name} {k}=\"{v}\">"),
                    format!("`{bad}` is not a number"),
                ));
            }
        }
    }
    None
}

fn parse_attributes(s: &str) -> Vec<(&str, &str)> {
    let mut out = Vec::new();
    let mut rest = s;
    while let Some(eq) = rest.find('=') {
        let key = rest[..eq].trim();
        let after = rest[eq + 1..].trim_start();
        let Some(q) = after.chars().next().filter(|c| *c == '"' || *c == '\'') else {
            break;
        };
        let Some(close) = after[1..].find(q) else {
            break;
        };
        out.push((key, &after[1..1 + close]));
        rest = &after[close + 2..];
    }
    out
}

fn rgb(c: [f64; 4]) -> [f32; 3] {
    [c[0] as f32, c[1] as f32, c[2] as f32].map(|x| x.clamp(0.0, 1.0))
}

fn invalid(file: &str, element: String, message: impl Into<String>) -> SimError {
    SimError::UrdfInvalid { file: file.to_string(), element, message: message.into() }
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn validate(file: &str, robot: &urdf_rs::Robot) -> Result<()> {
    if robot.links.is_empty() {
        return Err(invalid(file, format!("robot `{}`", robot.name), "has no links"));
    }
    let mut names = HashMap::new();
    for link in &robot.links {
        if names.insert(link.name.as_str(), ()).is_some() {
            return Err(invalid(file, format!("link `{}`", link.name), "duplicate link name"));
        }
        let el = |what: &str| format!("link `{}` {what}", link.name);
        let i = &link.inertial;
        if !(i.mass.value.is_finite() && i.mass.value >= 0.0) {
            return Err(invalid(
                file,
                el("<inertial><mass>"),
                format!("mass {} is not a finite non-negative number", i.mass.value),
            ));
        }
        let t = &i.inertia;
        if !finite(&[t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz]) || t.ixx < 0.0 || t.iyy < 0.0 || t.izz < 0.0 {
            return Err(invalid(file, el("<inertial><inertia>"), "inertia must be finite with non-negative diagonal"));
        }
        if !finite(&i.origin.xyz.0) || !finite(&i.origin.rpy.0) {
            return Err(invalid(file, el("<inertial><origin>"), "non-finite origin"));
        }
        for (k, c) in link.collision.iter().enumerate() {
            let el = el(&format!("<collision> #{k}"));
            if !finite(&c.origin.xyz.0) || !finite(&c.origin.rpy.0) {
                return Err(invalid(file, el, "non-finite origin"));
            }
            check_geometry(file, el, &c.geometry)?;
        }
    }
    for joint in &robot.joints {
        let el = |what: &str| format!("joint `{}`{what}", joint.name);
        for (role, l) in [("parent", &joint.parent.link), ("child", &joint.child.link)] {
            if !names.contains_key(l.as_str()) {
                return Err(invalid(file, el(&format!(" <{role} link=\"{l}\">")), "names a link that does not exist"));
            }
        }
        if !finite(&joint.origin.xyz.0) || !finite(&joint.origin.rpy.0) {
            return Err(invalid(file, el(" <origin>"), "non-finite origin"));
        }
        let a = joint.axis.xyz.0;
        if !finite(&a) || a.iter().map(|x| x * x).sum::<f64>() < 1e-12 {
            return Err(invalid(file, el(" <axis>"), "axis must be finite and non-zero"));
        }
        let l = &joint.limit;
        if !l.lower.is_finite() || !l.upper.is_finite() || l.lower > l.upper {
            return Err(invalid(
                file,
                el(" <limit>"),
                format!("limits [{}, {}] must be finite with lower <= upper", l.lower, l.upper),
            ));
        }
    }
    Ok(())
}

fn check_geometry(file: &str, el: String, g: &urdf_rs::Geometry) -> Result<()> {
    use urdf_rs::Geometry as G;
    let ok = match g {
        G::Box { size } => finite(&size.0) && size.0.iter().all(|x| *x > 0.0),
        G::Cylinder { radius, length } | G::Capsule { radius, length } => {
            finite(&[*radius, *length]) && *radius > 0.0 && *length > 0.0
        }
        G::Sphere { radius } => radius.is_finite() && *radius > 0.0,
        G::Mesh { filename, .. } => {
            return Err(invalid(
                file,
                el,
                format!("mesh `{filename}` is not supported (use boxes, cylinders, spheres or capsules)"),
            ));
        }
    };
    if ok { Ok(()) } else { Err(invalid(file, el, "geometry sizes must be finite and positive")) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_assets_parse_with_colours() {
        let a = Assets::bundled().unwrap();
        let cube = a.get(AssetKind::Cube);
        assert_eq!(cube.link_colors.len(), 1);
        assert!(cube.link_colors[0][0] > 0.8 && cube.link_colors[0][1] < 0.2, "cube is red");
        let g = a.get(AssetKind::Gripper);
        let palm = g.link_index("palm").unwrap();
        let finger = g.link_index("left_finger").unwrap();
        // Robot-level materials are resolved by name.
        assert_ne!(g.link_colors[palm], g.link_colors[finger]);
        let d = a.get(AssetKind::Drawer);
        assert_eq!(d.robot.joints.len(), 2);
    }

    #[test]
    fn bundled_files_match_the_urdf_directory() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../urdf");
        let from_disk = Assets::from_dir(&dir).unwrap();
        for kind in AssetKind::ALL {
            assert_eq!(from_disk.get(kind).robot.links.len(), Assets::bundled().unwrap().get(kind).robot.links.len());
        }
    }

    #[test]
    fn missing_file_names_the_file() {
        let err = load_urdf(Path::new("no/such/dir/ghost.urdf")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("ghost.urdf"), "{msg}");
    }

    const GOOD: &str = r#"<robot name="r">
      <link name="a"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
        <collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
      <link name="b"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
      <joint name="j" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/>
        <limit lower="0" upper="0.1" effort="1" velocity="1"/></joint>
    </robot>"#;

    #[test]
    fn good_urdf_parses() {
        parse_urdf("good.urdf", GOOD).unwrap();
    }

    #[test]
    fn unknown_joint_type_fails_naming_file_and_element() {
        let bad = GOOD.replace(r#"type="prismatic""#, r#"type="telescopic""#);
        let msg = parse_urdf("bad_joint.urdf", &bad).unwrap_err().to_string();
        assert!(msg.contains("bad_joint.urdf"), "{msg}");
        assert!(msg.contains("joint `j`") && msg.contains("telescopic") && msg.contains("line 5"), "{msg}");
    }

    #[test]
    fn joint_to_unknown_link_fails_naming_joint() {
        let bad = GOOD.replace(r#"<child link="b"/>"#, r#"<child link="nowhere"/>"#);
        let msg = parse_urdf("bad_link.urdf", &bad).unwrap_err().to_string();
        assert!(msg.contains("bad_link.urdf") && msg.contains("joint `j`") && msg.contains("nowhere"), "{msg}");
    }

    #[test]
    fn missing_required_joint_fails_naming_it() {
        let msg = match parse_urdf("g.urdf", GOOD).unwrap().joint_index("left_finger_joint") {
            Err(e) => e.to_string(),
            Ok(_) => panic!("joint should be missing"),
        };
        assert!(msg.contains("g.urdf") && msg.contains("left_finger_joint"), "{msg}");
    }

    #[test]
    fn bad_number_fails_naming_file_and_element() {
        let bad = GOOD.replace(r#"<mass value="1"/>"#, r#"<mass value="heavy"/>"#);
        let msg = parse_urdf("bad_mass.urdf", &bad).unwrap_err().to_string();
        assert!(msg.contains("bad_mass.urdf"), "{msg}");
        assert!(msg.contains("link `a`") && msg.contains("<mass value=\"heavy\">"), "{msg}");
        let bad = GOOD.replace(r#"<axis xyz="1 0 0"/>"#, r#"<axis xyz="1 zero 0"/>"#);
        let msg = parse_urdf("bad_axis.urdf", &bad).unwrap_err().to_string();
        assert!(msg.contains("bad_axis.urdf") && msg.contains("joint `j`") && msg.contains("`zero`"), "{msg}");
        let bad = GOOD.replace(r#"<mass value="1"/>"#, r#"<mass value="NaN"/>"#);
        let msg = parse_urdf("nan_mass.urdf", &bad).unwrap_err().to_string();
        assert!(msg.contains("nan_mass.urdf") && msg.contains("link `a`") && msg.contains("mass"), "{msg}");
        let bad = GOOD.replace(r#"size="0.1 0.1 0.1""#, r#"size="0.1 -0.1 0.1""#);
        let msg = parse_urdf("neg_box.urdf", &bad).unwrap_err().to_string();
        assert!(msg.contains("neg_box.urdf") && msg.contains("<collision> #0"), "{msg}");
    }
}
