//! A minimal safetensors writer and reader for named F32 tensors plus string metadata (the
//! optimiser state of checkpoints). The format: an 8-byte little-endian header length, a JSON
//! header `{name: {dtype, shape, data_offsets}, "__metadata__": {..}}`, then the raw data.
//!
//! Limitations: F32 only; the whole file is read into memory.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::Path;

/// Reading failed.
#[derive(Debug)]
pub enum ReadError {
    /// I/O.
    Io(std::io::Error),
    /// Not a valid file.
    Format(String),
}

/// A file's contents: tensors `(name, shape, data)` in file order and the metadata.
pub struct TensorFile {
    /// Tensors.
    pub tensors: Vec<(String, Vec<usize>, Vec<f32>)>,
    /// Metadata strings.
    pub meta: BTreeMap<String, String>,
}

/// Write `tensors` and `meta` to `path` (through `path.tmp` and a rename).
pub fn write(
    path: &Path,
    tensors: &[(String, Vec<usize>, Vec<f32>)],
    meta: &[(String, String)],
) -> std::io::Result<()> {
    let mut header = serde_json::Map::new();
    let m: serde_json::Map<String, serde_json::Value> =
        meta.iter().map(|(k, v)| (k.clone(), serde_json::Value::String(v.clone()))).collect();
    header.insert("__metadata__".into(), serde_json::Value::Object(m));
    let mut offset = 0usize;
    for (name, shape, data) in tensors {
        let end = offset + data.len() * 4;
        header.insert(name.clone(), serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [offset, end]}));
        offset = end;
    }
    let mut text = serde_json::to_vec(&serde_json::Value::Object(header))?;
    while text.len() % 8 != 0 {
        text.push(b' ');
    }
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        f.write_all(&(text.len() as u64).to_le_bytes())?;
        f.write_all(&text)?;
        for (_, _, data) in tensors {
            for x in data {
                f.write_all(&x.to_le_bytes())?;
            }
        }
        f.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// Read a file written by [`write()`] (or any safetensors file of F32 tensors).
pub fn read(path: &Path) -> Result<TensorFile, ReadError> {
    let bytes = std::fs::read(path).map_err(ReadError::Io)?;
    let bad = |m: &str| ReadError::Format(m.to_string());
    if bytes.len() < 8 {
        return Err(bad("shorter than the 8-byte header length: not a safetensors file"));
    }
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap_or_default()) as usize;
    let body_start = 8usize
        .checked_add(n)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| bad("header length runs past the end of the file"))?;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..body_start])
        .map_err(|e| ReadError::Format(format!("header is not JSON: {e}")))?;
    let obj = header.as_object().ok_or_else(|| bad("header is not a JSON object"))?;
    let body = &bytes[body_start..];
    let mut meta = BTreeMap::new();
    let mut tensors = Vec::new();
    for (name, v) in obj {
        if name == "__metadata__" {
            for (k, s) in v.as_object().into_iter().flatten() {
                meta.insert(k.clone(), s.as_str().unwrap_or_default().to_string());
            }
            continue;
        }
        let field = |f: &str| v.get(f).ok_or_else(|| ReadError::Format(format!("tensor `{name}` has no `{f}`")));
        if field("dtype")?.as_str() != Some("F32") {
            return Err(ReadError::Format(format!("tensor `{name}` is not F32")));
        }
        let shape: Vec<usize> = serde_json::from_value(field("shape")?.clone())
            .map_err(|e| ReadError::Format(format!("tensor `{name}` shape: {e}")))?;
        let off: [usize; 2] = serde_json::from_value(field("data_offsets")?.clone())
            .map_err(|e| ReadError::Format(format!("tensor `{name}` data_offsets: {e}")))?;
        let count = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if off[0] > off[1] || off[1] > body.len() || count.map(|c| c * 4) != Some(off[1] - off[0]) {
            return Err(ReadError::Format(format!(
                "tensor `{name}`: data offsets {off:?} do not fit shape {shape:?} in a body of {} bytes",
                body.len()
            )));
        }
        let data = body[off[0]..off[1]].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        tensors.push((name.clone(), shape, data));
    }
    Ok(TensorFile { tensors, meta })
}
