//! Named F32 tensors plus string metadata in a safetensors file (the optimiser state of
//! checkpoints), read and written with the [`safetensors`] crate. Files written before equiarm used
//! that crate were safetensors files already (8-byte header length, JSON header, raw little-endian
//! data) and read the same way.
//!
//! Limitations: F32 only; the whole file is read into memory.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use equiarm_types::files::{FileError, at, replace};

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};

/// Reading failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// I/O.
    #[error("{0}")]
    Io(std::io::Error),
    /// Not a valid file.
    #[error("{0}")]
    Format(String),
}

/// A file's contents: tensors `(name, shape, data)` sorted by name, and the metadata.
pub struct TensorFile {
    /// Tensors.
    pub tensors: Vec<(String, Vec<usize>, Vec<f32>)>,
    /// Metadata strings.
    pub meta: BTreeMap<String, String>,
}

/// Write `tensors` and `meta` to `path` (through `path.tmp`, synced, and a rename). Shapes must
/// match the data lengths.
pub fn write(
    path: &Path,
    tensors: &[(String, Vec<usize>, Vec<f32>)],
    meta: &[(String, String)],
) -> Result<(), FileError> {
    let invalid = |e: safetensors::SafeTensorError| {
        at(path)(std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))
    };
    let bytes: Vec<Vec<u8>> =
        tensors.iter().map(|(_, _, data)| data.iter().flat_map(|x| x.to_le_bytes()).collect()).collect();
    let views = tensors
        .iter()
        .zip(&bytes)
        .map(|((name, shape, _), b)| Ok((name.as_str(), TensorView::new(Dtype::F32, shape.clone(), b)?)))
        .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
        .map_err(invalid)?;
    let file = with_metadata(safetensors::serialize(views, None::<HashMap<String, String>>).map_err(invalid)?, meta)
        .map_err(at(path))?;
    replace(path, file)
}

/// `file` (a safetensors file without metadata) with `meta` as its `__metadata__`, keys sorted.
// NOTE: the safetensors crate takes metadata as a HashMap and writes it in the map's random
// iteration order, so the same state saved twice gave different bytes (found by equiarm_fuzz,
// whose seeds must be the same every time); here the header is rebuilt with the keys in order.
fn with_metadata(file: Vec<u8>, meta: &[(String, String)]) -> std::io::Result<Vec<u8>> {
    let bad = || std::io::Error::new(std::io::ErrorKind::InvalidData, "safetensors wrote an unexpected header");
    let n = usize::try_from(u64::from_le_bytes(file.get(..8).ok_or_else(bad)?.try_into().map_err(|_| bad())?))
        .map_err(|_| bad())?;
    let header = std::str::from_utf8(file.get(8..8 + n).ok_or_else(bad)?).map_err(|_| bad())?.trim_end();
    let tensors = header.strip_prefix('{').ok_or_else(bad)?;
    if meta.is_empty() {
        return Ok(file);
    }
    let sorted: BTreeMap<&str, &str> = meta.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let meta_json = serde_json::to_string(&sorted).map_err(|_| bad())?;
    let sep = if tensors.trim_start().starts_with('}') { "" } else { "," };
    let mut text = format!("{{\"__metadata__\":{meta_json}{sep}{tensors}").into_bytes();
    while !text.len().is_multiple_of(8) {
        text.push(b' ');
    }
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend(text);
    out.extend(&file[8 + n..]);
    Ok(out)
}

/// Read a file written by [`write()`] (or any safetensors file of F32 tensors).
pub fn read(path: &Path) -> Result<TensorFile, ReadError> {
    let bytes = std::fs::read(path).map_err(ReadError::Io)?;
    let st = SafeTensors::deserialize(&bytes).map_err(|e| ReadError::Format(format!("not a safetensors file: {e}")))?;
    let (_, header) =
        SafeTensors::read_metadata(&bytes).map_err(|e| ReadError::Format(format!("not a safetensors file: {e}")))?;
    let meta = header.metadata().iter().flatten().map(|(k, v)| (k.clone(), v.clone())).collect();
    let mut tensors = Vec::new();
    for (name, view) in st.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(ReadError::Format(format!("tensor `{name}` is {}, not F32", view.dtype())));
        }
        let data = view.data().chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        tensors.push((name, view.shape().to_vec(), data));
    }
    tensors.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(TensorFile { tensors, meta })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tensors_and_metadata_round_trip() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let path = dir.join("state.safetensors");
        let tensors = vec![
            ("b.v".to_string(), vec![2, 3], vec![1.0, -2.5, 3.25, f32::MIN_POSITIVE, 0.0, -0.0]),
            ("a.m".to_string(), vec![1], vec![7.0]),
            ("empty".to_string(), vec![0, 4], vec![]),
        ];
        write(&path, &tensors, &[("step".into(), "42".into()), ("lr".into(), "0.001".into())]).unwrap();
        assert!(!path.with_extension("tmp").exists());
        let f = read(&path).unwrap();
        let mut want = tensors.clone();
        want.sort_by(|a, b| a.0.cmp(&b.0));
        // Bit-identical values, -0.0 included.
        let bits = |t: &[(String, Vec<usize>, Vec<f32>)]| {
            t.iter()
                .map(|(n, s, d)| (n.clone(), s.clone(), d.iter().map(|x| x.to_bits()).collect::<Vec<_>>()))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&f.tensors), bits(&want));
        assert_eq!(f.meta.get("step").map(String::as_str), Some("42"));
        assert_eq!(f.meta.get("lr").map(String::as_str), Some("0.001"));
    }

    /// A file laid out as equiarm's own writer did before this module used the safetensors crate:
    /// header keys in any order, `__metadata__` first, padded with spaces to 8 bytes.
    #[test]
    fn files_of_the_former_writer_still_read() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let path = dir.join("old.safetensors");
        let header = r#"{"__metadata__":{"step":"3"},"w.m":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},"w.v":{"dtype":"F32","shape":[2],"data_offsets":[8,16]}}"#;
        let mut text = header.as_bytes().to_vec();
        while !text.len().is_multiple_of(8) {
            text.push(b' ');
        }
        let mut bytes = (text.len() as u64).to_le_bytes().to_vec();
        bytes.extend(&text);
        for x in [0.5f32, -1.0, 2.0, 4.0] {
            bytes.extend(x.to_le_bytes());
        }
        std::fs::write(&path, bytes).unwrap();
        let f = read(&path).unwrap();
        assert_eq!(
            f.tensors,
            vec![("w.m".to_string(), vec![2], vec![0.5, -1.0]), ("w.v".to_string(), vec![2], vec![2.0, 4.0])]
        );
        assert_eq!(f.meta.get("step").map(String::as_str), Some("3"));
    }

    /// Regression (issue 28, found by equiarm_fuzz): the metadata came out in a HashMap's random
    /// order, so the same optimiser state saved twice gave different files.
    #[test]
    fn the_same_state_always_gives_the_same_bytes() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let path = dir_tmp.path().join("state.safetensors");
        let tensors = vec![("w.m".to_string(), vec![2], vec![0.5, -1.0]), ("w.v".to_string(), vec![2], vec![2.0, 4.0])];
        let meta: Vec<(String, String)> =
            ["step", "lr", "beta1", "beta2"].iter().map(|k| (k.to_string(), format!("{k}-value"))).collect();
        write(&path, &tensors, &meta).unwrap();
        let first = std::fs::read(&path).unwrap();
        for i in 0..16 {
            write(&path, &tensors, &meta).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), first, "write {i}");
        }
        let f = read(&path).unwrap();
        assert_eq!(f.meta.len(), 4);
        assert_eq!(f.meta.get("beta2").map(String::as_str), Some("beta2-value"));
        assert_eq!(f.tensors.len(), 2);
        // without metadata the file is what the safetensors crate writes
        write(&path, &tensors, &[]).unwrap();
        assert!(read(&path).unwrap().meta.is_empty());
    }

    #[test]
    fn bad_files_are_format_errors() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let short = dir.join("short.safetensors");
        std::fs::write(&short, b"abc").unwrap();
        assert!(matches!(read(&short), Err(ReadError::Format(m)) if m.contains("not a safetensors file")));
        let truncated = dir.join("truncated.safetensors");
        write(&truncated, &[("w".into(), vec![4], vec![1.0; 4])], &[]).unwrap();
        let bytes = std::fs::read(&truncated).unwrap();
        std::fs::write(&truncated, &bytes[..bytes.len() - 4]).unwrap();
        assert!(matches!(read(&truncated), Err(ReadError::Format(_))));
        let f16 = dir.join("f16.safetensors");
        let view = TensorView::new(Dtype::F16, vec![2], &[0, 60, 0, 60]).unwrap();
        std::fs::write(&f16, safetensors::serialize([("h", view)], None).unwrap()).unwrap();
        assert!(matches!(read(&f16), Err(ReadError::Format(m)) if m.contains("`h` is F16")));
        assert!(matches!(read(&dir.join("missing.safetensors")), Err(ReadError::Io(_))));
        // A shape that does not match the data is refused when writing.
        let e = write(&dir.join("w.safetensors"), &[("w".into(), vec![3], vec![1.0; 4])], &[]).unwrap_err();
        assert_eq!(e.cause.kind(), std::io::ErrorKind::InvalidInput);
    }
}
