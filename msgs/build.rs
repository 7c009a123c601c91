//! Generates the Rust message types from the `.msg` files, so the `.msg` text stays the single source
//! of truth for field order, field types, units (in comments) and the schema text the recorder writes.
//!
//! Inputs: `msg/*.msg` (package `equiarm_msgs`, the ROS 2 interface package colcon builds) and
//! `ros_std/<package>/msg/*.msg` (the standard types we use: field lists as in ROS 2, our comments).
//! Output: `$OUT_DIR/messages.rs`, one module per package, included by `src/lib.rs`.
//!
//! Supported `.msg` syntax: primitive types, `string`, `string<=N`, nested `pkg/Type` or `Type`,
//! arrays `T[]`, `T[N]` (N <= 32), `T[<=N]`, constants `TYPE NAME=value` of primitive types, `#`
//! comments. Not supported (the build fails naming file and line): `wstring`, field default values.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const OWN_PACKAGE: &str = "equiarm_msgs";

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    collect(&root.join("msg"), OWN_PACKAGE, &mut files);
    let std_root = root.join("ros_std");
    println!("cargo:rerun-if-changed={}", std_root.display());
    println!("cargo:rerun-if-changed={}", root.join("msg").display());
    let mut packages: Vec<_> = read_dir_sorted(&std_root);
    packages.retain(|p| p.is_dir());
    for pkg in packages {
        let name = pkg.file_name().unwrap().to_string_lossy().to_string();
        collect(&pkg.join("msg"), &name, &mut files);
    }

    let mut specs = BTreeMap::new();
    for (package, path) in &files {
        println!("cargo:rerun-if-changed={}", path.display());
        let text = std::fs::read_to_string(path).unwrap_or_else(|e| fail(path, 0, &format!("cannot read: {e}")));
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        let spec = parse(package, &name, &text, path);
        specs.insert(format!("{package}/{name}"), spec);
    }
    for spec in specs.values() {
        for f in &spec.fields {
            if let Base::Msg(full) = &f.base
                && !specs.contains_key(full)
            {
                fail(&spec.path, f.line, &format!("unknown message type '{full}'"));
            }
        }
    }
    let code = generate(&specs);
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("messages.rs");
    std::fs::write(&out, code).expect("writing generated messages.rs");
}

fn read_dir_sorted(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = match std::fs::read_dir(dir) {
        Ok(rd) => rd.filter_map(|e| e.ok().map(|e| e.path())).collect(),
        Err(e) => fail(dir, 0, &format!("cannot list directory: {e}")),
    };
    v.sort();
    v
}

fn collect(dir: &Path, package: &str, out: &mut Vec<(String, PathBuf)>) {
    for p in read_dir_sorted(dir) {
        if p.extension().is_some_and(|e| e == "msg") {
            out.push((package.to_string(), p));
        }
    }
}

fn fail(path: &Path, line: usize, what: &str) -> ! {
    if line > 0 {
        panic!("{}:{}: {}", path.display(), line, what)
    }
    panic!("{}: {}", path.display(), what)
}

#[derive(Clone)]
enum Base {
    Prim(&'static str),
    Str,
    Msg(String),
}

#[derive(Clone, Copy, PartialEq)]
enum Array {
    None,
    Fixed(usize),
    Unbounded,
}

struct Field {
    name: String,
    msg_type: String,
    base: Base,
    array: Array,
    doc: String,
    line: usize,
}

struct Constant {
    name: String,
    rust_type: &'static str,
    value: String,
    doc: String,
}

struct Spec {
    package: String,
    name: String,
    text: String,
    path: PathBuf,
    doc: String,
    fields: Vec<Field>,
    constants: Vec<Constant>,
    /// Nested message types as written after qualification (`std_msgs/Header`), sorted.
    deps: BTreeSet<String>,
}

fn primitive(t: &str) -> Option<&'static str> {
    Some(match t {
        "bool" => "bool",
        "byte" | "char" | "uint8" => "u8",
        "int8" => "i8",
        "int16" => "i16",
        "uint16" => "u16",
        "int32" => "i32",
        "uint32" => "u32",
        "int64" => "i64",
        "uint64" => "u64",
        "float32" => "f32",
        "float64" => "f64",
        _ => return None,
    })
}

fn is_field_name(s: &str) -> bool {
    let b = s.as_bytes();
    !b.is_empty()
        && b[0].is_ascii_lowercase()
        && b.iter().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == b'_')
        && !s.contains("__")
        && !s.ends_with('_')
}

fn is_constant_name(s: &str) -> bool {
    let b = s.as_bytes();
    !b.is_empty()
        && b[0].is_ascii_uppercase()
        && b.iter().all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || *c == b'_')
}

fn is_type_name(s: &str) -> bool {
    let b = s.as_bytes();
    !b.is_empty() && b[0].is_ascii_uppercase() && b.iter().all(|c| c.is_ascii_alphanumeric())
}

fn parse(package: &str, name: &str, text: &str, path: &Path) -> Spec {
    if !is_type_name(name) {
        fail(path, 0, "message names must be CamelCase ASCII letters and digits");
    }
    let mut spec = Spec {
        package: package.to_string(),
        name: name.to_string(),
        text: text.to_string(),
        path: path.to_path_buf(),
        doc: String::new(),
        fields: Vec::new(),
        constants: Vec::new(),
        deps: BTreeSet::new(),
    };
    // Comment lines directly above a field or constant document it; the first block documents the type.
    let mut pending: Vec<String> = Vec::new();
    let mut header_done = false;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() {
            if !header_done && !pending.is_empty() {
                spec.doc = pending.join("\n");
                header_done = true;
            }
            pending.clear();
            continue;
        }
        if let Some(c) = trimmed.strip_prefix('#') {
            pending.push(c.trim().to_string());
            continue;
        }
        header_done = true;
        let (body, comment) = match trimmed.find('#') {
            Some(k) => (trimmed[..k].trim(), trimmed[k + 1..].trim()),
            None => (trimmed, ""),
        };
        let mut doc_lines = std::mem::take(&mut pending);
        if !comment.is_empty() {
            doc_lines.push(comment.to_string());
        }
        let doc = doc_lines.join("\n");
        let mut parts = body.splitn(2, char::is_whitespace);
        let ty = parts.next().unwrap_or_default();
        let rest = parts.next().unwrap_or_default().trim();
        if rest.is_empty() {
            fail(path, line_no, &format!("expected '<type> <name>', found '{body}'"));
        }
        if let Some((cname, value)) = rest.split_once('=') {
            let cname = cname.trim();
            let value = value.trim();
            let rust_type = primitive(ty).unwrap_or_else(|| {
                fail(path, line_no, &format!("constant '{cname}': only primitive constants are supported, not '{ty}'"))
            });
            if !is_constant_name(cname) {
                fail(path, line_no, &format!("constant name '{cname}' must be UPPER_CASE"));
            }
            let value = match rust_type {
                "bool" => match value {
                    "true" | "True" | "1" => "true".to_string(),
                    "false" | "False" | "0" => "false".to_string(),
                    _ => fail(path, line_no, &format!("bad bool constant '{value}'")),
                },
                "f32" | "f64" => {
                    value.parse::<f64>().unwrap_or_else(|_| fail(path, line_no, &format!("bad number '{value}'")));
                    if value.contains(['.', 'e', 'E']) { value.to_string() } else { format!("{value}.0") }
                }
                _ => {
                    value.parse::<i128>().unwrap_or_else(|_| fail(path, line_no, &format!("bad integer '{value}'")));
                    value.to_string()
                }
            };
            spec.constants.push(Constant { name: cname.to_string(), rust_type, value, doc });
            continue;
        }
        let mut rest_parts = rest.split_whitespace();
        let fname = rest_parts.next().unwrap_or_default();
        if rest_parts.next().is_some() {
            fail(path, line_no, &format!("field '{fname}': default values are not supported"));
        }
        if !is_field_name(fname) {
            fail(path, line_no, &format!("field name '{fname}' must be lower_snake_case"));
        }
        let (base_str, array) = match ty.find('[') {
            None => (ty, Array::None),
            Some(k) => {
                let inner = ty[k + 1..]
                    .strip_suffix(']')
                    .unwrap_or_else(|| fail(path, line_no, &format!("bad array type '{ty}'")));
                let array = if inner.is_empty() || inner.starts_with("<=") {
                    if let Some(b) = inner.strip_prefix("<=") {
                        b.parse::<usize>()
                            .unwrap_or_else(|_| fail(path, line_no, &format!("bad array bound in '{ty}'")));
                    }
                    Array::Unbounded
                } else {
                    let n = inner
                        .parse::<usize>()
                        .unwrap_or_else(|_| fail(path, line_no, &format!("bad array size in '{ty}'")));
                    if n == 0 || n > 32 {
                        fail(path, line_no, &format!("fixed array size {n} in '{ty}' is not in 1..=32"));
                    }
                    Array::Fixed(n)
                };
                (&ty[..k], array)
            }
        };
        let base = if let Some(p) = primitive(base_str) {
            Base::Prim(p)
        } else if base_str == "string" || base_str.starts_with("string<=") {
            Base::Str
        } else if base_str.starts_with("wstring") {
            fail(path, line_no, "wstring is not supported");
        } else {
            let full = match base_str.split_once('/') {
                Some((pkg, t)) if !pkg.is_empty() && is_type_name(t) => format!("{pkg}/{t}"),
                None if is_type_name(base_str) => format!("{package}/{base_str}"),
                _ => fail(path, line_no, &format!("unknown type '{base_str}'")),
            };
            // rosbag2 names a dependency the way the field wrote it, qualified with our package if bare.
            spec.deps.insert(full.clone());
            Base::Msg(full)
        };
        spec.fields.push(Field { name: fname.to_string(), msg_type: ty.to_string(), base, array, doc, line: line_no });
    }
    if !header_done && !pending.is_empty() {
        spec.doc = pending.join("\n");
    }
    spec
}

const RUST_KEYWORDS: &[&str] = &[
    "as", "break", "const", "continue", "crate", "else", "enum", "extern", "false", "fn", "for", "if", "impl", "in",
    "let", "loop", "match", "mod", "move", "mut", "pub", "ref", "return", "self", "static", "struct", "super", "trait",
    "true", "type", "unsafe", "use", "where", "while", "async", "await", "dyn", "abstract", "become", "box", "do",
    "final", "macro", "override", "priv", "typeof", "unsized", "virtual", "yield", "try", "gen",
];

fn rust_ident(name: &str) -> String {
    if RUST_KEYWORDS.contains(&name) { format!("r#{name}") } else { name.to_string() }
}

fn module_of(package: &str) -> &str {
    if package == OWN_PACKAGE { "msg" } else { package }
}

fn rust_type(f: &Field) -> String {
    let base = match &f.base {
        Base::Prim(p) => p.to_string(),
        Base::Str => "::std::string::String".to_string(),
        Base::Msg(full) => {
            let (pkg, t) = full.split_once('/').unwrap();
            format!("crate::{}::{}", module_of(pkg), t)
        }
    };
    match f.array {
        Array::None => base,
        Array::Fixed(n) => format!("[{base}; {n}]"),
        Array::Unbounded => format!("::std::vec::Vec<{base}>"),
    }
}

/// rosbag2's "complete message definition": the root text, then each dependency once, depth first,
/// in sorted order, each behind a line of 80 '=' and `MSG: pkg/Type`.
fn full_definition(specs: &BTreeMap<String, Spec>, root: &Spec) -> String {
    fn visit(specs: &BTreeMap<String, Spec>, spec: &Spec, seen: &mut BTreeSet<String>, out: &mut String) {
        for dep in &spec.deps {
            if seen.insert(dep.clone()) {
                let d = &specs[dep];
                out.push('\n');
                out.push_str(&"=".repeat(80));
                out.push_str("\nMSG: ");
                out.push_str(dep);
                out.push('\n');
                out.push_str(&d.text);
                visit(specs, d, seen, out);
            }
        }
    }
    let mut out = root.text.clone();
    let mut seen = BTreeSet::new();
    visit(specs, root, &mut seen, &mut out);
    out
}

fn doc_attr(out: &mut String, indent: &str, doc: &str) {
    for line in doc.lines() {
        let _ = writeln!(out, "{indent}#[doc = {:?}]", format!(" {line}"));
    }
}

fn generate(specs: &BTreeMap<String, Spec>) -> String {
    let mut out = String::from("// @generated by msgs/build.rs from the .msg files. Do not edit.\n\n");
    let mut by_module: BTreeMap<&str, Vec<&Spec>> = BTreeMap::new();
    for s in specs.values() {
        by_module.entry(module_of(&s.package)).or_default().push(s);
    }
    for (module, list) in &by_module {
        let package = &list[0].package;
        let _ = writeln!(out, "/// Messages of the ROS 2 package `{package}`.");
        let _ = writeln!(out, "pub mod {module} {{");
        for s in list {
            let rel = s.path.strip_prefix(std::env::var("CARGO_MANIFEST_DIR").unwrap()).unwrap_or(&s.path);
            let mut doc = if s.doc.is_empty() { String::new() } else { format!("{}\n\n", s.doc) };
            let _ = write!(doc, "ROS 2 type `{}/msg/{}`, generated from `msgs/{}`.", s.package, s.name, rel.display());
            doc_attr(&mut out, "    ", &doc);
            out.push_str("    #[derive(Clone, Debug, Default, PartialEq, ::serde::Serialize, ::serde::Deserialize)]\n");
            let _ = writeln!(out, "    pub struct {} {{", s.name);
            for f in &s.fields {
                let fdoc =
                    if f.doc.is_empty() { format!("`{}`", f.msg_type) } else { format!("`{}`: {}", f.msg_type, f.doc) };
                doc_attr(&mut out, "        ", &fdoc);
                if matches!(f.base, Base::Prim("u8")) && f.array == Array::Unbounded {
                    out.push_str("        #[serde(with = \"serde_bytes\")]\n");
                }
                let _ = writeln!(out, "        pub {}: {},", rust_ident(&f.name), rust_type(f));
            }
            out.push_str("    }\n");
            if !s.constants.is_empty() {
                let _ = writeln!(out, "    impl {} {{", s.name);
                for c in &s.constants {
                    if !c.doc.is_empty() {
                        doc_attr(&mut out, "        ", &c.doc);
                    }
                    let _ = writeln!(out, "        pub const {}: {} = {};", c.name, c.rust_type, c.value);
                }
                out.push_str("    }\n");
            }
            let _ = writeln!(out, "    impl crate::RosMessage for {} {{", s.name);
            let _ = writeln!(out, "        const PACKAGE: &'static str = {:?};", s.package);
            let _ = writeln!(out, "        const NAME: &'static str = {:?};", s.name);
            let _ =
                writeln!(out, "        const TYPE_NAME: &'static str = {:?};", format!("{}/msg/{}", s.package, s.name));
            let _ = writeln!(
                out,
                "        const DDS_TYPE_NAME: &'static str = {:?};",
                format!("{}::msg::dds_::{}_", s.package, s.name)
            );
            let _ = writeln!(out, "        const MSG_TEXT: &'static str = {:?};", s.text);
            let _ = writeln!(out, "        const DEFINITION: &'static str = {:?};", full_definition(specs, s));
            out.push_str("    }\n");
        }
        out.push_str("}\n\n");
    }
    out.push_str("/// Every message type this crate defines, for tools that look types up by name.\n");
    out.push_str("pub const ALL_TYPES: &[crate::TypeInfo] = &[\n");
    for s in specs.values() {
        let _ = writeln!(out, "    crate::TypeInfo::of::<crate::{}::{}>(),", module_of(&s.package), s.name);
    }
    out.push_str("];\n");
    out
}
